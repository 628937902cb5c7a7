"""The vectorized first-order lag and the wider registry of effects (issue 14, part 3)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.effects import first_order_lag


def lag_by_loop(times_s, values, tau_s, query_s):
    """The lag as it was computed before: the exact per-segment solution, sample by
    sample in a Python loop (the reference)."""
    t = np.asarray(times_s, dtype=float)
    x = np.asarray(values, dtype=float)
    flat = x.ndim == 1
    x = x.reshape(t.size, -1)
    h = np.diff(t)
    slope = np.zeros((t.size, x.shape[1]))
    moving = h > 0
    slope[:-1][moving] = np.diff(x, axis=0)[moving] / h[moving, None]

    def advance(y_j, x_j, b, d):
        decay = np.exp(-d / tau_s)
        rise = -np.expm1(-d / tau_s)
        return x_j + b * (d - tau_s * rise) + (y_j - x_j) * decay

    y = np.empty_like(x)
    y[0] = x[0]
    for j in range(t.size - 1):
        y[j + 1] = advance(y[j], x[j], slope[j], np.array(h[j]))
    q = np.asarray(query_s, dtype=float).reshape(-1)
    seg = np.clip(np.searchsorted(t, q, side="right") - 1, 0, t.size - 1)
    d = np.clip(q - t[seg], 0.0, None)[:, None]
    out = advance(y[seg], x[seg], slope[seg], d)
    return out[:, 0] if flat else out


@pytest.mark.parametrize("tau_s", [1.0, 120.0, 1800.0, 14400.0, 86400.0])
@pytest.mark.parametrize("m", [1, 2, 3, 7, 64, 1500])
def test_lag_equals_the_loop(tau_s, m):
    rng = np.random.default_rng(m)
    gaps = np.where(rng.random(m) < 0.15, 0.0, rng.uniform(1.0, 60.0, m))
    t = 1000.0 + np.cumsum(gaps)  # uneven, some times repeated
    x = 20.0 + np.cumsum(rng.normal(0, 0.3, (m, 6)), axis=0)
    query = np.concatenate([rng.uniform(t[0] - 100, t[-1] + 500, 300), t])
    got = first_order_lag(t, x, tau_s, query)
    np.testing.assert_allclose(got, lag_by_loop(t, x, tau_s, query), atol=1e-12, rtol=0)
    one = first_order_lag(t, x[:, 2], tau_s, query)
    np.testing.assert_allclose(one, lag_by_loop(t, x[:, 2], tau_s, query), atol=1e-12, rtol=0)


def test_lag_of_a_step_is_the_exponential():
    """A second truth: a step at t = 0 held afterwards relaxes as 1 - exp(-t/tau)."""
    t = np.array([-1e-9, 0.0, 1e5])
    x = np.array([0.0, 1.0, 1.0])
    query = np.linspace(0.0, 5000.0, 11)
    got = first_order_lag(t, x, 600.0, query)
    np.testing.assert_allclose(got, 1.0 - np.exp(-query / 600.0), atol=1e-12, rtol=0)
