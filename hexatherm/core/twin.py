"""The hexapod twin: what the CMM sees at each step of a plan.

For step k measured at time ``t_k`` with commanded pose ``X_k`` (spec, "The
hexapod twin and its effects"):

1. ``q_cmd = IGM(X_k)`` with the nominal geometry.
2. Leg temperatures ``T_i(t_k)``: thermocouple samples interpolated linearly in
   time; each leg grows by ``dq_i = sum_s cte_s L_s (T_s - T_ref)`` with the
   variable segment's length ``q_cmd_i - sum(fixed)``.
3. ``q = q_cmd + dq``; the platform pose is ``FGM(q)``; the measured pose is that
   pose relative to the predicted pose of the origin step.

Effects (:mod:`hexatherm.core.effects`) change this model stage by stage: the
leg temperatures (lag), the segment temperatures (overheat), the growth (CTE
error, a quadratic term), the leg lengths (offsets, backlash), the base joints of
each step (base expansion), the balls on the platform (the plate's expansion) and
the coordinates the CMM reports (drift, scale). A hexapod's positioning error
(repeatability) may be added to the leg lengths of each step.

The ball centres in the CMM frame follow from a placement ``origin2cmm`` of the
nominal frame O on the CMM. The *true corrected* pose of a step is the pose it
would have had in the thermal state of the first reference step (its segment
temperatures and its base joints), relative to the measured origin step.

>>> import numpy as np
>>> leg_temperatures_at([0.0, 100.0], [[20.0] * 6, [30.0] * 6], [50.0])[0, 0]
np.float64(25.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from hexatherm.core.effects import Effect, ThermocoupleLog, check_distinct
from hexatherm.core.geometry import (
    apply_transform,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.hexapod import FgmStart, Hexapod
from hexatherm.core.plan import Plan, find_repeats
from hexatherm.core.registration import register
from hexatherm.core.thermal import LegThermalModel
from hexatherm.core.touch import cap_directions, polar_uniform_directions
from hexatherm.typing import FloatArray


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
        True pose with the legs at the thermal state of the reference step, relative
        to the origin step in that state too (zero for that step; issue 35: relative to
        O as measured, in its own state, before).
    centres_cmm_mm : ndarray, shape (N, k, 3)
        True ball centres in the CMM frame (where the balls are when measured:
        ball effects included, CMM effects not).
    q_mm : ndarray, shape (N, 6)
        True leg lengths: commanded plus growth, offsets and positioning error.
    leg_temperature_C : ndarray, shape (N, 6)
        Effective temperature of each leg (after a lag).
    segment_temperature_C : ndarray, shape (N, 6, S)
        Temperature of every segment of every leg.
    base_joints_mm : ndarray, shape (N, 6, 3)
        Base joints of each step in the nominal frame O.
    reference_growth_mm : ndarray, shape (N, 6)
        Thermal growth of each leg of each step in the reference thermal state.
    reference_q_mm : ndarray, shape (N, 6)
        Leg lengths of each step in the reference thermal state.
    reference_index : int
        The step whose thermal state the corrected poses refer to (the first
        reference step R0, its last measurement when R0 is repeated, or the origin
        when the plan has none).
    measured_centres_cmm_mm : ndarray, shape (N, k, 3)
        Ball centres as the CMM reports them (CMM effects applied at each ball's
        time); equal to ``centres_cmm_mm`` without such effects.
    """

    q_cmd_mm: FloatArray
    growth_mm: FloatArray
    platform2origin_nominal: FloatArray
    pose: FloatArray
    corrected_pose: FloatArray
    centres_cmm_mm: FloatArray
    q_mm: FloatArray
    leg_temperature_C: FloatArray
    segment_temperature_C: FloatArray
    base_joints_mm: FloatArray
    reference_growth_mm: FloatArray
    reference_q_mm: FloatArray
    reference_index: int
    measured_centres_cmm_mm: FloatArray


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
    """Predict every step of ``plan`` given each step's leg temperatures (N, 6), no effect."""
    legs = _leg_model(hexapod)
    temps = np.asarray(leg_temperature_C, dtype=float)
    segments = np.broadcast_to(temps[..., None], temps.shape + (legs.variable.shape[1],))
    return _solve(
        hexapod,
        plan,
        temps,
        segments,
        None,
        (),
        np.asarray(balls_mm, dtype=float),
        origin2cmm,
        None,
        None,
        None,
        True,
        np.arange(len(plan.labels)),
    )


