"""Touch points on the upper caps of the balls: the pattern every part of hexatherm probes with.

One golden-angle spiral (:func:`cap_directions`) is the touch pattern that ``plan`` hands
the CMM (:func:`touch_points`, the DMIS program), that the twin probes with, that the
``cmm:`` uncertainty assumes and that the I++ DME client touches: one pattern, one home.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import apply_transform, transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.errors import PlanError
from hexatherm.typing import FloatArray

#: default half-angle of the cap of each ball the CMM touches, degrees
DEFAULT_CAP_HALF_ANGLE_DEG = 75.0
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def cap_directions(n: int, cap_half_angle_deg: float = DEFAULT_CAP_HALF_ANGLE_DEG) -> FloatArray:
    """``n`` unit vectors spread evenly over the cap around +z of half-angle ``cap``.

    A golden-angle spiral with equal areas per point: point ``k`` is at polar
    angle ``acos(1 - (1 - cos cap) (k + 1/2) / n)`` and azimuth ``k`` times the
    golden angle, so any number of points covers the cap uniformly, from near
    the pole to near the cap's rim.

    Examples
    --------
    >>> u = cap_directions(25, 60.0)
    >>> bool(np.allclose(np.linalg.norm(u, axis=1), 1.0)), bool(u[:, 2].min() > 0.5)
    (True, True)
    """
    if n < 1:
        raise PlanError(f"the number of points per ball must be at least 1, got {n}")
    if not 0 < cap_half_angle_deg <= 180:
        raise PlanError(f"the cap half-angle must be in (0, 180] degrees, got {cap_half_angle_deg}")
    k = np.arange(n) + 0.5
    cos_t = 1.0 - (1.0 - math.cos(math.radians(cap_half_angle_deg))) * k / n
    sin_t = np.sqrt(np.clip(1.0 - cos_t**2, 0.0, None))
    phi = np.arange(n) * _GOLDEN_ANGLE
    return np.column_stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t])


def polar_uniform_directions(n: int, polar_min_deg: float, polar_max_deg: float) -> FloatArray:
    """``n`` unit vectors with polar angles spread uniformly over ``[min, max]`` degrees.

    Another CMM program's touch pattern (equal steps in polar angle, azimuth ``k`` times
    the golden angle): denser near the pole than :func:`cap_directions`' equal areas, so
    a sphere fit's centre has another covariance shape. The twin probes with it when told
    to, to check what ``process`` assumes about patterns it was not given.

    >>> u = polar_uniform_directions(25, 5.0, 80.0)
    >>> bool(np.allclose(np.linalg.norm(u, axis=1), 1.0))
    True
    >>> [round(float(np.degrees(np.arccos(u[i, 2]))), 1) for i in (0, -1)]
    [6.5, 78.5]
    """
    if n < 1:
        raise PlanError(f"the number of points per ball must be at least 1, got {n}")
    if not 0 <= polar_min_deg < polar_max_deg <= 180:
        raise PlanError(
            f"the polar angles must satisfy 0 <= min < max <= 180 degrees, got "
            f"{polar_min_deg}, {polar_max_deg}"
        )
    theta = np.radians(polar_min_deg + (polar_max_deg - polar_min_deg) * (np.arange(n) + 0.5) / n)
    phi = np.arange(n) * _GOLDEN_ANGLE
    return np.column_stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    )


@dataclass(frozen=True)
class TouchPoints:
    """Nominal ball centres and touch points of every step, in the CMM frame.

    Attributes
    ----------
    centres_mm : ndarray, shape (N, k, 3)
        Nominal ball centres of each step.
    points_mm : ndarray, shape (N, k, n, 3)
        Nominal surface points to touch.
    normals : ndarray, shape (N, k, n, 3)
        Outward surface normal at each point (the probe approaches along minus it).
    """

    centres_mm: FloatArray
    points_mm: FloatArray
    normals: FloatArray


def nominal_centres(
    plan: Plan,
    ball_centres_mm: npt.ArrayLike,
    origin_on_cmm: Sequence[float],
    convention: str = "symetrie",
) -> FloatArray:
    """Nominal ball centres of every step in the CMM frame, shape (N, k, 3):
    ``origin2cmm @ platform2origin(X_k) @ b`` (see :func:`touch_points`)."""
    balls = np.asarray(ball_centres_mm, dtype=float).reshape(-1, 3)
    origin2cmm = transform_from_pose(np.asarray(origin_on_cmm, dtype=float), convention)
    return apply_transform(origin2cmm @ transform_from_pose(plan.poses, convention), balls)


def touch_points(
    plan: Plan,
    ball_centres_mm: npt.ArrayLike,
    ball_diameters_mm: npt.ArrayLike,
    origin_on_cmm: Sequence[float],
    convention: str = "symetrie",
    *,
    cap_half_angle_deg: float = DEFAULT_CAP_HALF_ANGLE_DEG,
) -> TouchPoints:
    """Where the CMM should touch each ball at each step.

    The ball centres (platform frame) of step k are at
    ``origin2cmm @ platform2origin(X_k) @ b`` in the CMM frame, with ``X_k`` the
    commanded pose and ``origin2cmm`` the nominal placement of frame O on the
    CMM (``origin_on_cmm``, a pose in the hexapod's convention). The touch points
    are spread over the cap of each ball around the CMM's +z axis (the side a
    vertical probe reaches), :func:`cap_directions`.

    Examples
    --------
    >>> from hexatherm.core.planning import build_plan
    >>> plan = build_plan([[0, 0, 5, 0, 0, 0]], points_per_ball=4)
    >>> tp = touch_points(plan, [[10, 0, 30], [0, 10, 30], [-10, 0, 30]], [20, 20, 20],
    ...                   [100, 200, 50, 0, 0, 0])
    >>> tp.centres_mm[2, 0].tolist()
    [110.0, 200.0, 85.0]
    >>> bool(np.allclose(np.linalg.norm(tp.points_mm - tp.centres_mm[:, :, None], axis=-1), 10))
    True
    """
    radii = np.asarray(ball_diameters_mm, dtype=float).reshape(-1) / 2.0
    centres = nominal_centres(plan, ball_centres_mm, origin_on_cmm, convention)
    u = cap_directions(plan.points_per_ball, cap_half_angle_deg)
    normals = np.broadcast_to(u, centres.shape[:2] + u.shape).copy()
    points = centres[:, :, None, :] + radii[None, :, None, None] * normals
    return TouchPoints(centres, points, normals)
