"""Measured records: what a measurement file holds, whatever its format.

A measurement file (centres CSV, points CSV, DMIS output, a serial capture) is
read into one or more :class:`Records`: rows of ``(label, ball, x, y, z, time)``
in the CMM frame M, each with the line of the file it came from so that later
errors can point at it.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.errors import InputError, InputWarning

RecordKind = Literal["centres", "points"]
TimeKind = Literal["iso", "seconds"]


@dataclass(frozen=True)
class Records:
    """Rows of measured ball centres or surface points from one file.

    Attributes
    ----------
    path : str
        The file the rows were read from (for messages).
    kind : {"centres", "points"}
        Ball centres (one row per step and ball) or probed surface points.
    label, ball : ndarray of str, shape (n,)
        Step label and ball name of each row.
    xyz_mm : ndarray, shape (n, 3)
        Coordinates in the CMM frame M, mm.
    time_s : ndarray, shape (n,)
        Time of each row in seconds: POSIX seconds (UTC) when ``time_kind`` is
        ``"iso"``, the file's own numbers when it is ``"seconds"``.
    time_kind : {"iso", "seconds"}
        How the file wrote its times.
    line : ndarray of int, shape (n,)
        1-based line of the file each row starts on.
    diameter_mm : ndarray, shape (n,), optional
        Fitted diameter of each centre row (NaN where the file gave none).
    ijk : ndarray, shape (n, 3), optional
        Probing direction of each point row (NaN where the file gave none).
    extra : dict of str to ndarray, optional
        Further per-row columns (``u_um``, ``form_um``, ``n``, a DMIS point's number).
    time_aware : bool or None, optional
        For ISO times: whether they carry a UTC offset (True) or are naive, taken as
        UTC (False); None for seconds or when unknown. See :func:`check_time_zones`.
    """

    path: str
    kind: RecordKind
    label: npt.NDArray[np.str_]
    ball: npt.NDArray[np.str_]
    xyz_mm: npt.NDArray[np.float64]
    time_s: npt.NDArray[np.float64]
    time_kind: TimeKind
    line: npt.NDArray[np.int64]
    diameter_mm: npt.NDArray[np.float64] | None = None
    ijk: npt.NDArray[np.float64] | None = None
    extra: dict[str, object] = field(default_factory=dict)
    time_aware: bool | None = None

    def __len__(self) -> int:
        return int(self.xyz_mm.shape[0])


def iso_to_seconds(text: str) -> float:
    """Parse an ISO 8601 timestamp into POSIX seconds; naive times are taken as UTC.

    >>> iso_to_seconds("2020-01-01T00:00:10")
    1577836810.0
    >>> iso_to_seconds("2020-01-01T01:00:10+01:00")
    1577836810.0
    """
    stamp = datetime.fromisoformat(text.strip())
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    return stamp.timestamp()


def seconds_to_iso(seconds: float) -> str:
    """Format POSIX seconds as an ISO 8601 UTC timestamp (microseconds kept).

    >>> seconds_to_iso(1577836810.25)
    '2020-01-01T00:00:10.250000'
    """
    stamp = datetime.fromtimestamp(float(seconds), tz=UTC).replace(tzinfo=None)
    return stamp.isoformat(timespec="microseconds")


#: POSIX seconds of 1970-01-01 and of 9999-12-31T23:59:59: where numpy's dates and
#: Python's write a timestamp alike (four-digit years, no sign)
_ISO_SPAN_S = (0.0, 253402300799.0)


def seconds_to_iso_texts(seconds: npt.ArrayLike) -> list[str]:
    """:func:`seconds_to_iso` of many times at once, the same texts: the microseconds
    rounded as ``datetime.fromtimestamp`` rounds them (the fraction of the second times
    1e6, half to even), formatted by numpy; a time outside 1970-9999 value by value.

    >>> seconds_to_iso_texts([1577836810.25, 0.0000005, 1.9999996])
    ['2020-01-01T00:00:10.250000', '1970-01-01T00:00:00.000000', '1970-01-01T00:00:02.000000']
    """
    values = np.asarray(seconds, dtype=float).ravel()
    micro = _microseconds(values)
    if micro is None:
        return [seconds_to_iso(v) for v in values.tolist()]
    texts = np.datetime_as_string(micro.astype("datetime64[us]"), unit="us")
    return [str(t) for t in texts.tolist()]


def _microseconds(values: npt.NDArray[np.float64]) -> npt.NDArray[np.int64] | None:
    """POSIX seconds as whole microseconds, rounded as ``datetime.fromtimestamp`` rounds
    them (the fraction of the second times 1e6, half to even); None when a time is
    outside 1970-9999 (:data:`_ISO_SPAN_S`) or not a number."""
    low, high = _ISO_SPAN_S
    if not (np.all(values >= low) and np.all(values <= high)):
        return None
    fraction, whole = np.modf(values)
    return whole.astype(np.int64) * 1_000_000 + np.rint(fraction * 1e6).astype(np.int64)


#: the texts ``00`` to ``99``, two ASCII bytes each
_DIGITS2 = np.frombuffer("".join(f"{i:02d}" for i in range(100)).encode(), np.uint8).reshape(100, 2)


def _date_fields(days: npt.NDArray[np.int64]) -> npt.NDArray[np.uint8]:
    """``YYYY-MM-DD`` of days since 1970-01-01 (0 <= days <= 9999-12-31's), ASCII bytes
    (n, 10): the proleptic Gregorian date in integers (H. Hinnant's ``civil_from_days``)."""
    era, day_of_era = np.divmod(days + 719_468, 146_097)  # from 0000-03-01: years from March
    year_of_era = (
        day_of_era - day_of_era // 1460 + day_of_era // 36_524 - day_of_era // 146_096
    ) // 365
    day_of_year = day_of_era - (365 * year_of_era + year_of_era // 4 - year_of_era // 100)
    month_march = (5 * day_of_year + 2) // 153  # 0: March .. 11: February
    day = day_of_year - (153 * month_march + 2) // 5 + 1
    month = np.where(month_march < 10, month_march + 3, month_march - 9)
    year = year_of_era + 400 * era + (month <= 2)
    out = np.empty((days.size, 10), np.uint8)
    out[:, [4, 7]] = ord("-")
    for at, part in ((0, year // 100), (2, year % 100), (5, month), (8, day)):
        out[:, at : at + 2] = _DIGITS2[part]
    return out


@functools.cache
def _clock_fields() -> tuple[npt.NDArray[np.uint64], npt.NDArray[np.uint8]]:
    """``HH:MM:SS`` of every second of a day as one 8-byte word each, and the texts
    ``000`` to ``999`` (three bytes each): the tables :func:`seconds_to_iso_fields`
    gathers from."""
    second = np.arange(86_400)
    clock = np.empty((86_400, 8), np.uint8)
    clock[:, [2, 5]] = ord(":")
    for at, part in ((0, second // 3600), (3, second // 60 % 60), (6, second % 60)):
        clock[:, at : at + 2] = _DIGITS2[part]
    thousand = np.frombuffer("".join(f"{i:03d}" for i in range(1000)).encode(), np.uint8)
    return clock.view(np.uint64).ravel(), thousand.reshape(1000, 3)


def seconds_to_iso_fields(seconds: npt.ArrayLike) -> npt.NDArray[np.uint8] | None:
    """:func:`seconds_to_iso_texts` as ASCII bytes, one row of 26 per time
    (``YYYY-MM-DDTHH:MM:SS.ffffff``), from integers and tables: each distinct day's date
    once (:func:`_date_fields`), the time of day and the microseconds gathered from
    :func:`_clock_fields`. For listings of millions of times (numpy's
    ``datetime_as_string`` takes about a microsecond a time). None when a time is
    outside 1970-9999 (:func:`seconds_to_iso_texts` writes those value by value).

    >>> bytes(seconds_to_iso_fields([1577836810.25])[0]).decode()
    '2020-01-01T00:00:10.250000'
    """
    micro = _microseconds(np.asarray(seconds, dtype=float).ravel())
    if micro is None:
        return None
    days, rest = np.divmod(micro, 86_400_000_000)
    second, fraction = np.divmod(rest, 1_000_000)
    out = np.empty((micro.size, 26), np.uint8)
    if micro.size:
        first, last = int(days.min()), int(days.max())
        if last - first < micro.size:  # a session's few days: each day's date once
            out[:, :10] = _date_fields(np.arange(first, last + 1))[days - first]
        else:
            out[:, :10] = _date_fields(days)
    clock, thousand = _clock_fields()
    out[:, 10] = ord("T")
    out[:, 11:19] = clock[second].view(np.uint8).reshape(-1, 8)
    out[:, 19] = ord(".")
    high, low = np.divmod(fraction, 1000)
    out[:, 20:23] = thousand[high]
    out[:, 23:26] = thousand[low]
    return out


def concat_records(records: list[Records]) -> Records:
    """Join records of one kind and time kind (the first one's path names the result)."""
    first = records[0]
    if any(r.kind != first.kind or r.time_kind != first.time_kind for r in records):
        raise ValueError("records of different kinds or time kinds cannot be joined")
    check_time_zones(records)
    aware = {r.time_aware for r in records} - {None}

    def join(name: str) -> npt.NDArray[np.float64] | None:
        values = [getattr(r, name) for r in records]
        return None if any(v is None for v in values) else np.concatenate(values)

    keys = set.intersection(*(set(r.extra) for r in records))
    extra: dict[str, object] = {
        key: np.concatenate([np.asarray(r.extra[key]) for r in records]) for key in keys
    }
    return Records(
        path=first.path,
        kind=first.kind,
        label=np.concatenate([r.label for r in records]),
        ball=np.concatenate([r.ball for r in records]),
        xyz_mm=np.concatenate([r.xyz_mm for r in records]),
        time_s=np.concatenate([r.time_s for r in records]),
        time_kind=first.time_kind,
        line=np.concatenate([r.line for r in records]),
        diameter_mm=join("diameter_mm"),
        ijk=join("ijk"),
        extra=extra,
        time_aware=aware.pop() if aware else None,
    )


class TimeSource(Protocol):
    """What :func:`check_time_zones` needs of a file's times (Records, Temperatures)."""

    @property
    def path(self) -> str: ...

    @property
    def time_kind(self) -> TimeKind: ...

    @property
    def time_aware(self) -> bool | None: ...


def check_time_zones(sources: Iterable[TimeSource]) -> None:
    """Refuse files of one session that mix naive ISO times and times with a UTC offset.

    A naive time is taken as UTC: beside times with offsets it would be off by the
    offset (hours), silently. Files with times in seconds, or whose kind is unknown
    (``time_aware`` None), are not compared.

    Parameters
    ----------
    sources : iterable of Records or Temperatures
        The session's measurement records and thermocouple log (anything with
        ``path``, ``time_kind`` and ``time_aware``; ``line`` when it has one).

    Raises
    ------
    InputError
        Naming the later file (and its first row's line when known), field ``time``,
        and the earlier file of the other kind.

    Examples
    --------
    >>> from types import SimpleNamespace as Source
    >>> check_time_zones([Source(path="a.csv", time_kind="iso", time_aware=False),
    ...                   Source(path="b.dmo", time_kind="iso", time_aware=False)])
    >>> check_time_zones([Source(path="a.csv", time_kind="iso", time_aware=True),
    ...                   Source(path="t.csv", time_kind="iso", time_aware=False)])
    Traceback (most recent call last):
    hexatherm.errors.InputError: t.csv: field 'time': times naive (no UTC offset) here but with ...
    """
    seen: dict[bool, TimeSource] = {}
    for source in sources:
        aware = source.time_aware
        if source.time_kind != "iso" or aware is None:
            continue
        other = seen.get(not aware)
        if other is not None:
            naive, offset = "naive (no UTC offset)", "with a UTC offset"
            mine, theirs = (offset, naive) if aware else (naive, offset)
            lines = getattr(source, "line", None)
            raise InputError(
                f"times {mine} here but {theirs} in {other.path}: naive times would be "
                "taken as UTC, hours off; give every time an offset or none",
                path=source.path,
                line=int(lines[0]) if lines is not None and len(lines) else None,
                field="time",
            )
        seen.setdefault(aware, source)


def _line_span(lines: npt.NDArray[np.int64], start: int, stop: int, prefix: bool = True) -> str:
    first, last = int(lines[start]), int(lines[stop - 1])
    span = str(first) if first == last else f"{first}-{last}"
    if not prefix:
        return span
    return f"line {span}" if first == last else f"lines {span}"


def check_groups(records: Records, *, keep_later: bool = False) -> Records:
    """Refuse a ball measured twice in one step, and a point label seen twice.

    The records of one file, in file order. Each step's ball is one *group* of
    consecutive rows (its probed points; a centre is a group of one row). A second
    group for the same step and ball (the ball probed again later, perhaps minutes
    and microns apart) would be merged into one sphere fit: it is refused, naming
    both groups' lines, unless ``keep_later``, which keeps the last group of each
    step and ball and drops the earlier ones with an :class:`InputWarning`. Then a
    point number (``extra["n"]``, a DMIS point label ``<step>_<ball>_<n>``) seen
    twice within a group is refused, naming both lines.

    Parameters
    ----------
    records : Records
        One file's rows, in the order of the file.
    keep_later : bool, optional
        Keep the last group of a step and ball measured more than once.

    Returns
    -------
    Records
        ``records`` itself when nothing is dropped, else the rows kept.

    Raises
    ------
    InputError
        Naming the file, the line of the later group (or row) and field ``ball``
        (``label`` for a centre given twice or a point label seen twice).

    Examples
    --------
    >>> rec = Records(path="p.csv", kind="points", label=np.array(["S1"] * 3),
    ...               ball=np.array(["B1", "B2", "B1"]), xyz_mm=np.zeros((3, 3)),
    ...               time_s=np.arange(3.0), time_kind="seconds", line=np.array([2, 3, 4]))
    >>> check_groups(rec)
    Traceback (most recent call last):
    hexatherm.errors.InputError: p.csv:4: field 'ball': step S1 ball B1 probed twice: ...
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     check_groups(rec, keep_later=True).line.tolist()
    [3, 4]
    >>> str(caught[0].message)
    'p.csv:2: step S1 ball B1 probed twice: the earlier group (line 2) dropped, line 4 kept'
    """
    n = len(records)
    if n == 0:
        return records
    label, ball, lines = records.label, records.ball, records.line
    if records.kind == "centres":
        starts = np.arange(n)
    else:
        change = (label[1:] != label[:-1]) | (ball[1:] != ball[:-1])
        starts = np.concatenate(([0], np.flatnonzero(change) + 1))
    stops = np.append(starts[1:], n)
    first_label, first_ball = label[starts].astype(str), ball[starts].astype(str)
    repeated: dict[tuple[str, str], list[int]] = {}
    if not _distinct_pairs(first_label, first_ball):
        groups: dict[tuple[str, str], list[int]] = {}
        # each group's step and ball as Python strings at once (not two numpy scalars a group)
        keys = zip(first_label.tolist(), first_ball.tolist(), strict=True)
        for g, key in enumerate(keys):
            groups.setdefault(key, []).append(g)
        repeated = {key: gs for key, gs in groups.items() if len(gs) > 1}
    keep = None
    if repeated and not keep_later:
        key, gs = min(repeated.items(), key=lambda item: item[1][1])
        first, second = gs[0], gs[1]
        if records.kind == "centres":
            message = (
                f"duplicate centre for step {key[0]} ball {key[1]} "
                f"(also on line {int(lines[starts[first]])}): --keep-later keeps the later one"
            )
            name = "label"
        else:
            message = (
                f"step {key[0]} ball {key[1]} probed twice: lines "
                f"{_line_span(lines, starts[first], stops[first], prefix=False)} and "
                f"{_line_span(lines, starts[second], stops[second], prefix=False)}, "
                "two groups of records that one sphere fit would merge "
                "(--keep-later keeps the later group)"
            )
            name = "ball"
        raise InputError(message, path=records.path, line=int(lines[starts[second]]), field=name)
    if repeated:
        keep = np.ones(n, dtype=bool)
        for key, gs in sorted(repeated.items(), key=lambda item: item[1][0]):
            dropped = ", ".join(_line_span(lines, starts[g], stops[g]) for g in gs[:-1])
            kept = _line_span(lines, starts[gs[-1]], stops[gs[-1]])
            what = "centre" if records.kind == "centres" else "group"
            many = "s" if len(gs) > 2 else ""
            times = "twice" if len(gs) == 2 else f"{len(gs)} times"
            warnings.warn(
                InputWarning(
                    f"{records.path}:{int(lines[starts[gs[0]]])}: step {key[0]} ball {key[1]} "
                    f"{'given' if records.kind == 'centres' else 'probed'} {times}: "
                    f"the earlier {what}{many} ({dropped}) dropped, {kept} kept"
                ),
                stacklevel=2,
            )
            for g in gs[:-1]:
                keep[starts[g] : stops[g]] = False
        records = _select(records, keep)
    number = records.extra.get("n")
    if records.kind == "points" and number is not None:
        _refuse_repeated_numbers(records, np.asarray(number))
    return records


def _distinct_pairs(first: npt.NDArray[np.str_], second: npt.NDArray[np.str_]) -> bool:
    """Whether no two of the pairs ``(first[i], second[i])`` are equal, by sorting them
    (a scanning campaign's 60,000 groups are not put in a dict one by one). numpy's texts
    compare as equal what Python's do (and a text with trailing NULs as equal to it
    without them): True here means no pair repeated as Python sees them either."""
    if first.size < 2:
        return True
    order = np.lexsort((second, first))
    a, b = first[order], second[order]
    return not bool(np.any((a[1:] == a[:-1]) & (b[1:] == b[:-1])))


def refuse_groups_in_two_files(records: Sequence[Records]) -> None:
    """Refuse a step and ball that two of ``records`` (files read one after another, each
    checked by :func:`check_groups`) both hold: one line naming the later file's first
    row of the group, as ``process`` refuses a ball measured again in another file.

    >>> import numpy as np
    >>> def rec(path, labels):
    ...     n = len(labels)
    ...     return Records(path, "points", np.array(labels), np.array(["B1"] * n),
    ...                    np.zeros((n, 3)), np.zeros(n), "seconds", np.arange(2, n + 2))
    >>> refuse_groups_in_two_files([rec("a.csv", ["O", "O"]), rec("b.csv", ["R0"])])
    >>> try:
    ...     refuse_groups_in_two_files([rec("a.csv", ["O", "R0"]), rec("b.csv", ["S1", "R0"])])
    ... except InputError as error:
    ...     print(error)
    b.csv:3: field 'label': step R0 ball B1 is measured again (already in a.csv)
    """
    seen: dict[tuple[str, str], str] = {}
    for rec in records:
        label, ball = rec.label, rec.ball
        starts = np.flatnonzero(
            np.concatenate(([True], (label[1:] != label[:-1]) | (ball[1:] != ball[:-1])))
        )
        groups = list(zip(label[starts].tolist(), ball[starts].tolist(), strict=True))
        for row, group in zip(starts.tolist(), groups, strict=True):
            if group in seen:
                raise InputError(
                    f"step {group[0]} ball {group[1]} is measured again (already in {seen[group]})",
                    path=rec.path,
                    line=int(rec.line[row]),
                    field="label",
                )
        seen.update(dict.fromkeys(groups, rec.path))


def _refuse_repeated_numbers(records: Records, number: npt.NDArray[np.generic]) -> None:
    """A point number seen twice within a group (groups are unique by now)."""
    label, ball = records.label, records.ball
    change = (label[1:] != label[:-1]) | (ball[1:] != ball[:-1])
    group = np.concatenate(([0], np.cumsum(change)))
    order = np.lexsort((number, group))
    same = (group[order][1:] == group[order][:-1]) & (number[order][1:] == number[order][:-1])
    if not np.any(same):
        return
    pairs = np.flatnonzero(same)
    rows = np.stack((order[pairs], order[pairs + 1]), axis=1)
    rows.sort(axis=1)
    first, second = rows[np.argmin(rows[:, 1])].tolist()
    lines = records.line
    name = f"{label[second]}_{ball[second]}_{number[second]}"
    raise InputError(
        f"point label {name} seen twice (also on line {int(lines[first])}): "
        "its points would count twice",
        path=records.path,
        line=int(lines[second]),
        field="label",
    )


def _select(records: Records, keep: npt.NDArray[np.bool_]) -> Records:
    """The rows ``keep`` of ``records`` (every per-row array, extra columns too)."""
    n = len(records)

    def pick(value: object) -> object:
        if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == n:
            return value[keep]
        return value

    return replace(
        records,
        label=records.label[keep],
        ball=records.ball[keep],
        xyz_mm=records.xyz_mm[keep],
        time_s=records.time_s[keep],
        line=records.line[keep],
        diameter_mm=None if records.diameter_mm is None else records.diameter_mm[keep],
        ijk=None if records.ijk is None else records.ijk[keep],
        extra={key: pick(value) for key, value in records.extra.items()},
    )


#: how far a centre's ``u_um`` may be from ``sqrt(tr C / 3)`` of its covariance columns
#: (relative; plus 0.001 um, the last digit a CSV may round away) before a warning
U_COVARIANCE_TOLERANCE = 0.05


def check_u_covariance(
    u_um: npt.NDArray[np.float64],
    cov_mm2: npt.NDArray[np.float64],
    lines: npt.NDArray[np.int64],
    path: str,
) -> None:
    """Warn (:class:`InputWarning`, once for the file) when a centre's ``u_um`` contradicts
    its covariance columns: ``fit-spheres`` writes ``u_um = sqrt(tr C / 3)``; a row further
    than :data:`U_COVARIANCE_TOLERANCE` from it was edited by hand or joined from two
    sources, and which of the two holds is for the user to say."""
    with np.errstate(invalid="ignore"):
        implied = np.sqrt(np.trace(cov_mm2, axis1=1, axis2=2) / 3) * 1e3
        off = np.abs(u_um - implied) > U_COVARIANCE_TOLERANCE * implied + 1e-3
    if not np.any(off):  # NaN rows compare False: a row without both is not checked
        return
    row = int(np.argmax(off))
    more = int(off.sum()) - 1
    warnings.warn(
        InputWarning(
            f"{path}:{int(lines[row])}: field 'u_um': {u_um[row]:g} um contradicts the "
            f"covariance columns u_x_um, u_y_um, u_z_um (sqrt(tr C / 3) = {implied[row]:.4g} "
            f"um, more than {U_COVARIANCE_TOLERANCE:.0%} apart)"
            + (f"; {more} more row{'s' if more > 1 else ''} like it" if more else "")
        ),
        stacklevel=2,
    )
