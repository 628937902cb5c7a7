"""A table of the CMM software's own columns, read through the column map of its
``session.yaml`` entry (an extension, :mod:`hexatherm.io.config.tablemap`): which
column is the step label and the ball (or one feature-name column split by a
pattern), x, y, z, the time (one column, or a date and a time column), the diameter
and the centre's uncertainty ``u``; the delimiter, the decimal mark, the length unit
(mm, um, inch), the time format and the UTC offset of naive times.

What is refused, in one line naming the file, the line and the column: text that is
not in the entry's encoding (a byte order mark, UTF-8 or UTF-16, wins), a NUL byte, a
file without a line break at its end (cut short: ``allow_truncated`` drops that line),
a header without a column the map names (then the line names ``session.yaml``), a
repeated column name, a row shorter than the columns it needs, a number in the other
decimal mark or not finite, a coordinate or diameter that is not a number, an empty
or unreadable time, a feature name the pattern does not split, a step or ball name
that is not ``[A-Za-z0-9-]+``, a diameter <= 0 and a ``u`` outside (0, 1000] um. The
primitives (decoding, numbers with a decimal comma, times by a format) serve the
Calypso reader (:mod:`hexatherm.io.calypso`) too.
"""

from __future__ import annotations

import csv
import os
import re
import warnings
from collections.abc import Sequence
from datetime import UTC, datetime

import numpy as np

from hexatherm.core.plan import NAME_PATTERN
from hexatherm.errors import InputError, InputWarning
from hexatherm.io.config.tablemap import refuse
from hexatherm.io.csvfile import U_UM_MAX
from hexatherm.io.files import read_bytes
from hexatherm.io.records import Records, check_groups
from hexatherm.session import LENGTH_UNITS, MeasurementFormat

__all__ = ["Row", "decode", "number", "read_table", "rows_of", "seconds_of"]

#: a row of a table: its 1-based line and its cells
Row = tuple[int, list[str]]

_NUMBER = {
    ".": re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"),
    ",": re.compile(r"[+-]?(?:[0-9]+,?[0-9]*|,[0-9]+)(?:[eE][+-]?[0-9]+)?"),
}


def decode(raw: bytes, path: str, encoding: str) -> str:
    """The text of a file: a byte order mark (UTF-8, UTF-16) chooses the encoding, else
    ``encoding``; InputError naming the line of the first byte that does not decode, or
    of a NUL byte. Line ends become LF.

    >>> decode("Maß;1\\r\\n".encode("utf-16"), "t.csv", "utf-8")
    'Maß;1\\n'
    >>> decode(b"Ma\\xdf;1\\n", "t.csv", "latin-1")
    'Maß;1\\n'
    >>> try:
    ...     decode(b"a\\nMa\\xdf;1\\n", "t.csv", "utf-8")
    ... except InputError as error:
    ...     print(error)  # doctest: +ELLIPSIS
    t.csv:2: not utf-8 text (invalid continuation byte): give the entry's encoding ...
    """
    for bom, name in (
        (b"\xef\xbb\xbf", "utf-8-sig"),
        (b"\xff\xfe", "utf-16"),
        (b"\xfe\xff", "utf-16"),
    ):
        if raw.startswith(bom):
            encoding = name
            break
    try:
        text = raw.decode(encoding)
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(
            f"not {encoding} text ({exc.reason}): give the entry's encoding (encoding: latin-1?)",
            path=path,
            line=line,
        ) from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise InputError(
            "NUL byte: not a text file (UTF-16 without a byte order mark?)", path=path, line=line
        )
    return text.replace("\r\n", "\n").replace("\r", "\n")


def rows_of(text: str, path: str, delimiter: str, allow_truncated: bool) -> tuple[Row, list[Row]]:
    """The header and the rows (blank lines skipped) of a delimited text; a last line
    without a line break is refused (cut short) or, with ``allow_truncated``, dropped
    with an :class:`InputWarning`."""
    lines = text.split("\n")
    if lines and lines[-1].strip():
        number = len(lines)
        if not allow_truncated:
            raise InputError(
                "the file ends without a line break: cut short? (a complete file ends with "
                "a line break; --allow-truncated drops this line)",
                path=path,
                line=number,
            )
        warnings.warn(
            InputWarning(f"{path}:{number}: the file ends without a line break: line dropped"),
            stacklevel=3,
        )
    lines = lines[:-1]
    try:
        parsed = list(csv.reader(lines, delimiter=delimiter, strict=True))
    except csv.Error as exc:
        raise InputError(f"malformed table: {exc}", path=path) from None
    numbered = [(i + 1, [c.strip() for c in cells]) for i, cells in enumerate(parsed)]
    numbered = [(n, cells) for n, cells in numbered if any(cells)]
    if not numbered:
        raise InputError("empty file: expected a header line", path=path, line=1)
    return numbered[0], numbered[1:]


