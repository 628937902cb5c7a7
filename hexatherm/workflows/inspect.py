"""A flat listing of the features of any measurement file (for ``hexatherm inspect``)."""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.io.config.session import read_feature_names
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.csvtext import read_text
from hexatherm.io.dmis import DMIS_SUFFIXES, looks_like_dmis, read_dmis_features
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.measurements import is_qif
from hexatherm.io.qif import scan_qif
from hexatherm.io.records import Records, seconds_to_iso, seconds_to_iso_texts
from hexatherm.io.texttable import (
    DECIMALS,
    Column,
    FloatColumn,
    IntColumn,
    IsoColumn,
    text_column,
    text_table,
)
from hexatherm.session import MeasurementFormat

COLUMNS = ["line", "label", "type", "x_mm", "y_mm", "z_mm", "size_mm", "time"]


@dataclass(frozen=True)
class Listing:
    """What ``inspect`` lists: a CSV file's (or a session's) records, listed from their
    arrays, or the table of a DMIS or QIF file.

    Attributes
    ----------
    records : tuple of Records
        The records listed, one row each (a file's, or every entry's of a session).
    files : bool
        A session's listing: a ``file`` column first, the name of each row's file.
    table : DataFrame or None
        A DMIS or QIF file's features (then ``records`` is empty); its ``attrs["notes"]``
        say what was read.
    """

    records: tuple[Records, ...] = ()
    files: bool = False
    table: pd.DataFrame | None = None

    def __len__(self) -> int:
        if self.table is not None:
            return len(self.table)
        return sum(len(r) for r in self.records)

    @property
    def notes(self) -> list[str]:
        """What was read, beyond the table (a QIF file's unit, names, steps)."""
        return [] if self.table is None else list(self.table.attrs.get("notes", []))

    def counts(self) -> list[tuple[str, int]]:
        """How many features of each type, the most first (ties: the first seen
        first, as pandas' ``value_counts``)."""
        if self.table is not None:
            if "type" not in self.table:
                return []
            counted = self.table["type"].value_counts()
            return [(str(k), int(n)) for k, n in counted.items()]
        seen: dict[str, int] = {}
        for rec in self.records:
            kind = _TYPES[rec.kind]
            seen[kind] = seen.get(kind, 0) + len(rec)
        return sorted(seen.items(), key=lambda item: -item[1])

    def frame(self) -> pd.DataFrame:
        """The listing as one DataFrame: the columns of :data:`COLUMNS` (after ``file``
        for a session)."""
        if self.table is not None:
            return self.table
        frames = []
        for rec in self.records:
            table = _records_table(rec)
            if self.files:
                table.insert(0, "file", Path(rec.path).name)
            frames.append(table)
        if not self.files:
            return frames[0]
        return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()

    def text(self) -> str:
        """The text table, as pandas writes it (every row)."""
        return self.frame().to_string(
            index=False, na_rep="", float_format=lambda v: f"{v:.{DECIMALS}f}"
        )

    def text_blocks(self) -> Iterator[bytes] | None:
        """:meth:`text` with a line break after every line, as bytes a block of lines at
        a time, laid out from the records' arrays (:mod:`hexatherm.io.texttable`): no
        text per cell, the memory of one block. None where pandas lays it out (a DMIS
        or QIF table; names that are not plain ASCII)."""
        if self.table is not None or not self.records:
            return None
        columns = _records_columns(self.records, self.files)
        if columns is None:
            return None
        return text_table(columns, len(self))


#: the ``type`` of a record's row
_TYPES = {"centres": "SPHERE", "points": "POINT"}


