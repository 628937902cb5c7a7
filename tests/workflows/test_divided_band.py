"""carryerror's divided differences' operator as a band against the dense (sets, n)
operator it replaced (``_divided`` of the identity), and the noise it gives."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.workflows.process.carryerror import _beyond_noise, _divided, _divided_band


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
    # the noise beyond which the differences count, as the dense operator gave it
    values = np.outer(1 - np.exp(-t / t[-1]), rng.uniform(0.5, 2.0, 6)) * 1e-2
    values += rng.normal(0, 1e-5, values.shape)
    var = rng.uniform(0.5, 2.0, values.shape) * 1e-10
    dd = _divided(t, values, order)
    shape = np.linalg.svd(values, full_matrices=False)[2][0]
    shape = shape * (-1.0 if shape @ values.sum(axis=0) < 0 else 1.0)
    along = dd @ shape
    noise = float(np.mean((dense**2 @ var) @ shape**2))
    rms = np.sqrt(max(float(np.mean(along**2)) - noise, 0.0))
    np.testing.assert_allclose(
        _beyond_noise(t, values, var, order),
        rms * np.sign(np.mean(along)) * shape,
        rtol=1e-12,
        atol=1e-14 * np.linalg.norm(dd),
    )
