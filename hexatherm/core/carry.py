"""Measured frames carried to another thermal state of the legs (O and R0, issue 35).

The method's corrected poses refer to one thermal state of the legs, R0's. O, the frame
every pose is expressed in, is measured in its own state (before R0: the legs were
shorter when warming), and repeated measurements of O and R0 (``plan --origin-repeats
--reference0-repeats``) are each in their own. A frame measured while the legs were grown
by ``g`` (mm per leg, relative to the wanted state) stands where the platform would stand
with the legs ``q_cmd + g``; in the wanted state it would stand at ``FGM(IGM(X) - g)``.
So the measured platform frame ``F`` is carried by the motion (in the platform's own
frame) ``M = T(X)^-1 T(FGM(IGM(X) - g))``: ``F' = F M``, and the measured ball centres
by the rigid motion ``F M F^-1`` (:func:`carry_centres`), their noise unchanged.

The growth comes from the leg model and the thermocouple log (:func:`leg_growth`:
``s(q) (T(t) - T(t_state))``, ``s`` the leg's sensitivity in mm/K), the thermal state of
a leg being its logged temperature; its error is estimated from how well the same model
predicts the references' measured growth (:func:`model_misfit`). Signs: a leg that
warmed since the wanted state has ``g > 0``; carrying takes it off.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    angle_rates,
    angle_velocities,
    apply_transform,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.thermal import LegThermalModel
from hexatherm.typing import FloatArray

__all__ = [
    "carry_centres",
    "carry_motion",
    "leg_growth",
    "model_misfit",
    "shifted_poses",
    "shifted_pose_derivative",
    "shift_derivative",
    "shift_jacobian",
]


def leg_growth(
    legs: LegThermalModel,
    q_cmd_mm: npt.ArrayLike,
    leg_C: npt.ArrayLike,
    state_leg_C: npt.ArrayLike,
) -> FloatArray:
    """Growth (..., 6) of legs at commanded lengths ``q_cmd_mm`` since a thermal state:
    ``s(q) (T - T_state)`` leg by leg (``leg_C`` (..., 6), ``state_leg_C`` (6,)).

    >>> from hexatherm.core.thermal import LegThermalModel
    >>> legs = LegThermalModel.uniform([("rod", "steel", 11.5e-6, None)])  # one steel rod
    >>> g = leg_growth(legs, np.full(6, 400.0), np.full(6, 21.0), np.full(6, 20.0))
    >>> round(float(g[0]) * 1e3, 3)  # um: 400 mm of steel warmed 1 K
    4.6
    """
    temp = np.asarray(leg_C, dtype=float) - np.asarray(state_leg_C, dtype=float)
    return np.asarray(legs.sensitivity_mm_per_K(q_cmd_mm) * temp, dtype=float)


def carry_motion(hexapod: Hexapod, pose_cmd: npt.ArrayLike, growth_mm: npt.ArrayLike) -> FloatArray:
    """Motions (n, 4, 4), in the platform's frame, from the state where the legs are grown
    by ``growth_mm`` (n, 6) to the wanted state, at commanded poses ``pose_cmd`` (n, 6).

    >>> from hexatherm.core.hexapod import Hexapod
    >>> hx = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
    ...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200)
    >>> m = carry_motion(hx, np.zeros((1, 6)), np.full((1, 6), 1e-3))  # every leg 1 um longer
    >>> bool(m[0, 2, 3] < 0) and bool(np.allclose(m[0, :3, :3], np.eye(3)))  # carried down
    True
    """
    x = np.atleast_2d(np.asarray(pose_cmd, dtype=float))
    g = np.broadcast_to(np.asarray(growth_mm, dtype=float).reshape(-1, 6), x.shape)
    moved = hexapod.fgm(hexapod.igm(x) - g, initial_poses=x)
    return invert_transform(transform_from_pose(x, hexapod.convention)) @ transform_from_pose(
        moved, hexapod.convention
    )


def carry_centres(
    platform2cmm: npt.ArrayLike, motion: npt.ArrayLike, centres_mm: npt.ArrayLike
) -> FloatArray:
    """Centres (n, k, 3) of frames ``platform2cmm`` (n, 4, 4) carried by ``motion`` (n, 4, 4)
    (the platform's own frame): ``F M F^-1 c``, a rigid motion of the measured centres."""
    f = np.asarray(platform2cmm, dtype=float)
    return apply_transform(f @ np.asarray(motion, dtype=float) @ invert_transform(f), centres_mm)


def model_misfit(
    measured_mm: npt.ArrayLike, predicted_mm: npt.ArrayLike, noise_mm2: float = 0.0
) -> float:
    """Relative error of the leg model's growth that the references show: the gain ``a``
    of ``measured = a predicted`` (least squares over references and legs), less twice
    its standard error ``se = sqrt(noise / n) / |predicted|`` (``noise`` the sum of the
    measured growths' noise variances over the n values): ``max(0, |a - 1| - 2 se)``. A
    gain reads what matters for carrying a growth (a lag, a wrong expansion coefficient);
    a gain error within the references' noise is not seen, and not stated. 1 when the
    model predicts no growth.

    >>> model_misfit([[1.0, 2.0]], [[1.0, 2.0]]), round(model_misfit([[1.1]], [[1.0]]), 3)
    (0.0, 0.1)
    """
    m = np.asarray(measured_mm, dtype=float).ravel()
    p = np.asarray(predicted_mm, dtype=float).ravel()
    size = float(np.sum(p**2))
    if not size > 0:
        return 1.0
    gain = float(np.sum(m * p)) / size
    se = float(np.sqrt(noise_mm2 / max(m.size, 1) / size))
    return max(0.0, abs(gain - 1.0) - 2.0 * se)


def shifted_poses(shift: npt.ArrayLike, poses: npt.ArrayLike, convention: str) -> FloatArray:
    """Poses (..., 6) relative to a frame ``shift`` (4, 4, given relative to the poses'
    frame): ``pose(shift^-1 T(X))``."""
    x = np.asarray(poses, dtype=float)
    t = transform_from_pose(x.reshape(-1, 6), convention).reshape(x.shape[:-1] + (4, 4))
    return pose_from_transform(invert_transform(np.asarray(shift, dtype=float)) @ t, convention)


def shifted_pose_derivative(shift: FloatArray, poses: FloatArray, convention: str) -> FloatArray:
    """Derivatives (M, 6, 6) of :func:`shifted_poses` (the poses
    relative to a fixed frame ``shift``) by the poses, analytic: the translations turn by
    ``D_R^T``; an angle step turns the rotation by ``E(X)`` (the inverse of
    :func:`~hexatherm.core.geometry.angle_rates`), seen as ``D_R^T E`` in the shifted frame,
    whose angles move by ``angle_rates(X') D_R^T E(X)``."""
    x = np.asarray(poses, dtype=float)
    back = np.asarray(shift, dtype=float)[:3, :3].T
    moved = shifted_poses(shift, x, convention)
    out = np.zeros(x.shape[:-1] + (6, 6))
    out[..., :3, :3] = back
    turn = back @ angle_velocities(x[..., 3:], convention)
    out[..., 3:, 3:] = angle_rates(moved[..., 3:], convention) @ turn
    return out


def shift_derivative(shift: FloatArray, poses: FloatArray, convention: str) -> FloatArray:
    """Derivatives (M, 6, 6) of :func:`shifted_poses` by the shift's own pose ``d``
    (``shift = T(d)``), analytic. ``Y = D^-1 T(X)``: the shift's translation moves ``Y``'s
    by ``-D_R^T``; an angle step turns ``D_R`` on the left by ``omega = E(d) delta``
    (``E`` the inverse of :func:`~hexatherm.core.geometry.angle_rates`), which turns
    ``Y``'s rotation by ``-D_R^T omega`` (its angles by ``angle_rates(Y)`` of that) and
    moves its translation by ``D_R^T [X_p - D_p]x omega``."""
    x = np.asarray(poses, dtype=float)
    d = np.asarray(shift, dtype=float)
    back = d[:3, :3].T
    rad_per_deg = angle_velocities(pose_from_transform(d, convention)[3:], convention)
    lever = x[..., :3] - d[:3, 3]
    skew = np.zeros(x.shape[:-1] + (3, 3))  # [lever]x
    skew[..., 0, 1], skew[..., 1, 0] = -lever[..., 2], lever[..., 2]
    skew[..., 0, 2], skew[..., 2, 0] = lever[..., 1], -lever[..., 1]
    skew[..., 1, 2], skew[..., 2, 1] = -lever[..., 0], lever[..., 0]
    moved = shifted_poses(d, x, convention)
    out = np.zeros(x.shape[:-1] + (6, 6))
    out[..., :3, :3] = -back
    out[..., :3, 3:] = back @ skew @ rad_per_deg
    out[..., 3:, 3:] = -(angle_rates(moved[..., 3:], convention) @ (back @ rad_per_deg))
    return out


def shift_jacobian(
    shift: npt.ArrayLike, poses: npt.ArrayLike, convention: str
) -> tuple[FloatArray, FloatArray]:
    """Derivatives of :func:`shifted_poses` by the poses (M, 6, 6) and by the shift's own
    pose (M, 6, 6), analytic (:func:`shifted_pose_derivative`, :func:`shift_derivative`)."""
    x = np.asarray(poses, dtype=float)
    d = np.asarray(shift, dtype=float)
    return shifted_pose_derivative(d, x, convention), shift_derivative(d, x, convention)
