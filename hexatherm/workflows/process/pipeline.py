"""From a session folder to results: read, assemble, register, correct.

This is the glue between the I/O layer and the core. It reads the session's
files, gathers every step's ball centres (fitting spheres where the files hold
probed points), registers each step's frame, and runs the thermal method. It
writes nothing: :mod:`hexatherm.workflows.process.outputs` does.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from hexatherm.core.correction import Correction, Interpolation, StepPoses, correct, step_poses
from hexatherm.core.plan import find_repeats, without_repeats
from hexatherm.core.plausibility import (
    PoseCheck,
    commanded_relative,
    default_pose_tolerance,
    likeliest_cause,
    mirrored,
    pose_deviations,
)
from hexatherm.core.registration import Registration, check_distances, register
from hexatherm.core.spherefit import fit_spheres, probe_radius_mm
from hexatherm.errors import FitError, InputError, PlanError, StepError
from hexatherm.io.config import read_pose_check, read_session
from hexatherm.io.csvfile import Temperatures, read_measurements, read_temperatures
from hexatherm.io.records import Records, TimeKind, seconds_to_iso
from hexatherm.session import Balls, Session
from hexatherm.typing import FloatArray

#: ``progress(path, lines_done, lines_total)`` while a measurement file is read
FileProgress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class StepCentres:
    """Ball centres of every plan step, in plan order and balls-file order.

    Attributes
    ----------
    centres_mm : ndarray, shape (N, k, 3)
        CMM frame.
    times_s : ndarray, shape (N,)
        Time of each step: the mean of its balls' times (a ball's time is the
        mean time of its records).
    time_kind : {"iso", "seconds"}
    u_um : ndarray, shape (N, k)
        Standard uncertainty of each centre (NaN when the file gave none).
    cov_mm2 : ndarray, shape (N, k, 3, 3), optional
        Covariance of each centre from its sphere fit (NaN for centres given as
        such); None when not gathered.
    """

    centres_mm: FloatArray
    times_s: FloatArray
    time_kind: TimeKind
    u_um: FloatArray
    cov_mm2: FloatArray | None = None
    count: npt.NDArray[np.intp] | None = None

    @property
    def measurements(self) -> npt.NDArray[np.intp]:
        """How many measurements each step's centres average (1 but for repeated O, R0)."""
        if self.count is None:
            return np.ones(len(self.times_s), dtype=np.intp)
        return self.count


@dataclass(frozen=True)
class RepeatGroup:
    """The measurements of one step repeated (O or R0), before they were averaged.

    Attributes
    ----------
    label : str
        The step kept (``O``, ``R0``).
    labels : tuple of str
        Every measurement's step, in plan order (``O``, ``O-2``, ...).
    times_s : ndarray, shape (n,)
    deviations_mm : ndarray, shape (n, k, 3)
        Each measurement's centres less their mean (n = 2) or less a straight line in
        time fitted per coordinate (n >= 3: a slow drift of the platform is not noise).
    dof : int
        Degrees of freedom of the deviations, ``3 k (n - 1)`` or ``3 k (n - 2)``.
    cov_mm2 : ndarray, shape (n, k, 3, 3)
        Each measurement's centre covariance from its sphere fit (NaN: none).
    """

    label: str
    labels: tuple[str, ...]
    times_s: FloatArray
    deviations_mm: FloatArray
    dof: int
    cov_mm2: FloatArray


