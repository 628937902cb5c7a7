"""curvature_error's sparse form (two columns a target, the stencils as three diagonals,
vectorized over targets) against the dense (M, n) implementation it replaced, kept here
as the reference (with the interval's own curvature of issue 35's round 5 added, target
by target); and smootherror._line_weights against its former loop."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hexatherm.core.curvature import CurvatureError, curvature_error
from hexatherm.workflows.process.smootherror import _line_weights


def dense_stencils(t: np.ndarray) -> np.ndarray:
    """The former second_difference_stencils: (n, n)."""
    n = len(t)
    out = np.zeros((n, n))
    for i in range(1, n - 1):
        h1, h2 = t[i] - t[i - 1], t[i + 1] - t[i]
        if h1 <= 0 or h2 <= 0:
            continue
        out[i, i - 1] = 2 / (h1 * (h1 + h2))
        out[i, i] = -2 / (h1 * h2)
        out[i, i + 1] = 2 / (h2 * (h1 + h2))
    return out


def dense_curvature_error(
    t: np.ndarray, g: np.ndarray, s: np.ndarray, ts: np.ndarray, used: np.ndarray, seen: float
) -> tuple[np.ndarray, np.ndarray]:
    """The former curvature_error, target by target over dense (n,) vectors: (vector,
    interval)."""
    m, n = len(ts), len(t)
    vector = np.zeros((m, 6))
    interval = np.full(m, -1, dtype=np.intp)
    stencils = dense_stencils(t)
    has = np.abs(stencils).sum(axis=1) > 0
    around = np.searchsorted(t, ts, side="right") - 1
    for k in range(m):
        p = min(int(around[k]), n - 2)
        if not used[k].any() or p < 0 or t[p + 1] <= t[p]:
            continue
        w = (ts[k] - t[p]) / (t[p + 1] - t[p])
        line = np.zeros(n)
        line[p], line[p + 1] = 1.0 - w, w
        rows = [i for i in (p, p + 1) if has[i]]
        if not rows and np.allclose(used[k], line):
            continue
        f = (ts[k] - t[p]) * (t[p + 1] - ts[k]) / 2
        if seen > 0:
            f = max(0.0, f - seen**2 / 8)
        readings = [stencils[rows].mean(axis=0)] if rows else [np.zeros(n)]
        if 1 <= p and p + 2 <= n - 1 and all(has[i] for i in (p - 1, p, p + 1, p + 2)):
            # the interval's own curvature (issue 35, round 5): the larger error is taken
            readings.append(stencils[p] + stencils[p + 1] - (stencils[p - 1] + stencils[p + 2]) / 2)
        best = np.zeros(6)
        for reading in readings:
            c = used[k] - line + (f * reading if rows else 0.0)
            error = c @ g
            noise = np.einsum("j,jlm->lm", c**2, s)
            total = float(error @ error)
            share = max(0.0, 1.0 - float(np.trace(noise)) / total) if total > 0 else 0.0
            if share * total > best @ best:
                best = np.sqrt(share) * error
        vector[k] = best
        interval[k] = around[k]
    return vector, interval


def loop_line_weights(t: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """The former _line_weights: (M, n)."""
    n = t.size
    out = np.zeros((ts.size, n))
    p = np.searchsorted(t, ts, side="right") - 1
    for k, (i, tk) in enumerate(zip(p, ts, strict=True)):
        if 0 <= i < n - 1 and t[i + 1] > t[i]:
            w = (tk - t[i]) / (t[i + 1] - t[i])
            out[k, i], out[k, i + 1] = 1.0 - w, w
    return out


def to_dense(columns: np.ndarray, weights: np.ndarray, n: int) -> np.ndarray:
    out = np.zeros((columns.shape[0], n))
    if n == 0:
        assert not weights.any()
        return out
    for j in range(columns.shape[1]):
        np.add.at(out, (np.arange(columns.shape[0]), columns[:, j]), weights[:, j])
    return out


def case(seed: int) -> tuple[np.ndarray, ...]:
    """Random references (some sharing a time), a growth of any shape and size, noise,
    and targets before, between, on and past the references, with every kind of weights:
    the line's two, one reference (before, after, nearest, the last past it), none."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 12))
    t = np.sort(rng.uniform(0.0, 5000.0, n))
    if n > 3 and seed % 2:
        t[2] = t[1]  # two references at one time
    if n > 5 and seed % 3 == 0:
        t[4] = t[3] = t[5]
    g = (
        rng.normal(size=(n, 6)) * 10.0 ** rng.uniform(-4, 0)
        + np.outer(t**2, rng.normal(size=6)) * 1e-9
    )
    a = rng.normal(size=(n, 6, 6)) * 1e-4
    s = a @ np.swapaxes(a, 1, 2) * rng.choice([0.0, 1.0, 1e3])
    m = 60
    ts = np.concatenate(
        [
            rng.uniform(t[0] - 500.0, t[-1] + 500.0, m - 8),
            t[rng.integers(0, n, 4)],  # on a reference
            [t[0] - 1.0, t[-1] + 1.0, t[-1] + 1e4, t[0]],
        ]
    )
    m = ts.size
    around = np.searchsorted(t, ts, side="right") - 1
    p = np.clip(np.minimum(around, n - 2), 0, n - 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.nan_to_num((ts - t[p]) / (t[p + 1] - t[p]))
    columns = np.stack([p, p + 1], axis=1)
    weights = np.stack([1.0 - w, w], axis=1)
    kind = rng.integers(0, 6, m)
    one = np.stack([np.zeros(m), np.ones(m)], axis=1)
    weights = np.where((kind == 1)[:, None], one[:, ::-1], weights)  # the one before
    weights = np.where((kind == 2)[:, None], one, weights)  # the one after
    weights = np.where((kind == 3)[:, None], 0.0, weights)  # none
    far = rng.integers(0, n, m)
    columns = np.where((kind == 4)[:, None], np.stack([far, far], axis=1), columns)
    weights = np.where((kind == 4)[:, None], np.array([0.7, 0.3]), weights)  # anywhere
    columns = np.where(weights == 0.0, 0, columns)
    return t, g, s, ts, columns.astype(np.intp), weights


def check(
    got: CurvatureError, want: tuple[np.ndarray, np.ndarray], scale: float, g: np.ndarray
) -> None:
    vector, interval = want
    assert got.vector_mm is not None and got.interval is not None
    if got.spread_mm is not None:  # legs whose histories differ: along the first shape, the
        # rest leg by leg (the dense form's vector split so)
        shape = np.linalg.svd(g, full_matrices=False)[2][0]
        along = np.where((interval >= 0)[:, None], (vector @ shape)[:, None] * shape, 0.0)
        np.testing.assert_allclose(
            got.spread_mm, np.abs(vector - along), rtol=1e-12, atol=1e-13 * scale
        )
        vector = along
    np.testing.assert_array_equal(got.interval, interval)
    np.testing.assert_allclose(got.vector_mm, vector, rtol=1e-12, atol=1e-13 * scale)
    np.testing.assert_array_equal(got.evaluated, interval >= 0)


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("seen", [0.0, 300.0])
def test_the_sparse_form_is_the_dense_one(seed: int, seen: float) -> None:
    t, g, s, ts, columns, weights = case(seed)
    dense = to_dense(columns, weights, t.size)
    want = dense_curvature_error(t, g, s, ts, dense, seen)
    scale = float(np.abs(g).max()) * 10.0
    check(curvature_error(t, g, s, ts, weights, seen, columns), want, scale, g)
    check(curvature_error(t, g, s, ts, dense, seen), want, scale, g)  # dense rows given
    # the line's own weights, as the smooth fit's fallback takes them
    line_cols, line_w = _line_weights(t, ts)
    line = loop_line_weights(t, ts)
    np.testing.assert_array_equal(to_dense(line_cols, line_w, t.size), line)
    check(
        curvature_error(t, g, s, ts, line_w, seen, line_cols),
        dense_curvature_error(t, g, s, ts, line, seen),
        scale,
        g,
    )


def test_hostile_references() -> None:
    """One reference used by every target, all references at one time, two references,
    one, none; rows of zeros."""
    rng = np.random.default_rng(7)
    for t in (
        np.array([0.0, 100.0]),
        np.array([50.0, 50.0, 50.0]),
        np.array([0.0, 100.0, 100.0, 250.0]),
        np.array([10.0]),
        np.zeros(0),
    ):
        n = t.size
        g = rng.normal(size=(n, 6)) * 1e-3
        s = np.broadcast_to(np.eye(6) * 1e-10, (n, 6, 6))
        ts = np.array([-10.0, 0.0, 25.0, 50.0, 99.0, 100.0, 160.0, 400.0])
        for dense in (np.zeros((ts.size, n)), np.zeros((ts.size, n))):
            if n:
                dense[:, 0] = 1.0  # the first reference alone
                dense[3] = 0.0
            want = dense_curvature_error(t, g, s, ts, dense, 0.0) if n else None
            got = curvature_error(t, g, s, ts, dense)
            if want is None:
                assert not got.evaluated.any()
            else:
                check(got, want, 1e-2, g)
            cols, w = _line_weights(t, ts)
            np.testing.assert_array_equal(to_dense(cols, w, n), loop_line_weights(t, ts))


def test_widest_gap_is_read_over_distinct_times() -> None:
    # three of five references share a time (a CMM output stamped once): the median of
    # all spacings is 0; the widest gap is read over the distinct ones: 300 s over their
    # median, 200 s
    t = np.array([0.0, 0.0, 0.0, 100.0, 400.0])
    g = np.outer(1e-6 * t**2, np.ones(6))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        err = curvature_error(t, g, np.zeros((5, 6, 6)), [250.0], [[0, 0, 0, 0.5, 0.5]])
        same = curvature_error(np.zeros(3), g[:3], np.zeros((3, 6, 6)), [0.0], [[1, 0, 0]])
    assert err.widest_gap == pytest.approx(300.0 / 200.0)
    assert same.widest_gap == 1.0
