"""The thermocouple log (``temperatures.csv``): time, the six legs, further sensors (degC)."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.errors import InputError
from hexatherm.io.csvcolumns import (
    ASCII_BLANKS,
    column_numbers,
    column_times,
    drop_blank_rows,
    iso_times_from_bytes,
)
from hexatherm.io.csvtext import complete_lines, csv_frame, read_text
from hexatherm.io.records import TimeKind

#: Temperatures accepted, degC, in a thermocouple log and in a hexapod file (a value
#: in kelvin, 293.15 for 20 degC, is refused)
TEMPERATURE_RANGE_C = (-60.0, 150.0)


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
    time_aware : bool or None
        For ISO times: whether they carry a UTC offset (see
        :func:`~hexatherm.io.records.check_time_zones`).
    """

    path: str
    time_s: npt.NDArray[np.float64]
    time_kind: TimeKind
    legs_C: npt.NDArray[np.float64]
    others_C: dict[str, npt.NDArray[np.float64]]
    time_aware: bool | None = None


LEG_COLUMNS = tuple(f"leg{i}" for i in range(1, 7))


def _temperatures(frame: pd.DataFrame, column: str, path: str) -> npt.NDArray[np.float64]:
    values = column_numbers(frame, column, path)
    low, high = TEMPERATURE_RANGE_C
    bad = (values < low) | (values > high)
    if np.any(bad):
        row = int(np.argmax(bad))
        hint = " (kelvin? the log is in degC)" if 200 <= values[row] <= 450 else ""
        raise InputError(
            f"temperature {frame[column].iloc[row]!r} degC outside [{low:g}, {high:g}]{hint}",
            path=path,
            line=int(frame.index[row]),
            field=column,
        )
    return values


def read_temperatures(
    path: str | os.PathLike[str], *, allow_truncated: bool = False
) -> Temperatures:
    """Read ``temperatures.csv`` (time sorted, at least one row).

    ``allow_truncated`` drops a last line without a line break (a logger stopped while
    writing), with an :class:`InputWarning`, instead of refusing the file.
    """
    path = os.fspath(path)
    text = complete_lines(read_text(path), path, allow_truncated)
    fast = _fast_temperatures(text, path)
    if fast is not None:
        return fast
    frame = csv_frame(text, path)
    columns = list(frame.columns)
    expected = ("time",) + LEG_COLUMNS
    if tuple(columns[:7]) != expected:
        raise InputError(
            f"header must start with {','.join(expected)}, got {','.join(columns)}",
            path=path,
            line=1,
        )
    frame = drop_blank_rows(frame)
    if frame.empty:
        raise InputError("no data rows", path=path, line=2)
    time, kind, aware = column_times(frame, path)
    decreasing = np.diff(time) < 0
    if np.any(decreasing):
        row = int(np.argmax(decreasing)) + 1
        raise InputError("time goes backwards", path=path, line=int(frame.index[row]), field="time")
    legs = np.column_stack([_temperatures(frame, c, path) for c in LEG_COLUMNS])
    others = {c: _temperatures(frame, c, path) for c in columns[7:]}
    return Temperatures(path, time, kind, legs, others, aware)


def _fast_temperatures(text: str, path: str) -> Temperatures | None:
    """:func:`read_temperatures` for a clean log, or None: then the general reader must.

    Clean: ASCII without a blank or a quote, a header of distinct names starting with
    ``time,leg1..leg6``, every line with all its fields, every temperature a finite
    number in range, times that :func:`column_times` takes, never going backwards. The
    numbers are parsed by pandas' C parser straight to floats (as ``pd.to_numeric``
    does), instead of stripped strings converted column by column. Anything else is
    left to the general reader, so that results and errors are the same.
    """
    if not text.isascii() or '"' in text or "\r" in text:
        return None
    if any(c in text for c in ASCII_BLANKS):
        return None
    columns = text[: text.find("\n")].split(",")
    if tuple(columns[:7]) != ("time", *LEG_COLUMNS) or len(set(columns)) != len(columns):
        return None
    if "" in columns or text.count(",") != (len(columns) - 1) * text.count("\n"):
        return None  # a nameless column, or a line with too few or too many fields
    numeric = columns[1:]
    raw = text.encode("ascii")
    # ISO times of one layout straight from the bytes (no Python string per row; pandas
    # then leaves the column out), else pandas reads them as text
    cut = iso_times_from_bytes(raw, 0, len(columns))
    read = columns if cut is None else numeric
    try:
        frame = pd.read_csv(
            io.BytesIO(raw),
            dtype={"time": object, **dict.fromkeys(numeric, float)},
            usecols=None if cut is None else read,
            keep_default_na=False,
            na_values=dict.fromkeys(numeric, [""]),
            skip_blank_lines=False,
            engine="c",
        )
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None
    if frame.empty or list(frame.columns) != read:
        return None
    if cut is None and frame["time"].isna().any():
        return None
    values = frame[numeric].to_numpy(dtype=np.float64)
    low, high = TEMPERATURE_RANGE_C
    if not (np.isfinite(values).all() and (values >= low).all() and (values <= high).all()):
        return None
    frame.index = np.arange(len(frame)) + 2
    kind: TimeKind = "iso"
    aware: bool | None
    if cut is not None:
        if cut[0].size != len(frame):
            return None
        time, aware = cut
    else:
        try:
            time, kind, aware = column_times(frame, path)
        except InputError:
            return None
    if np.any(np.diff(time) < 0):
        return None
    others = {c: values[:, j + 6] for j, c in enumerate(columns[7:])}
    return Temperatures(path, time, kind, values[:, :6].copy(), others, aware)
