"""Tests of hexatherm.core.spherefit against reference data with a known solution.

Reference data (the null-space method): with unit directions u_i, a centre c and a
radius R, residuals e_i orthogonal to the rows of [1; u_i^T] (sum e_i = 0 and
sum e_i u_i = 0) make p_i = c + (R + e_i) u_i a data set whose geometric
least-squares sphere is exactly (c, R): the gradient J^T e vanishes there.  For a
fixed radius only sum e_i u_i = 0 is needed.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hexatherm.core.spherefit import (
    COND_MAX,
    COPLANAR_RTOL,
    SphereFits,
    fit_sphere,
    fit_spheres,
    probe_radius_mm,
)
from hexatherm.errors import FitError

CENTRE = np.array([412.3, -873.1, 129.7])
RADIUS = 12.7


def cap_directions(
    n: int, half_angle_deg: float, rng: np.random.Generator, axis: np.ndarray | None = None
) -> np.ndarray:
    """n random unit vectors, uniform on the cap of the given half-angle around axis."""
    z = rng.uniform(np.cos(np.radians(half_angle_deg)), 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    u = np.c_[s * np.cos(phi), s * np.sin(phi), z]
    if axis is not None:
        rot, _ = Rotation.align_vectors([axis], [[0.0, 0.0, 1.0]])
        u = rot.apply(u)
    return u


def nullspace_residuals(
    u: np.ndarray, rms_mm: float, rng: np.random.Generator, *, fixed: bool = False
) -> np.ndarray:
    """Random residuals orthogonal to [1; u^T] (or to u^T only, fixed radius), given RMS."""
    m = u.T if fixed else np.vstack([np.ones(len(u)), u.T])
    v = rng.normal(size=len(u))
    e = v - m.T @ np.linalg.lstsq(m.T, v, rcond=None)[0]
    return e * rms_mm / np.sqrt(np.mean(e**2))


def reference_points(
    u: np.ndarray, e: np.ndarray, centre: np.ndarray = CENTRE, radius: float = RADIUS
) -> np.ndarray:
    return centre + (radius + e)[:, None] * u


# --------------------------------------------------------------------------------------
# Known least-squares solutions


@pytest.mark.parametrize("half_angle", [30.0, 45.0, 60.0, 90.0])
def test_free_radius_recovers_nullspace_solution(half_angle: float) -> None:
    rng = np.random.default_rng(int(half_angle))
    u = cap_directions(40, half_angle, rng, axis=rng.normal(size=3))
    e = nullspace_residuals(u, 5e-3, rng)
    assert abs(e.sum()) < 1e-12 and np.abs(e @ u).max() < 1e-12
    fit = fit_sphere(reference_points(u, e))
    assert isinstance(fit, SphereFits)
    np.testing.assert_allclose(fit.centre_mm[0], CENTRE, rtol=0, atol=1e-9)
    assert abs(fit.radius_mm[0] - RADIUS) < 1e-9
    np.testing.assert_allclose(fit.residuals_mm, e, rtol=0, atol=1e-9)
    assert np.sum(fit.residuals_mm**2) == pytest.approx(np.sum(e**2), rel=1e-9)
    assert fit.rms_um[0] == pytest.approx(5.0, rel=1e-6)
    assert fit.form_um[0] == pytest.approx(1e3 * np.ptp(e), rel=1e-6)
    assert fit.n.tolist() == [40]
    assert not fit.fixed_radius
    assert fit.iterations[0] >= 1


@pytest.mark.parametrize("half_angle", [5.0, 15.0, 30.0, 45.0, 60.0, 90.0])
def test_fixed_radius_recovers_nullspace_solution(half_angle: float) -> None:
    rng = np.random.default_rng(100 + int(half_angle))
    u = cap_directions(30, half_angle, rng, axis=rng.normal(size=3))
    e = nullspace_residuals(u, 2e-3, rng, fixed=True)
    if half_angle >= 30.0:
        assert abs(e.sum()) > 1e-6  # the mean residual is free: only sum(e u) = 0
    fit = fit_sphere(reference_points(u, e), radius_mm=RADIUS)
    np.testing.assert_allclose(fit.centre_mm[0], CENTRE, rtol=0, atol=1e-9)
    assert fit.radius_mm[0] == RADIUS
    assert fit.fixed_radius
    np.testing.assert_allclose(fit.residuals_mm, e, rtol=0, atol=1e-9)


def test_fixed_radius_is_not_a_free_fit() -> None:
    # On fixed-radius reference data the free fit finds a different (better) sphere.
    rng = np.random.default_rng(7)
    u = cap_directions(30, 45.0, rng)
    e = nullspace_residuals(u, 2e-3, rng, fixed=True) + 1e-3
    pts = reference_points(u, e)
    free, fixed = fit_sphere(pts), fit_sphere(pts, radius_mm=RADIUS)
    assert abs(free.radius_mm[0] - RADIUS) > 1e-4
    assert np.sum(free.residuals_mm**2) < np.sum(fixed.residuals_mm**2)


def test_noiseless_points_far_from_origin() -> None:
    rng = np.random.default_rng(3)
    u = cap_directions(12, 50.0, rng)
    centre = np.array([1.0e4, -2.5e4, 7.5e3])
    fit = fit_sphere(centre + 3.0 * u)
    np.testing.assert_allclose(fit.centre_mm[0], centre, rtol=0, atol=1e-9)
    assert abs(fit.radius_mm[0] - 3.0) < 1e-10
    assert fit.rms_um[0] < 1e-6


def test_interpolating_sphere_has_nan_covariance() -> None:
    u = np.vstack([np.eye(3), [[0.0, 0.6, -0.8]]])
    fit = fit_sphere(CENTRE + RADIUS * u)
    np.testing.assert_allclose(fit.centre_mm[0], CENTRE, atol=1e-9)
    assert np.isnan(fit.cov_centre_mm2).all()


# --------------------------------------------------------------------------------------
# Vectorization


def _ragged_problem(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    sizes = rng.integers(5, 60, m)
    pts, groups = [], []
    for k, n in enumerate(sizes):
        u = cap_directions(n, rng.uniform(25.0, 150.0), rng, axis=rng.normal(size=3))
        r = rng.uniform(3.0, 30.0)
        centre = rng.uniform(-800.0, 800.0, 3)
        pts.append(centre + (r + rng.normal(0.0, 3e-3, n))[:, None] * u)
        groups.append(np.full(n, k))
    p, g = np.vstack(pts), np.concatenate(groups)
    perm = rng.permutation(len(g))  # interleave the spheres
    return p[perm], g[perm]


@pytest.mark.parametrize("fixed", [False, True])
def test_vectorized_ragged_equals_one_by_one(fixed: bool) -> None:
    rng = np.random.default_rng(11)
    m = 40
    p, g = _ragged_problem(rng, m)
    radii = None
    if fixed:
        radii = np.array([fit_sphere(p[g == k]).radius_mm[0] + 1e-3 for k in range(m)])
    fits = fit_spheres(p, g, radius_mm=radii)
    assert fits.centre_mm.shape == (m, 3) and fits.cov_centre_mm2.shape == (m, 3, 3)
    assert fits.residuals_mm.shape == (len(g),)
    for k in range(m):
        one = fit_sphere(p[g == k], radius_mm=None if radii is None else radii[k])
        np.testing.assert_allclose(fits.centre_mm[k], one.centre_mm[0], rtol=0, atol=1e-10)
        assert fits.radius_mm[k] == pytest.approx(one.radius_mm[0], abs=1e-10)
        assert fits.rms_um[k] == pytest.approx(one.rms_um[0], rel=1e-8)
        assert fits.form_um[k] == pytest.approx(one.form_um[0], rel=1e-8)
        assert fits.cap_half_angle_deg[k] == pytest.approx(one.cap_half_angle_deg[0], abs=1e-9)
        np.testing.assert_allclose(fits.cov_centre_mm2[k], one.cov_centre_mm2[0], rtol=1e-6)
        np.testing.assert_allclose(fits.residuals_mm[g == k], one.residuals_mm, atol=1e-10)
        assert fits.n[k] == np.sum(g == k)


def test_scalar_fixed_radius_applies_to_all_spheres() -> None:
    rng = np.random.default_rng(5)
    pts, groups = [], []
    centres = rng.uniform(-100, 100, (3, 3))
    for k in range(3):
        u = cap_directions(10, 40.0, rng)
        pts.append(reference_points(u, nullspace_residuals(u, 1e-3, rng, fixed=True), centres[k]))
        groups += [k] * 10
    fits = fit_spheres(np.vstack(pts), groups, radius_mm=RADIUS)
    np.testing.assert_allclose(fits.centre_mm, centres, atol=1e-9)
    np.testing.assert_array_equal(fits.radius_mm, np.full(3, RADIUS))


def _hard_sphere(seed: int) -> np.ndarray:
    """8 points on a 30 deg cap with noise 0.3 mm: about a quarter of the sagitta."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(np.cos(np.radians(30.0)), 1.0, 8)
    phi = rng.uniform(0.0, 2.0 * np.pi, 8)
    s = np.sqrt(1.0 - z * z)
    u = np.c_[s * np.cos(phi), s * np.sin(phi), z]
    return (10.0 + rng.normal(0.0, 0.3, 8))[:, None] * u


