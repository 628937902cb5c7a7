"""neighbour_shape_error (two weights a target) against log_shape_error (the dense weights)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.smoothbias import log_shape_error, neighbour_shape_error


def dense(columns: np.ndarray, weights: np.ndarray, n: int) -> np.ndarray:
    """The (M, 6, n) weights log_shape_error takes, the same on every leg."""
    used = np.zeros((columns.shape[0], n))
    for k in range(columns.shape[0]):
        for j in range(columns.shape[1]):
            used[k, columns[k, j]] += weights[k, j]
    return np.broadcast_to(used[:, None, :], (columns.shape[0], 6, n))


def a_log(rng: np.random.Generator, span: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Log times (irregular), the legs' temperatures (a heating with a kink), gains."""
    times = np.sort(rng.uniform(-0.1 * span, 1.1 * span, 60))
    legs = 20.0 + np.cumsum(rng.normal(0.0, 0.05, (60, 6)), axis=0)
    legs[30:] += np.linspace(0.0, 1.5, 30)[:, None]  # switched on mid-session
    return times, legs, rng.uniform(5e-3, 2e-2, 6)


@pytest.mark.parametrize("seed", range(6))
def test_the_same_error_as_the_dense_weights(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(2, 40)), int(rng.integers(1, 200))
    ref_times = np.sort(rng.uniform(0.0, 3600.0, n))
    ref_times[rng.integers(0, n)] = ref_times[0]  # two references at one time
    targets = rng.uniform(-100.0, 3700.0, m)  # some outside the references
    before = rng.integers(0, n, m)
    after = np.minimum(before + rng.integers(1, 3, m), n - 1)
    w = rng.uniform(0.0, 1.0, m)
    w[: m // 4] = rng.choice([0.0, 1.0, 0.5], m // 4)  # on a reference, halfway
    columns = np.stack([before, after], axis=1)
    weights = np.stack([1.0 - w, w], axis=1)
    # one side only (the other's weight 0, its column anything), or none
    weights[rng.random(m) < 0.2, 0] = 0.0
    weights[rng.random(m) < 0.2, 1] = 0.0
    single = columns[:, 0] == columns[:, 1]  # the last reference on both sides: one
    weights[single, 1] = 0.0
    log = a_log(rng, 3600.0)
    got = neighbour_shape_error(columns, weights, ref_times, targets, *log)
    want = log_shape_error(dense(columns, weights, n), ref_times, targets, *log)
    assert got.shape == want.shape == (m, 6)
    # a sum of the same two products (the zeros add nothing): equal to rounding
    np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-15 * np.abs(want).max())


def test_more_references_a_target_and_none() -> None:
    rng = np.random.default_rng(7)
    n, m = 12, 50
    ref_times = np.linspace(0.0, 1100.0, n)
    targets = rng.uniform(0.0, 1100.0, m)
    columns = np.stack([rng.permutation(n)[:4] for _ in range(m)])  # distinct in a row
    weights = rng.normal(size=(m, 4))
    weights[0] = 0.0  # no reference used: the log's growth at the target, negated
    log = a_log(rng, 1100.0)
    got = neighbour_shape_error(columns, weights, ref_times, targets, *log)
    want = log_shape_error(dense(columns, weights, n), ref_times, targets, *log)
    np.testing.assert_allclose(got, want, rtol=0.0, atol=1e-14 * np.abs(want).max())
    assert np.all(got[0] <= 0.0) and np.any(got[0] < 0.0)  # -s T(t) with T > 0, s > 0
