"""smootherror.neighbour_weights against the dense weights the loop over targets made."""

from __future__ import annotations

from types import SimpleNamespace
from typing import cast

import numpy as np
import pytest

from hexatherm.core.correction import Correction
from hexatherm.workflows.process.smootherror import neighbour_weights


def loop_weights(
    before: np.ndarray, after: np.ndarray, w: np.ndarray, refs: np.ndarray
) -> np.ndarray:
    """curvature_excess's weights (M, n) as it made them before, target by target."""
    position = {int(step): i for i, step in enumerate(refs)}
    used = np.zeros((before.size, refs.size))
    for k, (b, a, wk) in enumerate(zip(before, after, w, strict=True)):
        if b >= 0:
            used[k, position[int(b)]] += 1.0 - wk
        if a >= 0:
            used[k, position[int(a)]] += wk
    return used


@pytest.mark.parametrize("seed", range(5))
def test_the_two_weights_are_the_loops(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_steps = 300
    refs = np.sort(rng.choice(n_steps, int(rng.integers(2, 60)), replace=False))
    m = 120
    pick = rng.integers(0, refs.size - 1, m)
    before, after = refs[pick], refs[pick + 1]
    w = rng.uniform(0.0, 1.0, m)
    w[:20] = rng.choice([0.0, 1.0, 0.5], 20)
    # a side not used (before the first reference, after the last, --interpolation
    # before/after/nearest), and neither
    before = np.where(rng.random(m) < 0.2, -1, before)
    after = np.where(rng.random(m) < 0.2, -1, after)
    w = np.where(after < 0, 0.0, np.where(before < 0, 1.0, w))
    before[:3], after[:3] = refs[0], refs[0]  # one reference on both sides
    correction = cast(
        Correction, SimpleNamespace(before_index=before, after_index=after, weight_after=w)
    )
    columns, weights = neighbour_weights(correction, refs, n_steps)
    want = loop_weights(before, after, w, refs)
    got = np.zeros_like(want)
    for j in range(2):
        np.add.at(got, (np.arange(m), columns[:, j]), weights[:, j])
    np.testing.assert_array_equal(got, want)  # the same sums of the same numbers
    # one column a reference: its weights in the first, the second's 0
    np.testing.assert_array_equal(weights[columns[:, 0] == columns[:, 1], 1], 0.0)
    np.testing.assert_array_equal(np.sum(weights**2, axis=1), np.sum(want**2, axis=1))
    np.testing.assert_array_equal((weights != 0).any(axis=1), want.any(axis=1))
