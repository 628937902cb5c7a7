"""What ``calibrate`` checks of its sessions before pooling them (issue 22, item 6).

1. **Each session once** (:func:`check_distinct_sessions`): a session given twice (the
   same path, a copy, a symbolic link, ``DIR`` and ``DIR/session.yaml``) would count its
   poses twice and shrink every parameter's uncertainty by sqrt(2). Sessions are compared
   by content: the SHA-256 of their measurement files (centres, points, DMIS), not their
   paths; one measurement file in two sessions is refused, naming both. (A temperatures
   log may be shared: one long log can cover several sessions.) The same measurements
   in other bytes or other digits (a blank line added, CRLF line endings, rows
   reordered, re-saved by a spreadsheet with 15 digits, rounded to 1 nm, shifted by
   1 nm) are caught once read (:func:`check_distinct_measurements`), by what was
   measured: independent measurements of a ball centre differ by the CMM's noise, so
   centres that agree far closer than that are one measurement; a tenth of either
   session's centres shared is one session given twice (refused), fewer but at least
   two a warning.
2. **One hexapod file** (:func:`check_one_hexapod`): every number a session's poses rest
   on must be the same in every session's hexapod file: the convention, the base and
   platform joints, the stroke, and the legs' thermal model (segments, lengths, CTE,
   reference temperature). The first field that differs is named. Likewise one balls
   file (:func:`check_one_balls`): the balls define the platform frame the poses refer
   to; their names and centres must be the same (the diameters and the order may
   differ). (Every plan's origin step commands the zero pose: the plan reader refuses
   another, :func:`hexatherm.io.config.read_plan`.)
3. **One reference state** (:func:`check_reference_states`): each session's corrected
   poses refer to the thermal state of its first reference R0; each leg's temperature at
   R0 (interpolated in the session's thermocouple log) must be within
   :data:`MAX_REFERENCE_STATE_K` of the first logged session's, leg by leg (a mean would
   let +1 K on three legs and -1 K on the others pass). A session without temperatures
   cannot be checked: a ``warning:`` says so (an :class:`~hexatherm.errors.InputWarning`).
4. **What process warns of** (:func:`session_warnings`): each session's own warnings
   and failed quality checks, as ``process`` prints them, for the screen.
"""

from __future__ import annotations

import os
import stat
import warnings
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import InputError, InputWarning
from hexatherm.io.manifest import sha256_file
from hexatherm.io.runrecord import RecordedFrames
from hexatherm.session import Session
from hexatherm.workflows.process.pipeline import ProcessResult
from hexatherm.workflows.process.quality import quality_checks

__all__ = [
    "MAX_REFERENCE_STATE_K",
    "SHARED_CENTRES",
    "check_distinct_measurements",
    "check_distinct_sessions",
    "check_one_balls",
    "check_one_hexapod",
    "check_reference_states",
    "hexapod_difference",
    "session_warnings",
]

#: the largest difference of any leg's temperature at R0 between the sessions of one
#: calibration, K (each session's corrected poses refer to its own R0)
MAX_REFERENCE_STATE_K = 0.5


def check_distinct_sessions(specs: Sequence[Session]) -> None:
    """Refuse a measurement file (by SHA-256) that two of the sessions hold. Only files
    of one size can have one content: a file whose size no other has is not read here
    (a scanning session's 150 MB would be read once more for nothing)."""
    seen: dict[str, tuple[Session, Path]] = {}
    files = [(spec, path, _size(path)) for spec in specs for path in spec.measurements]
    sizes = Counter(size for _, _, size in files if size is not None)
    for spec, path, size in files:
        if size is None or sizes[size] < 2:
            continue  # alone in its size, or not a regular file (the reader names why)
        digest = sha256_file(Path(os.path.realpath(path)))  # a live link is its file
        if digest is None:
            continue
        if digest in seen:
            first, where = seen[digest]
            same = (
                "is the same session as"
                if Path(first.path).resolve() == Path(spec.path).resolve()
                else "holds the same measurements as"
            )
            raise InputError(
                f"{same} {first.path} (its {where.name} and {Path(path).name} have one "
                f"SHA-256, {digest[:12]}...): a session given twice counts its poses "
                "twice; give each session once",
                path=str(spec.path),
                field="measurements",
            )
        seen[digest] = (spec, Path(path))


def _size(path: Path) -> int | None:
    """A regular file's size (a live link's file's), None for anything else."""
    try:
        info = os.stat(path)
    except OSError:
        return None
    return info.st_size if stat.S_ISREG(info.st_mode) else None


#: two ball centres are one measurement when every coordinate agrees within this share of
#: the centres' combined standard uncertainty (independent measurements of a centre differ
#: by the CMM's noise: all three coordinates within 5 % of it by chance, about 2e-5) ...
SAME_CENTRE_SHARE = 0.05
#: ... or within this, mm (what a spreadsheet's 15 digits, a rounding to 1 nm or a shift
#: by 1 nm change)
SAME_CENTRE_FLOOR_MM = 2e-6
#: two sessions are one when at least this share of either's measured ball centres are
#: centres of the other (refused) ...
SHARED_CENTRES = 0.1
#: ... and share too many when at least this many are, below that share (a warning)
MIN_SHARED_CENTRES = 2