@pytest.mark.parametrize("seed", [14, 67])
def test_large_residuals_damped_steps_reach_the_minimum(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from scipy.optimize import least_squares

    import hexatherm.core.spherefit as sf

    pts = _hard_sphere(seed)
    calls = []
    original = sf._solve
    monkeypatch.setattr(sf, "_solve", lambda a, b: calls.append(len(a)) or original(a, b))
    fit = fit_sphere(pts)
    monkeypatch.undo()
    assert len(calls) > fit.iterations[0]  # some steps were rejected and damped
    c, r = fit.centre_mm[0], fit.radius_mm[0]
    d = pts - c
    dist = np.linalg.norm(d, axis=1)
    e = dist - r
    gradient = np.r_[-(d / dist[:, None]).T @ e, -e.sum()]
    assert np.abs(gradient).max() < 1e-12
    ref = least_squares(
        lambda x: np.linalg.norm(pts - x[:3], axis=1) - x[3],
        np.r_[pts.mean(axis=0), 10.0],
        method="lm",
        xtol=1e-15,
        ftol=1e-15,
    )
    assert np.sum(e**2) <= 2.0 * ref.cost * (1 + 1e-12)
    np.testing.assert_allclose(fit.residuals_mm, e, atol=1e-12)
    # The same sphere among easy ones: vectorized result unchanged.
    rng = np.random.default_rng(seed)
    easy = [CENTRE + RADIUS * cap_directions(20, 60.0, rng) for _ in range(3)]
    fits = fit_spheres(
        np.vstack([easy[0], pts, *easy[1:]]), np.repeat([0, 1, 2, 3], [20, 8, 20, 20])
    )
    np.testing.assert_allclose(fits.centre_mm[1], c, atol=1e-10)
    assert fits.iterations[1] == fit.iterations[0] and fits.iterations.max() > fits.iterations.min()


# --------------------------------------------------------------------------------------
# Cap angle, covariance, probe radius


@pytest.mark.parametrize("half_angle", [12.5, 30.0, 60.0, 90.0, 100.0])
def test_cap_angle_of_symmetric_rings(half_angle: float) -> None:
    t = np.radians(half_angle)
    phi = np.radians(np.arange(0.0, 360.0, 45.0))
    ring = np.c_[np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.full(8, np.cos(t))]
    inner = ring.copy()
    inner[:, :2] *= np.sin(t / 2) / np.sin(t)
    inner[:, 2] = np.cos(t / 2)
    u = Rotation.from_rotvec([0.3, -1.1, 0.4]).apply(np.vstack([[0, 0, 1], ring, inner]))
    fit = fit_sphere(CENTRE + RADIUS * u)
    assert fit.cap_half_angle_deg[0] == pytest.approx(half_angle, abs=1e-8)


def test_cap_angle_matches_direct_computation() -> None:
    rng = np.random.default_rng(21)
    u = cap_directions(25, 70.0, rng, axis=[1.0, 2.0, -0.5])
    fit = fit_sphere(reference_points(u, np.zeros(25)))
    mean = u.sum(axis=0) / np.linalg.norm(u.sum(axis=0))
    expected = np.degrees(np.arccos(np.clip(u @ mean, -1, 1))).max()
    assert fit.cap_half_angle_deg[0] == pytest.approx(expected, abs=1e-6)


def test_cap_angle_is_180_when_directions_cancel() -> None:
    u = np.vstack([np.eye(3), -np.eye(3)])
    assert fit_sphere(CENTRE + RADIUS * u).cap_half_angle_deg[0] == 180.0


@pytest.mark.parametrize("fixed", [False, True])
def test_covariance_matches_monte_carlo(fixed: bool) -> None:
    rng = np.random.default_rng(2024)
    n, reps, sigma = 20, 4000, 2e-3
    u = cap_directions(n, 60.0, rng)
    noise = rng.normal(0.0, sigma, (reps, n))
    pts = CENTRE + (RADIUS + noise)[:, :, None] * u
    fits = fit_spheres(
        pts.reshape(-1, 3), np.repeat(np.arange(reps), n), radius_mm=RADIUS if fixed else None
    )
    empirical = np.cov(fits.centre_mm.T)
    reported = fits.cov_centre_mm2.mean(axis=0)
    j = -u if fixed else np.c_[-u, -np.ones(n)]
    theory = sigma**2 * np.linalg.inv(j.T @ j)[:3, :3]
    np.testing.assert_allclose(reported, theory, rtol=0.03, atol=0.03 * np.abs(theory).max())
    scale = np.abs(theory).max()
    assert np.abs(empirical - theory).max() < 0.1 * scale
    np.testing.assert_allclose(np.diag(empirical), np.diag(theory), rtol=0.1)
    # The mean of the fitted centres is unbiased to well within its standard error.
    se = np.sqrt(np.diag(theory) / reps)
    assert np.all(np.abs(fits.centre_mm.mean(axis=0) - CENTRE) < 4 * se)


def test_probe_radius() -> None:
    assert probe_radius_mm(25.4, 3.0, compensated=True) == pytest.approx(12.7)
    assert probe_radius_mm(25.4, 3.0, compensated=False) == pytest.approx(14.2)
    assert probe_radius_mm(10.0, 0.0, compensated=False) == 5.0
    with pytest.raises(FitError, match="ball diameter must be finite and positive"):
        probe_radius_mm(-1.0, 2.0, compensated=True)
    with pytest.raises(FitError, match="tip diameter must be finite and non-negative"):
        probe_radius_mm(25.4, float("nan"), compensated=False)


def test_probe_tip_centre_points_fit_ball_plus_tip_radius() -> None:
    rng = np.random.default_rng(9)
    u = cap_directions(20, 75.0, rng)
    tip_centres = CENTRE + probe_radius_mm(25.4, 2.0, compensated=False) * u
    fit = fit_sphere(tip_centres)
    assert fit.radius_mm[0] == pytest.approx(13.7, abs=1e-10)
    fixed = fit_sphere(tip_centres, radius_mm=probe_radius_mm(25.4, 2.0, compensated=False))
    np.testing.assert_allclose(fixed.centre_mm[0], CENTRE, atol=1e-10)


# --------------------------------------------------------------------------------------
# Property: a rigid motion of the points moves the centre with them


_BASE_U = cap_directions(15, 55.0, np.random.default_rng(42))
_BASE_E = nullspace_residuals(_BASE_U, 4e-3, np.random.default_rng(43))
_BASE_FIT = fit_sphere(reference_points(_BASE_U, _BASE_E))


@settings(max_examples=30, deadline=None)
@given(
    rotvec=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    shift=st.lists(st.floats(-2000.0, 2000.0), min_size=3, max_size=3),
)
def test_rigid_motion_moves_centre(rotvec: list[float], shift: list[float]) -> None:
    rot = Rotation.from_rotvec(rotvec)
    pts = rot.apply(reference_points(_BASE_U, _BASE_E)) + shift
    fit = fit_sphere(pts)
    expected = rot.apply(_BASE_FIT.centre_mm[0]) + shift
    np.testing.assert_allclose(fit.centre_mm[0], expected, rtol=0, atol=1e-9)
    assert fit.radius_mm[0] == pytest.approx(_BASE_FIT.radius_mm[0], abs=1e-9)
    np.testing.assert_allclose(fit.residuals_mm, _BASE_FIT.residuals_mm, atol=1e-9)
    assert fit.cap_half_angle_deg[0] == pytest.approx(_BASE_FIT.cap_half_angle_deg[0], abs=1e-6)


# --------------------------------------------------------------------------------------
# Preconditions


def _three_spheres(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    pts = np.vstack([CENTRE + k * 50.0 + RADIUS * cap_directions(8, 60.0, rng) for k in range(3)])
    return pts, np.repeat(np.arange(3), 8)


def test_non_finite_point_names_sphere_and_point() -> None:
    pts, g = _three_spheres(np.random.default_rng(0))
    pts[19, 1] = np.nan
    pts[21, 0] = np.inf
    with pytest.raises(FitError, match=r"^sphere 2: point 19 has a non-finite coordinate .*2 such"):
        fit_spheres(pts, g)


@pytest.mark.parametrize(
    ("n", "radius", "match"),
    [
        (3, None, r"^sphere 1: only 3 points; a free-radius fit needs at least 4$"),
        (2, RADIUS, r"^sphere 1: only 2 points; a fixed-radius fit needs at least 3$"),
    ],
)
def test_too_few_points(n: int, radius: float | None, match: str) -> None:
    pts, g = _three_spheres(np.random.default_rng(1))
    keep = (g != 1) | (np.cumsum(g == 1) <= n)
    with pytest.raises(FitError, match=match):
        fit_spheres(pts[keep], g[keep], radius_mm=radius)


def test_unused_group_index_is_an_empty_sphere() -> None:
    pts, g = _three_spheres(np.random.default_rng(2))
    with pytest.raises(FitError, match=r"^sphere 1: only 0 points"):
        fit_spheres(pts[g != 1], g[g != 1])


def test_several_bad_spheres_are_counted() -> None:
    pts, g = _three_spheres(np.random.default_rng(3))
    keep = np.isin(np.arange(len(g)) % 8, [0, 1, 2]) | (g == 0)
    with pytest.raises(FitError, match=r"^sphere 1: only 3 points.*\(also spheres 2; 2 spheres"):
        fit_spheres(pts[keep], g[keep])


def _circle_points(n: int = 12) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = np.c_[np.cos(a), np.sin(a), np.zeros(n)] * RADIUS
    return Rotation.from_rotvec([0.2, 0.7, -0.3]).apply(ring) + CENTRE


def test_coplanar_points_free_radius() -> None:
    with pytest.raises(
        FitError, match=r"^sphere 0: the points are coplanar .*< 1e-06\); the radius cannot"
    ):
        fit_sphere(_circle_points())


def test_nearly_coplanar_points_free_radius() -> None:
    pts = _circle_points()
    pts[0] += 1e-8 * RADIUS * Rotation.from_rotvec([0.2, 0.7, -0.3]).apply([0, 0, 1])
    with pytest.raises(FitError, match=r"^sphere 0: the points are coplanar or nearly so"):
        fit_sphere(pts)
    assert COPLANAR_RTOL == 1e-6


def test_coplanar_points_fixed_radius_are_ambiguous() -> None:
    with pytest.raises(FitError, match=r"^sphere 0: the points are coplanar.*either side"):
        fit_sphere(_circle_points(), radius_mm=20.0)
    with pytest.raises(FitError, match=r"either side of their plane \(two mirror solutions\)"):
        fit_sphere(_circle_points(3), radius_mm=20.0)


def test_coincident_points() -> None:
    with pytest.raises(FitError, match=r"^sphere 0: all points coincide"):
        fit_sphere(np.tile(CENTRE, (5, 1)))


def test_tiny_cap_is_ill_conditioned_for_free_radius_but_fine_fixed() -> None:
    rng = np.random.default_rng(4)
    u = cap_directions(25, 0.05, rng)
    pts = CENTRE + RADIUS * u
    with pytest.raises(
        FitError,
        match=r"^sphere 0: the normal equations are ill-conditioned \(condition number "
        r"\S+ > 1e\+12\): the points cover a cap of half-angle 0\.0\d+ deg.*fix the radius",
    ):
        fit_sphere(pts)
    fit = fit_sphere(pts, radius_mm=RADIUS)
    np.testing.assert_allclose(fit.centre_mm[0], CENTRE, atol=1e-9)
    assert COND_MAX == 1e12


def test_non_convergence() -> None:
    rng = np.random.default_rng(6)
    u = cap_directions(25, 20.0, rng)
    pts = CENTRE + (RADIUS + rng.normal(0.0, 0.05, 25))[:, None] * u
    with pytest.raises(
        FitError, match=r"^sphere 0: the geometric fit did not converge in 1 iteration \(last step"
    ):
        fit_spheres(pts, max_iter=1)


def test_non_convergence_towards_a_plane_is_explained() -> None:
    # Noise far larger than the sagitta: the best "sphere" runs off towards a plane.
    rng = np.random.default_rng(37)
    u = cap_directions(10, 30.0, rng)
    pts = (10.0 + rng.normal(0.0, 1.0, 10))[:, None] * u
    with pytest.raises(FitError, match=r"did not converge.*the points look coplanar within noise"):
        fit_sphere(pts)
    with pytest.raises(FitError, match=r"radius \S+ mm, growing far beyond") as info:
        fit_sphere(pts, max_iter=500)
    assert info.value.index == 0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"points_mm": np.zeros((5, 2))}, r"points_mm must have shape \(N, 3\), got \(5, 2\)"),
        ({"points_mm": [["a", "b", "c"]] * 4}, "points_mm must be a numeric"),
        ({"groups": [0, 1]}, r"groups must have shape \(6,\)"),
        ({"groups": [0.0] * 6}, "groups must be integer sphere indices"),
        ({"groups": [0, 0, 0, -1, 0, 0]}, "groups must be >= 0: point 3 has group -1"),
        ({"radius_mm": -2.0}, r"^sphere 0: the fixed radius must be finite and positive"),
        ({"radius_mm": [1.0, 2.0]}, r"radius_mm must be a scalar or have shape \(1,\)"),
        ({"tol_mm": 0.0}, "tol_mm must be a positive number"),
        ({"max_iter": 0}, "max_iter must be a positive integer"),
    ],
)
def test_malformed_arguments(kwargs: dict, match: str) -> None:
    args = {"points_mm": CENTRE + RADIUS * np.vstack([np.eye(3), -np.eye(3)])} | kwargs
    with pytest.raises(FitError, match=match):
        fit_spheres(**args)