def predict(
    hexapod: Hexapod,
    plan: Plan,
    times_s: npt.ArrayLike,
    log: ThermocoupleLog,
    balls_mm: npt.ArrayLike,
    origin2cmm: npt.ArrayLike,
    effects: Sequence[Effect] = (),
    *,
    ball_times_s: npt.ArrayLike | None = None,
    positioning_error_mm: npt.ArrayLike | None = None,
    reference_state: bool = True,
    true_parameters: npt.ArrayLike | None = None,
    prepared: PreparedPlan | None = None,
) -> TwinSteps:
    """Predict every step of ``plan`` from its times, a thermocouple log and effects.

    Parameters
    ----------
    hexapod : Hexapod
        Nominal geometry and leg model (``hexapod.legs`` is required).
    plan : Plan
    times_s : array_like, shape (N,)
        Time of every step (seconds, the log's time base).
    log : ThermocoupleLog
        Thermocouple samples; its first sample is ``t_0``.
    balls_mm : array_like, shape (k, 3)
        Ball centres in the platform frame.
    origin2cmm : array_like, shape (4, 4)
        The nominal frame O in the CMM frame.
    effects : sequence of Effect
        Applied stage by stage (see :mod:`hexatherm.core.effects`); one of each name.
    ball_times_s : array_like, shape (N, k), optional
        When each ball was measured, for the CMM effects (default: the step's time).
    positioning_error_mm : array_like, shape (N, 6), optional
        The hexapod's positioning error of each step, added to its leg lengths
        (the same in the reference thermal state: it is not thermal).
    reference_state : bool
        Also solve every step in the reference thermal state (``corrected_pose``,
        ``reference_growth_mm``, ``reference_q_mm``); when False those are NaN and
        the prediction costs one forward model instead of two (the diagnosis).
    true_parameters : array_like, shape (48,), optional
        The hexapod's true geometry where it differs from the nominal ``hexapod`` (a
        calibration's truth), in the layout of
        :data:`hexatherm.core.calibration.model.PARAMETER_NAMES`: base and platform
        joints, leg offsets and gains. The controller commands ``IGM_nominal(X_cmd)``;
        the actuators then give ``q_cmd + dq + g (q_cmd - q_home)`` (plus the thermal
        growth), and the platform stands where the true joints put it.
    prepared : PreparedPlan, optional
        What the prediction computes of ``plan`` before any time
        (:meth:`PreparedPlan.of` of this ``hexapod``, ``plan`` and ``true_parameters``,
        whose ``true_parameters`` it then stands for), for many predictions of one plan
        at other times (the twin's servers): the same result, bit for bit.

    Returns
    -------
    TwinSteps
    """
    legs = _leg_model(hexapod)
    if prepared is not None and prepared.plan is not plan:
        raise ValueError("predict: the prepared plan is another plan")
    true = _TrueGeometry.of(hexapod, true_parameters) if prepared is None else prepared.true
    effects = tuple(effects)
    check_distinct(effects)
    t = np.asarray(times_s, dtype=float).reshape(-1)
    if t.shape != (len(plan.labels),):
        raise ValueError(f"need one time per step ({len(plan.labels)}), got {t.shape}")
    leg = effective_leg_temperatures(log, np.concatenate([[log.t0_s], t]), effects)
    leg0, leg = leg[0], leg[1:]
    segments = np.broadcast_to(leg[..., None], leg.shape + (legs.variable.shape[1],))
    for effect in effects:
        segments = effect.segment_temperature_C(segments, leg, leg0, legs.variable)
    base = true.solver.base_joints_mm
    for effect in effects:
        base = effect.base_joints_mm(base, t, log)
    step_base = (
        None if base is true.solver.base_joints_mm else np.broadcast_to(base, (t.size, 6, 3))
    )
    balls = np.asarray(balls_mm, dtype=float)
    if ball_times_s is None:
        ball_t = np.broadcast_to(t[:, None], (t.size, balls.shape[0]))
    else:
        ball_t = np.asarray(ball_times_s, dtype=float)
    for effect in effects:
        balls = effect.ball_positions_mm(balls, ball_t, log)
    return _solve(
        hexapod,
        plan,
        leg,
        segments,
        step_base,
        effects,
        balls,
        origin2cmm,
        positioning_error_mm,
        log,
        ball_t,
        reference_state,
        np.argsort(t, kind="stable"),
        true,
        prepared,
    )


