"""The thermocouple log (``temperatures.csv``): time, the six legs, further sensors (degC)."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.errors import InputError
from hexatherm.io.csvfile import column_numbers, column_times, drop_blank_rows
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
    frame = csv_frame(complete_lines(read_text(path), path, allow_truncated), path)
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