@pytest.mark.parametrize("fixed", [False, True])
def test_refine_spheres_equals_the_general_fit_on_monte_carlo_draws(fixed: bool) -> None:
    """The batched refit of Monte Carlo draws gives the general fit's answer (1e-10 mm)."""
    from hexatherm.core.spherefit import refine_spheres
    from hexatherm.core.touch import cap_directions

    rng = np.random.default_rng(3)
    m, n, draws = 7, 25, 40
    centres = rng.uniform(-100, 100, size=(m, 3))
    radius = np.full(m, 12.7)
    base = centres[:, None] + radius[:, None, None] * cap_directions(n, 70.0)
    base += rng.normal(scale=1e-3, size=base.shape)
    ref = fit_spheres(base.reshape(-1, 3), np.repeat(np.arange(m), n))
    moved = base + rng.normal(scale=1e-3, size=(draws, m, n, 3))
    groups = (np.repeat(np.arange(m), n) + m * np.arange(draws)[:, None]).reshape(-1)
    truth = fit_spheres(
        moved.reshape(-1, 3), groups, radius_mm=np.tile(radius, draws) if fixed else None
    )
    centre, r = refine_spheres(
        moved,
        ref.centre_mm,
        radius if fixed else ref.radius_mm,
        fixed_radius=fixed,
        normal_points_mm=base,
    )
    np.testing.assert_allclose(centre.reshape(-1, 3), truth.centre_mm, atol=1e-10, rtol=0)
    if not fixed:
        np.testing.assert_allclose(r.reshape(-1), truth.radius_mm, atol=1e-10, rtol=0)


