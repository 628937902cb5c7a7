"""CSV readers: ball centres, probed points and thermocouple logs.

Centres and points files share the header ``label,ball,x,y,z,time``; centres may
add ``diameter``, points ``i,j,k`` (probing direction). Which of the two a file
holds is told by (in this order) its extra columns, its name (``centres``,
``centers`` or ``points`` in it), or its content (at least half the steps and balls
with one row means centres). ``time`` is an ISO 8601 timestamp or a number of seconds, the same kind
on every row.

Errors name the file, the line (header = line 1) and the column.
"""

from __future__ import annotations

import io
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.core.plan import NAME_PATTERN
from hexatherm.errors import InputError
from hexatherm.io.records import RecordKind, Records, TimeKind, seconds_to_iso

BASE_COLUMNS = ("label", "ball", "x", "y", "z", "time")
CENTRE_EXTRA = ("diameter", "form_um", "n", "u_um")  # all but diameter: extensions
POINT_EXTRA = ("i", "j", "k")


def read_text(path: str | os.PathLike[str]) -> str:
    """A file's text as UTF-8 (BOM allowed), any line ending; InputError when unreadable."""
    path = os.fspath(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", path=path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(f"not UTF-8 text ({exc.reason})", path=path, line=line) from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise InputError("NUL byte: not a text file", path=path, line=line)
    return text


def _frame(text: str, path: str) -> pd.DataFrame:
    """All cells as stripped strings; row ``r`` of the result is file line ``r + 2``."""
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    if not text.strip():
        raise InputError("empty file: expected a header line", path=path, line=1)
    try:
        frame = pd.read_csv(
            io.StringIO(text),
            dtype=str,
            keep_default_na=False,
            skip_blank_lines=False,
            skipinitialspace=True,
            engine="c",
        )
    except pd.errors.ParserError as exc:
        found = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(exc))
        if found:
            expected, line, saw = (int(g) for g in found.groups())
            raise InputError(
                f"expected {expected} comma-separated fields, found {saw}", path=path, line=line
            ) from None
        raise InputError(f"malformed CSV: {exc}", path=path) from None
    except (ValueError, pd.errors.EmptyDataError) as exc:
        raise InputError(f"malformed CSV: {exc}", path=path, line=1) from None
    frame.columns = [str(c).strip() for c in frame.columns]
    frame.index = np.arange(len(frame)) + 2
    frame = frame.fillna("")
    return frame.apply(lambda col: col.str.strip())


def _drop_blank(frame: pd.DataFrame) -> pd.DataFrame:
    blank = (frame == "").all(axis=1)
    return frame[~blank.to_numpy()]


def _numbers(
    frame: pd.DataFrame, column: str, path: str, allow_empty: bool = False
) -> npt.NDArray[np.float64]:
    text = frame[column]
    values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
    bad = ~np.isfinite(values)
    if allow_empty:
        bad &= (text != "").to_numpy()
    if np.any(bad):
        row = int(np.argmax(bad))
        raise InputError(
            f"not a finite number: {text.iloc[row]!r}",
            path=path,
            line=int(frame.index[row]),
            field=column,
        )
    return values


