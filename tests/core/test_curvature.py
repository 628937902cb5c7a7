"""The straight line's own error between references, and the references' height scatter
off a heating's motion (hexatherm.core.curvature), against known growths."""

from __future__ import annotations

import numpy as np

from hexatherm.core.curvature import curvature_error, scatter_off_heating
from hexatherm.core.propagation import reference_scatter

#: irregular reference times, s
TIMES = np.array([0.0, 300.0, 800.0, 1000.0, 1600.0, 1900.0])
#: a quadratic growth per leg, mm / s^2 (g = a t^2 + b t)
CURVATURE = np.array([2.0, -1.0, 0.5, 3.0, 0.0, -2.5]) * 1e-9
SLOPE = np.array([1.0, 2.0, -1.0, 0.5, 1.5, 0.0]) * 1e-6


def quadratic(t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=float)[..., None]
    return CURVATURE * t**2 + SLOPE * t


def line(targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The straight line's weights (M, n) between the references around each target, and
    the position of the one before."""
    before = np.searchsorted(TIMES, targets) - 1
    w = (targets - TIMES[before]) / (TIMES[before + 1] - TIMES[before])
    weights = np.zeros((len(targets), len(TIMES)))
    weights[np.arange(len(targets)), before] = 1 - w
    weights[np.arange(len(targets)), before + 1] = w
    return weights, before


def test_a_quadratic_growth_gives_the_straight_lines_error_exactly() -> None:
    targets = np.array([100.0, 550.0, 700.0, 1300.0, 1750.0])
    used, before = line(targets)
    err = curvature_error(TIMES, quadratic(TIMES), np.zeros((6, 6, 6)), targets, used)
    w = (targets - TIMES[before]) / (TIMES[before + 1] - TIMES[before])
    straight = (1 - w)[:, None] * quadratic(TIMES[before]) + w[:, None] * quadratic(
        TIMES[before + 1]
    )
    truth = straight - quadratic(targets)  # the straight line's error, known
    assert np.allclose(err.cov_mm2, truth[:, :, None] * truth[:, None, :], rtol=1e-9, atol=1e-20)
    assert err.evaluated.all()
    # only beyond an interval the smooth fit's residuals see: nothing for the 300 s ones
    seen = curvature_error(TIMES, quadratic(TIMES), np.zeros((6, 6, 6)), targets, used, 300.0)
    f = (targets - TIMES[before]) * (TIMES[before + 1] - targets) / 2
    beyond = np.maximum(0.0, f - 300.0**2 / 8) / f
    assert np.allclose(seen.cov_mm2, err.cov_mm2 * beyond[:, None, None] ** 2)


def test_a_target_past_the_last_reference_gets_the_growth_since_it_exactly() -> None:
    """Extrapolated (it takes the last reference alone): the line through the last two
    carried on, and the quadratic's extrapolation error; before issue 35, nothing. With
    two references only, the first-order part alone (exact on a straight line)."""
    targets = np.array([2100.0, 2500.0])
    used = np.zeros((2, len(TIMES)))
    used[:, -1] = 1.0
    err = curvature_error(TIMES, quadratic(TIMES), np.zeros((6, 6, 6)), targets, used)
    truth = quadratic(TIMES[-1]) - quadratic(targets)  # the growth since the last reference
    assert np.allclose(err.vector_mm**2, truth**2, rtol=1e-9, atol=1e-24)
    assert err.evaluated.all() and err.interval.tolist() == [5, 5]
    two = curvature_error(
        TIMES[:2], SLOPE * TIMES[:2, None], np.zeros((2, 6, 6)), [400.0], [[0, 1]]
    )
    assert np.allclose(two.vector_mm[0] ** 2, (SLOPE * 100.0) ** 2, rtol=1e-9)


def test_two_targets_of_one_interval_carry_signed_vectors() -> None:
    """T T R: the first takes the reference before, the second the one after; their
    errors are of opposite signs, and the covariance between them is ``v_a v_b^T``."""
    targets = np.array([400.0, 700.0, 1300.0])
    used = np.zeros((3, len(TIMES)))
    used[0, 1], used[1, 2], used[2, 3] = 1.0, 1.0, 1.0
    growth = np.outer(1e-9 * TIMES**2, np.ones(6))  # every leg grows, faster and faster
    err = curvature_error(TIMES, growth, np.zeros((6, 6, 6)), targets, used)
    assert err.interval.tolist() == [1, 1, 3]
    assert np.all(err.vector_mm[0] < 0) and np.all(err.vector_mm[1] > 0)
    assert np.allclose(err.cov_mm2, err.vector_mm[:, :, None] * err.vector_mm[:, None, :])


def test_one_reference_gives_the_growth_since_it_exactly() -> None:
    """Two targets between two references: the first takes the one before, the second
    the one after (a first-order error, the growth between that reference and the
    target's time), exact on a quadratic."""
    targets = np.array([400.0, 700.0])
    used = np.zeros((2, len(TIMES)))
    used[0, 1], used[1, 2] = 1.0, 1.0  # 300 s before the first, 800 s after the second
    err = curvature_error(TIMES, quadratic(TIMES), np.zeros((6, 6, 6)), targets, used)
    truth = quadratic(TIMES[[1, 2]]) - quadratic(targets)
    assert np.allclose(err.cov_mm2, truth[:, :, None] * truth[:, None, :], rtol=1e-9, atol=1e-20)


def test_the_references_noise_is_not_counted_twice() -> None:
    """Over noise draws, the added variance is the quadratic's error squared on average
    (the curvature read through noise holds the noise's share, taken off); on a straight
    line it adds a small part of what the noise alone would."""
    rng = np.random.default_rng(3)
    sigma = 0.3e-3  # each reference's legs, mm
    s = np.broadcast_to(np.eye(6) * sigma**2, (6, 6, 6))
    targets = np.array([550.0])
    used, _ = line(targets)
    exact = curvature_error(TIMES, quadratic(TIMES), np.zeros((6, 6, 6)), targets, used)
    added, line_added = [], []
    for _ in range(4000):
        noise = rng.normal(scale=sigma, size=(6, 6))
        curved = curvature_error(TIMES, quadratic(TIMES) + noise, s, targets, used)
        straight = curvature_error(TIMES, noise, s, targets, used)
        added.append(np.trace(curved.cov_mm2[0]))
        line_added.append(np.trace(straight.cov_mm2[0]))
    truth = np.trace(exact.cov_mm2[0])
    assert 0.9 < np.mean(added) / truth < 1.1, np.mean(added) / truth
    # what the read curvature's noise alone would add if it were not taken off: f^2 tr N,
    # the stencils around [300, 800] s averaged
    stencil = 0.5 * (
        np.array([2 / (300 * 800), -2 / (300 * 500), 2 / (500 * 800), 0, 0, 0])
        + np.array([0, 2 / (500 * 700), -2 / (500 * 200), 2 / (200 * 700), 0, 0])
    )
    f = (550.0 - 300.0) * (800.0 - 550.0) / 2
    noise_only = f**2 * 6 * sigma**2 * np.sum(stencil**2)
    assert np.mean(line_added) < 0.3 * noise_only, np.mean(line_added) / noise_only


def test_the_heights_scatter_is_read_off_a_bending_heatings_motion() -> None:
    """Heights of 3 balls moved by a heating switched on mid-session (40 um along one
    direction, a kink and an exponential, as the twin's legs move them) plus 1 um noise,
    7 references: the plain second differences read several times the noise; off the
    heating's direction, the noise (over draws); on noise alone, the plain estimate
    (the heating's direction read off only beyond chance, p = 0.05: 10 % of the draws,
    the stencils sharing references)."""
    rng = np.random.default_rng(5)
    t = np.arange(7) * 400.0
    heat = 40e-3 * (1 - np.exp(-np.clip(t - 1000.0, 0, None) / 600.0))
    direction = np.array([1.0, 0.4, -0.7])
    plain, off, still, fired = [], [], [], []
    for _ in range(800):
        noise = rng.normal(scale=1e-3, size=(7, 3))
        plain.append(reference_scatter(t, np.outer(heat, direction) + noise)[0])
        s2, dof, projected = scatter_off_heating(t, np.outer(heat, direction) + noise)
        off.append(s2)
        alone = scatter_off_heating(t, noise)
        still.append(alone[0])
        fired.append(alone[2] > 0)
    assert (dof, projected) == (10, 5)
    assert np.mean(plain) / 1e-6 > 3.0
    assert np.mean(fired) < 0.15
    assert 0.9 < np.mean(off) / 1e-6 < 1.1, np.mean(off) / 1e-6
    assert 0.9 < np.mean(still) / 1e-6 < 1.1, np.mean(still) / 1e-6
