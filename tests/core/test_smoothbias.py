"""The smooth growth's own error at the references: its noise expectation against Monte
Carlo, and a known bias recovered."""

from __future__ import annotations

import numpy as np

from hexatherm.core.correction import smooth_growth
from hexatherm.core.smoothbias import growth_excess

TIMES = np.array([0.0, 400.0, 800.0, 1200.0, 1600.0, 2000.0, 2400.0])
NOISE_MM = 1e-3


def leg_cov(n: int) -> np.ndarray:
    """Correlated 6x6 noise of every reference's legs (as a frame's noise reaches them)."""
    rng = np.random.default_rng(3)
    root = rng.normal(size=(6, 6)) * NOISE_MM / np.sqrt(6)
    return np.broadcast_to(root @ root.T, (n, 6, 6)).copy()


def test_the_noise_expectation_is_the_residuals_scatter_under_noise() -> None:
    """Straight-line growth plus noise of known covariance: the residuals' mean square over
    2000 draws equals the expectation it is compared with, and the excess is small."""
    cov = leg_cov(len(TIMES))
    root = np.linalg.cholesky(cov[0])
    rng = np.random.default_rng(7)
    growth = np.outer(TIMES / 2400.0, np.arange(1, 7)) * 5e-3
    observed, excess, expected = [], [], 0.0
    for _ in range(2000):
        g = growth + rng.normal(size=(len(TIMES), 6)) @ root.T
        ex = growth_excess(TIMES, g, np.ones(len(TIMES)), 1e-2, cov)
        observed.append(ex.observed_um**2)
        excess.append(ex.excess_um**2)
        expected = ex.noise_um**2
    assert abs(np.mean(observed) / expected - 1) < 0.05, np.mean(observed) / expected
    # what is added from noise alone (the positive part of a noisy difference) stays a
    # small share of the noise
    assert np.mean(excess) < 0.25 * expected, np.mean(excess) / expected  # measured 0.16


def test_a_bias_the_spline_cannot_follow_is_found() -> None:
    """Noise-free growth with a kink (heating switched on at 1000 s): the residuals are
    the spline's own error, all of it added (no noise share)."""
    t = TIMES
    shape = np.where(t > 1000.0, 1 - np.exp(-(t - 1000.0) / 300.0), 0.0)
    g = np.outer(shape, np.arange(1, 7)) * 5e-3
    fit = smooth_growth(t, g, t[1:-1])
    ex = growth_excess(t, g, np.ones(len(t)), float(fit.lam[0]), np.zeros((len(t), 6, 6)))
    assert ex.noise_um == 0.0 and ex.excess_um > 0.0
    np.testing.assert_allclose(ex.excess_um, ex.observed_um, rtol=1e-12)
    # the legs' errors follow one history: the added covariance has rank one, along the
    # legs' gains
    values, vectors = np.linalg.eigh(ex.cov_mm2)
    assert values[-2] < 1e-9 * values[-1]
    direction = np.abs(vectors[:, -1])
    np.testing.assert_allclose(direction, np.arange(1, 7) / np.linalg.norm(np.arange(1, 7)))