def _centre_noise_mm(result: ProcessResult) -> float:
    """The typical standard uncertainty per coordinate of a session's centres (mm): the
    median over its centres of the covariance ``process`` propagates (fits, file, cmm:
    or the registration residuals); 0 when none is finite."""
    from hexatherm.workflows.process.uncertainty import centre_covariance

    u_um = centre_covariance(result).u_um
    u_um = u_um[np.isfinite(u_um)]
    return float(np.median(u_um)) * 1e-3 if u_um.size else 0.0


def _finite_centres(result: ProcessResult) -> np.ndarray:
    rows = np.asarray(result.centres.centres_mm, float).reshape(-1, 3)
    return rows[np.isfinite(rows).all(axis=1)]


def check_distinct_measurements(results: Sequence[ProcessResult]) -> None:
    """Refuse two sessions that hold the same measurements in other files or other digits,
    compared by what they measured, not by their bytes: a ball centre of one is a centre
    of the other when every coordinate agrees within :data:`SAME_CENTRE_SHARE` of their
    combined standard uncertainty (at least :data:`SAME_CENTRE_FLOOR_MM`), far closer
    than two measurements of one ball ever come (the same pose measured twice differs by
    the CMM's noise). At least :data:`SHARED_CENTRES` of either session's centres shared:
    refused, naming both sessions; :data:`MIN_SHARED_CENTRES` or more below that share: a
    ``warning:`` (an :class:`~hexatherm.errors.InputWarning`) naming both."""
    from scipy.spatial import cKDTree

    seen: list[tuple[ProcessResult, np.ndarray, float]] = []
    for result in results:
        mine = _finite_centres(result)
        noise = _centre_noise_mm(result)
        for other, theirs, their_noise in seen:
            if not (mine.size and theirs.size):
                continue
            tol = max(SAME_CENTRE_FLOOR_MM, SAME_CENTRE_SHARE * float(np.hypot(noise, their_noise)))
            found = cKDTree(theirs).query_ball_point(mine, r=tol, p=np.inf, return_length=True)
            shared = int(np.count_nonzero(found))
            if shared < MIN_SHARED_CENTRES:
                continue
            n = len(mine)
            count = f"all {n} of its" if shared == n else f"{shared} of its {n}"
            what = (
                f"{count} measured ball centres are those of {other.session.path} "
                f"(every coordinate within {tol * 1e6:.3g} nm; two measurements of a ball "
                f"differ by the CMM's noise, {np.hypot(noise, their_noise) * 1e3:.2g} um here)"
            )
            if shared >= SHARED_CENTRES * min(n, len(theirs)):
                raise InputError(
                    f"{what}: the same measurements in another file (copied, re-saved, "
                    "rounded, shifted?); a session given twice counts its poses twice; "
                    "give each session once",
                    path=str(result.session.path),
                    field="measurements",
                )
            warnings.warn(
                InputWarning(
                    f"{result.session.path}: {what}: those measurements count twice "
                    "(copied from one session into the other?); give each once"
                ),
                stacklevel=2,
            )
        seen.append((result, mine, noise))


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.shape(a) == np.shape(b) and np.array_equal(a, b))


def hexapod_difference(a: Hexapod, b: Hexapod) -> str | None:
    """The first field in which two hexapod models differ (what the poses rest on), or None.

    >>> from hexatherm.core.hexapod import Hexapod
    >>> h = Hexapod.symmetric(base_radius_mm=180, platform_radius_mm=110, base_half_angle_deg=10,
    ...                       platform_half_angle_deg=10, height_mm=240, stroke_mm=(220, 310))
    >>> import dataclasses
    >>> hexapod_difference(h, dataclasses.replace(h, stroke_mm=np.array([220.0, 300.0])))
    'stroke'
    >>> hexapod_difference(h, h) is None
    True
    """
    if a.convention != b.convention:
        return "convention"
    for name, label in (
        ("base_joints_mm", "base_joints"),
        ("platform_joints_mm", "platform_joints"),
        ("stroke_mm", "stroke"),
    ):
        if not _same(getattr(a, name), getattr(b, name)):
            return label
    if (a.legs is None) != (b.legs is None):
        return "legs"
    if a.legs is not None and b.legs is not None:
        la, lb = a.legs, b.legs
        if la.variable.shape != lb.variable.shape or not np.array_equal(la.variable, lb.variable):
            return "legs: segments"
        if not _same(la.fixed_length_mm, lb.fixed_length_mm):
            return "legs: segment lengths"
        if not _same(la.cte_per_K, lb.cte_per_K):
            return "legs: cte"
        if la.reference_temperature_C != lb.reference_temperature_C:
            return "legs: reference_temperature"
    return None