@dataclass(frozen=True)
class ProcessResult:
    """Everything ``hexatherm process`` computed for a session.

    ``records`` are the centres of every measurement file (fitted to the probed
    points where the file holds points); ``points`` gives, for each of them, the
    probed points they were fitted to (None for a centres file), and
    ``fixed_diameter_mm`` the fits' setting (see :func:`fit_points`).
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
        beyond it the step is refused with a diagnosis (swapped balls, inch/mm).
    registration_tolerance_um : float
        Largest registration RMS residual of a step.
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

    distance_tolerance_um: float = 50.0
    registration_tolerance_um: float = 10.0
    registration_fails: bool = False
    pose_tolerance: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("distance_tolerance_um", "registration_tolerance_um"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
                raise ValueError(f"{name} must be a number >= 0, got {value!r}")
        if self.pose_tolerance is not None:
            PoseCheck(*self.pose_tolerance)  # the same checks


def nominal_fit_diameter_mm(balls: Balls) -> FloatArray:
    """Diameter a sphere fit should find for each ball (probe tip added if uncompensated)."""
    return np.array(
        [
            2 * probe_radius_mm(d, balls.tip_diameter_mm, balls.probe_compensated)
            for d in balls.diameters_mm
        ]
    )


def point_groups(records: Records) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The ``(label, ball)`` group of every point record, numbered in file order, and the
    first record of each group: the spheres of :func:`fit_points`, in its order."""
    keys = np.char.add(np.char.add(records.label.astype(str), "\x1f"), records.ball.astype(str))
    _, first, groups = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first)  # groups in file order
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[groups.reshape(-1)], first[order]


def fit_radii(
    records: Records,
    first: npt.NDArray[np.intp],
    balls: Balls | None,
    fixed_diameter_mm: float | None,
) -> float | FloatArray | None:
    """The fixed radius of each sphere of :func:`fit_points` (None: free radii).

    ``first`` is the first record of each sphere (see :func:`point_groups`).
    """
    if fixed_diameter_mm is None:
        return None
    if fixed_diameter_mm > 0:
        return fixed_diameter_mm / 2
    if balls is None:
        return None
    nominal = dict(zip(balls.names, nominal_fit_diameter_mm(balls) / 2, strict=True))
    missing = [b for b in records.ball[first] if b not in nominal]
    if missing:
        row = int(first[[b in missing for b in records.ball[first]]][0])
        raise InputError(
            f"ball {str(records.ball[row])!r} is not in the balls file",
            path=records.path,
            line=int(records.line[row]),
            field="ball",
        )
    return np.array([nominal[b] for b in records.ball[first]])


def fit_points(
    records: Records, balls: Balls | None = None, fixed_diameter_mm: float | None = None
) -> Records:
    """Fit a sphere to every ``(label, ball)`` group of a points file; return centres.

    The centres' ``extra`` holds per-row ``n``, ``form_um``, ``rms_um``, ``cap_deg``,
    ``u_um``, ``cov_centre_mm2`` (3x3 covariance of the centre from the residuals) and
    ``sigma_um`` (the residuals' standard deviation, ``sqrt(SSR / (n - p))``).
    With ``fixed_diameter_mm`` (or, when it is 0 and ``balls`` is given, the nominal
    fit diameter of each ball) the radius is fixed.
    """
    groups, first = point_groups(records)
    radius = fit_radii(records, first, balls, fixed_diameter_mm)
    try:
        fits = fit_spheres(records.xyz_mm, groups, radius_mm=radius)
    except FitError as exc:
        row = None if exc.index is None else int(first[exc.index])
        where = "" if row is None else (f"step {records.label[row]} ball {records.ball[row]}: ")
        raise InputError(
            f"{where}sphere fit: {exc}",
            path=records.path,
            line=None if row is None else int(records.line[row]),
        ) from None
    counts = np.bincount(groups)
    times = np.bincount(groups, weights=records.time_s) / counts
    u_um = np.sqrt(np.trace(fits.cov_centre_mm2, axis1=1, axis2=2) / 3) * 1e3
    dof = fits.n - (3 if fits.fixed_radius else 4)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma_um = np.where(dof > 0, fits.rms_um * np.sqrt(fits.n / np.maximum(dof, 1)), np.nan)
    extra = {
        "n": fits.n,
        "form_um": fits.form_um,
        "rms_um": fits.rms_um,
        "cap_deg": fits.cap_half_angle_deg,
        "u_um": u_um,
        "cov_centre_mm2": fits.cov_centre_mm2,
        "sigma_um": sigma_um,
    }
    # replace() keeps every other attribute of the file's records (its time zone kind)
    return dataclasses.replace(
        records,
        kind="centres",
        label=records.label[first],
        ball=records.ball[first],
        xyz_mm=fits.centre_mm,
        time_s=times,
        line=records.line[first],
        diameter_mm=2 * fits.radius_mm,
        ijk=None,
        extra=extra,
    )


