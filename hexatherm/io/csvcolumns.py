"""The columns every CSV reader of hexatherm shares (measurements, the thermocouple log,
the tables of a column map): numbers, strict ISO 8601 times or seconds, blank rows.

Errors name the file, the line and the column.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.errors import InputError
from hexatherm.io.records import TimeKind

#: the ASCII characters that ``str.strip`` takes off, but for the line breaks
ASCII_BLANKS = " \t\x0b\x0c\x1c\x1d\x1e\x1f"


def drop_blank_rows(frame: pd.DataFrame) -> pd.DataFrame:
    blank = (frame == "").all(axis=1)
    return frame[~blank.to_numpy()]


def column_numbers(
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


#: An ISO 8601 time as hexatherm reads it: two-digit fields, a time of day, an optional
#: offset (``T`` or a blank between date and time)
ISO_TIME = re.compile(
    r"[0-9]{4}-[0-9]{2}-[0-9]{2}[T ][0-9]{2}:[0-9]{2}(?::[0-9]{2}(?:\.[0-9]{1,9})?)?"
    r"(?P<offset>Z|[+-][0-9]{2}(?::?[0-9]{2})?)?"
)
_ISO_HELP = "YYYY-MM-DDTHH:MM[:SS[.ffffff]][Z|+HH:MM]"


def _iso_layout(values: npt.NDArray[np.object_]) -> bool | None:
    """Whether every time has an offset (True) or none has (False), when all follow one
    layout that :data:`ISO_TIME` accepts (of one length, digits where the first has
    digits, the same other characters); None when they do not: then each is checked.

    The times are compared as one block of ASCII bytes, a row each (a scanning probe's
    file has millions of them), one byte wider than the first so that a longer one shows.

    >>> _iso_layout(np.array(["2024-03-05T07:30:00", "2024-03-05T07:31:02"], dtype=object))
    False
    >>> _iso_layout(np.array(["2024-03-05T07:30:00", "2024-03-05T07:31:02Z"], dtype=object))
    """
    first = values[0]
    if not isinstance(first, str) or not first.isascii():
        return None
    width = len(first)
    try:
        fixed = values.astype(f"S{width + 1}")
    except (UnicodeEncodeError, TypeError, ValueError):
        return None  # characters beyond ASCII, or not text
    codes = fixed.view(np.uint8).reshape(values.size, width + 1)
    if codes[:, width].any() or not codes[:, width - 1].all():
        return None  # a longer or a shorter one
    digit = (codes[:, :width] - np.uint8(48)) < 10
    if not (digit == digit[0]).all():
        return None
    other = np.flatnonzero(~digit[0])
    if not (codes[:, other] == codes[0, other]).all():
        return None
    match = ISO_TIME.fullmatch(
        np.where(digit[0], np.uint8(48), codes[0, :width]).tobytes().decode()
    )
    return None if match is None else match.group("offset") is not None


def _iso_seconds(
    text: pd.Series, lines: npt.NDArray[np.int64], path: str, layout: bool | None = None
) -> tuple[npt.NDArray[np.float64], bool]:
    """POSIX seconds of strict ISO times (naive ones taken as UTC) and whether they have
    an offset; InputError for a time off the layout, mixed offsets or an invalid date.
    ``layout``: :func:`_iso_layout` of the times when the caller has it."""
    values = text.to_numpy(dtype=object)
    if layout is not None:
        aware: bool | None = layout
    else:
        aware = _iso_layout(values) if values.size else False
    if aware is None:  # check one by one, in order, for the first bad one
        first_aware: bool | None = None
        for row, value in enumerate(values.tolist()):
            match = ISO_TIME.fullmatch(value)
            if match is None:
                raise InputError(
                    f"not an ISO 8601 time with two-digit fields ({_ISO_HELP}) "
                    f"or a number of seconds: {value!r}",
                    path=path,
                    line=int(lines[row]),
                    field="time",
                )
            has = match.group("offset") is not None
            if first_aware is None:
                first_aware = has
            elif has != first_aware:
                what = "has a UTC offset" if has else "has no UTC offset"
                raise InputError(
                    f"time {value!r} {what} but the time on line {int(lines[0])} "
                    f"({str(values[0])!r}) {'has none' if has else 'has one'}: mixed naive and "
                    "offset-aware times; give every time an offset or none",
                    path=path,
                    line=int(lines[row]),
                    field="time",
                )
        aware = bool(first_aware)
    try:
        stamps = pd.to_datetime(text, errors="coerce", utc=True, format="ISO8601")
        since = (stamps - pd.Timestamp(0, tz="UTC")).dt.total_seconds()
        seconds = since.to_numpy(dtype=np.float64)
    except (OverflowError, pd.errors.OutOfBoundsDatetime, pd.errors.OutOfBoundsTimedelta):
        seconds = np.full(values.size, np.nan)  # years beyond pandas' nanoseconds: below
    missing = np.flatnonzero(np.isnan(seconds))
    for row in missing.tolist():  # beyond pandas' years 1677-2262, or invalid
        value = str(values[row])
        try:
            stamp = datetime.fromisoformat(value)
        except ValueError as exc:
            raise InputError(
                f"not a valid date and time: {value!r} ({exc})",
                path=path,
                line=int(lines[row]),
                field="time",
            ) from None
        if stamp.tzinfo is None:
            stamp = stamp.replace(tzinfo=UTC)
        seconds[row] = (stamp - datetime(1970, 1, 1, tzinfo=UTC)).total_seconds()
    return np.asarray(seconds, dtype=np.float64), aware


def column_times(
    frame: pd.DataFrame, path: str
) -> tuple[npt.NDArray[np.float64], TimeKind, bool | None]:
    """The ``time`` column: seconds, its kind, and (ISO) whether it has UTC offsets."""
    text = frame["time"]
    lines = frame.index.to_numpy(dtype=np.int64)
    values = text.to_numpy(dtype=object)
    layout = _iso_layout(values) if values.size else None
    if layout is not None:
        # every time of one ISO layout (the common case): none is empty or a number
        seconds, aware = _iso_seconds(text, lines, path, layout)
        return seconds, "iso", aware
    empty = (text == "").to_numpy()
    if np.any(empty):
        row = int(np.argmax(empty))
        raise InputError("missing time", path=path, line=int(lines[row]), field="time")
    if all(":" in value for value in text.to_numpy()):
        is_number = np.zeros(len(text), dtype=bool)  # numbers have no ':': skip parsing them
    else:
        numeric = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        is_number = np.isfinite(numeric)
        if np.all(is_number):
            return numeric, "seconds", None
    if np.any(is_number):
        row = int(np.argmax(is_number))
        raise InputError(
            f"time {text.iloc[row]!r} is a number of seconds but other rows are "
            "ISO 8601 timestamps: use one kind in a file",
            path=path,
            line=int(lines[row]),
            field="time",
        )
    seconds, aware = _iso_seconds(text, lines, path)
    return seconds, "iso", aware
