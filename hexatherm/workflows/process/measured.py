"""What ``process`` reads, before any pose: every step's ball centres (spheres fitted
where the files hold probed points) and the thermocouple log, with the checks that
belong to reading (time zones, the log's span)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from hexatherm.core.plan import name_indices
from hexatherm.errors import FitError, InputError, PlanError
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.measurements import read_measurements
from hexatherm.io.records import (
    Records,
    TimeKind,
    refuse_groups_in_two_files,
    seconds_to_iso,
    seconds_to_iso_texts,
)
from hexatherm.io.temperatures import Temperatures, read_temperatures
from hexatherm.session import Balls, Session
from hexatherm.typing import FloatArray

#: ``progress(path, lines_done, lines_total)`` while a measurement file is read

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
        Covariance of each centre from its sphere fit, or from the covariance columns
        of a centres file (NaN for centres given without them); None when not gathered.
    time_aware : bool or None
        ISO times: whether the files gave a UTC offset (then every time written out
        carries one, :func:`time_text`); None for seconds.
    spread : ndarray, shape (N,), optional
        The sum of the squared weights of the measurements each step's centres combine
        (its variance over one measurement's): ``1/n`` for a mean, ``sum l^2`` for R0's
        line in time at its last measurement (no thermocouple log); None: ``1 /
        measurements``.
    """

    centres_mm: FloatArray
    times_s: FloatArray
    time_kind: TimeKind
    u_um: FloatArray
    cov_mm2: FloatArray | None = None
    count: npt.NDArray[np.intp] | None = None
    time_aware: bool | None = None
    #: (N, k): which of ``cov_mm2`` a centres file gave (the others are sphere fits)
    cov_from_file: npt.NDArray[np.bool_] | None = None
    spread: FloatArray | None = None

    def time_text(self, seconds: float) -> str:
        """A time as the outputs write it: ISO 8601 in UTC with ``+00:00`` when the
        files gave offsets (never a UTC time that reads as local), as given (no offset
        known) when they did not; for a seconds time base the number itself."""
        if self.time_kind != "iso":
            return repr(float(seconds))
        text = seconds_to_iso(seconds)
        return text + "+00:00" if self.time_aware else text

    def time_texts(self, seconds: npt.ArrayLike) -> list[str]:
        """:meth:`time_text` of many times (the ISO texts formatted at once)."""
        if self.time_kind != "iso":
            return [repr(v) for v in np.asarray(seconds, dtype=float).ravel().tolist()]
        texts = seconds_to_iso_texts(seconds)
        return [t + "+00:00" for t in texts] if self.time_aware else texts

    @property
    def measurements(self) -> npt.NDArray[np.intp]:
        """How many measurements each step's centres average (1 but for repeated O, R0)."""
        if self.count is None:
            return np.ones(len(self.times_s), dtype=np.intp)
        return self.count

    @property
    def variance_factor(self) -> FloatArray:
        """Each step's centre variance over one measurement's (:attr:`spread`)."""
        if self.spread is None:
            return 1.0 / self.measurements
        return self.spread


def nominal_fit_diameter_mm(balls: Balls) -> FloatArray:
    """Diameter a sphere fit should find for each ball (probe tip added if uncompensated)."""
    from hexatherm.core.spherefit import probe_radius_mm  # a session of centres fits none

    return np.array(
        [
            2 * probe_radius_mm(d, balls.tip_diameter_mm, balls.probe_compensated)
            for d in balls.diameters_mm
        ]
    )