def assemble_centres(records: list[Records], session: Session) -> StepCentres:
    """Gather one centre per plan step and ball from the records of all files.

    Raises InputError (naming file and line) for records of unknown steps or balls
    and for mixed time kinds, and PlanError (naming the step) for a step or a
    ball that was not measured.
    """
    plan, balls = session.plan, session.balls
    step_index = {label: i for i, label in enumerate(plan.labels)}
    ball_index = {name: j for j, name in enumerate(balls.names)}
    n, k = len(plan.labels), len(balls.names)
    sums = np.zeros((n, k, 3))
    counts = np.zeros((n, k), dtype=int)
    ball_time = np.zeros((n, k))
    u_um = np.full((n, k), np.nan)
    cov = np.full((n, k, 3, 3), np.nan)
    kinds = {r.time_kind for r in records}
    if len(kinds) > 1:
        iso = next(r for r in records if r.time_kind == "iso")
        sec = next(r for r in records if r.time_kind == "seconds")
        raise InputError(
            f"times are ISO 8601 here but seconds in {sec.path}: all the files "
            "of a session must use one kind",
            path=iso.path,
            line=int(iso.line[0]),
            field="time",
        )
    for rec in records:
        if rec.kind != "centres":
            raise ValueError("fit points records before assembling centres")
        si = np.array([step_index.get(s, -1) for s in rec.label])
        bi = np.array([ball_index.get(b, -1) for b in rec.ball])
        if np.any(si < 0):
            row = int(np.argmax(si < 0))
            raise InputError(
                f"step {str(rec.label[row])!r} is not in the plan",
                path=rec.path,
                line=int(rec.line[row]),
                field="label",
            )
        if np.any(bi < 0):
            row = int(np.argmax(bi < 0))
            raise InputError(
                f"ball {str(rec.ball[row])!r} is not in the balls file ({', '.join(balls.names)})",
                path=rec.path,
                line=int(rec.line[row]),
                field="ball",
            )
        dup = counts[si, bi] > 0
        if np.any(dup):
            row = int(np.argmax(dup))
            raise InputError(
                f"step {rec.label[row]} ball {rec.ball[row]} is measured again "
                "(already in an earlier file)",
                path=rec.path,
                line=int(rec.line[row]),
                field="label",
            )
        sums[si, bi] = rec.xyz_mm
        counts[si, bi] = 1
        ball_time[si, bi] = rec.time_s
        if "u_um" in rec.extra:
            u_um[si, bi] = np.asarray(rec.extra["u_um"], dtype=float)
        if "cov_centre_mm2" in rec.extra:
            cov[si, bi] = np.asarray(rec.extra["cov_centre_mm2"], dtype=float)
    missing_step = counts.sum(axis=1) == 0
    if np.any(missing_step):
        i = int(np.argmax(missing_step))
        raise PlanError(
            f"step {plan.labels[i]}: not measured (no record in "
            f"{', '.join(str(p.name) for p in session.measurements)})"
        )
    missing_ball = counts == 0
    if np.any(missing_ball):
        i, j = np.argwhere(missing_ball)[0]
        raise PlanError(f"step {plan.labels[i]}: ball {balls.names[j]} not measured")
    return StepCentres(sums, ball_time.mean(axis=1), kinds.pop() if kinds else "seconds", u_um, cov)


