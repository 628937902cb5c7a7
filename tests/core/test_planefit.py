"""Tests of hexatherm.core.planefit against data with a known least-squares solution."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from hexatherm.core.planefit import (
    COLLINEAR_RTOL,
    CircleFit,
    PlaneFit,
    fit_circle_3d,
    fit_plane,
)
from hexatherm.errors import FitError

ORIGIN = np.array([-150.0, 420.0, 35.0])
ROT = Rotation.from_rotvec([0.4, -0.9, 1.3])
E1, E2, NORMAL = ROT.apply(np.eye(3))  # a tilted orthonormal frame


def project_out(v: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Component of v orthogonal to the rows of ``rows``."""
    return v - rows.T @ np.linalg.lstsq(rows.T, v, rcond=None)[0]


# --------------------------------------------------------------------------------------
# Plane


def test_plane_noiseless_exact() -> None:
    rng = np.random.default_rng(0)
    xy = rng.uniform(-50.0, 50.0, (30, 2))
    pts = ORIGIN + xy[:, :1] * E1 + xy[:, 1:] * E2
    fit = fit_plane(pts)
    assert isinstance(fit, PlaneFit)
    assert abs(abs(fit.normal @ NORMAL) - 1.0) < 1e-14
    assert abs((fit.point_mm - ORIGIN) @ NORMAL) < 1e-10
    np.testing.assert_allclose(fit.point_mm, pts.mean(axis=0), atol=1e-12)
    assert fit.rms_um < 1e-8 and fit.form_um < 1e-8 and fit.n == 30


def test_plane_nullspace_solution() -> None:
    # In-plane coordinates x (centred), deviations e with sum e = 0 and sum e x = 0:
    # the orthogonal least-squares plane is exactly the reference plane.
    rng = np.random.default_rng(1)
    xy = rng.uniform(-40.0, 40.0, (50, 2))
    xy -= xy.mean(axis=0)
    e = project_out(rng.normal(size=50), np.vstack([np.ones(50), xy.T]))
    e *= 0.01 / np.sqrt(np.mean(e**2))
    pts = ORIGIN + xy[:, :1] * E1 + xy[:, 1:] * E2 + e[:, None] * NORMAL
    fit = fit_plane(pts, towards=NORMAL)
    np.testing.assert_allclose(fit.normal, NORMAL, rtol=0, atol=1e-13)
    np.testing.assert_allclose(fit.point_mm, ORIGIN, rtol=0, atol=1e-11)
    np.testing.assert_allclose(fit.residuals_mm, e, rtol=0, atol=1e-11)
    assert fit.rms_um == pytest.approx(10.0, rel=1e-9)
    assert fit.form_um == pytest.approx(1e3 * np.ptp(e), rel=1e-9)


def test_plane_normal_orientation() -> None:
    pts = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0], [0.0, 1.0, 5.0], [1.0, 1.0, 5.0]])
    assert fit_plane(pts).normal.tolist() == pytest.approx([0.0, 0.0, 1.0])
    assert fit_plane(pts, towards=[0.1, 0.0, -2.0]).normal.tolist() == pytest.approx([0, 0, -1])
    tilted = pts @ Rotation.from_rotvec([2.5, 0.0, 0.0]).as_matrix().T  # normal now ~ -Z+Y
    normal = fit_plane(tilted).normal
    k = int(np.argmax(np.abs(normal)))
    assert normal[k] > 0
    assert fit_plane(tilted, towards=-normal).normal == pytest.approx(-normal)


@pytest.mark.parametrize(
    ("pts", "kwargs", "match"),
    [
        (np.zeros((2, 3)), {}, r"^plane: only 2 points; at least 3 are needed$"),
        (
            np.array([[0, 0, 0], [1, 0, 0], [0, 1, np.nan], [1, 1, 0]]),
            {},
            r"^plane: point 2 has a non-finite coordinate",
        ),
        (np.outer(np.arange(5.0), [1.0, 2.0, 3.0]), {}, r"^plane: the points are collinear"),
        (np.ones((4, 3)), {}, r"^plane: all 4 points coincide$"),
        (np.eye(3), {"towards": [0.0, 0.0, 0.0]}, r"^plane: towards must not be the zero"),
        (np.eye(3), {"towards": [1.0, -1.0, 0.0]}, r"^plane: towards .* lies in the plane"),
        (np.zeros((4, 2)), {}, r"points_mm must have shape \(N, 3\)"),
    ],
)
def test_plane_preconditions(pts: np.ndarray, kwargs: dict, match: str) -> None:
    with pytest.raises(FitError, match=match):
        fit_plane(pts, **kwargs)


