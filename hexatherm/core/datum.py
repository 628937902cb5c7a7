"""The platform frame from its datum features: a 3-2-1 alignment (the paper's section 4).

The platform frame is defined by features machined on the platform: its top
face and two bores. From one CMM measurement:

* **Z**: the normal of the plane fitted to points on the top face, pointing to
  the side of the balls (the balls stand on the top face);
* **X**: from the first bore's centre to the second's, both fitted as circles in
  the top face's plane, made orthogonal to Z;
* **origin**: the first bore's centre projected on the plane, moved by an
  optional offset given in the datum frame.

The balls' centres, fitted to their points in the same measurement, are then
expressed in that frame: that is the balls file.

>>> import numpy as np
>>> plane = np.array([[0, 0, 0], [50, 0, 0], [0, 50, 0], [50, 50, 0.0]])
>>> ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
>>> bore1 = np.column_stack([5 * np.cos(ang) + 10, 5 * np.sin(ang), np.full(8, -3.0)])
>>> bore2 = bore1 + [40, 0, 0]
>>> frame = datum_frame(plane, bore1, bore2, towards=[0, 0, 1])
>>> np.round(frame.datum2cmm, 12) + 0.0
array([[ 1.,  0.,  0., 10.],
       [ 0.,  1.,  0.,  0.],
       [ 0.,  0.,  1.,  0.],
       [ 0.,  0.,  0.,  1.]])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.planefit import CircleFit, PlaneFit, fit_circle_3d, fit_plane
from hexatherm.errors import FitError
from hexatherm.typing import FloatArray

#: smallest accepted distance between the two bore centres, mm
MIN_BORE_DISTANCE_MM = 1.0


@dataclass(frozen=True)
class DatumFrame:
    """The frame built from the datum features, and the fits behind it.

    Attributes
    ----------
    datum2cmm : ndarray, shape (4, 4)
        The datum frame (before any origin offset) in CMM coordinates.
    plane : PlaneFit
    bores : tuple of CircleFit
        The two bore circles, with their centres projected on the plane.
    """

    datum2cmm: FloatArray
    plane: PlaneFit
    bores: tuple[CircleFit, CircleFit]


def datum_frame(
    plane_points_mm: npt.ArrayLike,
    bore1_points_mm: npt.ArrayLike,
    bore2_points_mm: npt.ArrayLike,
    *,
    towards: npt.ArrayLike,
    tip_radius_mm: float = 0.0,
) -> DatumFrame:
    """Build the datum frame from the top face and two bores (CMM coordinates).

    Parameters
    ----------
    plane_points_mm, bore1_points_mm, bore2_points_mm : array_like, shape (n, 3)
        Points on the top face and on the walls of the two bores.
    towards : array_like, shape (3,)
        A direction from the face towards the side where the balls are (Z's sense).
    tip_radius_mm : float
        For points that are probe-tip centres (not compensated): the face points
        lie ``tip_radius_mm`` above the face, which is corrected here. Bore
        centres are not affected.
    """
    plane = fit_plane(plane_points_mm, towards=towards)
    z = plane.normal
    face_point = plane.point_mm - tip_radius_mm * z
    bores = []
    for name, points in (("bore 1", bore1_points_mm), ("bore 2", bore2_points_mm)):
        try:
            circle = fit_circle_3d(points, normal=z)
        except FitError as exc:
            raise FitError(f"{name}: {exc}") from None
        centre = circle.centre_mm - np.dot(circle.centre_mm - face_point, z) * z
        bores.append(
            CircleFit(
                centre,
                circle.radius_mm,
                circle.normal,
                circle.rms_um,
                circle.form_um,
                circle.n,
                circle.residuals_mm,
                circle.arc_half_angle_deg,
                circle.iterations,
            )
        )
    x = bores[1].centre_mm - bores[0].centre_mm
    distance = float(np.linalg.norm(x))
    if distance < MIN_BORE_DISTANCE_MM:
        raise FitError(
            f"the two bore centres are {distance:.3f} mm apart: they cannot give "
            f"the X direction (need at least {MIN_BORE_DISTANCE_MM} mm)"
        )
    x = x / distance
    y = np.cross(z, x)
    frame = np.eye(4)
    frame[:3, :3] = np.column_stack([x, y, z])
    frame[:3, 3] = bores[0].centre_mm
    return DatumFrame(frame, plane, (bores[0], bores[1]))
