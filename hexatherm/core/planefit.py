"""Orthogonal least-squares plane fits and circle-in-3D fits.

Plane
    The plane minimising the sum of squared orthogonal distances passes
    through the centroid, and its normal is the right singular vector of the
    centred points with the smallest singular value (total least squares):
    :func:`fit_plane` computes exactly that, with an SVD of the centred points.
Circle in 3D
    The points are projected onto a plane (the fitted plane, or the plane
    through their centroid with a given normal) and a geometric 2D circle fit
    minimises the sum of squared *in-plane radial* distances
    ``|x_i - c| - r`` of the projected points, by the same algebraic start +
    Gauss-Newton / Levenberg-Marquardt engine as the sphere fits
    (:mod:`hexatherm.core.spherefit`).  The out-of-plane deviations are the
    business of the plane (its form), not of the circle.

Thresholds
----------
``COLLINEAR_RTOL = 1e-9``
    Points are collinear when the second singular value of the centred points
    is below 1e-9 times the first.  Here the SVD is taken of the points
    themselves (not of a scatter matrix), so singular values are resolved down
    to about ``eps * sigma_1``; at 1e-9 a rounding error of ``eps`` tilts the
    normal by about 2e-7 rad at worst.  The circle fit also applies the sphere
    engine's own limits (:data:`~hexatherm.core.spherefit.COPLANAR_RTOL` on its
    2D scatter matrix and :data:`~hexatherm.core.spherefit.COND_MAX`), so a
    very short arc is rejected as ill-conditioned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hexatherm.core.spherefit import _as_points, _fit_nspheres
from hexatherm.errors import FitError

__all__ = ["COLLINEAR_RTOL", "CircleFit", "PlaneFit", "fit_circle_3d", "fit_plane"]

COLLINEAR_RTOL = 1e-9
"""Smallest accepted ratio of second to first singular value of the centred points."""


@dataclass(frozen=True)
class PlaneFit:
    """Orthogonal least-squares plane.

    Attributes
    ----------
    point_mm : numpy.ndarray
        (3,) point on the plane: the centroid of the points.
    normal : numpy.ndarray
        (3,) unit normal, oriented as described in :func:`fit_plane`.
    rms_um : float
        RMS of the point-to-plane distances, micrometres.
    form_um : float
        Flatness: max minus min of the signed distances, micrometres.
    n : int
        Number of points.
    residuals_mm : numpy.ndarray
        (n,) signed distance of each point to the plane, along ``normal``.
    """

    point_mm: np.ndarray
    normal: np.ndarray
    rms_um: float
    form_um: float
    n: int
    residuals_mm: np.ndarray


@dataclass(frozen=True)
class CircleFit:
    """Least-squares circle in 3D.

    Attributes
    ----------
    centre_mm : numpy.ndarray
        (3,) centre, in the plane of the circle.
    radius_mm : float
        Radius.
    normal : numpy.ndarray
        (3,) unit normal of the circle's plane.
    rms_um : float
        RMS of the in-plane radial residuals, micrometres.
    form_um : float
        Roundness: max minus min of the radial residuals, micrometres.
    n : int
        Number of points.
    residuals_mm : numpy.ndarray
        (n,) signed radial residual ``|x - c| - r`` of each projected point.
    arc_half_angle_deg : float
        Half-angle of the arc covered by the points, seen from the centre
        (angle between the mean direction and the farthest point direction);
        180 when the directions cancel exactly.
    iterations : int
        Gauss-Newton / Levenberg-Marquardt iterations used.
    """

    centre_mm: np.ndarray
    radius_mm: float
    normal: np.ndarray
    rms_um: float
    form_um: float
    n: int
    residuals_mm: np.ndarray
    arc_half_angle_deg: float
    iterations: int


def _check_points(points_mm: ArrayLike, what: str) -> NDArray[np.float64]:
    pts = _as_points(points_mm)
    n = pts.shape[0]
    if n < 3:
        raise FitError(f"{what}: only {n} points; at least 3 are needed")
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FitError(
            f"{what}: point {i} has a non-finite coordinate {pts[i].tolist()} "
            f"({int(bad.sum())} such points)"
        )
    return pts


def _unit_vector(v: ArrayLike | None, name: str, what: str) -> NDArray[np.float64]:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FitError(f"{what}: {name} must be a numeric 3-vector: {exc}") from None
    if a.shape != (3,) or not np.isfinite(a).all():
        raise FitError(f"{what}: {name} must be a finite 3-vector, got {a.tolist()}")
    norm = float(np.linalg.norm(a))
    if norm == 0.0:
        raise FitError(f"{what}: {name} must not be the zero vector")
    return a / norm


def _orient(normal: NDArray[np.float64], towards: ArrayLike | None, what: str) -> NDArray:
    if towards is None:
        k = int(np.argmax(np.abs(normal)))
        return normal if normal[k] >= 0 else -normal
    t = _unit_vector(towards, "towards", what)
    dot = float(normal @ t)
    if abs(dot) < 1e-9:
        raise FitError(
            f"{what}: towards {t.tolist()} lies in the plane (angle to the normal "
            f"{np.degrees(np.arccos(np.clip(abs(dot), 0, 1))):.6f} deg), it cannot orient it"
        )
    return normal if dot > 0 else -normal


def fit_plane(points_mm: ArrayLike, *, towards: ArrayLike | None = None) -> PlaneFit:
    """Fit a plane by orthogonal (total) least squares.

    Parameters
    ----------
    points_mm : array_like
        (n, 3) points, mm, n >= 3, not collinear.
    towards : array_like, optional
        (3,) direction the normal must point to (positive dot product), e.g.
        away from the material.  Default: the normal's largest-magnitude
        component is made non-negative (a plane near z = const gets +Z).

    Returns
    -------
    PlaneFit
        Centroid, unit normal, RMS and flatness, residuals.

    Raises
    ------
    FitError
        Fewer than 3 points, non-finite coordinates, collinear points
        (second/first singular value below :data:`COLLINEAR_RTOL`), or a
        ``towards`` vector that is zero or lies in the plane.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 1.0], [10, 0, 1.0], [0, 10, 1.0], [10, 10, 1.002]])
    >>> fit = fit_plane(pts)
    >>> print(np.round(fit.normal, 6).tolist(), round(fit.form_um, 6))
    [-0.0001, -0.0001, 1.0] 1.0
    >>> print(np.round(fit_plane(pts, towards=[0, 0, -1]).normal, 6).tolist())
    [0.0001, 0.0001, -1.0]
    """
    what = "plane"
    pts = _check_points(points_mm, what)
    centroid = pts.mean(axis=0)
    q = pts - centroid
    _, sv, vt = np.linalg.svd(q, full_matrices=False)
    if not sv[0] > 0.0:
        raise FitError(f"{what}: all {pts.shape[0]} points coincide")
    if sv[1] < COLLINEAR_RTOL * sv[0]:
        raise FitError(
            f"{what}: the points are collinear or nearly so (second/first singular value "
            f"of the centred points {sv[1] / sv[0]:.3g} < {COLLINEAR_RTOL:.0e}); "
            "the plane is undetermined"
        )
    normal = _orient(vt[2], towards, what)
    res = q @ normal
    return PlaneFit(
        point_mm=centroid,
        normal=normal,
        rms_um=1e3 * float(np.sqrt(np.mean(res**2))),
        form_um=1e3 * float(res.max() - res.min()),
        n=int(pts.shape[0]),
        residuals_mm=res,
    )


def _plane_basis(normal: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Two unit vectors completing ``normal`` to a right-handed orthonormal basis."""
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(normal)))] = 1.0
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    return e1, e2