def registration_weights(u_um: FloatArray, floor_um: float = 1e-3) -> FloatArray | None:
    """Weights ``1/u^2`` of each step's balls when every centre has an uncertainty.

    Steps with a missing uncertainty get equal weights; ``u`` is floored at
    ``floor_um`` so that noise-free fits do not get infinite weights.
    """
    if np.all(np.isnan(u_um)):
        return None
    u = np.maximum(np.nan_to_num(u_um, nan=1.0), floor_um)
    weights = 1.0 / u**2
    weights[np.isnan(u_um).any(axis=1)] = 1.0
    return weights


def read_measured(
    session: Session, fixed_diameter_mm: float | None = None, progress: FileProgress | None = None
) -> tuple[list[Records], list[Records | None], StepCentres, Temperatures | None]:
    """Every measurement file of ``session`` (points fitted) and its thermocouple log.

    ``progress(path, lines_done, lines_total)``, when given, is called now and then
    while a measurement file is read (see :func:`~hexatherm.io.csvfile.read_measurements`).

    Returns the records (centres), the probed points each was fitted to (None for
    centres read as such), the centres of every step and the temperatures (None
    when the session has none); InputError when the temperatures and the
    measurements use different kinds of time.
    """
    records: list[Records] = []
    points: list[Records | None] = []
    for file in session.measurements:
        report = None if progress is None else functools.partial(progress, str(file))
        for rec in read_measurements(file, progress=report):
            records.append(
                rec if rec.kind == "centres" else fit_points(rec, session.balls, fixed_diameter_mm)
            )
            points.append(None if rec.kind == "centres" else rec)
    centres = assemble_centres(records, session)
    temperatures = None
    if session.temperatures is not None:
        temperatures = read_temperatures(session.temperatures)
        if temperatures.time_kind != centres.time_kind:
            raise InputError(
                f"times are {temperatures.time_kind} here but "
                f"{centres.time_kind} in the measurements: use one kind",
                path=temperatures.path,
                line=2,
                field="time",
            )
    check_time_zones([*records, *([] if temperatures is None else [temperatures])])
    if temperatures is not None:
        check_log_span(centres.times_s, session.plan.labels, temperatures)
    return records, points, centres, temperatures


def check_time_zones(sources: Sequence[object]) -> None:
    """Refuse a session whose files mix naive ISO times and times with a UTC offset.

    A naive time is taken as UTC: beside times with an offset it is hours off, and a
    thermocouple log read that way is held at its ends silently. ``sources`` are
    records and thermocouple logs; one whose reader does not tell (no ``time_aware``,
    or None) is not compared. InputError naming the later file and field ``time``.
    """
    seen: dict[bool, object] = {}
    for source in sources:
        aware = getattr(source, "time_aware", None)
        if getattr(source, "time_kind", None) != "iso" or aware is None:
            continue
        other = seen.get(not aware)
        if other is not None:
            naive, offset = "naive (no UTC offset)", "with a UTC offset"
            mine, theirs = (offset, naive) if aware else (naive, offset)
            raise InputError(
                f"times {mine} here but {theirs} in {getattr(other, 'path', '?')}: naive "
                "times would be taken as UTC, hours off; give every time an offset or none",
                path=getattr(source, "path", None),
                field="time",
            )
        seen.setdefault(bool(aware), source)


def _format_time(seconds: float, kind: TimeKind) -> str:
    return seconds_to_iso(seconds) if kind == "iso" else f"{seconds:g} s"


