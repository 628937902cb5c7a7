"""The hexapod twin: what the CMM sees at each step of a plan (no effects yet).

For step k measured at time ``t_k`` with commanded pose ``X_k`` (spec, "The
hexapod twin"):

1. ``q_cmd = IGM(X_k)`` with the nominal geometry.
2. Leg temperatures ``T_i(t_k)``: thermocouple samples interpolated linearly in
   time; each leg grows by ``dq_i = sum_s cte_s L_s (T_i - T_ref)`` with the
   variable segment's length ``q_cmd_i - sum(fixed)``.
3. ``q = q_cmd + dq``; the platform pose is ``FGM(q)``; the measured pose is that
   pose relative to the predicted pose of the origin step.

The ball centres in the CMM frame follow from a placement ``origin2cmm`` of the
nominal frame O on the CMM. The *true corrected* pose of a step is the pose it
would have had with the legs at the temperatures of the first reference step.

>>> import numpy as np
>>> leg_temperatures_at([0.0, 100.0], [[20.0] * 6, [30.0] * 6], [50.0])[0, 0]
np.float64(25.0)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    apply_transform,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TwinSteps:
    """The twin's prediction for every step of a plan.

    Attributes
    ----------
    q_cmd_mm : ndarray, shape (N, 6)
        Commanded leg lengths.
    growth_mm : ndarray, shape (N, 6)
        Thermal growth of each leg at the step's time.
    platform2origin_nominal : ndarray, shape (N, 4, 4)
        True platform frame relative to the nominal frame O.
    pose : ndarray, shape (N, 6)
        True pose at measurement time relative to the measured origin step.
    corrected_pose : ndarray, shape (N, 6)
        True pose with the legs at the thermal state of the first reference step,
        relative to the measured origin step (equals ``pose`` for that step).
    centres_cmm_mm : ndarray, shape (N, k, 3)
        True ball centres in the CMM frame.
    """

    q_cmd_mm: FloatArray
    growth_mm: FloatArray
    platform2origin_nominal: FloatArray
    pose: FloatArray
    corrected_pose: FloatArray
    centres_cmm_mm: FloatArray


def leg_temperatures_at(
    sample_times_s: npt.ArrayLike, samples_C: npt.ArrayLike, times_s: npt.ArrayLike
) -> FloatArray:
    """Leg temperatures (n, L) at ``times_s``, joining the samples (m, L) by straight lines.

    Outside the sampled span the first/last sample holds.
    """
    ts = np.asarray(sample_times_s, dtype=float)
    temps = np.asarray(samples_C, dtype=float)
    t = np.asarray(times_s, dtype=float)
    return np.column_stack([np.interp(t, ts, temps[:, j]) for j in range(temps.shape[1])])


def predict_steps(
    hexapod: Hexapod,
    plan: Plan,
    leg_temperature_C: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    origin2cmm: npt.ArrayLike,
) -> TwinSteps:
    """Predict every step of ``plan`` given each step's leg temperatures (N, 6)."""
    if hexapod.legs is None:
        raise ValueError("the twin needs the hexapod's leg model (legs:)")
    temps = np.asarray(leg_temperature_C, dtype=float)
    q_cmd = hexapod.igm(plan.poses)
    growth = hexapod.legs.growth_mm(q_cmd, temps)
    absolute = hexapod.fgm(q_cmd + growth, initial_poses=plan.poses)
    platform2origin = transform_from_pose(absolute, hexapod.convention)
    origin = plan.origin_index
    measured = invert_transform(platform2origin[origin]) @ platform2origin

    refs = plan.reference_indices
    state = temps[refs[0]] if refs.size else temps[origin]
    growth0 = hexapod.legs.growth_mm(q_cmd, np.broadcast_to(state, temps.shape))
    absolute0 = hexapod.fgm(q_cmd + growth0, initial_poses=plan.poses)
    corrected = invert_transform(platform2origin[origin]) @ transform_from_pose(
        absolute0, hexapod.convention
    )

    frames = np.asarray(origin2cmm, dtype=float) @ platform2origin
    centres = apply_transform(frames, np.asarray(balls_mm, dtype=float))
    return TwinSteps(
        q_cmd_mm=q_cmd,
        growth_mm=growth,
        platform2origin_nominal=platform2origin,
        pose=pose_from_transform(measured, hexapod.convention),
        corrected_pose=pose_from_transform(corrected, hexapod.convention),
        centres_cmm_mm=centres,
    )


def cap_directions(n_points: int, cap_half_angle_deg: float) -> FloatArray:
    """``n_points`` unit vectors spread evenly over a cap around +Z (a Fibonacci spiral).

    >>> d = cap_directions(25, 60.0)
    >>> bool(np.allclose(np.linalg.norm(d, axis=1), 1.0)), bool(d[:, 2].min() >= 0.5 - 1e-12)
    (True, True)
    """
    if n_points < 1:
        raise ValueError("need at least one point")
    i = np.arange(n_points) + 0.5
    cos_min = np.cos(np.deg2rad(cap_half_angle_deg))
    z = 1.0 - (1.0 - cos_min) * i / n_points
    golden = np.pi * (3.0 - np.sqrt(5.0))
    phi = golden * i
    rho = np.sqrt(np.clip(1.0 - z**2, 0.0, None))
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


def probe_points(
    centres_mm: npt.ArrayLike,
    radius_mm: npt.ArrayLike,
    n_points: int,
    cap_half_angle_deg: float,
    noise_mm: float = 0.0,
    rng: np.random.Generator | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Surface points probed on the upper caps (CMM +Z) of balls, with normal noise.

    Parameters
    ----------
    centres_mm : array_like, shape (..., 3)
        Ball centres in the CMM frame.
    radius_mm : array_like, broadcastable to ``centres_mm.shape[:-1]``
        Radius of the surface the points lie on (ball radius for compensated points,
        plus the tip radius for tip-centre points).
    n_points, cap_half_angle_deg : int, float
        Points per ball and the half-angle of the probed cap.
    noise_mm : float
        Standard deviation of the probing error along the surface normal.

    Returns
    -------
    points : ndarray, shape (..., n_points, 3)
    directions : ndarray, shape (n_points, 3)
        Outward normals (the probing direction is their opposite).
    """
    rng = rng or np.random.default_rng(0)
    centres = np.asarray(centres_mm, dtype=float)
    radius = np.broadcast_to(np.asarray(radius_mm, dtype=float), centres.shape[:-1])
    dirs = cap_directions(n_points, cap_half_angle_deg)
    noise = rng.normal(scale=noise_mm, size=centres.shape[:-1] + (n_points,)) if noise_mm else 0.0
    dist = radius[..., None] + noise
    return centres[..., None, :] + dist[..., None] * dirs, dirs
