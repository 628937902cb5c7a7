"""A folder of Zeiss Calypso table files, one run of the measurement plan per step (an
extension, :mod:`hexatherm.io.config.tablemap`).

Calypso writes, per run, ``<name>_chr.txt``: tab-separated, a header line that starts
``planid  partnb  id  type  idsymbol  actual  nominal ...`` and one row per
characteristic; a sphere's centre and diameter are rows of their own, told by
``idsymbol`` (``xValue``, ``yValue``, ``zValue``, ``diameter``) and tied to the sphere by
``featureid`` (the feature's name), with the length ``unit`` of the row when the
version writes one. Beside it ``<name>_hdr.txt``, the run's header: a line of field
names (``planid``, ``partnb``, ``operid``, ``date``, ``time``, ``lengthunit``, ...) and
a line of their values, tab-separated (or one ``name<TAB>value`` line per field); and
``<name>_fet.txt`` (the features), which hexatherm does not need.

hexatherm reads each run's sphere features (the balls file's names, the entry's
``balls:`` map, or ``feature_pattern``'s group ``ball``) and the run's time from its
header's ``date`` and ``time`` (the entry's ``time_format``, else ``YYYY-M-D``,
``D.M.YYYY`` or ``Mon D, YYYY`` with ``H:MM[:SS]`` and an optional am/pm; read at the
entry's or the session's ``utc_offset``). The step of a run is the header field the
entry names (``step_field``), or, without one, the runs in time order are the plan's
steps in order, which the reader says in a warning line.

Refused, in one line naming the file, the line and the field: a folder without runs, a
run without its header (or a header without ``date``, ``time`` or the step field), a
time that reads in no known layout, a ``_chr.txt`` whose header lacks ``featureid``,
``idsymbol`` or ``actual``, a mapped feature missing from a run, a sphere without all
of x, y and z, a characteristic given twice, a unit that is not ``mm``, ``um`` or
``inch``, numbers that are not numbers, a step named twice, more runs than steps, and
what the table reader refuses of the text itself (encoding, a file cut short, NUL).
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from hexatherm.errors import InputError, InputWarning
from hexatherm.io.files import read_bytes
from hexatherm.io.records import Records, check_groups
from hexatherm.io.tables import Row, decode, number, rows_of, seconds_of
from hexatherm.session import LENGTH_UNITS, MeasurementFormat

__all__ = ["CalypsoRun", "read_calypso"]

#: ``idsymbol`` of a sphere's rows -> what they hold
SPHERE_SYMBOLS = {"xValue": 0, "yValue": 1, "zValue": 2, "diameter": 3}
#: unit names Calypso writes -> hexatherm's
_UNITS = {"mm": "mm", "inch": "inch", "in": "inch", "um": "um", "µm": "um"}
#: date and time layouts of a Calypso header, tried in order (unambiguous ones only)
_DATES = ("%Y-%m-%d", "%d.%m.%Y", "%b %d, %Y", "%B %d, %Y")
_TIMES = ("%H:%M:%S", "%H:%M", "%I:%M:%S %p", "%I:%M %p")


@dataclass(frozen=True)
class CalypsoRun:
    """One run as read: its files, its header's time, step (or None) and spheres."""

    chr_path: str
    hdr_path: str
    time_s: float
    time_line: int
    step: str | None
    step_line: int
    features: dict[str, tuple[np.ndarray, float, int]]  # name -> (xyz mm, diameter mm, line)


def _header(path: str, text: str) -> dict[str, tuple[str, int]]:
    """A run header's fields -> (value, line): a line of names and a line of values, or
    one ``name<TAB>value`` line per field."""
    lines = [(i + 1, line.split("\t")) for i, line in enumerate(text.split("\n")) if line.strip()]
    if not lines:
        raise InputError("empty run header", path=path, line=1)
    first = lines[0][1]
    if len(lines) == 1 and len(first) > 2:
        raise InputError(
            "the run header has a line of field names but no line of values (cut short?)",
            path=path,
            line=2,
        )
    if len(lines) >= 2 and len(first) > 2:
        number_, values = lines[1]
        return {
            name.strip(): (values[i].strip() if i < len(values) else "", number_)
            for i, name in enumerate(first)
            if name.strip()
        }
    fields: dict[str, tuple[str, int]] = {}
    for number_, cells in lines:
        if len(cells) >= 2:
            fields.setdefault(cells[0].strip(), (cells[1].strip(), number_))
    return fields