def test_nearly_collinear_plane() -> None:
    pts = np.outer(np.linspace(0.0, 100.0, 6), [1.0, 2.0, 3.0])
    pts[2] += 1e-12 * np.array([1.0, -1.0, 0.0])
    with pytest.raises(FitError, match=r"collinear or nearly so .* < 1e-09"):
        fit_plane(pts)
    pts[2] += 1e-6 * np.array([1.0, -1.0, 0.0])  # well above COLLINEAR_RTOL: fine
    assert fit_plane(pts).n == 6
    assert COLLINEAR_RTOL == 1e-9


# --------------------------------------------------------------------------------------
# Circle


def circle_points(
    angles_deg: np.ndarray, radius: float, e: np.ndarray | None = None, centre=ORIGIN
) -> np.ndarray:
    a = np.radians(angles_deg)
    r = radius + (0.0 if e is None else e)
    return centre + (r * np.cos(a))[:, None] * E1 + (r * np.sin(a))[:, None] * E2


@pytest.mark.parametrize("arc", [30.0, 120.0, 360.0])
def test_circle_noiseless_tilted(arc: float) -> None:
    full = arc == 360.0
    angles = np.linspace(10.0, 10.0 + arc, 8 if full else 9, endpoint=not full)
    pts = circle_points(angles, 25.0)
    fit = fit_circle_3d(pts)
    assert isinstance(fit, CircleFit)
    np.testing.assert_allclose(fit.centre_mm, ORIGIN, rtol=0, atol=1e-9)
    assert fit.radius_mm == pytest.approx(25.0, abs=1e-10)
    assert abs(abs(fit.normal @ NORMAL) - 1.0) < 1e-14
    assert fit.rms_um < 1e-6 and fit.n == len(angles)
    expected_arc = 180.0 if full else arc / 2
    assert fit.arc_half_angle_deg == pytest.approx(expected_arc, abs=1e-8)


@pytest.mark.parametrize("arc", [45.0, 90.0, 180.0, 300.0])
def test_circle_nullspace_solution(arc: float) -> None:
    rng = np.random.default_rng(int(arc))
    angles = rng.uniform(0.0, arc, 30)
    a = np.radians(angles)
    e = project_out(rng.normal(size=30), np.vstack([np.ones(30), np.cos(a), np.sin(a)]))
    e *= 4e-3 / np.sqrt(np.mean(e**2))
    pts = circle_points(angles, 40.0, e)
    fit = fit_circle_3d(pts, towards=NORMAL)
    np.testing.assert_allclose(fit.centre_mm, ORIGIN, rtol=0, atol=1e-9)
    assert fit.radius_mm == pytest.approx(40.0, abs=1e-9)
    np.testing.assert_allclose(fit.normal, NORMAL, atol=1e-13)
    np.testing.assert_allclose(fit.residuals_mm, e, atol=1e-9)
    assert fit.rms_um == pytest.approx(4.0, rel=1e-6)
    assert fit.form_um == pytest.approx(1e3 * np.ptp(e), rel=1e-6)