def check_log_span(times_s: FloatArray, labels: Sequence[str], temperatures: Temperatures) -> None:
    """Refuse steps whose time is outside the thermocouple log's span.

    ``np.interp`` holds a log's first and last values beyond its ends: a logger that
    stopped early would give every later step the last temperatures, and the twin,
    the temperature check and the diagnosis would take them for measured ones.

    Parameters
    ----------
    times_s : ndarray, shape (N,)
        Every step's time, seconds (as the log's).
    labels : sequence of str
        The steps' labels.
    temperatures : Temperatures
        The thermocouple log.

    Raises
    ------
    InputError
        Naming the log, field ``time``, the first step outside, its time and the log's span.
    """
    log = np.asarray(temperatures.time_s, dtype=float)
    t = np.asarray(times_s, dtype=float)
    start, end = float(log[0]), float(log[-1])
    outside = (t < start) | (t > end)
    if not np.any(outside):
        return
    i = int(np.argmax(outside))
    kind = temperatures.time_kind
    side = "before its first row" if t[i] < start else "after its last row"
    more = f" ({int(outside.sum()) - 1} more step(s) too)" if outside.sum() > 1 else ""
    raise InputError(
        f"step {labels[i]} at {_format_time(float(t[i]), kind)} is outside the thermocouple "
        f"log, {side} (the log spans {_format_time(start, kind)} to "
        f"{_format_time(end, kind)}){more}: its temperatures are unknown; complete the log "
        "or remove 'temperatures:' from the session file",
        path=temperatures.path,
        field="time",
    )


def session_pose_check(session: Session, checks: Checks | None = None) -> PoseCheck:
    """The measured-versus-commanded check of ``session``: ``checks.pose_tolerance`` (the
    command line) over the session file's ``pose_check:`` mapping over the default
    sized from the leg stroke (:func:`hexatherm.core.plausibility.default_pose_tolerance`);
    the session file's offset."""
    tol_mm, tol_deg = default_pose_tolerance(
        session.hexapod.stroke_mm, session.hexapod.platform_joints_mm
    )
    offset = np.zeros(6)
    declared = read_pose_check(session.path)
    if declared is not None:
        tol_mm = declared.get("tolerance_mm", tol_mm)
        tol_deg = declared.get("tolerance_deg", tol_deg)
        offset = np.asarray(declared.get("offset", offset), dtype=float)
    if checks is not None and checks.pose_tolerance is not None:
        tol_mm, tol_deg = checks.pose_tolerance
    return PoseCheck(float(tol_mm), float(tol_deg), offset)


def check_poses(session: Session, centres: StepCentres, steps: StepPoses, check: PoseCheck) -> None:
    """Refuse a step whose measured pose relative to O is not its commanded one.

    Thermal errors are micrometres; millimetres or degrees are a mistake in the data
    that registers without a residual: swapped step labels, a mirrored measurement
    (x and y columns swapped), a plan in other units. PlanError (a StepError) naming
    the first failing step, its deviation, the tolerance and the likeliest cause
    (:func:`hexatherm.core.plausibility.likeliest_cause`).
    """
    if not check.enabled:
        return
    plan = session.plan
    commanded = commanded_relative(plan.poses, plan.origin_index, session.hexapod.convention)
    dev = pose_deviations(steps.pose, commanded, check, plan.origin_index)
    if not np.any(dev.failing):
        return
    i = int(np.argmax(dev.failing))
    flipped = mirrored(centres.centres_mm, session.balls.centres_mm)
    cause = likeliest_cause(
        i, steps.pose, commanded, check, plan.labels, flipped, plan.origin_index
    )
    more = int(dev.failing.sum()) - 1

    def pose(p: FloatArray) -> str:
        return "[" + ", ".join(f"{v:.4f}" for v in p) + "]"

    offset = " less the declared offset" if np.any(check.offset) else ""
    raise StepError(
        f"measured pose relative to O {pose(steps.pose[i])} is {dev.translation_mm[i]:.3f} mm, "
        f"{dev.rotation_deg[i]:.3f} deg from the commanded {pose(commanded[i])}{offset} "
        f"(tolerance {check.tolerance_mm:g} mm, {check.tolerance_deg:.3g} deg: "
        "--pose-tolerance MM,DEG or the session file's pose_check:)"
        + (f" ({more} more step(s) too)" if more else "")
        + f"; likeliest cause: {cause}",
        step=plan.labels[i],
        index=i,
    )