def _run_time(path: str, fields: dict[str, tuple[str, int]], time_format: str) -> tuple[float, int]:
    """POSIX seconds (naive, as UTC) of a header's ``date`` and ``time``, and the line."""
    for key in ("date", "time"):
        if not fields.get(key, ("", 0))[0]:
            raise InputError(
                f"the run header has no {key} (the run's time)", path=path, line=1, field=key
            )
    (date, line), clock = fields["date"], fields["time"][0]
    text = f"{date} {clock}"
    if time_format not in ("iso", "calypso"):
        return seconds_of(text, time_format, path, line, "date")[0], line
    for day in _DATES:
        for hour in _TIMES:
            try:
                stamp = datetime.strptime(text, f"{day} {hour}")
            except ValueError:
                continue
            return (
                stamp.replace(tzinfo=UTC) - datetime(1970, 1, 1, tzinfo=UTC)
            ).total_seconds(), line
    raise InputError(
        f"date and time {text!r} in no known layout (YYYY-M-D, D.M.YYYY, Mon D, YYYY with "
        "H:MM:SS): give the entry's time_format",
        path=path,
        line=line,
        field="date",
    )


def _spheres(
    path: str, header: Row, rows: list[Row], unit: str
) -> dict[str, tuple[np.ndarray, float, int]]:
    """The sphere features of a ``_chr.txt``: name -> (x, y, z in mm, diameter, line)."""
    names = header[1]
    for needed in ("featureid", "idsymbol", "actual"):
        if needed not in names:
            raise InputError(
                f"not a Calypso _chr.txt: no {needed!r} column in its header",
                path=path,
                line=header[0],
                field=needed,
            )
    at = {
        name: names.index(name)
        for name in ("featureid", "idsymbol", "actual", "unit")
        if name in names
    }
    found: dict[str, list[float]] = {}
    lines: dict[str, int] = {}
    for line, cells in rows:
        if len(cells) <= max(at["featureid"], at["idsymbol"], at["actual"]):
            raise InputError(
                f"{len(cells)} fields: the row is cut short", path=path, line=line, field="actual"
            )
        slot = SPHERE_SYMBOLS.get(cells[at["idsymbol"]])
        if slot is None:
            continue
        feature = cells[at["featureid"]]
        row_unit = cells[at["unit"]] if "unit" in at and at["unit"] < len(cells) else ""
        if row_unit and row_unit not in _UNITS:
            raise InputError(
                f"unit {row_unit!r}: expected mm, um or inch", path=path, line=line, field="unit"
            )
        scale = LENGTH_UNITS[_UNITS[row_unit]] if row_unit else LENGTH_UNITS[unit]
        value = _actual(cells[at["actual"]], path, line) * scale
        values = found.setdefault(feature, [np.nan] * 4)
        if not np.isnan(values[slot]):
            raise InputError(
                f"feature {feature!r}: {cells[at['idsymbol']]} given twice",
                path=path,
                line=line,
                field="idsymbol",
            )
        values[slot] = value
        lines.setdefault(feature, line)
    spheres = {}
    for feature, values in found.items():
        xyz = np.array(values[:3])
        if np.isnan(xyz).all():
            continue  # a circle's or cylinder's diameter alone
        if np.isnan(xyz).any():
            missing = "xyz"[int(np.argmax(np.isnan(xyz)))]
            raise InputError(
                f"feature {feature!r} has no {missing}Value row (a sphere needs x, y and z)",
                path=path,
                line=lines[feature],
                field="idsymbol",
            )
        spheres[feature] = (xyz, values[3], lines[feature])
    return spheres


def _actual(text: str, path: str, line: int) -> float:
    """An ``actual``: a decimal point, or (a German Calypso) a decimal comma."""
    decimal = "," if "," in text and "." not in text else "."
    return number(text, decimal, path, line, "actual")


def read_run(chr_path: Path, spec: MeasurementFormat, allow_truncated: bool) -> CalypsoRun:
    """One run: its ``_chr.txt`` and ``_hdr.txt``."""
    stem = chr_path.name[: -len("_chr.txt")]
    hdr_path = chr_path.parent / f"{stem}_hdr.txt"
    if not hdr_path.is_file():
        raise InputError(
            f"the run has no header {hdr_path.name} (the run's date and time)", path=chr_path
        )
    hdr = os.fspath(hdr_path)
    fields = _header(hdr, decode(read_bytes(hdr), hdr, spec.encoding))
    time_s, time_line = _run_time(hdr, fields, spec.time_format)
    step, step_line = None, 0
    if spec.step_field is not None:
        if spec.step_field not in fields or not fields[spec.step_field][0]:
            raise InputError(
                f"the run header has no {spec.step_field!r} (the session's step_field)",
                path=hdr,
                line=1,
                field=spec.step_field,
            )
        step, step_line = fields[spec.step_field]
    unit_field = fields.get("lengthunit", ("", 0))[0]
    unit = _UNITS.get(unit_field, spec.unit)
    where = os.fspath(chr_path)
    text = decode(read_bytes(where), where, spec.encoding)
    header, rows = rows_of(text, where, "\t", allow_truncated)
    spheres = _spheres(where, header, rows, unit)
    return CalypsoRun(where, hdr, time_s, time_line, step, step_line, spheres)