def effective_leg_temperatures(
    log: ThermocoupleLog, times_s: npt.ArrayLike, effects: Sequence[Effect] = ()
) -> FloatArray:
    """Each leg's effective temperature (n, 6) at ``times_s``.

    The thermocouple log joined by straight lines, then the leg temperature stage
    of the effects (a lag).
    """
    t = np.asarray(times_s, dtype=float).reshape(-1)
    leg = log.legs_at(t)
    for effect in effects:
        leg = effect.leg_temperature_C(leg, t, log)
    return leg


def cmm_readings(
    xyz_mm: npt.ArrayLike,
    times_s: npt.ArrayLike,
    log: ThermocoupleLog,
    effects: Sequence[Effect] = (),
) -> FloatArray:
    """What the CMM reports for true coordinates (..., 3) measured at ``times_s`` (...)."""
    xyz = np.asarray(xyz_mm, dtype=float)
    t = np.broadcast_to(np.asarray(times_s, dtype=float), xyz.shape[:-1])
    for effect in effects:
        xyz = effect.cmm_coordinates_mm(xyz, t, log)
    return xyz


def _leg_model(hexapod: Hexapod) -> LegThermalModel:
    if hexapod.legs is None:
        raise ValueError("the twin needs the hexapod's leg model (legs:)")
    return hexapod.legs


def _solve(
    hexapod: Hexapod,
    plan: Plan,
    leg_C: FloatArray,
    segment_C: FloatArray,
    base: FloatArray | None,
    effects: tuple[Effect, ...],
    balls_mm: FloatArray,
    origin2cmm: npt.ArrayLike,
    positioning_error_mm: npt.ArrayLike | None,
    log: ThermocoupleLog | None,
    ball_times_s: FloatArray | None,
    reference_state: bool,
    order: npt.NDArray[np.intp],
    true: _TrueGeometry | None = None,
    prepared: PreparedPlan | None = None,
) -> TwinSteps:
    """Leg lengths, poses and centres from the segment temperatures and base joints.

    ``balls_mm`` are the balls in the platform frame, (k, 3) or per step (N, k, 3);
    ``order`` lists the steps in the order they were moved through; ``true`` the
    geometry the platform really has (default: the nominal ``hexapod``); ``prepared``
    what of this is the plan's alone, computed once (:class:`PreparedPlan`).
    """
    legs = _leg_model(hexapod)
    if prepared is None:
        prepared = PreparedPlan.of(hexapod, plan, true=true, start=False)
    true, q_cmd, actuated = prepared.true, prepared.q_cmd_mm, prepared.actuated_mm
    error = None if positioning_error_mm is None else np.asarray(positioning_error_mm, float)

    def lengths(segments: FloatArray, leg: FloatArray) -> tuple[FloatArray, FloatArray]:
        growth = legs.growth_mm(q_cmd, segments, per_segment=True)
        for effect in effects:
            growth = effect.leg_growth_mm(growth, leg, legs.reference_temperature_C)
        q = actuated + growth
        for effect in effects:
            q = effect.commanded_leg_length_mm(q, q_cmd, order)
        if error is not None:
            q = q + error
        return growth, q

    growth, q = lengths(segment_C, leg_C)
    absolute = prepared.fgm(q, base)
    platform2origin = transform_from_pose(absolute, hexapod.convention)
    origin = plan.origin_index
    origin2measured = invert_transform(platform2origin[origin])
    measured = origin2measured @ platform2origin

    # the reference state: R0's last measurement (R0's only one unless it is repeated),
    # the state process carries every measurement of O and R0 to
    r = prepared.reference_index
    if reference_state:
        growth0, q0 = lengths(
            np.broadcast_to(segment_C[r], segment_C.shape),
            np.broadcast_to(leg_C[r], leg_C.shape),
        )
        base0 = None if base is None else np.broadcast_to(base[r], base.shape)
        absolute0 = prepared.fgm(q0, base0)
        # relative to O in that state too (O's own state differs while the legs warm)
        frames0 = transform_from_pose(absolute0, hexapod.convention)
        corrected = pose_from_transform(
            invert_transform(frames0[origin]) @ frames0, hexapod.convention
        )
    else:
        growth0 = q0 = np.full_like(q, np.nan)
        corrected = np.full((q.shape[0], 6), np.nan)

    frames = np.asarray(origin2cmm, dtype=float) @ platform2origin
    centres = apply_transform(frames, balls_mm)
    measured_centres = centres
    if log is not None and ball_times_s is not None:
        measured_centres = cmm_readings(centres, ball_times_s, log, effects)
    n = q_cmd.shape[0]
    return TwinSteps(
        q_cmd_mm=q_cmd,
        growth_mm=growth,
        platform2origin_nominal=platform2origin,
        pose=pose_from_transform(measured, hexapod.convention),
        corrected_pose=corrected,
        centres_cmm_mm=centres,
        q_mm=q,
        leg_temperature_C=np.array(leg_C, dtype=float),
        segment_temperature_C=np.array(segment_C, dtype=float),
        base_joints_mm=np.array(
            np.broadcast_to(true.solver.base_joints_mm if base is None else base, (n, 6, 3))
        ),
        reference_growth_mm=growth0,
        reference_q_mm=q0,
        reference_index=r,
        measured_centres_cmm_mm=measured_centres,
    )


