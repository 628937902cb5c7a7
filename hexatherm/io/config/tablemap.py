"""A ``measurements:`` entry of ``session.yaml`` given as a mapping (an extension): a
table of the CMM software's own columns through a column map, or a folder of Zeiss
Calypso table files. Checked strictly: an unknown key, a role without its column, a
column map that cannot tell step and ball, a pattern without its groups, each in one
line naming ``session.yaml``, the line and the field.

>>> from hexatherm.io.yamlfile import YamlDoc
>>> doc = YamlDoc.from_text(
...     "measurements:\\n"
...     "  - {file: x.csv, columns: {label: Step, ball: Ball, x: X, y: Y, z: Z,\\n"
...     "     time: [Date, Time]}, delimiter: ';', decimal: ',', unit: inch}\\n", "s.yaml")
>>> spec = read_format(doc, 0, ("B1", "B2", "B3"))
>>> spec.kind, spec.columns["time"], spec.delimiter, spec.decimal, spec.unit
('table', ('Date', 'Time'), ';', ',', 'inch')
>>> doc = YamlDoc.from_text(
...     "measurements:\\n  - {file: x.csv, columns: {label: Step, x: X, y: Y, z: Z, time: T}}\\n",
...     "s.yaml")
>>> try:
...     read_format(doc, 0, ("B1", "B2", "B3"))
... except InputError as error:
...     print(error)  # doctest: +ELLIPSIS
s.yaml:2: field 'measurements[0].columns': give both label and ball columns, or a feature ...
"""

from __future__ import annotations

import codecs
import re
from typing import Any

from hexatherm.errors import InputError
from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import LENGTH_UNITS, MeasurementFormat

__all__ = ["ENTRY_KEYS", "ROLES", "read_format", "read_utc_offset", "refuse"]

#: the keys of a mapped ``measurements:`` entry
ENTRY_KEYS = (
    "file",
    "format",
    "columns",
    "feature_pattern",
    "delimiter",
    "decimal",
    "unit",
    "time_format",
    "utc_offset",
    "encoding",
    "balls",
    "step_field",
)
#: what a column of a mapped table can be
ROLES = ("label", "ball", "feature", "x", "y", "z", "time", "diameter", "u")
#: keys that only one of the two kinds takes
_TABLE_ONLY = ("columns", "delimiter", "decimal")
_CALYPSO_ONLY = ("step_field",)
#: how a delimiter may be written in YAML
_DELIMITERS = {",": ",", ";": ";", "\t": "\t", "tab": "\t", "|": "|", " ": " "}

#: ``utc_offset:``: ``+HH:MM``, ``-HH:MM`` or ``Z``
_UTC_OFFSET = re.compile(r"(?:Z|([+-])(\d\d):(\d\d))")


def read_utc_offset(doc: YamlDoc, *keys: Any) -> float | None:
    """The optional offset at ``keys`` (``+HH:MM``, ``-HH:MM`` or ``Z``, quoted) in
    seconds east of UTC; None when absent."""
    value = doc.get(*keys, default=None)
    if value is None:
        return None
    match = _UTC_OFFSET.fullmatch(value) if isinstance(value, str) else None
    if match is None:
        raise doc.error(f"expected an offset as +HH:MM, -HH:MM or Z (quoted), got {value!r}", *keys)
    if match.group(1) is None:
        return 0.0
    hours, minutes = int(match.group(2)), int(match.group(3))
    if hours > 14 or minutes > 59:
        raise doc.error(f"no place on Earth is {value} from UTC", *keys)
    return (1.0 if match.group(1) == "+" else -1.0) * (hours * 3600 + minutes * 60)


def read_format(doc: YamlDoc, index: int, ball_names: tuple[str, ...]) -> MeasurementFormat:
    """The :class:`~hexatherm.session.MeasurementFormat` of entry ``index`` of
    ``measurements:`` (a mapping), checked against the balls file's ``ball_names``."""
    at = ("measurements", index)
    doc.check_keys(list(ENTRY_KEYS), *at)
    doc.string(*at, "file")
    given = doc.get(*at)
    kind = doc.string(*at, "format", default="table" if "columns" in given else "")
    if kind not in ("table", "calypso"):
        raise doc.error(
            "give columns: {...} (a table through a column map) or format: calypso "
            f"(a folder of Calypso table files), got format {kind!r}",
            *at,
            "format" if "format" in given else "file",
        )
    wrong = _CALYPSO_ONLY if kind == "table" else _TABLE_ONLY
    for key in wrong:
        if key in given:
            raise doc.error(f"not a key of a {kind} entry", *at, key)
    unit = doc.string(*at, "unit", default="mm", choices=list(LENGTH_UNITS))
    encoding = doc.string(*at, "encoding", default="utf-8")
    try:
        codecs.lookup(encoding)
    except LookupError:
        raise doc.error(f"unknown text encoding {encoding!r}", *at, "encoding") from None
    balls = _balls_map(doc, at, ball_names)
    pattern = _pattern(doc, at, ("step", "ball") if kind == "table" else ("ball",))
    where = f"{doc.path}:{doc.line(*at)}"
    offset = read_utc_offset(doc, *at, "utc_offset")
    time_format = doc.string(*at, "time_format", default="iso" if kind == "table" else "calypso")
    if time_format not in ("iso", "seconds", "calypso") and "%" not in time_format:
        raise doc.error(
            "expected iso, seconds or a strptime format such as '%d.%m.%Y %H:%M:%S', got "
            + repr(time_format),
            *at,
            "time_format",
        )
    if kind == "calypso":
        step_field = doc.get(*at, "step_field", default=None)
        if step_field is not None:
            step_field = doc.string(*at, "step_field")
        return MeasurementFormat(
            "calypso",
            feature_pattern=pattern,
            unit=unit,
            time_format=time_format,
            utc_offset_s=offset,
            encoding=encoding,
            balls=balls,
            step_field=step_field,
            where=where,
        )
    columns = _columns(doc, at, pattern)
    delimiter = doc.get(*at, "delimiter", default=",")
    if not isinstance(delimiter, str) or delimiter not in _DELIMITERS:
        raise doc.error(
            "expected one of ',', ';', '|', ' ', tab (or \"\\t\"), got " + repr(delimiter),
            *at,
            "delimiter",
        )
    delimiter = _DELIMITERS[delimiter]
    decimal = doc.string(*at, "decimal", default=".", choices=[".", ","])
    if decimal == delimiter:
        raise doc.error("the decimal mark cannot be the delimiter", *at, "decimal")
    if time_format == "calypso":
        raise doc.error("time_format: calypso is for format: calypso", *at, "time_format")
    return MeasurementFormat(
        "table",
        columns=columns,
        feature_pattern=pattern,
        delimiter=delimiter,
        decimal=decimal,
        unit=unit,
        time_format=time_format,
        utc_offset_s=offset,
        encoding=encoding,
        balls=balls,
        where=where,
        column_lines={role: doc.line(*at, "columns", role) or 0 for role in columns},
        key=f"measurements[{index}]",
    )