def _records_columns(records: Sequence[Records], files: bool) -> list[tuple[str, Column]] | None:
    """The columns of :meth:`Listing.frame` as :mod:`~hexatherm.io.texttable` columns;
    None when a name needs pandas (not plain ASCII) or the files mix ISO times and
    seconds."""
    rows = [len(r) for r in records]
    total = sum(rows)
    # a row's label_ball from the runs of rows of one step and ball (a text per run)
    names: list[str] = []
    codes = []
    for rec in records:
        starts = _run_starts(rec)
        run = np.zeros(len(rec), dtype=np.intp)
        run[starts[1:]] = 1
        codes.append(len(names) + np.cumsum(run))
        names += [f"{a}_{b}" for a, b in zip(rec.label[starts], rec.ball[starts], strict=True)]
    labels = text_column(names, np.concatenate(codes) if codes else None, total)
    kinds = list(dict.fromkeys(_TYPES[r.kind] for r in records))
    each = np.repeat(np.arange(len(records)), rows)
    kind_codes = [kinds.index(_TYPES[r.kind]) for r in records]
    types = text_column(kinds, np.asarray(kind_codes, dtype=np.intp)[each], total)
    file_names = text_column([Path(r.path).name for r in records], each, total)
    times = {r.time_kind for r in records}
    if labels is None or file_names is None or types is None or len(times) > 1:
        return None
    joined = {
        "line": np.concatenate([r.line for r in records]),
        "xyz": np.concatenate([r.xyz_mm for r in records]),
        "size": np.concatenate(
            [
                r.diameter_mm if r.diameter_mm is not None else np.full(len(r), np.nan)
                for r in records
            ]
        ),
        "time": np.concatenate([r.time_s for r in records]),
    }
    columns: list[tuple[str, Column]] = [("file", file_names)] if files else []
    columns += [
        ("line", IntColumn(joined["line"])),
        ("label", labels),
        ("type", types),
        *((f"{a}_mm", FloatColumn(joined["xyz"][:, k])) for k, a in enumerate("xyz")),
        ("size_mm", FloatColumn(joined["size"])),
        ("time", IsoColumn(joined["time"]) if times == {"iso"} else FloatColumn(joined["time"])),
    ]
    return columns


def _run_starts(rec: Records) -> npt.NDArray[np.intp]:
    """The first row of every run of rows of one step and ball (a points file's sphere)."""
    label, ball = rec.label, rec.ball
    change = (label[1:] != label[:-1]) | (ball[1:] != ball[:-1])
    return np.flatnonzero(np.concatenate((len(rec) > 0, change), axis=None))


def feature_table(
    path: str | os.PathLike[str],
    reading: ReadOptions = STRICT,
    session: str | os.PathLike[str] | None = None,
) -> pd.DataFrame:
    """Every feature of a DMIS output or a centres/points CSV, one row each: the table
    of :func:`feature_listing`."""
    return feature_listing(path, reading, session).frame()


def feature_listing(
    path: str | os.PathLike[str],
    reading: ReadOptions = STRICT,
    session: str | os.PathLike[str] | None = None,
) -> Listing:
    """Every feature of a DMIS output or a centres/points CSV, one row each (``reading``:
    a file cut short, a ball probed twice in one step, as the other commands read it).
    A QIF file's table carries what was read in ``attrs["notes"]`` (:func:`qif_table`),
    its names mapped by the ``feature_names`` of ``session`` (a session file or folder)."""
    path = Path(path)
    if is_qif(path):
        names = None if session is None else read_feature_names(session)
        return Listing(table=qif_table(path, reading, names))
    if path.suffix.lower() in DMIS_SUFFIXES or (
        path.suffix.lower() != ".csv" and looks_like_dmis(read_text(path)[:4096])
    ):
        rows = []
        for feat in read_dmis_features(path, allow_truncated=reading.allow_truncated):
            xyz = feat.xyz_mm if feat.xyz_mm is not None else (np.nan,) * 3
            rows.append(
                [
                    feat.line,
                    feat.label,
                    feat.type,
                    *xyz,
                    np.nan if feat.size_mm is None else feat.size_mm,
                    "" if feat.time is None else feat.time.isoformat(),
                ]
            )
        return Listing(table=pd.DataFrame(rows, columns=COLUMNS))
    rec = read_measurement_csv(
        path, allow_truncated=reading.allow_truncated, keep_later=reading.keep_later
    )
    return Listing((rec,))


def program_without_actuals(path: str | os.PathLike[str], features: int) -> bool:
    """Whether ``path`` is a DMIS program (nominal ``F(...)`` features and ``MEAS``
    statements, as ``plan --dmis`` writes) rather than a CMM's output: it has no actual
    feature ``FA(...)`` to list (``features``: how many were listed)."""
    if features:
        return False
    text = read_text(Path(path))
    if not looks_like_dmis(text[:4096]):
        return False
    lines = [line.lstrip().upper() for line in text.splitlines()]
    return any(line.startswith("MEAS/") for line in lines) and not any(
        line.startswith("FA(") for line in lines
    )