@dataclass(frozen=True)
class PreparedPlan:
    """What :func:`predict` computes of a plan before any time, computed once for many
    predictions of the plan at other times (the twin's servers predict one pose at every
    CMM motion): the true geometry, the commanded and actuated leg lengths, the reference
    step and the FGM's first iteration at the plan's poses (:meth:`Hexapod.fgm_start`).

    The same arithmetic on the same numbers as without it: a prediction is the same, bit
    for bit (``tests/core/test_twin_prepared.py``).
    """

    plan: Plan
    true: _TrueGeometry
    q_cmd_mm: FloatArray
    actuated_mm: FloatArray
    reference_index: int
    start: FgmStart | None

    @classmethod
    def of(
        cls,
        hexapod: Hexapod,
        plan: Plan,
        true_parameters: npt.ArrayLike | None = None,
        *,
        true: _TrueGeometry | None = None,
        start: bool = True,
    ) -> PreparedPlan:
        """The plan's part of :func:`predict` with ``hexapod`` (``true_parameters`` as
        there); ``start=False`` leaves the FGM's start to each call (a single prediction)."""
        true = true or _TrueGeometry.of(hexapod, true_parameters)
        q_cmd = hexapod.igm(plan.poses)
        repeats = find_repeats(plan)
        r = int(repeats.reference0[-1]) if repeats.reference0 else plan.origin_index
        fgm_start = true.solver.fgm_start(plan.poses) if start else None
        return cls(plan, true, q_cmd, true.actuated_mm(q_cmd), r, fgm_start)

    def fgm(self, q_mm: FloatArray, base: FloatArray | None) -> FloatArray:
        """The true platform's poses for leg lengths ``q_mm`` from the plan's poses, the
        base joints ``base`` per step (None: the true geometry's)."""
        if base is None and self.start is not None:
            return self.true.solver.fgm(q_mm, start=self.start)
        return self.true.solver.fgm(q_mm, initial_poses=self.plan.poses, base_joints_mm=base)