def _times(frame: pd.DataFrame, path: str) -> tuple[npt.NDArray[np.float64], TimeKind]:
    text = frame["time"]
    empty = (text == "").to_numpy()
    if np.any(empty):
        row = int(np.argmax(empty))
        raise InputError("missing time", path=path, line=int(frame.index[row]), field="time")
    if all(":" in value for value in text.to_numpy()):
        is_number = np.zeros(len(text), dtype=bool)  # numbers have no ':': skip parsing them
    else:
        numeric = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        is_number = np.isfinite(numeric)
        if np.all(is_number):
            return numeric, "seconds"
    if np.any(is_number):
        row = int(np.argmax(is_number))
        raise InputError(
            f"time {text.iloc[row]!r} is a number of seconds but other rows are "
            "ISO 8601 timestamps: use one kind in a file",
            path=path,
            line=int(frame.index[row]),
            field="time",
        )
    stamps = pd.to_datetime(text, errors="coerce", utc=True, format="ISO8601")
    bad = stamps.isna().to_numpy()
    if np.any(bad):
        row = int(np.argmax(bad))
        raise InputError(
            f"not an ISO 8601 timestamp or a number of seconds: {text.iloc[row]!r}",
            path=path,
            line=int(frame.index[row]),
            field="time",
        )
    seconds = (stamps - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy(dtype=np.float64)
    return np.asarray(seconds, dtype=np.float64), "iso"


def _check_header(frame: pd.DataFrame, path: str, extras: tuple[str, ...]) -> None:
    columns = list(frame.columns)
    if tuple(columns[:6]) != BASE_COLUMNS:
        raise InputError(
            f"header must start with {','.join(BASE_COLUMNS)}, got {','.join(columns)}",
            path=path,
            line=1,
        )
    for column in columns[6:]:
        if column not in extras:
            raise InputError(
                f"unknown column {column!r}; allowed after the first six: {', '.join(extras)}",
                path=path,
                line=1,
                field=column,
            )
    if len(set(columns)) != len(columns):
        raise InputError("duplicate column in header", path=path, line=1)


def _names(frame: pd.DataFrame, column: str, path: str) -> npt.NDArray[np.str_]:
    values = frame[column].to_numpy(dtype=str)
    ok = np.array([bool(NAME_PATTERN.fullmatch(v)) for v in values], dtype=bool)
    if not np.all(ok):
        row = int(np.argmax(~ok))
        raise InputError(
            f"{str(values[row])!r} must match [A-Za-z0-9-]+",
            path=path,
            line=int(frame.index[row]),
            field=column,
        )
    return values


def _kind(frame: pd.DataFrame, path: str) -> RecordKind:
    columns = set(frame.columns[6:])
    if columns & set(CENTRE_EXTRA):
        return "centres"
    if columns & set(POINT_EXTRA):
        return "points"
    name = Path(path).name.lower()
    if "centre" in name or "center" in name:
        return "centres"
    if "point" in name:
        return "points"
    counts = frame.groupby(["label", "ball"]).size()
    return "centres" if len(counts) and (counts == 1).mean() >= 0.5 else "points"


def read_measurement_csv(path: str | os.PathLike[str], kind: RecordKind | None = None) -> Records:
    """Read a centres or points CSV file into :class:`Records`."""
    path = os.fspath(path)
    text = read_text(path)
    fast = _fast_measurement_csv(text, path, kind)
    if fast is not None:
        return fast
    frame = _frame(text, path)
    _check_header(frame, path, CENTRE_EXTRA + POINT_EXTRA)
    frame = _drop_blank(frame)
    if frame.empty:
        raise InputError("no data rows", path=path, line=2)
    kind = kind or _kind(frame, path)
    extras = CENTRE_EXTRA if kind == "centres" else POINT_EXTRA
    misplaced = [c for c in frame.columns[6:] if c not in extras]
    if misplaced:
        raise InputError(
            f"column {misplaced[0]!r} does not belong in a {kind} file",
            path=path,
            line=1,
            field=misplaced[0],
        )
    label, ball = _names(frame, "label", path), _names(frame, "ball", path)
    xyz = np.column_stack([_numbers(frame, c, path) for c in ("x", "y", "z")])
    time, time_kind = _times(frame, path)
    lines = frame.index.to_numpy(dtype=np.int64)
    diameter = ijk = None
    extra: dict[str, object] = {}
    if kind == "centres":
        keys = pd.Series(label).str.cat(pd.Series(ball), sep="\x1f")
        dup = keys.duplicated().to_numpy()
        if np.any(dup):
            row = int(np.argmax(dup))
            first = int(np.argmax((keys == keys.iloc[row]).to_numpy()))
            raise InputError(
                f"duplicate centre for step {label[row]} ball {ball[row]} "
                f"(also on line {lines[first]})",
                path=path,
                line=int(lines[row]),
                field="label",
            )
        if "diameter" in frame.columns:
            diameter = _numbers(frame, "diameter", path, allow_empty=True)
        for column in ("form_um", "n", "u_um"):
            if column in frame.columns:
                extra[column] = _numbers(frame, column, path, allow_empty=True)
    elif all(c in frame.columns for c in POINT_EXTRA):
        ijk = np.column_stack([_numbers(frame, c, path, allow_empty=True) for c in POINT_EXTRA])
    elif any(c in frame.columns for c in POINT_EXTRA):
        raise InputError("give all of i, j, k or none", path=path, line=1)
    return Records(
        path=path,
        kind=kind,
        label=label,
        ball=ball,
        xyz_mm=xyz,
        time_s=time,
        time_kind=time_kind,
        line=lines,
        diameter_mm=diameter,
        ijk=ijk,
        extra=extra,
    )


def _fast_measurement_csv(text: str, path: str, kind: RecordKind | None) -> Records | None:
    """:func:`read_measurement_csv` for a clean file, or None: then the general reader must.

    Clean: a header of known column names without blanks, no quotes, no blank lines, and
    every value that the general reader would take without complaint and without
    stripping blanks (names, times), with no empty or non-finite number. The numbers are
    parsed by pandas' C parser straight to floats (the converter of ``pd.to_numeric``,
    correctly rounded), instead of strings that are stripped and converted one column
    after the other. Anything else (and any error) is left to the general reader, so that
    results and errors are the same.
    """
    if '"' in text:
        return None
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    columns = text.partition("\n")[0].split(",")
    known = set(BASE_COLUMNS + CENTRE_EXTRA + POINT_EXTRA)
    if (
        tuple(columns[:6]) != BASE_COLUMNS
        or not set(columns) <= known
        or len(set(columns)) != len(columns)
    ):
        return None
    numeric = [c for c in columns if c not in ("label", "ball", "time")]
    try:
        frame = pd.read_csv(
            io.StringIO(text),
            dtype={
                "label": object,
                "ball": object,
                "time": object,
                **dict.fromkeys(numeric, float),
            },
            keep_default_na=False,
            na_values=dict.fromkeys(numeric, [""]),
            skipinitialspace=True,
            skip_blank_lines=False,
            engine="c",
        )
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    if frame.empty or list(frame.columns) != columns:
        return None
    frame.index = np.arange(len(frame)) + 2
    for column in ("label", "ball"):
        names = pd.unique(frame[column].to_numpy())
        if not all(isinstance(v, str) and NAME_PATTERN.fullmatch(v) for v in names):
            return None
    if not all(isinstance(v, str) and v and v == v.strip() for v in frame["time"].to_numpy()):
        return None
    values = {c: frame[c].to_numpy(dtype=np.float64) for c in numeric}
    if not all(np.isfinite(v).all() for v in values.values()):
        return None  # empty or non-finite numbers: the general reader tells them apart
    kind = kind or _kind(frame, path)
    extras = CENTRE_EXTRA if kind == "centres" else POINT_EXTRA
    if any(c not in extras for c in columns[6:]):
        return None
    label, ball = frame["label"].to_numpy(dtype=str), frame["ball"].to_numpy(dtype=str)
    try:
        time, time_kind = _times(frame, path)
    except InputError:
        return None
    lines = frame.index.to_numpy(dtype=np.int64)
    diameter = ijk = None
    extra: dict[str, object] = {}
    if kind == "centres":
        if pd.Series(label).str.cat(pd.Series(ball), sep="\x1f").duplicated().any():
            return None
        if "diameter" in values:
            diameter = values["diameter"]
        extra = {c: values[c] for c in ("form_um", "n", "u_um") if c in values}
    elif all(c in values for c in POINT_EXTRA):
        ijk = np.column_stack([values[c] for c in POINT_EXTRA])
    elif any(c in values for c in POINT_EXTRA):
        return None
    xyz = np.column_stack([values[c] for c in ("x", "y", "z")])
    return Records(
        path=path,
        kind=kind,
        label=label,
        ball=ball,
        xyz_mm=xyz,
        time_s=time,
        time_kind=time_kind,
        line=lines,
        diameter_mm=diameter,
        ijk=ijk,
        extra=extra,
    )


def centres_to_csv(records: Records) -> str:
    """Centres CSV text: the contract columns, then ``diameter`` and, when known, the
    extension columns ``form_um``, ``n``, ``u_um`` (written by ``fit-spheres``)."""
    if records.time_kind == "iso":
        times: object = [seconds_to_iso(t) for t in records.time_s]
    else:
        times = records.time_s
    data: dict[str, object] = {
        "label": records.label,
        "ball": records.ball,
        "x": records.xyz_mm[:, 0],
        "y": records.xyz_mm[:, 1],
        "z": records.xyz_mm[:, 2],
        "time": times,
    }
    if records.diameter_mm is not None:
        data["diameter"] = records.diameter_mm
    for column in ("form_um", "n", "u_um"):
        if column in records.extra:
            data[column] = records.extra[column]
    buffer = io.StringIO()
    pd.DataFrame(data).to_csv(buffer, index=False, lineterminator="\n")
    return buffer.getvalue()


@dataclass(frozen=True)
class Temperatures:
    """A thermocouple log: ``time`` plus ``leg1``..``leg6`` and optional further columns.

    Attributes
    ----------
    path : str
    time_s : ndarray, shape (m,)
    time_kind : {"iso", "seconds"}
    legs_C : ndarray, shape (m, 6)
    others_C : dict of str to ndarray, shape (m,)
    """

    path: str
    time_s: npt.NDArray[np.float64]
    time_kind: TimeKind
    legs_C: npt.NDArray[np.float64]
    others_C: dict[str, npt.NDArray[np.float64]]


LEG_COLUMNS = tuple(f"leg{i}" for i in range(1, 7))


def read_temperatures(path: str | os.PathLike[str]) -> Temperatures:
    """Read ``temperatures.csv`` (time sorted, at least one row)."""
    path = os.fspath(path)
    frame = _frame(read_text(path), path)
    columns = list(frame.columns)
    expected = ("time",) + LEG_COLUMNS
    if tuple(columns[:7]) != expected:
        raise InputError(
            f"header must start with {','.join(expected)}, got {','.join(columns)}",
            path=path,
            line=1,
        )
    if len(set(columns)) != len(columns) or any(not c for c in columns):
        raise InputError("duplicate or empty column name in header", path=path, line=1)
    frame = _drop_blank(frame)
    if frame.empty:
        raise InputError("no data rows", path=path, line=2)
    time, kind = _times(frame, path)
    decreasing = np.diff(time) < 0
    if np.any(decreasing):
        row = int(np.argmax(decreasing)) + 1
        raise InputError("time goes backwards", path=path, line=int(frame.index[row]), field="time")
    legs = np.column_stack([_numbers(frame, c, path) for c in LEG_COLUMNS])
    others = {c: _numbers(frame, c, path) for c in columns[7:]}
    return Temperatures(path, time, kind, legs, others)


def read_measurements(
    path: str | os.PathLike[str], *, progress: Callable[[int, int], None] | None = None
) -> list[Records]:
    """Read any measurement file: centres/points CSV or DMIS output (by extension or content).

    ``progress(lines_done, lines_total)``, when given, is called now and then while a
    DMIS file is read the slow way (one with continuations or comments: seconds for
    a hundred thousand points); a CSV file or a plain DMIS file reports once, done.
    """
    path = os.fspath(path)
    suffix = Path(path).suffix.lower()
    if suffix in (".dmo", ".dms", ".dmi"):
        from hexatherm.io.dmis import read_dmis

        return read_dmis(path, progress=progress)
    if suffix != ".csv":
        text = read_text(path)
        from hexatherm.io.dmis import looks_like_dmis, read_dmis

        if looks_like_dmis(text[:4096]):
            return read_dmis(path, progress=progress)
    records = [read_measurement_csv(path)]
    if progress is not None:
        progress(len(records[0]) + 1, len(records[0]) + 1)
    return records