def fit_circle_3d(
    points_mm: ArrayLike,
    normal: ArrayLike | None = None,
    *,
    towards: ArrayLike | None = None,
    tol_mm: float = 1e-12,
    max_iter: int = 50,
) -> CircleFit:
    """Fit a circle to points in 3D.

    Parameters
    ----------
    points_mm : array_like
        (n, 3) points, mm, n >= 3.
    normal : array_like, optional
        (3,) normal of the circle's plane (need not be unit).  The points are
        projected onto the plane through their centroid with this normal.
        None: fit a plane first (:func:`fit_plane`).
    towards : array_like, optional
        Orientation of the reported normal (see :func:`fit_plane`).  With a
        given ``normal`` and no ``towards``, the given normal's sense is kept.
    tol_mm, max_iter
        Convergence tolerance on the Gauss-Newton step and iteration limit.

    Returns
    -------
    CircleFit
        Centre (in the plane), radius, unit normal, RMS and roundness of the
        radial residuals, arc half-angle.

    Raises
    ------
    FitError
        Fewer than 3 points, non-finite coordinates, collinear points (also
        after projection along the given normal), a zero or non-finite
        ``normal``, an arc too short for a well-conditioned fit, or no
        convergence.

    Examples
    --------
    A quarter arc of radius 5 in the plane x = 2:

    >>> import numpy as np
    >>> a = np.radians([0.0, 30.0, 60.0, 90.0])
    >>> pts = np.c_[np.full(4, 2.0), 1.0 + 5.0 * np.cos(a), -3.0 + 5.0 * np.sin(a)]
    >>> fit = fit_circle_3d(pts)
    >>> print(np.round(fit.centre_mm, 9) + 0.0, round(fit.radius_mm, 9), fit.normal + 0.0)
    [ 2.  1. -3.] 5.0 [1. 0. 0.]
    >>> round(fit.arc_half_angle_deg, 6)
    45.0
    """
    what = "circle"
    pts = _check_points(points_mm, what)
    if normal is None:
        plane = fit_plane(pts, towards=towards)
        nrm = plane.normal
    else:
        nrm = _unit_vector(normal, "normal", what)
        if towards is not None:
            nrm = _orient(nrm, towards, what)
    centroid = pts.mean(axis=0)
    e1, e2 = _plane_basis(nrm)
    q = pts - centroid
    x = np.c_[q @ e1, q @ e2]
    offset = x.mean(axis=0)  # ~0 already; exact centring in the plane for the engine
    x -= offset
    sv = np.linalg.svd(x, compute_uv=False)
    if not sv[0] > 0.0:
        raise FitError(f"{what}: all {pts.shape[0]} points coincide after projection")
    if sv[1] < COLLINEAR_RTOL * sv[0]:
        how = "" if normal is None else " after projection along the given normal"
        raise FitError(
            f"{what}: the points are collinear{how} (second/first singular value "
            f"{sv[1] / sv[0]:.3g} < {COLLINEAR_RTOL:.0e}); the circle is undetermined"
        )
    if not (np.isfinite(tol_mm) and tol_mm > 0):
        raise FitError(f"{what}: tol_mm must be a positive number, got {tol_mm!r}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise FitError(f"{what}: max_iter must be a positive integer, got {max_iter!r}")

    n = x.shape[0]
    try:
        sol = _fit_nspheres(
            x,
            np.array([n], dtype=np.int64),
            None,
            tol_mm=float(tol_mm),
            max_iter=int(max_iter),
            label="circle",
        )
    except FitError as exc:
        # The engine names "circle 0"; there is only one circle here.
        raise FitError(str(exc).replace("circle 0:", "circle:", 1)) from None
    c2 = sol.centre[0] + offset
    res = sol.residuals
    return CircleFit(
        centre_mm=centroid + c2[0] * e1 + c2[1] * e2,
        radius_mm=float(sol.radius[0]),
        normal=nrm,
        rms_um=1e3 * float(np.sqrt(np.mean(res**2))),
        form_um=1e3 * float(res.max() - res.min()),
        n=n,
        residuals_mm=res.copy(),
        arc_half_angle_deg=float(sol.coverage_deg[0]),
        iterations=int(sol.iterations[0]),
    )