def number(text: str, decimal: str, path: str, line: int, field: str) -> float:
    """A finite number written with the ``decimal`` mark; InputError otherwise (a number
    in the other mark is named as such).

    >>> number("-1,25e1", ",", "t.csv", 2, "X")
    -12.5
    >>> try:
    ...     number("1.25", ",", "t.csv", 2, "X")
    ... except InputError as error:
    ...     print(error)
    t.csv:2: field 'X': '1.25' is not a number with the decimal mark ',' (decimal: '.'?)
    """
    if _NUMBER[decimal].fullmatch(text):
        value = float(text.replace(",", ".")) if decimal == "," else float(text)
        if np.isfinite(value):
            return value
        raise InputError(f"not a finite number: {text!r}", path=path, line=line, field=field)
    other = "," if decimal == "." else "."
    hint = f" (decimal: {other!r}?)" if _NUMBER[other].fullmatch(text) else ""
    raise InputError(
        f"{text!r} is not a number with the decimal mark {decimal!r}{hint}",
        path=path,
        line=line,
        field=field,
    )


def seconds_of(
    text: str, time_format: str, path: str, line: int, field: str
) -> tuple[float, bool | None]:
    """POSIX seconds of a time and whether it carries a UTC offset (None for a number
    of seconds). ``time_format``: ``iso``, ``seconds`` or a strptime format; naive
    times are taken as UTC here (the caller applies the entry's offset).

    >>> seconds_of("27.11.2026 14:03:05", "%d.%m.%Y %H:%M:%S", "t.csv", 3, "Zeit")
    (1795788185.0, False)
    >>> seconds_of("2026-11-27T14:03:05+01:00", "iso", "t.csv", 3, "Zeit")
    (1795784585.0, True)
    """
    if not text:
        raise InputError("missing time", path=path, line=line, field=field)
    if time_format == "seconds":
        return number(text, ".", path, line, field), None
    try:
        if time_format == "iso":
            stamp = datetime.fromisoformat(text)
        else:
            stamp = datetime.strptime(text, time_format)
    except ValueError as exc:
        wanted = "an ISO 8601 time" if time_format == "iso" else f"a time as {time_format!r}"
        raise InputError(
            f"{text!r} is not {wanted} ({exc})", path=path, line=line, field=field
        ) from None
    aware = stamp.tzinfo is not None
    if not aware:
        stamp = stamp.replace(tzinfo=UTC)
    return (stamp - datetime(1970, 1, 1, tzinfo=UTC)).total_seconds(), aware


def _column_index(header: Row, spec: MeasurementFormat, path: str) -> dict[str, list[int]]:
    """Role -> index of its column(s) in the header; the header's names unique, every
    column the map names there (else the line names the session file's entry)."""
    names = header[1]
    seen: set[str] = set()
    for name in names:
        if name and name in seen:
            raise InputError(
                f"column {name!r} appears twice in the header",
                path=path,
                line=header[0],
                field=name,
            )
        seen.add(name)
    index: dict[str, list[int]] = {}
    for role, columns in spec.columns.items():
        for column in columns:
            if column not in names:
                shown = ", ".join(n for n in names if n) or "none"
                raise refuse(
                    f"{os.path.basename(path)} has no column {column!r} (its columns: {shown})",
                    spec,
                    field=f"columns.{role}",
                    line=spec.column_lines.get(role),
                )
        index[role] = [names.index(c) for c in columns]
    return index


def _name(value: str, path: str, line: int, field: str) -> str:
    if not NAME_PATTERN.fullmatch(value):
        raise InputError(
            f"{value!r} must match [A-Za-z0-9-]+ (a step or ball name)",
            path=path,
            line=line,
            field=field,
        )
    return value