def read_calypso(
    folder: str | os.PathLike[str],
    spec: MeasurementFormat,
    labels: Sequence[str] | None,
    *,
    allow_truncated: bool = False,
    keep_later: bool = False,
) -> list[Records]:
    """The ball centres of every run in ``folder``, one :class:`Records` per run (its
    ``_chr.txt`` names the rows), in mm, times in UTC when an offset is known.

    ``labels``: the plan's steps in order, for runs without a step field (None: the
    runs are named by their file names' stems, as ``inspect`` lists them).
    """
    where = os.fspath(folder)
    runs = [read_run(p, spec, allow_truncated) for p in sorted(Path(where).glob("*_chr.txt"))]
    if not runs:
        raise InputError("no Calypso run in the folder (no <name>_chr.txt)", path=where)
    if spec.step_field is None:
        runs = _steps_by_time(where, runs, labels)
    seen: dict[str, str] = {}
    for run in runs:
        assert run.step is not None
        if run.step in seen:
            raise InputError(
                f"step {run.step!r} again (already the step of {seen[run.step]})",
                path=run.hdr_path,
                line=run.step_line,
                field=spec.step_field,
            )
        seen[run.step] = os.path.basename(run.hdr_path)
    return [_records(run, spec, keep_later) for run in runs]


def _steps_by_time(
    where: str, runs: list[CalypsoRun], labels: Sequence[str] | None
) -> list[CalypsoRun]:
    """Runs without a step field: in time order, the plan's steps in order (warned)."""
    runs = sorted(runs, key=lambda run: run.time_s)
    if labels is None:
        names = [Path(r.chr_path).name[: -len("_chr.txt")] for r in runs]
        return [_with_step(r, n) for r, n in zip(runs, names, strict=True)]
    if len(runs) > len(labels):
        extra = runs[len(labels)]
        raise InputError(
            f"{len(runs)} runs but {len(labels)} steps in the plan (no step_field): "
            f"{os.path.basename(extra.chr_path)} and after have no step",
            path=extra.hdr_path,
            line=extra.time_line,
            field="time",
        )
    times = [r.time_s for r in runs]
    if len(set(times)) < len(times):
        twin = runs[int(np.argmax(np.diff(times) == 0)) + 1]
        raise InputError(
            "two runs at the same time: their order, hence their steps, is unknown "
            "(give the entry's step_field)",
            path=twin.hdr_path,
            line=twin.time_line,
            field="time",
        )
    pairs = ", ".join(
        f"{Path(r.chr_path).name[: -len('_chr.txt')]} -> {label}"
        for r, label in zip(runs, labels, strict=False)
    )
    warnings.warn(
        InputWarning(
            f"{where}: no step_field: the {len(runs)} runs are the plan's steps in their "
            f"time order: {pairs}"
        ),
        stacklevel=3,
    )
    return [_with_step(r, label) for r, label in zip(runs, labels, strict=False)]


def _with_step(run: CalypsoRun, step: str) -> CalypsoRun:
    return CalypsoRun(
        run.chr_path, run.hdr_path, run.time_s, run.time_line, step, run.time_line, run.features
    )


def _records(run: CalypsoRun, spec: MeasurementFormat, keep_later: bool) -> Records:
    """A run's spheres as centre records of its step."""
    pattern = None if spec.feature_pattern is None else re.compile(spec.feature_pattern)
    chosen: list[tuple[str, str]] = []  # (feature, ball)
    if spec.balls:
        for feature, ball in spec.balls.items():
            if feature not in run.features:
                raise InputError(
                    f"no sphere feature {feature!r} (ball {ball} in the session's balls map); "
                    f"its spheres: {', '.join(sorted(run.features)) or 'none'}",
                    path=run.chr_path,
                    field="featureid",
                )
            chosen.append((feature, ball))
    else:
        for feature in run.features:
            match = None if pattern is None else pattern.fullmatch(feature)
            if pattern is not None and match is None:
                continue  # not a ball: an alignment feature
            chosen.append((feature, feature if match is None else match.group("ball")))
    if not chosen:
        raise InputError("no sphere feature in the run", path=run.chr_path, field="featureid")
    chosen.sort(key=lambda pair: run.features[pair[0]][2])
    xyz = np.array([run.features[f][0] for f, _ in chosen])
    diameter = np.array([run.features[f][1] for f, _ in chosen])
    time_s, aware = run.time_s, False
    if spec.utc_offset_s is not None:
        time_s, aware = time_s - spec.utc_offset_s, True
    n = len(chosen)
    records = Records(
        path=run.chr_path,
        kind="centres",
        label=np.full(n, run.step, dtype=object).astype(str),
        ball=np.array([b for _, b in chosen], dtype=str),
        xyz_mm=xyz,
        time_s=np.full(n, time_s),
        time_kind="iso",
        line=np.array([run.features[f][2] for f, _ in chosen], dtype=np.int64),
        diameter_mm=None if np.isnan(diameter).all() else diameter,
        time_aware=aware,
    )
    return check_groups(records, keep_later=keep_later)
