"""carryerror's divided differences' operator as a band against the dense (sets, n)
operator it replaced (``_divided`` of the identity)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.workflows.process.carryerror import _divided, _divided_band


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_the_band_is_the_dense_operator(seed: int, order: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(order + 1, 40))
    t = np.cumsum(rng.uniform(1.0, 500.0, n))
    dense = _divided(t, np.eye(n), order)  # (n - order, n)
    band = _divided_band(t, order)
    assert band.shape == (n - order, order + 1)
    rows = np.arange(n - order)[:, None]
    on = rows + np.arange(order + 1)
    np.testing.assert_array_equal(band, dense[rows, on])  # the same numbers
    rest = dense.copy()
    rest[rows, on] = 0.0
    np.testing.assert_array_equal(rest, 0.0)
