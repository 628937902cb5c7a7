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


#: a plus sign before a number's digits
_PLUS = r"^\+(?=[0-9.])"


def to_numbers(text: pd.Series) -> npt.NDArray[np.float64]:
    """The numbers of a column of texts (NaN where not a number), as pandas' C parser reads
    them (the fast readers'): a leading ``+`` is taken off first, for ``pd.to_numeric``
    reads ``+113.63956695822269`` one step off (113.63956695822267) where the parser and
    ``float`` read 113.63956695822269."""
    if text.dtype == object or pd.api.types.is_string_dtype(text.dtype):
        signed = text.str.startswith("+", na=False)
        if signed.any():
            text = text.str.replace(_PLUS, "", regex=True)
    return pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)


def column_numbers(
    frame: pd.DataFrame, column: str, path: str, allow_empty: bool = False
) -> npt.NDArray[np.float64]:
    text = frame[column]
    values = to_numbers(text)
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


def ns_seconds(ns: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
    """Seconds (float) of integer nanoseconds as pandas' ``total_seconds`` makes them
    (pandas 3): whole seconds plus the remainder's fraction, a value that rounds onto a
    whole second while it is not one moved off it by one step.

    >>> ns_seconds(np.array([1_500_000_000, -2_250_000_000]))
    array([ 1.5 , -2.25])
    """
    whole, rest = np.divmod(ns, 1_000_000_000)
    return _whole_and_rest(whole, rest, np.abs(ns) > 2**53)


def _whole_and_rest(
    whole: npt.NDArray[np.int64], rest: npt.NDArray[np.int64], big: npt.NDArray[np.bool_]
) -> npt.NDArray[np.float64]:
    """:func:`ns_seconds` of ``whole * 10**9 + rest`` nanoseconds (``0 <= rest < 10**9``;
    ``big``: where their magnitude is beyond ``2**53``)."""
    seconds = np.asarray(whole + rest / 1e9, dtype=np.float64)
    if big.any():
        fixable = big & (rest != 0) & (np.abs(whole) < 2**52)
        floor = whole.astype(np.float64)
        # moved only where rounding put them on a whole second (a few): not every one
        up = np.flatnonzero(fixable & (seconds == floor))
        seconds[up] = np.nextafter(seconds[up], np.inf)
        down = np.flatnonzero(fixable & (seconds == floor + 1.0))
        seconds[down] = np.nextafter(seconds[down], -np.inf)
    return seconds


#: the fields of an ISO time's layout (its digits written as 0): where each is
_ISO_FIELDS = re.compile(
    r"(?P<Y>0{4})-(?P<M>00)-(?P<D>00)[T ](?P<h>00):(?P<m>00)(?::(?P<s>00)(?:\.(?P<f>0{1,9}))?)?"
    r"(?:Z|(?P<sign>[+-])(?P<oh>00)(?::?(?P<om>00))?)?"
)


def _block_seconds(codes: npt.NDArray[np.uint8], template: str) -> npt.NDArray[np.float64] | None:
    """POSIX seconds of ISO times of one layout from their bytes (rows of ``codes``;
    ``template`` the layout with its digits as 0), field by field in integers, as
    :func:`_iso_seconds` gives them; None when a field is out of its range or the
    year beyond 1678-2261 (then pandas and ``datetime`` decide, and say what is wrong).

    A block whose rows share their date (a file's lines of one day) has it converted
    once, from its first row."""
    match = _ISO_FIELDS.fullmatch(template)
    if match is None:
        return None
    date_end = match.end("D")
    one_date = bool((codes[:, :date_end] == codes[0, :date_end]).all())
    date_rows = codes[:1] if one_date else codes

    def field(name: str, rows: npt.NDArray[np.uint8] = codes) -> npt.NDArray[np.int64]:
        start, end = match.span(name)
        if start < 0:  # absent
            return np.zeros(rows.shape[0], dtype=np.int64)
        # digit by digit, times ten (whole numbers: exact); the layout holds digits there
        value = rows[:, start].astype(np.int64) - 48
        for at in range(start + 1, end):
            value *= 10
            value += rows[:, at]
            value -= 48
        return value

    year, month, day = field("Y", date_rows), field("M", date_rows), field("D", date_rows)
    hour, minute, second = field("h"), field("m"), field("s")
    leap = (year % 4 == 0) & ((year % 100 != 0) | (year % 400 == 0))
    month_days = np.array([0, 31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])
    ok = (
        (year >= 1678)
        & (year <= 2261)
        & (month >= 1)
        & (month <= 12)
        & (day >= 1)
        & (day <= month_days[np.clip(month, 0, 12)] + (leap & (month == 2)))
    ).all() and ((hour <= 23) & (minute <= 59) & (second <= 59)).all()
    offset = np.zeros(1, dtype=np.int64)
    if match.group("sign") is not None:
        oh, om = field("oh"), field("om")
        ok = ok and bool(((oh <= 23) & (om <= 59)).all())
        sign = 1 if codes[0, match.start("sign")] == ord("+") else -1
        offset = sign * (oh * 3600 + om * 60)
    if not ok:
        return None
    # days from 1970-01-01 of the proleptic Gregorian calendar (H. Hinnant's days_from_civil)
    y = year - (month <= 2)
    era = y // 400
    yoe = y - era * 400
    doy = (153 * (month + np.where(month > 2, -3, 9)) + 2) // 5 + day - 1
    days = era * 146097 + yoe * 365 + yoe // 4 - yoe // 100 + doy - 719468
    whole = days * 86400 + hour * 3600 + minute * 60 + second - offset
    digits = match.end("f") - match.start("f") if match.group("f") is not None else 0
    fraction = field("f") * 10 ** (9 - digits) if digits else np.zeros_like(whole)
    # ns_seconds of the nanoseconds whole * 10**9 + fraction (0 <= fraction < 10**9),
    # which it would split into these two again
    big = np.abs(whole * 1_000_000_000 + fraction) > 2**53
    return _whole_and_rest(whole, fraction, big)


def _iso_layout(values: npt.NDArray[np.object_]) -> bool | None:
    """Whether every time has an offset (True) or none has (False), when all follow one
    layout that :data:`ISO_TIME` accepts (of one length, digits where the first has
    digits, the same other characters); None when they do not: then each is checked.

    >>> _iso_layout(np.array(["2024-03-05T07:30:00", "2024-03-05T07:31:02"], dtype=object))
    False
    >>> _iso_layout(np.array(["2024-03-05T07:30:00", "2024-03-05T07:31:02Z"], dtype=object))
    """
    block = _iso_block(values)
    return None if block is None else block[2]


def _iso_block(
    values: npt.NDArray[np.object_],
) -> tuple[npt.NDArray[np.uint8], str, bool] | None:
    """:func:`_iso_layout` with the times' bytes (a row each) and the layout (its digits
    as 0), or None.

    The times are compared as one block of ASCII bytes, a row each (a scanning probe's
    file has millions of them), one byte wider than the first so that a longer one shows.
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
    return _iso_codes(codes[:, :width])


def _iso_codes(
    codes: npt.NDArray[np.uint8],
) -> tuple[npt.NDArray[np.uint8], str, bool] | None:
    """:func:`_iso_block` of times given as their bytes, a row each of one width (no NUL):
    the codes, the layout (its digits as 0) and whether it has an offset, or None when the
    rows do not all follow one layout that :data:`ISO_TIME` accepts."""
    if codes.size == 0:
        return None
    digit = (codes - np.uint8(48)) < 10
    if not (digit == digit[0]).all():
        return None
    other = np.flatnonzero(~digit[0])
    if not (codes[:, other] == codes[0, other]).all():
        return None
    template = np.where(digit[0], np.uint8(48), codes[0]).tobytes().decode("ascii")
    match = ISO_TIME.fullmatch(template)
    if match is None:
        return None
    return codes, template, match.group("offset") is not None


#: bytes of a file :func:`iso_times_from_bytes` looks at in one go (its temporaries stay
#: small, in the CPU's caches: a scanning probe's file is hundreds of MB)
_TIME_SCAN = 1 << 21


def iso_times_from_bytes(
    raw: bytes, column: int, count: int
) -> tuple[npt.NDArray[np.float64], bool] | None:
    """POSIX seconds of the ``time`` column (index ``column`` of ``count``) of a CSV file
    whose every data line holds exactly ``count`` fields, taken from the file's bytes
    (no Python string per row), and whether they have a UTC offset; None unless every
    line after the header has ``count - 1`` commas and its time is of one ISO layout
    within :func:`_block_seconds`' ranges (then pandas' reading of the column decides).

    ``raw`` must be what the fast reader takes: ASCII, no quote, no NUL, no CR, LF-ended.
    Each block of lines is split at its commas and line feeds; every line's field
    ``column`` is cut out as one row of bytes (the same text as pandas' C parser gives
    it: nothing to unquote or strip)."""
    cut = times_and_names_from_bytes(raw, column, count)
    return None if cut is None else cut[:2]


#: the bytes of :data:`ASCII_BLANKS`
BLANK_BYTES = np.zeros(256, dtype=bool)
BLANK_BYTES[list(ASCII_BLANKS.encode("ascii"))] = True

#: the longest name :func:`times_and_names_from_bytes` cuts from the bytes (a longer one:
#: pandas reads the names)
NAME_WIDTH = 64
#: the bytes a name may hold (``core.plan.NAME_PATTERN``: ASCII letters, digits, ``-``)
NAME_BYTES = np.zeros(256, dtype=bool)
for _low, _high in ((b"A", b"Z"), (b"a", b"z"), (b"0", b"9"), (b"-", b"-")):
    NAME_BYTES[_low[0] : _high[0] + 1] = True


def times_and_names_from_bytes(
    raw: bytes, column: int, count: int, names: tuple[int, ...] = (), no_blanks: bool = False
) -> tuple[npt.NDArray[np.float64], bool, list[npt.NDArray[np.str_]]] | None:
    """:func:`iso_times_from_bytes`, and the fields ``names`` (indices below ``count``)
    of every line as str arrays, cut from the same split of the bytes: each a name of
    1 to :data:`NAME_WIDTH` of :data:`NAME_BYTES`, else None (the caller reads the file
    another way). The arrays are what ``numpy.asarray(list_of_names, dtype=str)`` makes
    (a unicode array as wide as the longest name).

    With ``no_blanks``, None also when a line past the header holds one of
    :data:`ASCII_BLANKS` (every blank is below ``,``: the split finds them among the
    bytes it looks at, so that the caller need not scan the file for them again)."""
    data = np.frombuffer(raw, dtype=np.uint8)
    start = raw.find(b"\n") + 1
    if start <= 0 or start >= data.size or not 0 <= column < count:
        return None
    if not all(0 <= c < column for c in names):
        return None  # names before the time (16 bytes at least: see _name_runs)
    seconds: list[npt.NDArray[np.float64]] = []
    named: list[list[tuple[npt.NDArray[np.uint64], npt.NDArray[np.intp]]]] = [[] for _ in names]
    layout: tuple[str, bool] | None = None
    while start < data.size:
        end = raw.rfind(b"\n", start, start + _TIME_SCAN) + 1
        if end <= start:  # a line longer than a block
            end = raw.find(b"\n", start) + 1
        part = data[start:end]
        # commas and line feeds: the bytes up to ',' found in one pass, then those two (a
        # clean file may hold '+', of an exponent or an offset) told apart on the few found
        found = np.flatnonzero(part <= 44)
        found_bytes = part[found]
        feeds = found_bytes == 10
        separators = feeds | (found_bytes == 44)
        if not separators.all():
            if no_blanks and BLANK_BYTES[found_bytes[~separators]].any():
                return None
            found, feeds = found[separators], feeds[separators]
        if found.size % count:
            return None
        cuts = found.reshape(-1, count)
        feeds = feeds.reshape(-1, count)
        if not feeds[:, -1].all() or feeds[:, :-1].any():
            return None  # a line with more or fewer fields
        # where each line starts (the block starts with a line)
        lines = np.concatenate(([0], cuts[:-1, -1] + 1)) if column == 0 or 0 in names else None
        first = lines if column == 0 else cuts[:, column - 1] + 1
        assert first is not None
        width = cuts[0, column] - first[0]
        if width <= 0 or (cuts[:, column] - first != width).any():
            return None
        # every line's time, a row of ``width`` bytes each: rows of the block's windows
        # (whole rows copied, not ``width`` indices per line gathered one by one)
        block = _iso_codes(np.lib.stride_tricks.sliding_window_view(part, width)[first])
        if block is None or (layout is not None and block[1:] != layout):
            return None  # not one layout (of one width) in every block
        layout = block[1:]
        block_seconds = _block_seconds(block[0], layout[0])
        if block_seconds is None:
            return None
        seconds.append(block_seconds)
        for k, c in enumerate(names):
            begin = lines if c == 0 else cuts[:, c - 1] + 1
            assert begin is not None
            runs = _name_runs(data, begin + start, cuts[:, c] + start)
            if runs is None:
                return None
            named[k].append(runs)
        start = end
    assert layout is not None
    spread = [_unicode(runs) for runs in named]
    if any(names is None for names in spread):
        return None
    return np.concatenate(seconds), layout[1], spread  # type: ignore[return-value]


#: the bytes of a name kept in a word of 8 (little-endian: the first byte the lowest), by
#: the name's length within the word: 0 to 8
_WORD_MASKS = np.array([(1 << (8 * n)) - 1 for n in range(9)], dtype="<u8")


def _name_runs(
    data: npt.NDArray[np.uint8], begin: npt.NDArray[np.intp], end: npt.NDArray[np.intp]
) -> tuple[npt.NDArray[np.uint64], npt.NDArray[np.intp]] | None:
    """The names ``data[begin:end]`` of a block's rows as runs of one name each (a file's
    rows come in runs: a step's ball is probed point after point): each run's name as
    words of 8 bytes (little-endian, NUL past its end) and its length; None for a name
    of no bytes or more than :data:`NAME_WIDTH`.

    Each name is read as words of 8 bytes from where it starts (``data`` seen as 8-byte
    words at every offset) and the bytes past its end masked off: a few word operations
    a row, not one per byte. ``data`` must hold 16 bytes after the start of any name
    (the names come before an ISO time)."""
    width = end - begin
    most = int(width.max())
    if int(width.min()) < 1 or most > NAME_WIDTH:
        return None
    at_every = np.ndarray(shape=(data.size - 7,), dtype="<u8", buffer=data, strides=(1,))
    count = -(-most // 8)
    rows = np.empty((begin.size, count), dtype="<u8")
    for k in range(count):
        # a word past the file's last 8 bytes is clipped: its bytes are past the name's end
        word = at_every[np.minimum(begin + 8 * k, at_every.size - 1)]
        rows[:, k] = word & _WORD_MASKS[np.clip(width - 8 * k, 0, 8)]
    change = (rows[1:] != rows[:-1]).any(axis=1) if count > 1 else rows[1:, 0] != rows[:-1, 0]
    starts = np.flatnonzero(np.concatenate(([True], change)))
    return rows[starts], np.diff(np.append(starts, begin.size))


def _unicode(
    runs: list[tuple[npt.NDArray[np.uint64], npt.NDArray[np.intp]]],
) -> npt.NDArray[np.str_] | None:
    """The rows of ``runs`` (:func:`_name_runs` of each block) as one str array, as wide
    as the longest name: each distinct name checked (:data:`NAME_BYTES`) and converted
    once, then spread to its rows; None when a name holds another byte."""
    count = max(r[0].shape[1] for r in runs)
    words = np.zeros((sum(r[0].shape[0] for r in runs), count), dtype="<u8")
    at = 0
    for names, _ in runs:
        words[at : at + names.shape[0], : names.shape[1]] = names
        at += names.shape[0]
    if count == 1:  # names of up to 8 bytes: one word each, sorted as numbers
        distinct, which = np.unique(words[:, 0], return_inverse=True)
        distinct = distinct[:, None]
    else:
        distinct, which = np.unique(words, axis=0, return_inverse=True)
    text = np.ascontiguousarray(distinct).view(np.uint8).reshape(distinct.shape[0], 8 * count)
    length = np.count_nonzero(text, axis=1)
    inside = np.arange(8 * count) < length[:, None]
    if not (NAME_BYTES[text] | ~inside).all() or (text[~inside] != 0).any():
        return None  # a byte outside names (a NUL inside a name ends it too early)
    names = text.view(f"S{8 * count}").ravel()
    most = int(length.max())
    lengths = np.concatenate([r[1] for r in runs])
    return np.repeat(names.astype(f"U{most}")[which.ravel()], lengths)


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
        since = (stamps - pd.Timestamp(0, tz="UTC")).to_numpy(dtype="timedelta64[ns]")
        seconds = ns_seconds(since.view(np.int64))
        seconds[np.isnat(since)] = np.nan
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
    block = _iso_block(values) if values.size else None
    if block is not None:
        # every time of one ISO layout (the common case): none is empty or a number; the
        # seconds from the bytes, field by field, unless a field is out of range
        codes, template, aware = block
        from_bytes = _block_seconds(codes, template)
        if from_bytes is not None:
            return from_bytes, "iso", aware
        seconds, aware = _iso_seconds(text, lines, path, aware)
        return seconds, "iso", aware
    empty = (text == "").to_numpy()
    if np.any(empty):
        row = int(np.argmax(empty))
        raise InputError("missing time", path=path, line=int(lines[row]), field="time")
    if all(":" in value for value in text.to_numpy()):
        is_number = np.zeros(len(text), dtype=bool)  # numbers have no ':': skip parsing them
    else:
        numeric = to_numbers(text)
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