def point_groups(records: Records) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The ``(label, ball)`` group of every point record, numbered in file order, and the
    first record of each group: the spheres of :func:`fit_points`, in its order.

    A file's groups are runs of consecutive rows (:func:`~hexatherm.io.records.check_groups`
    refuses a ball probed twice in one step), so the groups are found where the label or
    the ball changes; a key that comes back in a later run (records joined from several
    files) joins its first run's group.

    >>> rec = Records("p.csv", "points", np.array(["O", "O", "O", "R0", "O"]),
    ...               np.array(["B1", "B1", "B2", "B1", "B1"]), np.zeros((5, 3)), np.zeros(5),
    ...               "seconds", np.arange(2, 7))
    >>> [a.tolist() for a in point_groups(rec)]
    [[0, 0, 1, 2, 0], [0, 2, 3]]
    """
    label, ball = records.label, records.ball
    n = len(records)
    if n == 0:
        return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
    change = (label[1:] != label[:-1]) | (ball[1:] != ball[:-1])
    starts = np.concatenate(([0], np.flatnonzero(change) + 1))
    run = np.cumsum(np.concatenate(([False], change)), dtype=np.intp)
    # (numpy's string ``+``: ``np.char`` costs its module's import at every start)
    keys = label[starts].astype(str) + "\x1f" + ball[starts].astype(str)
    _, first_run, groups = np.unique(keys, return_index=True, return_inverse=True)
    if first_run.size == starts.size:  # every key one run: the runs are the groups
        return run, starts.astype(np.intp)
    order = np.argsort(first_run)  # groups in file order
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[groups.reshape(-1)][run], starts[first_run[order]].astype(np.intp)


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
    from hexatherm.core.spherefit import fit_spheres  # a session of centres fits none

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
    n, k = len(plan.labels), len(balls.names)
    sums = np.zeros((n, k, 3))
    counts = np.zeros((n, k), dtype=int)
    ball_time = np.zeros((n, k))
    u_um = np.full((n, k), np.nan)
    cov = np.full((n, k, 3, 3), np.nan)
    cov_from_file = np.zeros((n, k), dtype=bool)
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
        si, bi = name_indices(plan.labels, rec.label), name_indices(balls.names, rec.ball)
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
        if "cov_from_file" in rec.extra:
            cov_from_file[si, bi] = np.asarray(rec.extra["cov_from_file"], dtype=bool)
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
    aware = {r.time_aware for r in records} - {None}
    return StepCentres(
        sums,
        ball_time.mean(axis=1),
        kinds.pop() if kinds else "seconds",
        u_um,
        cov,
        time_aware=aware.pop() if aware else None,
        cov_from_file=cov_from_file,
    )


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


_Timed = TypeVar("_Timed", Records, Temperatures)


def _in_utc(source: _Timed, offset_s: float) -> _Timed:
    """``source`` with its naive ISO times, read at ``offset_s`` east of UTC, made UTC."""
    if source.time_kind != "iso" or source.time_aware is not False:
        return source
    return dataclasses.replace(source, time_s=source.time_s - offset_s, time_aware=True)


def session_temperatures(session: Session, reading: ReadOptions) -> Temperatures | None:
    """The session's thermocouple log (None without one), its naive times made UTC by
    the session's ``utc_offset``, as processing reads it."""
    if session.temperatures is None:
        return None
    temperatures = read_temperatures(session.temperatures, allow_truncated=reading.allow_truncated)
    if session.utc_offset_s is not None:
        temperatures = _in_utc(temperatures, session.utc_offset_s)
    return temperatures


def read_measured(
    session: Session,
    fixed_diameter_mm: float | None = None,
    progress: FileProgress | None = None,
    reading: ReadOptions = STRICT,
) -> tuple[list[Records], list[Records | None], StepCentres, Temperatures | None]:
    """Every measurement file of ``session`` (points fitted) and its thermocouple log.

    ``reading`` says what the readers may read past (a file cut short, a ball
    probed twice), each with an :class:`~hexatherm.errors.InputWarning`.

    ``progress(path, lines_done, lines_total)``, when given, is called now and then
    while a measurement file is read (see :func:`~hexatherm.io.measurements.read_measurements`).

    Returns the records (centres), the probed points each was fitted to (None for
    centres read as such), the centres of every step and the temperatures (None
    when the session has none); InputError when the temperatures and the
    measurements use different kinds of time.
    """
    records: list[Records] = []
    points: list[Records | None] = []
    for file in session.measurements:
        report = None if progress is None else functools.partial(progress, str(file))
        found = read_measurements(
            file,
            progress=report,
            allow_truncated=reading.allow_truncated,
            keep_later=reading.keep_later,
            spec=session.formats.get(file),
            labels=session.plan.labels,
            names=session.feature_names,
        )
        if len(found) > 1:  # a folder of runs: one step's ball in two runs is refused
            refuse_groups_in_two_files(found)
        for rec in found:
            records.append(
                rec if rec.kind == "centres" else fit_points(rec, session.balls, fixed_diameter_mm)
            )
            points.append(None if rec.kind == "centres" else rec)
    if session.utc_offset_s is not None:  # the files' naive times are local: make them UTC
        records = [_in_utc(r, session.utc_offset_s) for r in records]
        points = [None if p is None else _in_utc(p, session.utc_offset_s) for p in points]
    centres = assemble_centres(records, session)
    temperatures = session_temperatures(session, reading)
    if temperatures is not None:
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


def constant_legs_warning(temperatures: Temperatures) -> str | None:
    """A warning when a leg's thermocouple column holds one value in every row (a logger
    stuck or not connected: the twin then sees no thermal change of that leg), or None."""
    legs = temperatures.legs_C
    if len(legs) < 2:
        return None
    flat = np.flatnonzero(np.ptp(legs, axis=0) == 0)
    if flat.size == 0:
        return None
    names = ", ".join(f"leg{i + 1}" for i in flat)
    values = ", ".join(sorted({f"{legs[0, i]:g}" for i in flat}))
    return (
        f"{temperatures.path}: the log of {names} never changes ({values} C in all "
        f"{len(legs)} rows): the twin sees no thermal change there; a thermocouple stuck "
        "or not connected?"
    )


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