def is_session(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a session folder or its ``session.yaml`` (then ``inspect``
    says what each measurement entry reads: :func:`session_reading`)."""
    path = Path(path)
    return (path.is_dir() and (path / "session.yaml").is_file()) or (
        path.is_file() and path.suffix.lower() in (".yaml", ".yml")
    )


def session_reading(
    path: str | os.PathLike[str], reading: ReadOptions = STRICT
) -> tuple[list[str], Listing]:
    """What a session's measurement entries read, before anything is processed: one
    line per entry (its format and mapping, units, steps, balls, times) and the listing
    of every centre read (``file`` and the columns of :func:`feature_table`), in mm and
    UTC when an offset is known. Runs given a step by their time order are warned of
    by the reader (an :class:`~hexatherm.errors.InputWarning`)."""
    from hexatherm.io.config import read_session
    from hexatherm.io.measurements import read_measurements

    session = read_session(path)
    lines: list[str] = []
    records: list[Records] = []
    for file in session.measurements:
        spec = session.formats.get(file)
        found = read_measurements(
            file,
            allow_truncated=reading.allow_truncated,
            keep_later=reading.keep_later,
            spec=spec,
            labels=session.plan.labels,
        )
        records += found
        lines.append(_entry_line(file, spec, found, session.utc_offset_s))
    return lines, Listing(tuple(records), files=True)


def _records_table(rec: Records) -> pd.DataFrame:
    """A file's records, one row each (times in UTC when the file gave offsets)."""
    times = seconds_to_iso_texts(rec.time_s) if rec.time_kind == "iso" else rec.time_s
    return pd.DataFrame(
        {
            "line": rec.line,
            "label": np.char.add(np.char.add(rec.label, "_"), rec.ball),
            "type": "SPHERE" if rec.kind == "centres" else "POINT",
            "x_mm": rec.xyz_mm[:, 0],
            "y_mm": rec.xyz_mm[:, 1],
            "z_mm": rec.xyz_mm[:, 2],
            "size_mm": rec.diameter_mm if rec.diameter_mm is not None else np.nan,
            "time": times,
        }
    )[COLUMNS]


def _entry_line(
    file: Path, spec: MeasurementFormat | None, found: list[Records], offset_s: float | None
) -> str:
    """One entry's summary: what it is, how it is mapped, what it holds."""
    # the names where they change: a points file's runs of rows, not its every row
    runs = [_run_starts(r) for r in found]
    pairs = list(zip(found, runs, strict=True))
    labels = list(dict.fromkeys(str(s) for r, at in pairs for s in r.label[at]))
    balls = sorted({str(b) for r, at in pairs for b in r.ball[at]})
    times = np.concatenate([r.time_s for r in found]) if found else np.zeros(0)
    kind = found[0].time_kind if found else "seconds"
    span = ""
    if times.size:
        first, last = (
            (seconds_to_iso(times.min()), seconds_to_iso(times.max()))
            if kind == "iso"
            else (f"{times.min():g} s", f"{times.max():g} s")
        )
        aware = any(r.time_aware for r in found)
        zone = (
            " UTC"
            if aware
            else (
                ""
                if kind != "iso"
                else (
                    " naive (the session's utc_offset applies)"
                    if offset_s is not None
                    else " naive (taken as UTC)"
                )
            )
        )
        span = f", times {first} .. {last}{zone}"
    steps = f"{len(labels)} steps ({', '.join(labels[:3])}{' ...' if len(labels) > 3 else ''})"
    held = f"{sum(len(r) for r in found)} centres, {steps}, balls {', '.join(balls)}{span}"
    if spec is None:
        return f"{file.name}: hexatherm's own format: {held}"
    units = f"unit {spec.unit}"
    if spec.kind == "calypso":
        step = (
            f"step from header field {spec.step_field}"
            if spec.step_field is not None
            else "steps by the runs' time order"
        )
        mapping = ", ".join(f"{k} -> {v}" for k, v in spec.balls.items()) or (
            f"feature_pattern {spec.feature_pattern}" if spec.feature_pattern else "feature names"
        )
        return (
            f"{file.name}: Calypso runs ({len(found)} runs, {step}; balls: {mapping}; "
            f"{units} unless a row says; {spec.encoding}): {held}"
        )
    columns = ", ".join(f"{role} <- {'+'.join(names)}" for role, names in spec.columns.items())
    split = f", feature_pattern {spec.feature_pattern}" if spec.feature_pattern else ""
    return (
        f"{file.name}: table (columns: {columns}{split}; delimiter {spec.delimiter!r}, "
        f"decimal {spec.decimal!r}, {units}, time {spec.time_format}): {held}"
    )


def qif_table(
    path: str | os.PathLike[str],
    reading: ReadOptions = STRICT,
    names: Mapping[str, str | None] | None = None,
) -> pd.DataFrame:
    """Every sphere of a QIF 3 results file, one row each (``type`` ``SPHERE``, or
    ``SPHERE+n`` for one measured by ``n`` points, fitted as a points file is), and in
    ``attrs["notes"]`` what was read: the unit, the steps, balls and times, the names and
    how they map to steps and balls, what was read past."""
    read = scan_qif(path, names=names, keep_later=reading.keep_later, unmapped=True)
    unnamed = [s for s in read.spheres if not s.step]
    spheres = [s for s in read.spheres if s.step]
    rows = [
        [
            s.line,
            f"{s.step}_{s.ball}" if s.step else s.name,
            "SPHERE" if not s.point_sets else f"SPHERE+{s.points}",
            *(s.xyz_mm if s.xyz_mm is not None else (np.nan,) * 3),
            s.diameter_mm,
            s.time or "",
        ]
        for s in read.spheres
    ]
    table = pd.DataFrame(rows, columns=COLUMNS)
    notes = [f"{path}: QIF 3 results; length unit {read.unit}, converted to mm"]
    if spheres:
        steps = list(dict.fromkeys(s.step for s in spheres))
        balls = sorted({s.ball for s in spheres})
        times = sorted(s.time for s in spheres if s.time)
        shown = ", ".join(steps[:6]) + (f", ... ({len(steps)} steps)" if len(steps) > 6 else "")
        notes.append(
            f"{len(spheres)} spheres: steps {shown}; balls {', '.join(balls)}; "
            f"times {times[0]} to {times[-1]}"
        )
        renamed = [
            (s.name, f"{s.step}_{s.ball}") for s in spheres if s.name != f"{s.step}_{s.ball}"
        ]
        if renamed:
            pairs = ", ".join(f"{a!r} -> {b}" for a, b in renamed[:4])
            more = f", ... ({len(renamed)} names)" if len(renamed) > 4 else ""
            notes.append(f"names mapped by feature_names: {pairs}{more}")
        else:
            notes.append("names: hexatherm's <step>_<ball>, as the file gives them")
        pointed = sum(1 for s in spheres if s.point_sets)
        if pointed:
            notes.append(
                f"{pointed} spheres with measured points ({sum(s.points for s in spheres)} "
                "points): hexatherm fits them as a points file, the file's centres unused"
            )
        per_axis = sum(1 for s in spheres if s.u_mm is not None)
        combined = sum(1 for s in spheres if not np.isnan(s.u_combined_mm))
        if per_axis or combined:
            notes.append(
                f"centre uncertainties stated: per axis on {per_axis}, combined on "
                f"{combined} of {len(spheres)} spheres"
            )
    elif not unnamed:
        notes.append("no sphere feature measured: nothing hexatherm reads")
    if unnamed:
        shown = ", ".join(repr(s.name) for s in unnamed[:4])
        more = f", ... ({len(unnamed)} names)" if len(unnamed) > 4 else ""
        notes.append(
            f"{len(unnamed)} spheres named neither <step>_<ball> nor by a map ({shown}{more}): "
            "process refuses them; map them in session.yaml's feature_names "
            "(inspect --session shows a session's map at work)"
        )
    past = [f"{n} {kind}" for kind, n in read.others.items()]
    past += [f"sphere {name!r} (line {line}, mapped to nothing)" for line, name in read.skipped]
    if past:
        notes.append("read past: " + ", ".join(past))
    table.attrs["notes"] = notes
    return table