# --------------------------------------------------------------------------------------
# The plain Gauss-Newton passes against the general iteration alone


def _hostile_spheres(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Shallow caps, few points, noise from far below to about the cap's sagitta, far
    from the origin, interleaved: the cases where the plain passes could stop early."""
    rng = np.random.default_rng(seed)
    pts, groups = [], []
    for k in range(120):
        n = int(rng.choice([4, 5, 6, 9, 25, 400]))
        half = float(rng.choice([8.0, 12.0, 20.0, 45.0, 90.0, 150.0]))
        u = cap_directions(n, half, rng, axis=rng.normal(size=3))
        sagitta = RADIUS * (1 - np.cos(np.radians(half)))
        noise = sagitta * float(rng.choice([1e-7, 1e-4, 1e-2, 0.1]))
        centre = rng.uniform(-900.0, 900.0, 3)
        pts.append(centre + (RADIUS + rng.normal(0.0, noise, n))[:, None] * u)
        groups.append(np.full(n, k))
    for k, seed_hard in enumerate((14, 67), start=120):
        pts.append(_hard_sphere(seed_hard) + rng.uniform(-50.0, 50.0, 3))
        groups.append(np.full(8, k))
    p, g = np.vstack(pts), np.concatenate(groups)
    perm = rng.permutation(len(g))
    return p[perm], g[perm]


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("fixed", [False, True])
def test_plain_passes_agree_with_the_general_iteration(
    seed: int, fixed: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every output of the fit with the plain passes agrees with the general iteration's
    (``_PLAIN_PASSES = 0``: all spheres fitted as before the passes) far below what the
    files resolve (centres 1e-7 mm): the same centres and radii within 1e-11 mm, the same
    iterations, residuals, RMS, form and covariance to rounding."""
    import hexatherm.core.spherefit as sf

    p, g = _hostile_spheres(seed)
    m = int(g.max()) + 1
    radius = None
    if fixed:  # a fixed radius a few micrometres off the fitted one, as a nominal is
        free = fit_spheres(p, g)
        radius = free.radius_mm + np.random.default_rng(seed).normal(0.0, 3e-3, m)
    fits = fit_spheres(p, g, radius_mm=radius)
    monkeypatch.setattr(sf, "_PLAIN_PASSES", 0)
    ref = fit_spheres(p, g, radius_mm=radius)
    monkeypatch.undo()
    np.testing.assert_allclose(fits.centre_mm, ref.centre_mm, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fits.radius_mm, ref.radius_mm, rtol=0, atol=1e-11)
    np.testing.assert_array_equal(fits.iterations, ref.iterations)
    assert fits.iterations.max() > 3  # some spheres left to the general iteration
    np.testing.assert_allclose(fits.residuals_mm, ref.residuals_mm, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fits.rms_um, ref.rms_um, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fits.form_um, ref.form_um, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fits.cap_half_angle_deg, ref.cap_half_angle_deg, atol=1e-9)
    # the covariance rests on the residuals, which the passes take one step (below
    # 1e-12 mm) earlier: relative differences of 1e-7 where the residuals are 1e-10 mm
    np.testing.assert_allclose(fits.cov_centre_mm2, ref.cov_centre_mm2, rtol=1e-6, atol=1e-18)
    u_um = [1e3 * np.sqrt(np.diagonal(f.cov_centre_mm2, axis1=1, axis2=2)) for f in (fits, ref)]
    np.testing.assert_allclose(u_um[0], u_um[1], rtol=1e-9, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    p=st.integers(2, 4),
    seed=st.integers(0, 2**31),
    log_spread=st.floats(0.0, 8.0),
)
def test_condition_screen_decides_as_the_eigenvalues(p: int, seed: int, log_spread: float) -> None:
    """The conditioning check's cheap bound (a Cholesky elimination, no eigenvalues) makes
    the same verdict against COND_MAX as the eigenvalues, over matrices from well to
    hopelessly conditioned (and singular, indefinite); where it is in doubt the numbers
    are the eigenvalues' own."""
    from hexatherm.core import spherefit

    rng = np.random.default_rng(seed)
    x = rng.normal(size=(400, p, p)) * 10.0 ** rng.uniform(-log_spread, 0.0, (400, 1, p))
    a = x @ np.swapaxes(x, 1, 2)
    a[:5, :, -1] = a[:5, :, 0]  # singular
    a[:5, -1, :] = a[:5, 0, :]
    a[5:8] *= -1.0  # negative definite
    lam = np.linalg.eigvalsh(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        exact = np.where(lam[:, 0] > 0.0, lam[:, -1] / lam[:, 0], np.inf)
    screened = spherefit._condition(a)
    assert np.array_equal(screened <= COND_MAX, exact <= COND_MAX)
    doubt = ~(screened <= 1e-2 * COND_MAX)
    np.testing.assert_array_equal(screened[doubt], exact[doubt])
    # a bound, above (both carry rounding of about eps x cond, below 1e-6 here)
    assert np.all(screened[~doubt] >= exact[~doubt] * (1 - 1e-5))