def check_one_hexapod(specs: Sequence[Session]) -> None:
    """Refuse sessions whose hexapod files differ in anything their poses rest on."""
    first = specs[0]
    for spec in specs[1:]:
        field = hexapod_difference(first.hexapod, spec.hexapod)
        if field is not None:
            raise InputError(
                f"its hexapod file differs from {first.path}'s in {field}: the sessions of "
                "one calibration must share one hexapod file",
                path=str(spec.path),
                field=f"hexapod: {field}",
            )


def check_one_frames(recorded: Sequence[RecordedFrames]) -> RecordedFrames:
    """The controller frames the sessions were measured with (``run.yaml``'s record; not
    recorded: zero, assumed); sessions measured with other frames refused in one line
    naming both records (frame O moves with the frames: one calibration, one setting)."""
    first = recorded[0]
    for other in recorded[1:]:
        if np.abs(other.values - first.values).max() > 1e-9:
            raise InputError(
                f"the controller's frames were {_numbers(other.values)} (mm, deg; "
                f"{other.source}), {first.path}'s {_numbers(first.values)} ({first.source}): "
                "calibrate sessions measured with one frame setting together",
                path=other.path,
                field="controller: frames_mm_deg",
            )
    return first


def _numbers(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.10g}" for v in values) + "]"


def check_one_balls(specs: Sequence[Session]) -> None:
    """Refuse sessions whose balls files differ in the balls' names or centres (the
    platform frame their poses refer to), naming the first ball that differs."""
    first = specs[0]
    centres = dict(zip(first.balls.names, first.balls.centres_mm, strict=True))
    for spec in specs[1:]:
        balls = spec.balls
        if sorted(balls.names) != sorted(centres):
            raise InputError(
                f"its balls file names the balls {', '.join(sorted(balls.names))}, "
                f"{first.path}'s {', '.join(sorted(centres))}: the poses of the sessions of "
                "one calibration must refer to one platform frame; give them one balls file",
                path=str(spec.path),
                field="balls",
            )
        for name, centre in zip(balls.names, balls.centres_mm, strict=True):
            if not np.array_equal(centre, centres[name]):
                raise InputError(
                    f"its balls file puts ball {name} at {_numbers(centre)} mm, "
                    f"{first.path}'s at {_numbers(centres[name])} mm: the poses of the "
                    "sessions of one calibration must refer to one platform frame; give "
                    "them one balls file",
                    path=str(spec.path),
                    field=f"balls: {name}",
                )


def _legs_at_r0(result: ProcessResult) -> np.ndarray | None:
    """Each leg's temperature at the session's R0 (degC), or None without temperatures."""
    temps = result.temperatures
    if temps is None:
        return None
    r0 = int(result.session.plan.reference_indices[0])
    t = float(result.centres.times_s[r0])
    return np.array([np.interp(t, temps.time_s, temps.legs_C[:, k]) for k in range(6)])


def check_reference_states(results: Sequence[ProcessResult], *, warn: bool = True) -> None:
    """Refuse sessions whose legs' temperatures at R0 differ, leg by leg, by more than
    :data:`MAX_REFERENCE_STATE_K`; warn (when ``warn``) for each session that has no
    temperatures."""
    if len(results) < 2:
        return
    states = [(result, _legs_at_r0(result)) for result in results]
    logged = [(result, legs) for result, legs in states if legs is not None]
    for result, legs in states:
        if legs is None and warn:
            warnings.warn(
                InputWarning(
                    f"{result.session.path}: no temperatures, so the thermal state of its "
                    "R0 (which its corrected poses refer to) cannot be checked against the "
                    "other sessions'"
                ),
                stacklevel=2,
            )
    if len(logged) < 2:
        return
    first, base = logged[0]
    for result, legs in logged[1:]:
        diff = legs - base
        k = int(np.argmax(np.abs(diff)))
        if abs(diff[k]) > MAX_REFERENCE_STATE_K:
            raise InputError(
                f"leg {k + 1} was at {legs[k]:.2f} degC at its R0 and at {base[k]:.2f} degC "
                f"at {first.session.path}'s ({diff[k]:+.2f} K): its corrected poses refer to "
                f"another thermal state (more than {MAX_REFERENCE_STATE_K} K apart on a "
                "leg); calibrate them apart",
                path=str(result.session.path),
                field="temperatures",
            )


def session_warnings(results: Sequence[ProcessResult]) -> list[str]:
    """What ``process`` warns of each session (its warnings, and the steps whose quality
    checks failed at the session's limits), each line naming the session file: the
    calibration rests on those poses."""
    lines = []
    for result in results:
        where = result.session.path
        lines += [f"{where}: {warning}" for warning in result.warnings]
        quality = quality_checks(result)
        if quality.any_failed:
            steps = quality.failed_steps
            lines.append(
                f"{where}: quality checks failed at {len(steps)} step(s) "
                f"({', '.join(steps[:5])}{' ...' if len(steps) > 5 else ''})"
            )
    return lines