@dataclass(frozen=True)
class _TrueGeometry:
    """The geometry a twin's platform really has: its joints (``solver``) and the
    actuators' offsets and gains about the nominal home lengths."""

    solver: Hexapod
    offsets_mm: FloatArray
    gains: FloatArray
    home_mm: FloatArray

    @classmethod
    def of(cls, hexapod: Hexapod, true_parameters: npt.ArrayLike | None) -> _TrueGeometry:
        zeros = np.zeros(6)
        if true_parameters is None:
            return cls(hexapod, zeros, zeros, zeros)
        # here, not at the top: the calibration package imports its fit and scipy.stats
        # (0.35 s of CPU), which a twin of the nominal geometry (diagnose) never needs
        from hexatherm.core.calibration.model import split_parameters

        base, platform, offsets, gains = split_parameters(true_parameters)
        solver = replace(hexapod, base_joints_mm=base, platform_joints_mm=platform)
        return cls(solver, offsets, gains, hexapod.zero_pose_leg_length_mm())

    def actuated_mm(self, q_cmd: FloatArray) -> FloatArray:
        """Joint-to-joint lengths the actuators give for commanded lengths (no heat)."""
        return q_cmd + self.offsets_mm + self.gains * (q_cmd - self.home_mm)


def probe_points(
    centres_mm: npt.ArrayLike,
    radius_mm: npt.ArrayLike,
    n_points: int,
    cap_half_angle_deg: float,
    noise_mm: float = 0.0,
    rng: np.random.Generator | None = None,
    polar_range_deg: tuple[float, float] | None = None,
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
    polar_range_deg : (float, float), optional
        Probe with polar angles uniform over this range
        (:func:`~hexatherm.core.touch.polar_uniform_directions`) instead of the equal-area
        spiral over ``cap_half_angle_deg``.

    Returns
    -------
    points : ndarray, shape (..., n_points, 3)
    directions : ndarray, shape (n_points, 3)
        Outward normals (the probing direction is their opposite).
    """
    rng = rng or np.random.default_rng(0)
    centres = np.asarray(centres_mm, dtype=float)
    radius = np.broadcast_to(np.asarray(radius_mm, dtype=float), centres.shape[:-1])
    if polar_range_deg is None:
        dirs = cap_directions(n_points, cap_half_angle_deg)
    else:
        dirs = polar_uniform_directions(n_points, *polar_range_deg)
    noise = rng.normal(scale=noise_mm, size=centres.shape[:-1] + (n_points,)) if noise_mm else 0.0
    dist = radius[..., None] + noise
    return centres[..., None, :] + dist[..., None] * dirs, dirs


def twin_corrected(
    hexapod: Hexapod,
    plan: Plan,
    times_s: npt.ArrayLike,
    log: ThermocoupleLog,
    balls_mm: npt.ArrayLike,
    platform2cmm: npt.ArrayLike,
    effects: Sequence[Effect] = (),
    *,
    ball_times_s: npt.ArrayLike | None = None,
) -> FloatArray:
    """Every step's measured pose corrected by the twin from the thermocouples alone.

    The twin predicts each step twice: as the CMM sees it at its time (``P_k``,
    relative to the origin step, CMM effects included) and in the thermal state
    of the first reference step (``Pc_k``). The measured pose ``M_k`` (relative to
    the measured origin) is corrected by the predicted thermal deflection:
    ``M_k P_k^-1 Pc_k``. With a perfect twin and no noise that is the true
    corrected pose; no reference measurement is used.

    Parameters
    ----------
    hexapod, plan : Hexapod, Plan
    times_s : array_like, shape (N,)
        Step times in the log's time base.
    log : ThermocoupleLog
    balls_mm : array_like, shape (k, 3)
    platform2cmm : array_like, shape (N, 4, 4)
        The measured (registered) platform frame of every step.
    effects : sequence of Effect
        The twin's effects (a hexapod file's ``thermal_model``).
    ball_times_s : array_like, shape (N, k), optional

    Returns
    -------
    ndarray, shape (N, 6)
        Twin-corrected pose of every step, mm and deg, relative to the measured O.
    """
    frames = np.asarray(platform2cmm, dtype=float)
    origin = plan.origin_index
    steps = predict(
        hexapod, plan, times_s, log, balls_mm, frames[origin], effects, ball_times_s=ball_times_s
    )
    predicted = register(steps.measured_centres_cmm_mm, balls_mm).platform2cmm
    seen = invert_transform(predicted[origin]) @ predicted
    measured = invert_transform(frames[origin]) @ frames
    corrected = transform_from_pose(steps.corrected_pose, hexapod.convention)
    return pose_from_transform(measured @ invert_transform(seen) @ corrected, hexapod.convention)