def read_table(
    path: str | os.PathLike[str],
    spec: MeasurementFormat,
    *,
    allow_truncated: bool = False,
    keep_later: bool = False,
) -> Records:
    """The ball centres of a table read through ``spec``'s column map, in mm.

    Raises
    ------
    InputError
        Naming the file, the line and the column (see the module's list).
    """
    path = os.fspath(path)
    text = decode(read_bytes(path), path, spec.encoding)
    header, rows = rows_of(text, path, spec.delimiter, allow_truncated)
    index = _column_index(header, spec, path)
    names = header[1]
    if not rows:
        raise InputError("no data rows", path=path, line=header[0] + 1)
    scale = LENGTH_UNITS[spec.unit]
    pattern = None if spec.feature_pattern is None else re.compile(spec.feature_pattern)
    needed = max(i for columns in index.values() for i in columns)
    n = len(rows)
    label, ball = np.empty(n, dtype=object), np.empty(n, dtype=object)
    xyz, time = np.empty((n, 3)), np.empty(n)
    diameter, u_um = np.full(n, np.nan), np.full(n, np.nan)
    aware_seen: set[bool | None] = set()
    for r, (line, cells) in enumerate(rows):
        if len(cells) <= needed:
            missing = names[len(cells)] if len(cells) < len(names) else None
            raise InputError(
                f"{len(cells)} fields, the map needs {needed + 1} (cut short?)",
                path=path,
                line=line,
                field=missing,
            )

        def cell(role: str, cells: list[str] = cells) -> str:
            return " ".join(cells[i] for i in index[role])

        if pattern is not None:
            match = pattern.fullmatch(cell("feature"))
            if match is None:
                raise InputError(
                    f"{cell('feature')!r} does not match feature_pattern {pattern.pattern!r}",
                    path=path,
                    line=line,
                    field=names[index["feature"][0]],
                )
            step, name = match.group("step"), match.group("ball")
            step_field = ball_field = names[index["feature"][0]]
        else:
            step, name = cell("label"), cell("ball")
            step_field, ball_field = names[index["label"][0]], names[index["ball"][0]]
        label[r] = _name(step, path, line, step_field)
        ball[r] = _name(spec.balls.get(name, name), path, line, ball_field)
        for j, axis in enumerate("xyz"):
            xyz[r, j] = number(cell(axis), spec.decimal, path, line, names[index[axis][0]]) * scale
        time[r], aware = seconds_of(
            cell("time"), spec.time_format, path, line, names[index["time"][0]]
        )
        aware_seen.add(aware)
        if len(aware_seen) > 1:
            raise InputError(
                "times with and without a UTC offset (or numbers) mixed in one file",
                path=path,
                line=line,
                field=names[index["time"][0]],
            )
        for role, target, factor in (("diameter", diameter, scale), ("u", u_um, scale * 1e3)):
            if role in index and cell(role):
                target[r] = number(cell(role), spec.decimal, path, line, names[index[role][0]])
                target[r] *= factor
        _check_extras(diameter[r], u_um[r], path, line, names, index)
    aware = aware_seen.pop()
    if spec.utc_offset_s is not None and aware is False:
        time -= spec.utc_offset_s
        aware = True
    extra: dict[str, object] = {}
    if "u" in index:
        extra["u_um"] = u_um
    records = Records(
        path=path,
        kind="centres",
        label=label.astype(str),
        ball=ball.astype(str),
        xyz_mm=xyz,
        time_s=time,
        time_kind="seconds" if aware is None else "iso",
        line=np.array([line for line, _ in rows], dtype=np.int64),
        diameter_mm=diameter if "diameter" in index else None,
        extra=extra,
        time_aware=aware,
    )
    return check_groups(records, keep_later=keep_later)


def _check_extras(
    diameter: float,
    u_um: float,
    path: str,
    line: int,
    names: Sequence[str],
    index: dict[str, list[int]],
) -> None:
    if diameter <= 0:
        raise InputError(
            f"a diameter must be > 0 mm, got {diameter:g} mm",
            path=path,
            line=line,
            field=names[index["diameter"][0]],
        )
    if not (np.isnan(u_um) or 0 < u_um <= U_UM_MAX):
        raise InputError(
            f"a standard uncertainty must be > 0 and <= {U_UM_MAX:g} um, got {u_um:g} um",
            path=path,
            line=line,
            field=names[index["u"][0]],
        )