def average_repeats(
    session: Session, centres: StepCentres
) -> tuple[Session, StepCentres, tuple[RepeatGroup, ...]]:
    """Average the repeated measurements of O and R0 (``plan --origin-repeats`` ...).

    Each ball's centre is the mean of its repeated centres (before registration: one
    frame from the mean centres), its covariance the sum of theirs over ``n^2`` (fits),
    its ``u_um`` ``sqrt(sum u^2) / n`` (files), the step's time the mean of the times.
    The session's plan loses the repeats (:func:`hexatherm.core.plan.without_repeats`).
    Returns the session and centres unchanged when nothing is repeated.
    """
    plan = session.plan
    repeats = find_repeats(plan)
    if not repeats.any:
        return session, centres, ()
    c, t, u = centres.centres_mm.copy(), centres.times_s.copy(), centres.u_um.copy()
    cov = None if centres.cov_mm2 is None else centres.cov_mm2.copy()
    count = np.ones(len(plan.labels), dtype=np.intp)
    groups = []
    for steps in repeats.groups():
        idx = np.asarray(steps, dtype=np.intp)
        n, first = len(idx), int(idx[0])
        times = centres.times_s[idx]
        values = centres.centres_mm[idx]  # (n, k, 3)
        if n >= 3 and np.ptp(times) > 0:
            # per coordinate a straight line in time: drift is not noise
            design = np.column_stack([np.ones(n), times - times.mean()])
            coef, *_ = np.linalg.lstsq(design, values.reshape(n, -1), rcond=None)
            deviations = (values.reshape(n, -1) - design @ coef).reshape(values.shape)
            dof = values[0].size * (n - 2)
        else:
            deviations = values - values.mean(axis=0)
            dof = values[0].size * (n - 1)
        one_cov = (
            np.full(values.shape + (3,), np.nan)
            if centres.cov_mm2 is None
            else centres.cov_mm2[idx]
        )
        groups.append(
            RepeatGroup(
                plan.labels[first],
                tuple(plan.labels[i] for i in idx),
                times,
                deviations,
                int(dof),
                one_cov,
            )
        )
        c[first] = values.mean(axis=0)
        t[first] = times.mean()
        u[first] = np.sqrt((centres.u_um[idx] ** 2).sum(axis=0)) / n
        if cov is not None and centres.cov_mm2 is not None:
            cov[first] = centres.cov_mm2[idx].sum(axis=0) / n**2
        count[first] = n
    reduced, keep = without_repeats(plan, repeats)
    averaged = StepCentres(
        c[keep],
        t[keep],
        centres.time_kind,
        u[keep],
        None if cov is None else cov[keep],
        count[keep],
    )
    return dataclasses.replace(session, plan=reduced), averaged, tuple(groups)


def process_session(
    path: str | Path,
    interpolation: Interpolation = "linear",
    fixed_diameter_mm: float | None = None,
    checks: Checks | None = None,
    progress: FileProgress | None = None,
) -> ProcessResult:
    """Read a session and compute conventional and corrected poses of every target.

    ``progress`` reports the reading of the measurement files (see :func:`read_measured`).
    """
    session = read_session(path)
    records, points, centres, temperatures = read_measured(session, fixed_diameter_mm, progress)
    checks = checks or Checks()
    plan, balls = session.plan, session.balls
    distances = check_distances(
        centres.centres_mm, balls.centres_mm, balls.names, checks.distance_tolerance_um * 1e-3
    )
    bad = [i for i, text in enumerate(distances.diagnosis) if text]
    if bad:
        more = f" ({len(bad) - 1} more step(s) too)" if len(bad) > 1 else ""
        raise PlanError(f"step {plan.labels[bad[0]]}: {distances.diagnosis[bad[0]]}{more}")
    session, centres, repeats = average_repeats(session, centres)
    plan = session.plan
    registration = register(
        centres.centres_mm, balls.centres_mm, registration_weights(centres.u_um)
    )
    warnings = []
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
    )
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
    )
