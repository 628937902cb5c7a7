"""From a session folder to results: read, assemble, register, correct.

This is the glue between the I/O layer and the core. It reads the session's
files, gathers every step's ball centres (fitting spheres where the files hold
probed points), registers each step's frame, and runs the thermal method. It
writes nothing: :mod:`hexatherm.workflows.process.outputs` does.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexatherm.core.correction import (
    Correction,
    Interpolation,
    StepPoses,
    correct,
    step_poses,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plausibility import (
    ROTATION_FLOOR_DEG,
    ROTATION_FRACTION,
    PoseCheck,
    commanded_relative,
    default_pose_tolerance,
    likeliest_cause,
    mirrored,
    pose_deviations,
)
from hexatherm.core.registration import Registration, check_distances, register
from hexatherm.errors import PlanError, StepError
from hexatherm.io.config import read_pose_check, read_session
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.records import Records
from hexatherm.io.temperatures import Temperatures
from hexatherm.session import DISTANCE_REFUSAL_UM, QualityLimits, Session
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.carrying import OriginCarry, RepeatGroup, carry_and_average
from hexatherm.workflows.process.frames import session_frames, session_in_origin
from hexatherm.workflows.process.measured import (
    FileProgress,
    StepCentres,
    constant_legs_warning,
    read_measured,
    registration_weights,
)


@dataclass(frozen=True)
class ProcessResult:
    """Everything ``hexatherm process`` computed for a session.

    ``records`` are the centres of every measurement file (fitted to the probed
    points where the file holds points); ``points`` gives, for each of them, the
    probed points they were fitted to (None for a centres file), and
    ``fixed_diameter_mm`` the fits' setting (see :func:`fit_points`). ``frames`` are the
    controller's frames the session was measured with (``run.yaml``'s 12 values, mm and
    deg; None: zero or not recorded): ``session`` is then the session relative to frame O
    (:func:`hexatherm.workflows.process.frames.session_in_origin`: its plan's poses those the
    frames made of the commanded ones, its hexapod's base joints moved).
    """

    session: Session
    centres: StepCentres
    registration: Registration
    steps: StepPoses
    correction: Correction
    temperatures: Temperatures | None
    interpolation: Interpolation
    records: tuple[Records, ...] = ()
    warnings: tuple[str, ...] = ()
    points: tuple[Records | None, ...] = ()
    fixed_diameter_mm: float | None = None
    repeats: tuple[RepeatGroup, ...] = ()
    carry: OriginCarry | None = None
    frames: FloatArray | None = None

    @property
    def repeat_of(self) -> dict[str, str]:
        """The step each repeated measurement's label was averaged into (``O-2``: ``O``)."""
        return {label: g.label for g in self.repeats for label in g.labels}


@dataclass(frozen=True)
class Checks:
    """Tolerances of the checks ``process`` makes before and after registration.

    Attributes
    ----------
    distance_tolerance_um : float
        Largest deviation of a measured inter-ball distance from the balls file;
        beyond it the step is refused with a diagnosis (swapped balls, inch/mm). Default
        :data:`~hexatherm.session.DISTANCE_REFUSAL_UM`.
    registration_tolerance_um : float
        Largest registration RMS residual of a step; default the quality limit
        ``registration_rms_um`` (:class:`~hexatherm.session.QualityLimits`).
    registration_fails : bool
        Whether exceeding ``registration_tolerance_um`` is an error (else a warning).
    pose_tolerance : (float, float) or None
        Largest deviation ``(mm, deg)`` of a step's measured pose relative to O from its
        commanded pose relative to O (see :mod:`hexatherm.core.plausibility`); beyond it
        the step is refused, naming the likeliest cause. None: the session file's
        ``pose_check:`` tolerances, else the default sized from the leg stroke;
        ``(inf, inf)`` turns the check off.

    Raises
    ------
    ValueError
        A tolerance that is not a number >= 0 (NaN would turn a check off unseen).
    """

    distance_tolerance_um: float = DISTANCE_REFUSAL_UM
    registration_tolerance_um: float = QualityLimits.registration_rms_um
    registration_fails: bool = False
    pose_tolerance: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("distance_tolerance_um", "registration_tolerance_um"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
                raise ValueError(f"{name} must be a number >= 0, got {value!r}")
        if self.pose_tolerance is not None:
            PoseCheck(*self.pose_tolerance)  # the same checks


def session_pose_check(session: Session, checks: Checks | None = None) -> PoseCheck:
    """The measured-versus-commanded check of ``session``: ``checks.pose_tolerance`` (the
    command line) over the session file's ``pose_check:`` mapping over the default
    sized from the leg stroke (:func:`hexatherm.core.plausibility.default_pose_tolerance`);
    the session file's offset."""
    tol_mm, tol_deg = default_pose_tolerance(
        session.hexapod.stroke_mm, session.hexapod.platform_joints_mm
    )
    offset = np.zeros(6)
    # the default rotation tolerance is scaled to the commanded motion (a convention
    # mix-up is second order in the angles); a declared one is taken as it is
    floor: float | None = ROTATION_FLOOR_DEG
    declared = read_pose_check(session.path)
    if declared is not None:
        tol_mm = declared.get("tolerance_mm", tol_mm)
        if "tolerance_deg" in declared:
            tol_deg, floor = declared["tolerance_deg"], None
        offset = np.asarray(declared.get("offset", offset), dtype=float)
    if checks is not None and checks.pose_tolerance is not None:
        (tol_mm, tol_deg), floor = checks.pose_tolerance, None
    return PoseCheck(float(tol_mm), float(tol_deg), offset, floor, ROTATION_FRACTION)


def check_poses(
    session: Session,
    centres: StepCentres,
    steps: StepPoses,
    check: PoseCheck,
    records: Sequence[Records] = (),
    framed: bool = False,
) -> None:
    """Refuse a step whose measured pose relative to O is not its commanded one, or
    whose measured balls are a mirror image of the balls file's.

    Thermal errors are micrometres; millimetres or degrees are a mistake in the data
    that registers without a residual: swapped step labels, a mirrored measurement
    (x and y columns swapped), a plan in other units. PlanError (a StepError) naming
    the first failing step, its deviation, the tolerance and the likeliest cause
    (:func:`hexatherm.core.plausibility.likeliest_cause`). A mirror image is refused
    even within the tolerance (a small motion mirrors into a small deviation; a
    reflection is never a rotation: :func:`hexatherm.core.plausibility.mirrored`),
    naming the step and the file and line of its first measurement in ``records``.
    ``framed``: the session's plan holds the poses the controller's frames made of the
    commanded ones (:func:`~hexatherm.workflows.process.frames.session_in_origin`), which
    the message says.
    """
    if not check.enabled:
        return
    plan = session.plan
    commanded = commanded_relative(plan.poses, plan.origin_index, session.hexapod.convention)
    dev = pose_deviations(steps.pose, commanded, check, plan.origin_index)
    flipped = mirrored(centres.centres_mm, session.balls.centres_mm)
    if not np.any(dev.failing):
        if np.any(flipped):
            i = int(np.argmax(flipped))
            more = int(flipped.sum()) - 1
            raise StepError(
                "the measured balls are a mirror image of the balls file's (a reflection, "
                "never a rotation: x and y columns swapped, or an axis' sign flipped?)"
                + where_measured(records, plan.labels[i])
                + (f" ({more} more step(s) too)" if more else "")
                + "; the pose check is off with --pose-tolerance inf",
                step=plan.labels[i],
                index=i,
            )
        return
    i = int(np.argmax(dev.failing))
    cause = likeliest_cause(
        i, steps.pose, commanded, check, plan.labels, flipped, plan.origin_index
    )
    more = int(dev.failing.sum()) - 1

    def pose(p: FloatArray) -> str:
        return "[" + ", ".join(f"{v:.4f}" for v in p) + "]"

    offset = " less the declared offset" if np.any(check.offset) else ""
    if framed:
        offset = " (the plan's through the controller's frames, run.yaml)" + offset
    scaled = ""
    if check.scaled and dev.tolerance_deg[i] < check.tolerance_deg:
        angle = np.abs(commanded[i, 3:]).max()
        scaled = (
            f" = {check.rotation_floor_deg:g} deg + {check.rotation_fraction:.0%} of the "
            f"commanded {angle:.3g} deg"
        )
    raise StepError(
        f"measured pose relative to O {pose(steps.pose[i])} is {dev.translation_mm[i]:.3f} mm, "
        f"{dev.rotation_deg[i]:.3f} deg from the commanded {pose(commanded[i])}{offset} "
        f"(tolerance {check.tolerance_mm:g} mm, {dev.tolerance_deg[i]:.3g} deg{scaled}: "
        "--pose-tolerance MM,DEG or the session file's pose_check:)"
        + (f" ({more} more step(s) too)" if more else "")
        + f"; likeliest cause: {cause}",
        step=plan.labels[i],
        index=i,
    )


def where_measured(records: Sequence[Records], label: str) -> str:
    """`` in FILE:LINE`` of the first row of step ``label`` in ``records`` (its repeats'
    labels ``O-2`` ... too), or ``""``."""
    pattern = re.compile(re.escape(label) + r"(-[0-9]+)?")
    for rec in records:
        rows = np.flatnonzero([pattern.fullmatch(str(x)) is not None for x in rec.label])
        if rows.size:
            return f" in {rec.path}:{int(rec.line[rows[0]])}"
    return ""


def check_target_times(
    session: Session,
    centres: StepCentres,
    correction: Correction,
    records: Sequence[Records] = (),
) -> None:
    """Refuse a target measured outside the times of its two references.

    The linear (and smooth) correction weighs the reference after a target by
    ``(t_S - t_b) / (t_a - t_b)``: a target measured before the reference before it, or
    after the reference after it (times out of the plan's order: swapped labels, a clock
    set during the session) would get a weight outside [0, 1], an extrapolation written
    as a corrected pose. StepError naming the target, both references with their times
    and the file and line of the target's first measurement in ``records``. Only targets
    that ``correction`` corrects from both references are checked (the other
    interpolations use one); references at the same time (a burst) are
    :func:`~hexatherm.core.correction.choose_references`' case.
    """
    plan, t = session.plan, centres.times_s
    before, after = correction.before_index, correction.after_index
    targets = correction.target_index
    both = (before >= 0) & (after >= 0)
    tb = np.where(both, t[before], np.nan)
    ta = np.where(both, t[after], np.nan)
    ts = t[targets]
    outside = both & (ta > tb) & ((ts < tb) | (ts > ta))
    if not np.any(outside):
        return
    j = int(np.argmax(outside))
    i, b, a = int(targets[j]), int(before[j]), int(after[j])
    more = int(outside.sum()) - 1
    raise StepError(
        f"measured at {centres.time_text(t[i])}"
        + where_measured(records, plan.labels[i])
        + f", outside the times of its references {plan.labels[b]} "
        f"({centres.time_text(t[b])}) and {plan.labels[a]} ({centres.time_text(t[a])})"
        + (f" ({more} more target(s) too)" if more else "")
        + ": the times are not in the plan's order (swapped labels or times, a clock set "
        "during the session?), and interpolating between the references would "
        f"extrapolate (weight {(t[i] - t[b]) / (t[a] - t[b]):.3g} on {plan.labels[a]}); "
        "--interpolation nearest uses one reference",
        step=plan.labels[i],
        index=i,
    )


def one_sided(
    session: Session, centres: StepCentres, correction: Correction, interpolation: Interpolation
) -> list[str]:
    """A warning for the targets with a reference on one side only (a plan with
    ``--reference-every before``, a session cut short) when the interpolation would use
    both: the target is corrected from that reference alone, the growth between them is
    not corrected. Empty for ``before``, ``after`` and ``nearest`` (one side by choice).
    """
    if interpolation not in ("linear", "smooth"):
        return []
    before, after = correction.before_index, correction.after_index
    single = (before >= 0) ^ (after >= 0)
    if not np.any(single):
        return []
    j = int(np.argmax(single))
    target = int(correction.target_index[j])
    ref = int(before[j] if before[j] >= 0 else after[j])
    side = "before" if before[j] >= 0 else "after"
    gap = abs(float(centres.times_s[target] - centres.times_s[ref]))
    labels = session.plan.labels
    smooth = correction.smooth is not None and correction.smooth.used
    how = (
        "the smooth fit of the growth is extrapolated to it"
        if smooth
        else "corrected from it alone, the legs' growth in between is not corrected"
    )
    return [
        f"{int(single.sum())} target(s), the first {labels[target]}: a reference on one side "
        f"only ({labels[ref]}, {gap:.0f} s {side} it): {how} (plan --reference-every both "
        "puts one on each side)"
    ]


def process_session(
    path: str | Path,
    interpolation: Interpolation = "linear",
    fixed_diameter_mm: float | None = None,
    checks: Checks | None = None,
    progress: FileProgress | None = None,
    reading: ReadOptions = STRICT,
    hexapod: Hexapod | None = None,
    session: Session | None = None,
) -> ProcessResult:
    """Read a session and compute conventional and corrected poses of every target.

    ``progress`` reports the reading of the measurement files and ``reading`` says what
    the readers may read past (see :func:`read_measured`). ``hexapod`` replaces the
    session's hexapod file for the IGM and FGM of the correction (a calibrated
    geometry; the commanded poses stay as planned). ``session`` is the session file of
    ``path`` already read (``hexatherm process`` reads it first, to check the output
    folder against its inputs), so that its YAML files are read once.
    """
    session = read_session(path) if session is None else session
    if hexapod is not None:
        session = dataclasses.replace(session, hexapod=hexapod)
    # with the controller's frames set, the session as frame O sees it (the commanded poses
    # compared with the measured ones, the IGM and FGM of the correction)
    frames = session_frames(session).values
    session = session_in_origin(session, frames)
    records, points, centres, temperatures = read_measured(
        session, fixed_diameter_mm, progress, reading
    )
    checks = checks or Checks()
    plan, balls = session.plan, session.balls
    distances = check_distances(
        centres.centres_mm, balls.centres_mm, balls.names, checks.distance_tolerance_um * 1e-3
    )
    bad = [i for i, text in enumerate(distances.diagnosis) if text]
    if bad:
        more = f" ({len(bad) - 1} more step(s) too)" if len(bad) > 1 else ""
        raise PlanError(f"step {plan.labels[bad[0]]}: {distances.diagnosis[bad[0]]}{more}")
    session, centres, repeats, carry = carry_and_average(session, centres, temperatures)
    plan = session.plan
    registration = register(
        centres.centres_mm, balls.centres_mm, registration_weights(centres.u_um)
    )
    warnings = []
    if fixed_diameter_mm is not None and all(p is None for p in points):
        warnings.append(
            "--fixed-diameter: the measurement files hold ball centres, no probed points to "
            "fit spheres to: it changes nothing"
        )
    constant = None if temperatures is None else constant_legs_warning(temperatures)
    if constant is not None:
        warnings.append(constant)
    if temperatures is None:
        warnings.append(
            "no thermocouple log in the session (no 'temperatures:' in the session file): the "
            "correction rests on the references alone, and the temperature check is n/a"
        )
    over = np.flatnonzero(registration.rms_um > checks.registration_tolerance_um)
    if over.size:
        message = (
            f"step {plan.labels[over[0]]}: registration residual "
            f"{registration.rms_um[over[0]]:.2f} um RMS exceeds "
            f"{checks.registration_tolerance_um:g} um"
            + (f" ({over.size - 1} more step(s) too)" if over.size > 1 else "")
        )
        if checks.registration_fails:
            raise PlanError(message)
        warnings.append(message)
    check_poses(
        session,
        centres,
        step_poses(session.hexapod, registration.platform2cmm, plan.origin_index),
        session_pose_check(session, checks),
        records,
        framed=bool(frames.any()),
    )
    q_steps = session.hexapod.igm(plan.poses)
    outside = np.flatnonzero(session.hexapod.check_stroke(q_steps).any(axis=1))
    if outside.size and session.hexapod.stroke_mm is not None:
        warnings.append(
            f"step {plan.labels[outside[0]]}: commanded pose is outside the stroke "
            f"{session.hexapod.stroke_mm.tolist()} mm"
        )
    steps, correction = correct(
        session.hexapod,
        session.plan,
        centres.times_s,
        registration.platform2cmm,
        interpolation,
        centres.measurements,
        None if carry is None else carry.shift,
    )
    check_target_times(session, centres, correction, records)
    warnings.extend(one_sided(session, centres, correction, interpolation))
    both = (correction.before_index >= 0) & (correction.after_index >= 0)
    untimed = both & (
        centres.times_s[correction.after_index] <= centres.times_s[correction.before_index]
    )
    if np.any(untimed):
        first = plan.labels[correction.target_index[np.argmax(untimed)]]
        warnings.append(
            f"{int(untimed.sum())} target(s), the first {first}: both references have the same "
            "time (points stamped on arrival, in one burst?): each reference weighs 1/2, by "
            "the plan's order; the times carry no distances to interpolate on"
        )
    return ProcessResult(
        session,
        centres,
        registration,
        steps,
        correction,
        temperatures,
        interpolation,
        tuple(records),
        tuple(warnings),
        tuple(points),
        fixed_diameter_mm,
        repeats,
        carry,
        frames if frames.any() else None,
    )
