"""The smooth growth at R (``--interpolation smooth``): the smoother, its choice, its fallback."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import make_smoothing_spline

from hexatherm.core.correction import smooth_growth, smoothing_hat, spline_evaluation

LEG_GAIN_UM = np.array([3.0, 7.0, 2.0, 3.0, 9.0, 3.5]) * 4.5  # ~4.5 um per kelvin


def reference_times(n: int = 25, span_s: float = 7200.0) -> np.ndarray:
    return np.linspace(0.0, span_s, n) + np.r_[0, np.random.default_rng(0).uniform(-60, 60, n - 1)]


def target_times(t: np.ndarray) -> np.ndarray:
    return (t[:-1] + t[1:]) / 2  # one target between consecutive references


def exponential_um(t: np.ndarray, tau_s: float = 2400.0) -> np.ndarray:
    return (1 - np.exp(-t / tau_s))[:, None] * LEG_GAIN_UM


def step_um(t: np.ndarray, at_s: float = 3000.0, tau_s: float = 1.0) -> np.ndarray:
    return (1 - np.exp(-np.clip(t - at_s, 0, None) / tau_s))[:, None] * LEG_GAIN_UM


@pytest.mark.parametrize("lam", [1e-6, 1e-3, 1.0])
def test_the_hat_matrix_is_scipys_smoothing_spline(lam: float) -> None:
    """A second method: scipy's make_smoothing_spline minimizes the same objective."""
    rng = np.random.default_rng(1)
    x = np.sort(rng.uniform(0, 1, 20))
    y = np.sin(6 * x) + rng.normal(0, 0.1, 20)
    w = rng.uniform(0.5, 3, 20)
    spline = make_smoothing_spline(x, y, w=w, lam=lam)
    hat = smoothing_hat(x, w, lam)
    np.testing.assert_allclose(hat @ y, spline(x), atol=1e-9)
    inside = np.linspace(x[0], x[-1], 37)
    np.testing.assert_allclose(spline_evaluation(x, inside) @ (hat @ y), spline(inside), atol=1e-9)


def test_a_growth_linear_in_time_is_reproduced_exactly() -> None:
    t = reference_times()
    growth = (t / 3600)[:, None] * LEG_GAIN_UM * 1e-3
    rng = np.random.default_rng(2)
    at = np.r_[target_times(t), t[-1] + 200.0]  # a target after the last reference too
    smooth = smooth_growth(t, growth + rng.normal(0, 1e-4, growth.shape), at)
    exact = smooth_growth(t, growth, at)
    np.testing.assert_allclose(exact.weights.sum(axis=-1), 1.0, atol=1e-12)
    got = np.einsum("mln,nl->ml", exact.weights, growth)
    np.testing.assert_allclose(got, (at / 3600)[:, None] * LEG_GAIN_UM * 1e-3, atol=1e-12)
    assert smooth.used  # with noise the smooth fit predicts better than the neighbours


def test_a_smooth_growth_is_followed_closer_than_by_the_neighbours() -> None:
    """Noise-free exponential heating: within 0.1 % of the growth (the natural spline's
    straight ends cost most at the start, where the curvature is largest), and closer
    than the neighbours' straight line everywhere."""
    t = reference_times()
    at = target_times(t)
    smooth = smooth_growth(t, exponential_um(t) * 1e-3, at)
    assert smooth.used, smooth.reason
    got_um = np.einsum("mln,nl->ml", smooth.weights, exponential_um(t))
    error = np.abs(got_um - exponential_um(at))
    linear = np.abs((exponential_um(t)[:-1] + exponential_um(t)[1:]) / 2 - exponential_um(at))
    assert error.max() < 1e-3 * exponential_um(t).max()
    assert np.all(error < linear)


def errors_um(growth, noise_um: float, seed: int):
    t = reference_times()
    at = target_times(t)
    rng = np.random.default_rng(seed)
    measured = growth(t) + rng.normal(0, noise_um, (len(t), 6))
    smooth = smooth_growth(t, measured * 1e-3, at)
    linear = (measured[:-1] + measured[1:]) / 2  # the two neighbours, halfway
    fitted = np.einsum("mln,nl->ml", smooth.weights, measured) if smooth.used else linear
    truth = growth(at)
    return (
        smooth.used,
        np.sqrt(np.mean((fitted - truth) ** 2)),
        np.sqrt(np.mean((linear - truth) ** 2)),
    )


def test_on_smooth_heating_the_fit_beats_the_neighbours() -> None:
    runs = [errors_um(exponential_um, 0.5, seed) for seed in range(20)]
    assert sum(used for used, _, _ in runs) >= 17  # measured 18 of 20
    smooth_rms = np.sqrt(np.mean([s**2 for _, s, _ in runs]))
    linear_rms = np.sqrt(np.mean([lin**2 for _, _, lin in runs]))
    assert smooth_rms < 0.85 * linear_rms, (smooth_rms, linear_rms)  # measured 0.77


def test_on_a_growth_step_the_cross_validation_keeps_the_neighbours() -> None:
    """A step within a second between two references: no smooth function follows it, the
    cross-validation falls back to the neighbours (measured: 20 of 20 seeds)."""
    runs = [errors_um(lambda t: step_um(t, tau_s=1.0), 0.5, seed) for seed in range(20)]
    assert sum(u for u, _, _ in runs) <= 1
    assert np.mean([s for _, s, _ in runs]) <= 1.001 * np.mean([lin for _, _, lin in runs])


def test_on_a_fast_rise_whatever_is_chosen_loses_nothing() -> None:
    """A rise of tau = 30 s between references 300 s apart: the smooth fit is kept there
    (measured 1.95 against 2.05 um for the neighbours): no loss either way."""
    runs = [errors_um(lambda t: step_um(t, tau_s=30.0), 0.5, seed) for seed in range(20)]
    assert np.mean([s for _, s, _ in runs]) <= 1.0 * np.mean([lin for _, _, lin in runs])


def test_too_few_or_untimed_references_fall_back() -> None:
    t = np.array([0.0, 600.0, 1200.0, 1800.0])
    assert not smooth_growth(t, np.zeros((4, 6)), [300.0]).used
    t = np.array([0.0, 600.0, 600.0, 1200.0, 1800.0, 2400.0])
    fit = smooth_growth(t, np.zeros((6, 6)), [300.0])
    assert not fit.used and "distinct times" in fit.reason
