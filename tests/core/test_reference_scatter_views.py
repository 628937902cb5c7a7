"""``propagation.reference_scatter`` takes the three neighbours as views when every
measurement is kept (a log whose times all differ) and gathers them otherwise: against
the former code (always gathered, kept here as the reference), the same numbers to the
bit on random logs, weights, repeated and equal times, and too short series."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.propagation import reference_scatter


def _former(times_s, values, weights=None):  # type: ignore[no-untyped-def]
    """The code before: the neighbours always gathered by index."""
    t = np.asarray(times_s, dtype=float)
    v = np.asarray(values, dtype=float)
    v = v.reshape(len(t), -1)
    w = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=float)
    if len(t) < 3:
        return float("nan"), 0
    keep = np.flatnonzero(t[2:] - t[:-2] > 0)
    if not keep.size:
        return float("nan"), 0
    before, mid, after = keep, keep + 1, keep + 2
    f = (t[mid] - t[before]) / (t[after] - t[before])
    e = v[mid] - ((1 - f)[:, None] * v[before] + f[:, None] * v[after])
    factor = 1 / w[mid] + (1 - f) ** 2 / w[before] + f**2 / w[after]
    return float((e**2 / factor[:, None]).mean()), int(e.size)


def _same(a: tuple[float, int], b: tuple[float, int]) -> bool:
    return a[1] == b[1] and (a[0] == b[0] or (np.isnan(a[0]) and np.isnan(b[0])))


@pytest.mark.parametrize("seed", range(8))
def test_random_logs(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 400))
    t = np.sort(rng.uniform(0, 3600, n))
    if seed % 2:  # repeated times: some neighbours at one time, gathered
        t[rng.integers(0, n, size=n // 5)] = t[0]
        t = np.sort(t)
    v = rng.normal(size=(n, int(rng.integers(1, 7)))) * 1e-3
    w = rng.integers(1, 5, size=n).astype(float) if seed % 3 == 0 else None
    assert _same(reference_scatter(t, v, w), _former(t, v, w))
    assert _same(reference_scatter(t, v[:, 0], w), _former(t, v[:, 0], w))


@pytest.mark.parametrize(
    "times",
    [[0.0, 1.0], [0.0, 1.0, 2.0], [5.0, 5.0, 5.0, 5.0], [0.0, 0.0, 1.0, 1.0], [0.0, 1.0, 1.0, 2.0]],
)
def test_short_and_equal_times(times: list[float]) -> None:
    v = np.arange(len(times) * 2, dtype=float).reshape(-1, 2) ** 2
    assert _same(reference_scatter(times, v), _former(times, v))