def test_circle_with_given_normal_ignores_out_of_plane_deviations() -> None:
    rng = np.random.default_rng(5)
    angles = rng.uniform(0.0, 200.0, 25)
    a = np.radians(angles)
    e = project_out(rng.normal(size=25), np.vstack([np.ones(25), np.cos(a), np.sin(a)]))
    e *= 2e-3 / np.sqrt(np.mean(e**2))
    w = rng.normal(0.0, 0.05, 25)  # large out-of-plane (flatness) deviations
    pts = circle_points(angles, 8.0, e) + w[:, None] * NORMAL
    fit = fit_circle_3d(pts, normal=-3.0 * NORMAL)
    np.testing.assert_allclose(fit.normal, -NORMAL, atol=1e-15)
    np.testing.assert_allclose(fit.centre_mm, ORIGIN + w.mean() * NORMAL, rtol=0, atol=1e-9)
    assert fit.radius_mm == pytest.approx(8.0, abs=1e-9)
    np.testing.assert_allclose(fit.residuals_mm, e, atol=1e-9)
    assert fit_circle_3d(pts, normal=-NORMAL, towards=NORMAL).normal @ NORMAL == pytest.approx(1)


def test_circle_three_points_is_the_circumcircle() -> None:
    pts = circle_points(np.array([0.0, 100.0, 250.0]), 6.0)
    fit = fit_circle_3d(pts)
    np.testing.assert_allclose(fit.centre_mm, ORIGIN, atol=1e-10)
    assert fit.radius_mm == pytest.approx(6.0, abs=1e-12)


@settings(max_examples=25, deadline=None)
@given(
    rotvec=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
    shift=st.lists(st.floats(-1000.0, 1000.0), min_size=3, max_size=3),
)
def test_circle_rigid_motion(rotvec: list[float], shift: list[float]) -> None:
    rng = np.random.default_rng(8)
    base = circle_points(rng.uniform(0.0, 150.0, 12), 15.0, rng.normal(0.0, 2e-3, 12))
    ref = fit_circle_3d(base)
    rot = Rotation.from_rotvec(rotvec)
    fit = fit_circle_3d(rot.apply(base) + shift)
    np.testing.assert_allclose(fit.centre_mm, rot.apply(ref.centre_mm) + shift, atol=1e-9)
    assert fit.radius_mm == pytest.approx(ref.radius_mm, abs=1e-9)
    assert abs(abs(fit.normal @ rot.apply(ref.normal)) - 1.0) < 1e-12
    np.testing.assert_allclose(fit.residuals_mm, ref.residuals_mm, atol=1e-9)


def test_circle_preconditions() -> None:
    with pytest.raises(FitError, match=r"^circle: only 2 points; at least 3 are needed$"):
        fit_circle_3d(np.zeros((2, 3)))
    pts = circle_points(np.array([0.0, 90.0, 180.0, 270.0]), 5.0)
    bad = pts.copy()
    bad[3, 2] = np.inf
    with pytest.raises(FitError, match=r"^circle: point 3 has a non-finite coordinate"):
        fit_circle_3d(bad)
    with pytest.raises(FitError, match=r"^plane: the points are collinear"):
        fit_circle_3d(np.outer(np.arange(4.0), [1.0, 1.0, 0.0]))
    with pytest.raises(FitError, match=r"^circle: the points are collinear after projection"):
        fit_circle_3d(pts, normal=E1)  # the circle seen edge-on
    with pytest.raises(FitError, match=r"^circle: normal must not be the zero vector"):
        fit_circle_3d(pts, normal=[0.0, 0.0, 0.0])
    with pytest.raises(FitError, match=r"^circle: normal must be a finite 3-vector"):
        fit_circle_3d(pts, normal=[0.0, np.nan, 1.0])


def test_short_arc_is_ill_conditioned() -> None:
    pts = circle_points(np.linspace(0.0, 0.01, 10), 20.0)
    with pytest.raises(
        FitError,
        match=r"^circle: the normal equations are ill-conditioned .* arc of half-angle "
        r"0\.005 deg, too small to determine the centre and radius; measure a larger arc$",
    ):
        fit_circle_3d(pts, normal=NORMAL)


def test_circle_non_convergence() -> None:
    rng = np.random.default_rng(3)
    pts = circle_points(rng.uniform(0.0, 40.0, 20), 10.0, rng.normal(0.0, 0.05, 20))
    with pytest.raises(FitError, match=r"^circle: the geometric fit did not converge in 1 "):
        fit_circle_3d(pts, max_iter=1)
