"""Touch points on a ball's upper cap with clearance moves, and their execution."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.touch import cap_directions
from hexatherm.devices.ipp.client import IppClient
from hexatherm.devices.ipp.transcript import ProbedPoint
from hexatherm.errors import (
    IppDmeError,
)
from hexatherm.typing import FloatArray


# ------------------------------------------------------------------- touch plans
@dataclass(frozen=True)
class CapTouchPlan:
    """Touch points on the upper caps of balls, with their clearance moves (CMM frame, mm).

    Shapes for ``m`` balls (any leading shape ``...``) and ``n`` points per ball. Positions
    named ``*_mm`` of the probe are of its tip centre (what ``GoTo`` moves).

    Attributes
    ----------
    points_mm : ndarray, shape (..., n, 3)
        Nominal surface points (``PtMeas`` targets).
    ijk : ndarray, shape (..., n, 3)
        Unit outward normals at the points (``PtMeas`` IJK; the probe moves along minus it).
    approach_mm : ndarray, shape (..., n, 3)
        Tip centre ``approach`` mm off the surface along the normal (``GoTo`` before each
        ``PtMeas``).
    above_mm : ndarray, shape (..., n, 3)
        Tip centre at the safe height straight above each approach position.
    safe_mm : ndarray, shape (..., 3)
        Tip centre at the safe height straight above the ball's centre.
    """

    points_mm: FloatArray
    ijk: FloatArray
    approach_mm: FloatArray
    above_mm: FloatArray
    safe_mm: FloatArray

    def ball(self, index: int | tuple[int, ...]) -> CapTouchPlan:
        """The plan of one ball of a multi-ball plan."""
        return CapTouchPlan(
            self.points_mm[index],
            self.ijk[index],
            self.approach_mm[index],
            self.above_mm[index],
            self.safe_mm[index],
        )


def cap_touch_plan(
    centre_mm: npt.ArrayLike,
    ball_diameter_mm: float,
    tip_diameter_mm: float,
    n_points: int,
    cap_angle_deg: float,
    *,
    approach_mm: float = 2.0,
    clearance_mm: float = 5.0,
) -> CapTouchPlan:
    """Touch points on the upper cap (CMM +Z) of balls around their predicted centres.

    The points follow a golden-angle spiral of equal areas from near the pole to the cap's
    rim (:func:`hexatherm.core.touch.cap_directions`). The moves that go with them, for each
    point: ``above`` (safe height) -> ``approach`` -> ``PtMeas`` -> ``above``; between points
    the probe travels at the safe height, ``clearance`` above the ball's top, so it never
    crosses the ball: the vertical descent to an approach position at polar angle ``theta``
    stays at least ``radius + tip radius + approach`` from the centre as long as
    ``theta <= 90`` deg, and the horizontal travel is above the ball.

    Parameters
    ----------
    centre_mm : array_like, shape (..., 3)
        Predicted ball centres in the CMM frame, mm.
    ball_diameter_mm, tip_diameter_mm : float
        Ball and probe tip diameters, mm.
    n_points : int
        Points per ball (>= 1; a free-radius sphere fit needs 4).
    cap_angle_deg : float
        Half-angle of the probed cap from +Z, deg, in (0, 90].
    approach_mm : float
        Distance of the approach positions from the surface, mm (> 0); the prediction's
        error along the normal must stay below it plus the server's search distance.
    clearance_mm : float
        Height of the safe plane above the ball's top (tip surface), mm (>= approach_mm).

    Returns
    -------
    CapTouchPlan

    Raises
    ------
    IppDmeError
        On a bad argument.

    Examples
    --------
    >>> plan = cap_touch_plan([[0, 0, 100.0], [50, 0, 100.0]], 25.4, 2.0, 5, 60.0)
    >>> plan.points_mm.shape, plan.safe_mm[1].tolist()
    ((2, 5, 3), [50.0, 0.0, 118.7])
    >>> d = np.linalg.norm(plan.points_mm - np.array([[[0, 0, 100.0]], [[50, 0, 100.0]]]), axis=-1)
    >>> bool(np.allclose(d, 12.7)), bool(np.all(plan.ijk[..., 2] >= 0.5 - 1e-12))
    (True, True)
    """
    centres = np.asarray(centre_mm, dtype=float)
    if centres.ndim < 1 or centres.shape[-1] != 3:
        raise IppDmeError(f"centre_mm must have shape (..., 3), got {centres.shape}")
    if not np.all(np.isfinite(centres)):
        raise IppDmeError("centre_mm has non-finite values")
    for name, value in (
        ("ball_diameter_mm", ball_diameter_mm),
        ("tip_diameter_mm", tip_diameter_mm),
    ):
        if not (math.isfinite(value) and value > 0):
            raise IppDmeError(f"{name} must be positive, got {value!r}")
    if int(n_points) != n_points or n_points < 1:
        raise IppDmeError(f"n_points must be a positive integer, got {n_points!r}")
    if not (math.isfinite(cap_angle_deg) and 0 < cap_angle_deg <= 90):
        raise IppDmeError(f"cap_angle_deg must be in (0, 90], got {cap_angle_deg!r}")
    if not (math.isfinite(approach_mm) and approach_mm > 0):
        raise IppDmeError(f"approach_mm must be positive, got {approach_mm!r}")
    if not (math.isfinite(clearance_mm) and clearance_mm >= approach_mm):
        raise IppDmeError(
            f"clearance_mm must be at least approach_mm ({approach_mm}), got {clearance_mm!r}"
        )
    radius = 0.5 * float(ball_diameter_mm)
    tip = 0.5 * float(tip_diameter_mm)
    u = cap_directions(int(n_points), float(cap_angle_deg))
    c = centres[..., None, :]
    points = c + radius * u
    approach = c + (radius + tip + approach_mm) * u
    safe_z = centres[..., 2] + radius + tip + clearance_mm
    above = approach.copy()
    above[..., 2] = safe_z[..., None]
    safe = centres.copy()
    safe[..., 2] = safe_z
    ijk = np.broadcast_to(u, points.shape).copy()
    return CapTouchPlan(points, ijk, approach, above, safe)


@dataclass(frozen=True)
class CapMeasurement:
    """Points probed on one ball by :func:`probe_cap`.

    Attributes
    ----------
    points_mm : ndarray, shape (n, 3)
        Reported points, mm.
    ijk : ndarray, shape (n, 3)
        Reported IJK (NaN when not in the report).
    er_mm : ndarray, shape (n,)
        Reported effective tool radius (NaN when not in the report), mm.
    probed : tuple of ProbedPoint
        The points as reported (tags, times).
    """

    points_mm: FloatArray
    ijk: FloatArray
    er_mm: FloatArray
    probed: tuple[ProbedPoint, ...]


def probe_cap(client: IppClient, plan: CapTouchPlan) -> CapMeasurement:
    """Probe one ball's cap: safe height, then for each point above -> approach -> PtMeas -> above.

    The move to the first safe position is a straight ``GoTo`` from wherever the probe is:
    the caller brings it to a travel height free of obstacles first.

    Parameters
    ----------
    client : IppClient
        Connected, in a session, homed, with a tool and a report holding X, Y, Z.
    plan : CapTouchPlan
        Of one ball (``points_mm`` of shape (n, 3); :meth:`CapTouchPlan.ball`).

    Returns
    -------
    CapMeasurement
    """
    if plan.points_mm.ndim != 2:
        raise IppDmeError(
            f"probe_cap takes the plan of one ball (points (n, 3)), got {plan.points_mm.shape}"
        )
    client.goto(*plan.safe_mm)
    probed = []
    for k in range(plan.points_mm.shape[0]):
        client.goto(*plan.above_mm[k])
        client.goto(*plan.approach_mm[k])
        probed.append(client.pt_meas(*plan.points_mm[k], *plan.ijk[k]))
        client.goto(*plan.above_mm[k])
    client.goto(*plan.safe_mm)
    nan3 = (math.nan, math.nan, math.nan)
    return CapMeasurement(
        points_mm=np.array([p.point_mm for p in probed], dtype=float).reshape(-1, 3),
        ijk=np.array([p.ijk or nan3 for p in probed], dtype=float).reshape(-1, 3),
        er_mm=np.array([math.nan if p.er_mm is None else p.er_mm for p in probed], dtype=float),
        probed=tuple(probed),
    )