def _columns(doc: YamlDoc, at: tuple[Any, ...], pattern: str | None) -> dict[str, tuple[str, ...]]:
    """``columns:``: role -> column names; the roles that must be there, there."""
    doc.check_keys(list(ROLES), *at, "columns")
    mapping = doc.get(*at, "columns")
    columns: dict[str, tuple[str, ...]] = {}
    for role, value in mapping.items():
        names = value if isinstance(value, list) and role == "time" else [value]
        if not 1 <= len(names) <= 2 or not all(isinstance(n, str) and n.strip() for n in names):
            what = (
                "a column name, or [date column, time column]"
                if role == "time"
                else ("a column name")
            )
            raise doc.error(f"expected {what}, got {value!r}", *at, "columns", role)
        columns[role] = tuple(n.strip() for n in names)
    for role in ("x", "y", "z", "time"):
        if role not in columns:
            raise doc.error(f"missing the {role} column (required)", *at, "columns")
    naming = {"label", "ball"} & set(columns)
    if "feature" in columns:
        if naming:
            raise doc.error(
                "give label and ball columns or a feature column, not both", *at, "columns"
            )
        if pattern is None:
            raise doc.error(
                "a feature column needs feature_pattern: a regular expression with the "
                "groups (?P<step>...) and (?P<ball>...)",
                *at,
                "columns",
                "feature",
            )
    elif naming != {"label", "ball"}:
        raise doc.error(
            "give both label and ball columns, or a feature column with feature_pattern",
            *at,
            "columns",
        )
    elif pattern is not None:
        raise doc.error("feature_pattern splits a feature column: give one", *at, "feature_pattern")
    return columns


def _pattern(doc: YamlDoc, at: tuple[Any, ...], groups: tuple[str, ...]) -> str | None:
    """``feature_pattern:``, compiled once to check it and its named groups."""
    text = doc.get(*at, "feature_pattern", default=None)
    if text is None:
        return None
    text = doc.string(*at, "feature_pattern")
    try:
        compiled = re.compile(text)
    except re.error as exc:
        raise doc.error(f"not a regular expression: {exc}", *at, "feature_pattern") from None
    missing = [g for g in groups if g not in compiled.groupindex]
    if missing:
        raise doc.error(
            "the pattern needs the named group(s) " + ", ".join(f"(?P<{g}>...)" for g in missing),
            *at,
            "feature_pattern",
        )
    return text


def _balls_map(doc: YamlDoc, at: tuple[Any, ...], ball_names: tuple[str, ...]) -> dict[str, str]:
    """``balls:``: the file's ball (or feature) name -> a ball of the balls file."""
    if doc.get(*at, "balls", default=None) is None:
        return {}
    mapping = doc.get(*at, "balls")
    if not isinstance(mapping, dict):
        raise doc.error("expected a mapping: name in the file -> ball", *at, "balls")
    out: dict[str, str] = {}
    for name, ball in mapping.items():
        if ball not in ball_names:
            raise doc.error(
                f"{ball!r} is not a ball of the balls file ({', '.join(ball_names)})",
                *at,
                "balls",
                name,
            )
        if ball in out.values():
            raise doc.error(f"two names map to ball {ball}", *at, "balls", name)
        out[str(name)] = str(ball)
    return out


def refuse(
    message: str, spec: MeasurementFormat, field: str | None = None, line: int | None = None
) -> InputError:
    """An InputError at the session file's entry ``spec`` (``where`` is ``path:line``),
    or at ``line`` of it."""
    path, _, at = spec.where.rpartition(":")
    number = line or (int(at) if at.isdigit() else None)
    where = spec.key if field is None else f"{spec.key}.{field}"
    return InputError(message, path=path or spec.where, line=number, field=where)
