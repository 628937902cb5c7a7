"""Reader of DMIS output files (``.dmo``, ``.dms``, ``.dmi``) as CMM software writes them.

A DMIS output file is a list of statements, one or more lines each. hexatherm
reads the *actual* features, ``FA(label)=FEAT/type,...``, and reads past
everything else (nominal features ``F(...)``, tolerances ``T(...)``/``TA(...)``,
``OUTPUT``, ...), except the statements that change how the actuals are read:
``UNITS/`` (length and angle units) and ``DATE=`` / ``TIME=`` (the time of the
features that follow).

Lines are joined into statements the way CMM software writes them:

* ``$`` at the end of a line joins the next line as raw text, even in the middle
  of a number or a label (the DMIS standard's continuation);
* ``$$`` starts a comment that runs to the end of the line; a line whose text
  before the comment ends with a comma (``...,$$``) continues on the next line.
  Such a continuation ends early, dropping the trailing comma, when the next
  line visibly starts a new statement (``WORD/``, ``WORD(``, ``WORD=``,
  ``ENDFIL``): CMM software writes that (``impeller-part-1.dmo``, line 2110);
* a line starting with a comma (after blanks) continues the previous statement;
* CRLF or LF line ends, UTF-8 (a BOM is skipped), leading blanks;
* keywords are matched without regard to case.

Each actual feature becomes a :class:`Feature`; :func:`read_dmis` turns the
hexatherm-named spheres and points into :class:`~hexatherm.io.records.Records`.
Every problem in what hexatherm reads raises :class:`~hexatherm.errors.InputError`
naming the file, the line where the statement starts and the field.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import UTC, date, datetime, time
from pathlib import Path
from typing import NoReturn

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.records import RecordKind, Records

__all__ = [
    "DMIS_SUFFIXES",
    "Feature",
    "features_from_text",
    "looks_like_dmis",
    "read_dmis",
    "read_dmis_features",
    "records_from_features",
]

#: File name suffixes that mark a DMIS file (compared without regard to case).
DMIS_SUFFIXES = (".dmo", ".dms", ".dmi")

Value = float | str | None


@dataclass(frozen=True)
class Feature:
    """One actual feature, ``FA(label)=FEAT/type,...``, of a DMIS output file.

    Attributes
    ----------
    label : str
        The feature's label, e.g. ``"Esfera_10"`` or ``"S1_B2"``.
    type : str
        The feature type in upper case: ``"SPHERE"``, ``"POINT"``, ``"CIRCLE"``,
        ``"CYLINDER"``, ``"CONE"``, ...
    values : tuple
        The fields after the type as written, in the file's units: floats where
        numeric, stripped strings otherwise, None for empty fields.
    xyz_mm : tuple of float or None
        The feature's position, mm (``POL`` coordinates converted to cartesian);
        None for types that have no position (``PATERN``, ``GSURF``, ...).
    ijk : tuple of float or None
        The feature's direction (probing direction of a point, axis of a
        circle, cylinder, cone, normal of a plane, ...) as written, or None.
    size_mm : float or None
        Diameter, mm, of a ``SPHERE``, ``CIRCLE``, ``CYLNDR`` or ``CYLINDER``;
        None for other types.
    time : datetime or None
        Naive date and time from the last ``DATE=`` and ``TIME=`` statements
        before the feature; None unless both came before it.
    line : int
        1-based line of the file where the statement starts.
    """

    label: str
    type: str
    values: tuple[Value, ...]
    xyz_mm: tuple[float, float, float] | None
    ijk: tuple[float, float, float] | None
    size_mm: float | None
    time: datetime | None
    line: int


# ---------------------------------------------------------------------------
# Feature types

# Types that are located by CART or POL coordinates: x, y, z follow the keyword.
_AXIS_TYPES = frozenset(
    {
        "ARC",
        "CIRCLE",
        "CONE",
        "CPARLN",
        "CYLINDER",  # non-standard spelling of CYLNDR, written by real software
        "CYLNDR",
        "EDGEPT",
        "ELLIPS",
        "ELONGCYL",
        "GCURVE",
        "PLANE",
        "RCTNGL",
        "TORUS",
    }
)
_POSITIONAL_TYPES = _AXIS_TYPES | {"POINT", "SPHERE", "LINE"}
# Index, among the fields after CART/POL, of the diameter.
_DIAMETER_AT = {"SPHERE": 3, "CIRCLE": 6, "CYLNDR": 6, "CYLINDER": 6}
# The words allowed between the type and CART/POL, for the types hexatherm uses.
_ALLOWED_MODIFIERS = {"POINT": (0, frozenset()), "SPHERE": (1, frozenset({"INNER", "OUTER"}))}
# The fields after CART/POL of the types hexatherm measures with, as the contract has them.
_LAYOUTS = {"POINT": ("x, y, z[, i, j, k]", 6), "SPHERE": ("x, y, z, diameter", 4)}

_SYSTEMS = ("CART", "POL")
_LENGTH_UNITS = {"MM": 1.0, "CM": 10.0, "M": 1000.0, "INCH": 25.4, "FEET": 304.8}
_ANGLE_UNITS = frozenset({"ANGDEC", "ANGDMS", "ANGRAD"})
_TEMPERATURE_UNITS = frozenset({"TEMPC", "TEMPF"})

# ---------------------------------------------------------------------------
# Regular expressions

_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_TYPE = re.compile(r"[A-Z][A-Z0-9_]*")
_FA_START = re.compile(r"FA\s*\(", re.IGNORECASE)
_FA_LABEL = re.compile(r"FA\s*\(([^()]*)\)\s*", re.IGNORECASE | re.DOTALL)
_FA_FEAT = re.compile(r"=\s*FEAT\s*/(.*)", re.IGNORECASE | re.DOTALL)
_UNITS = re.compile(r"UNITS\s*/(.*)", re.IGNORECASE | re.DOTALL)
_DATE = re.compile(r"DATE\s*=(.*)", re.IGNORECASE | re.DOTALL)
_TIME = re.compile(r"TIME\s*=(.*)", re.IGNORECASE | re.DOTALL)
_DATE_VALUE = re.compile(r"([0-9]{4})\s*([/.-])\s*([0-9]{1,2})\s*\2\s*([0-9]{1,2})")
_TIME_VALUE = re.compile(r"([0-9]{1,2}):([0-9]{2})(?::([0-9]{2})(?:[.,]([0-9]+))?)?")
# A line that visibly starts a new statement: WORD/..., WORD(...)..., WORD=..., ENDxxx.
_STATEMENT_START = re.compile(r"\s*(?:[A-Za-z][A-Za-z0-9]*\s*[(/=]|END[A-Za-z]*\s*$)")
_HEXATHERM_NAME = "[A-Za-z0-9-]+"
_CENTRE_LABEL = re.compile(rf"({_HEXATHERM_NAME})_({_HEXATHERM_NAME})")
_POINT_LABEL = re.compile(rf"({_HEXATHERM_NAME})_({_HEXATHERM_NAME})_({_HEXATHERM_NAME})")

# DMIS major words (statements ``WORD/...``) and label types (``XX(label)=...``)
# that may open a DMIS file; used to sniff content.
_MAJOR_WORDS = frozenset(
    """
    ACLRAT ALGDEF ASSIGN BADTST BOUND CALIB CALL CASE CLMPID CLMPSN CLOSE CMPNTGRP
    CNFRM CONST CRGDEF CRMODE CROSCL CRSLCT CUTCOM CZONE CZSLCT DATDEF DATSET DECL
    DECPL DELETE DEVICE DFTCAS DISPLY DMEHW DMEID DMESW DMESWI DMESWV DMISMD DMISMN
    DO ELSE EQUATE ERROR EVAL EXTENS EXTFIL FEDRAT FILDEF FILNAM FINPOS FIXTID FIXTSN
    FLY FROM GEOALG GEOM GOHOME GOTARG GOTO GROUP IF INCLUD ITERAT JUMPTO KEYCHAR
    LITDEF LOCATE LOTID MACRO MATDEF MEAS MFGDEV MODE OBTAIN OPEN OPERID OUTPUT
    PAMEAS PARTID PARTRV PARTSN PLANID POP PRCOMP PREVOP PROCID PROMPT PSTHRU PTBUFF
    PTMEAS PUSH QISDEF RAPID READ RECALL REFMNT REPORT RESUME RMEAS ROTAB ROTATE
    ROTDEF ROTSET SAVE SCNMOD SCNSET SELECT SENSOR SIMREQT SNSDEF SNSET SNSGRP SNSLCT
    SNSMNT TECOMP TEXT THLDEF TOL TOOLDF TRANS UNITS VALUE VFORM WINDEF WKPLAN WRIST
    WRITE XTERN XTRACT
    """.split()
)
_LABEL_TYPES = frozenset(
    """
    CR CS CZ D DA DI DS DV F FA FI FS G GSA K KC L LI MA MD OP P PC PL PN PR PS PV Q
    R RM RT S SA SE SG SS SW SX T TA TH TL U V VA VF VL VR VW
    """.split()
)
_FIRST_WORD = re.compile(r"([A-Za-z][A-Za-z0-9]*)\s*([/(=]|$)")


# ---------------------------------------------------------------------------
# Public API


def looks_like_dmis(text_head: str) -> bool:
    """Tell whether text starts like a DMIS file: its first statement is a DMIS one.

    Blank lines, a byte order mark and ``$$`` comment lines are skipped; the
    first remaining line must start with a DMIS major word and ``/``
    (``DMISMN/``, ``UNITS/``, ``FILNAM/``, ...), a DMIS label (``F(``, ``FA(``,
    ``T(``, ...), ``DATE=``/``TIME=``, or be ``ENDFIL``.

    Parameters
    ----------
    text_head : str
        The first characters of a file (a few hundred are enough).

    Returns
    -------
    bool

    Examples
    --------
    >>> looks_like_dmis("DMISMN/'part 9',04.0\\r\\nUNITS/MM,ANGDEC\\r\\n")
    True
    >>> looks_like_dmis("\\n$$ written by the CMM\\nFA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25")
    True
    >>> looks_like_dmis("label,ball,x,y,z,time\\nS1,B1,1,2,3,0\\n")
    False
    """
    for raw in text_head.lstrip("\ufeff").splitlines():
        line = raw.strip()
        if not line or line.startswith("$$"):
            continue
        match = _FIRST_WORD.match(line)
        if match is None:
            return False
        word, sep = match.group(1).upper(), match.group(2)
        if sep == "/":
            return word in _MAJOR_WORDS or word == "FEAT"
        if sep == "(":
            return word in _LABEL_TYPES
        if sep == "=":
            return word in ("DATE", "TIME")
        return word.startswith("END") and word in ("ENDFIL", "ENDMES", "ENDGO")
    return False


def read_dmis_features(path: str | os.PathLike[str]) -> list[Feature]:
    """Read every actual feature ``FA(...)`` of a DMIS output file, in file order.

    Parameters
    ----------
    path : str or path-like
        The DMIS file (UTF-8, CRLF or LF line ends).

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        If the file cannot be read, is not UTF-8, ends inside a continued
        statement, has a bad ``UNITS``, ``DATE`` or ``TIME`` statement, or an
        actual feature is malformed (non-numeric coordinate, missing field, ...).

    See Also
    --------
    features_from_text : the same from text already in memory.
    """
    return features_from_text(_read_text(path), path)


def read_dmis(path: str | os.PathLike[str]) -> list[Records]:
    """Read the hexatherm measurements of a DMIS output file.

    Sphere actuals ``FA(<label>_<ball>)=FEAT/SPHERE,...`` give ball centres,
    point actuals ``FA(<label>_<ball>_<n>)=FEAT/POINT,...`` give surface points;
    other actual features are read past.

    Parameters
    ----------
    path : str or path-like
        The DMIS file.

    Returns
    -------
    list of Records
        At most one ``kind="centres"`` (with ``diameter_mm``) and one
        ``kind="points"`` (with ``ijk``, NaN where a point has none), in this
        order, each omitted when the file has none. Times are ``"iso"``: POSIX
        seconds of the ``DATE=``/``TIME=`` before each feature, taken as UTC.

    Raises
    ------
    InputError
        As :func:`read_dmis_features`, and when a sphere or point label does not
        follow hexatherm's naming or a sphere or point has no ``DATE=`` and
        ``TIME=`` before it.
    """
    return records_from_features(read_dmis_features(path), path)


def features_from_text(text: str, path: str | os.PathLike[str] = "<string>") -> list[Feature]:
    """Read the actual features of DMIS text (see :func:`read_dmis_features`).

    Parameters
    ----------
    text : str
        The content of a DMIS file.
    path : str or path-like, optional
        The file name used in error messages.

    Returns
    -------
    list of Feature

    Examples
    --------
    >>> text = '''UNITS/INCH,ANGDEC
    ... DATE=2020/01/01
    ... TIME=00:00:10
    ... F(S1_B1)=FEAT/SPHERE,OUTER,CART,0,0,0,1
    ... FA(S1_B1)=FEAT/SPHERE,CART,1,2,2.$
    ... 5,1
    ... FA(S1_B1_1)=FEAT/POINT,CART,$$ continued
    ...     1,0,0,$$
    ...     -1,0,0
    ... ENDFIL'''
    >>> sphere, point = features_from_text(text)
    >>> sphere.xyz_mm, sphere.size_mm, sphere.line
    ((25.4, 50.8, 63.5), 25.4, 5)
    >>> point.type, point.values, point.ijk
    ('POINT', ('CART', 1.0, 0.0, 0.0, -1.0, 0.0, 0.0), (-1.0, 0.0, 0.0))
    >>> point.time.isoformat()
    '2020-01-01T00:00:10'
    """
    features: list[Feature] = []
    scale = 1.0
    angle_unit = "ANGDEC"
    day: date | None = None
    clock: time | None = None
    for line, statement in _statements(text, path):
        if _FA_START.match(statement):
            when = None if day is None or clock is None else datetime.combine(day, clock)
            features.append(_parse_actual(statement, line, path, scale, angle_unit, when))
        elif (match := _UNITS.match(statement)) is not None:
            scale, angle_unit = _parse_units(match.group(1), line, path)
        elif (match := _DATE.match(statement)) is not None:
            day = _parse_date(match.group(1), line, path)
        elif (match := _TIME.match(statement)) is not None:
            clock = _parse_time(match.group(1), line, path)
    return features


def records_from_features(
    features: Iterable[Feature], path: str | os.PathLike[str] = "<string>"
) -> list[Records]:
    """Turn hexatherm-named sphere and point features into measurement records.

    Parameters
    ----------
    features : iterable of Feature
        Actual features, as :func:`read_dmis_features` returns them.
    path : str or path-like, optional
        The file they came from (kept in the records, used in messages).

    Returns
    -------
    list of Records
        See :func:`read_dmis`.

    Examples
    --------
    >>> text = '''DATE=2020/01/01
    ... TIME=00:00:10
    ... FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25.4
    ... FA(S1_B2_7)=FEAT/POINT,CART,4,5,6
    ... FA(Datum_A)=FEAT/PLANE,CART,0,0,0,0,0,1'''
    >>> centres, points = records_from_features(features_from_text(text))
    >>> centres.kind, centres.label.tolist(), centres.ball.tolist(), centres.diameter_mm.tolist()
    ('centres', ['S1'], ['B1'], [25.4])
    >>> points.kind, points.ijk.tolist(), points.time_s.tolist()
    ('points', [[nan, nan, nan]], [1577836810.0])
    """
    where = os.fspath(path)
    rows: dict[str, list[_Row]] = {"centres": [], "points": []}
    for feature in features:
        if feature.type == "SPHERE":
            kind, match = "centres", _CENTRE_LABEL.fullmatch(feature.label)
        elif feature.type == "POINT":
            kind, match = "points", _POINT_LABEL.fullmatch(feature.label)
        else:
            continue
        if match is None:
            naming = "<label>_<ball>" if kind == "centres" else "<label>_<ball>_<n>"
            raise InputError(
                f"{feature.type.lower()} label {feature.label!r} does not follow hexatherm's "
                f"naming {naming} (each part [A-Za-z0-9-]+)",
                path=where,
                line=feature.line,
                field="label",
            )
        if feature.time is None:
            raise InputError(
                f"FA({feature.label}) has no DATE= and TIME= statements before it",
                path=where,
                line=feature.line,
                field="time",
            )
        if feature.xyz_mm is None:  # pragma: no cover - spheres and points always have one
            raise InputError(f"FA({feature.label}) has no position", path=where, line=feature.line)
        rows[kind].append(
            _Row(
                step=match.group(1),
                ball=match.group(2),
                n=match.group(3) if kind == "points" else "",
                xyz=feature.xyz_mm,
                seconds=feature.time.replace(tzinfo=UTC).timestamp(),
                line=feature.line,
                diameter=_nan(feature.size_mm),
                ijk=feature.ijk if feature.ijk is not None else (math.nan,) * 3,
            )
        )

    records: list[Records] = []
    if rows["centres"]:
        centres = rows["centres"]
        diameter = np.array([row.diameter for row in centres], dtype=np.float64)
        records.append(_records(where, "centres", centres, diameter_mm=diameter))
    if rows["points"]:
        points = rows["points"]
        ijk = np.array([row.ijk for row in points], dtype=np.float64).reshape(-1, 3)
        number = np.array([row.n for row in points], dtype=np.str_)
        records.append(_records(where, "points", points, ijk=ijk, extra={"n": number}))
    return records


# ---------------------------------------------------------------------------
# Reading the file and joining lines into statements


def _read_text(path: str | os.PathLike[str]) -> str:
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", path=path) from exc
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise InputError(
            f"not UTF-8 text: byte 0x{data[exc.start]:02x} at offset {exc.start} cannot be decoded",
            path=path,
            line=line,
        ) from exc


def _split_comment(line: str, in_quote: bool) -> tuple[str, bool, bool]:
    """Split a ``$$`` comment (outside quotes) off a line.

    Returns the text before the comment, whether there was a comment, and whether
    a quoted string is still open at the end of the text.

    >>> _split_comment("FA(A)=FEAT/POINT,CART,$$ comment", False)
    ('FA(A)=FEAT/POINT,CART,', True, False)
    >>> _split_comment("TEXT/OUTFIL,'$$ quoted'", False)
    ("TEXT/OUTFIL,'$$ quoted'", False, False)
    """
    if "$$" not in line:
        return line, False, in_quote ^ (line.count("'") % 2 == 1)
    for index, char in enumerate(line):
        if char == "'":
            in_quote = not in_quote
        elif char == "$" and not in_quote and line.startswith("$$", index):
            return line[:index], True, in_quote
    return line, False, in_quote


_END, _RAW, _SOFT = 0, 1, 2


def _statements(text: str, path: str | os.PathLike[str]) -> list[tuple[int, str]]:
    """Join the lines of DMIS text into statements ``(first line, text)``.

    >>> text = "A/1,$\\r\\n2\\r\\n\\r\\nB/$$ x\\r\\n FA(a)=FEAT/POINT,$$\\r\\n 1,$$\\nC/3\\n,4"
    >>> _statements(text, "f")
    [(1, 'A/1,2'), (4, 'B/'), (5, 'FA(a)=FEAT/POINT, 1'), (7, 'C/3,4')]
    """
    lines = text.split("\n")
    while lines and not lines[-1].strip():
        lines.pop()
    statements: list[tuple[int, str]] = []
    pieces: list[str] = []
    start = 0
    mode = _END
    in_quote = False
    for number, raw in enumerate(lines, start=1):
        line = raw.rstrip("\r")
        if mode == _RAW:
            code, comment, in_quote = _split_comment(line, in_quote)
        else:
            code, comment, in_quote = _split_comment(line, False)
            if not code.strip():
                continue  # blank or comment-only line
            if mode == _SOFT and _STATEMENT_START.match(code):
                # A ",$$" continuation that the writer never continued.
                statements.append((start, "".join(pieces).rstrip().removesuffix(",").strip()))
                mode = _END
            if mode == _END:
                if code.lstrip().startswith(",") and statements:
                    start, previous = statements.pop()
                    pieces = [previous]
                else:
                    start, pieces = number, []
        body = code.rstrip()
        if body.endswith("$"):
            pieces.append(body[:-1])
            mode = _RAW
        elif comment and body.endswith(","):
            pieces.append(body)
            mode = _SOFT
        else:
            pieces.append(body)
            statements.append((start, "".join(pieces).strip()))
            mode = _END
    if mode == _RAW:
        raise InputError(
            f"the file ends inside a statement continued with '$' (last line {len(lines)})",
            path=path,
            line=start,
        )
    if mode == _SOFT:
        raise InputError(
            f"the file ends inside a statement continued with ',$$' (last line {len(lines)})",
            path=path,
            line=start,
        )
    return statements


# ---------------------------------------------------------------------------
# Statements that change how features are read


def _fields(text: str) -> list[str]:
    return [part.strip().strip("'").strip() for part in text.split(",")]


def _parse_units(text: str, line: int, path: str | os.PathLike[str]) -> tuple[float, str]:
    fields = [part.upper() for part in _fields(text)]
    length = fields[0]
    if length not in _LENGTH_UNITS:
        raise InputError(
            f"unknown length unit {length!r} in UNITS (expected one of {', '.join(_LENGTH_UNITS)})",
            path=path,
            line=line,
            field="units",
        )
    angle = fields[1] if len(fields) > 1 else "ANGDEC"
    if angle not in _ANGLE_UNITS:
        raise InputError(
            f"unknown angle unit {angle!r} in UNITS "
            f"(expected one of {', '.join(sorted(_ANGLE_UNITS))})",
            path=path,
            line=line,
            field="units",
        )
    if len(fields) > 2 and fields[2] not in _TEMPERATURE_UNITS or len(fields) > 3:
        raise InputError(
            f"unexpected fields in UNITS: {', '.join(fields[2:])!r}",
            path=path,
            line=line,
            field="units",
        )
    return _LENGTH_UNITS[length], angle


def _parse_date(text: str, line: int, path: str | os.PathLike[str]) -> date:
    value = text.strip().strip("'").strip()
    match = _DATE_VALUE.fullmatch(value)
    try:
        if match is None:
            raise ValueError("expected YYYY/MM/DD")
        return date(int(match.group(1)), int(match.group(3)), int(match.group(4)))
    except ValueError as exc:
        raise InputError(
            f"not a date: {value!r} ({exc})", path=path, line=line, field="date"
        ) from exc


def _parse_time(text: str, line: int, path: str | os.PathLike[str]) -> time:
    value = text.strip().strip("'").strip()
    match = _TIME_VALUE.fullmatch(value)
    try:
        if match is None:
            raise ValueError("expected HH:MM:SS")
        hour, minute, second, fraction = match.groups()
        micro = int((fraction or "0")[:6].ljust(6, "0"))
        return time(int(hour), int(minute), int(second or 0), micro)
    except ValueError as exc:
        raise InputError(
            f"not a time: {value!r} ({exc})", path=path, line=line, field="time"
        ) from exc


# ---------------------------------------------------------------------------
# Actual features


def _value(text: str) -> Value:
    text = text.strip()
    if not text:
        return None
    if _NUMBER.fullmatch(text):
        number = float(text)
        if math.isfinite(number):
            return number
    return text


def _parse_actual(
    statement: str,
    line: int,
    path: str | os.PathLike[str],
    scale: float,
    angle_unit: str,
    when: datetime | None,
) -> Feature:
    """Parse ``FA(label)=FEAT/type,...`` into a :class:`Feature` (lengths in mm)."""
    label_match = _FA_LABEL.match(statement)
    label = label_match.group(1).strip() if label_match else ""
    shown = f"FA({label})" if label_match else statement[:40]

    def fail(message: str, field: str | None) -> NoReturn:
        raise InputError(f"{shown}: {message}", path=path, line=line, field=field)

    if label_match is None:
        fail("malformed label: expected FA(label)=FEAT/...", "label")
    if not label:
        fail("empty label", "label")
    feat = _FA_FEAT.fullmatch(statement, label_match.end())
    if feat is None:
        rest = statement[label_match.end() :][:30]
        fail(f"expected '=FEAT/<type>,...' after the label, found {rest!r}", None)
    parts = feat.group(1).split(",")
    kind = parts[0].strip().upper()
    if not _TYPE.fullmatch(kind):
        fail(f"bad feature type {parts[0].strip()!r}", "type")
    shown = f"FA({label})=FEAT/{kind}"
    values = tuple(_value(part) for part in parts[1:])

    # Words before the coordinate system keyword (INNER, OUTER, ROUND, UNBND, ...).
    at = next(
        (n for n, v in enumerate(values) if not isinstance(v, str) or _upper(v) in _SYSTEMS),
        len(values),
    )
    system = _upper(values[at]) if at < len(values) else ""
    if system not in _SYSTEMS:
        if kind in _POSITIONAL_TYPES:
            fail("expected CART or POL before the coordinates", "coordinates")
        return Feature(label, kind, values, None, None, None, when, line)
    modifiers = [_upper(v) for v in values[:at]]
    if kind in _ALLOWED_MODIFIERS:
        most, allowed = _ALLOWED_MODIFIERS[kind]
        if len(modifiers) > most or not set(modifiers) <= allowed:
            expected = " or ".join(sorted(allowed)) if allowed else "nothing"
            fail(
                f"unexpected {', '.join(modifiers)} before {system} (expected {expected})",
                "modifier",
            )
    coords = values[at + 1 :]
    if kind in _LAYOUTS and len(coords) > _LAYOUTS[kind][1]:
        layout, most = _LAYOUTS[kind]
        fail(
            f"{len(coords)} values after {system}, expected {layout}: "
            f"unexpected {', '.join(repr(v) for v in coords[most:])}",
            "values",
        )

    def number(index: int, name: str) -> float:
        if index >= len(coords):
            fail(f"missing {name}: only {len(coords)} values after {system}", name)
        value = coords[index]
        if value is None:
            fail(f"empty {name}", name)
        if isinstance(value, str):
            fail(f"{name} is not a number: {value!r}", name)
        return value

    def length(index: int, name: str) -> float:
        value = number(index, name) * scale
        if not math.isfinite(value):
            fail(f"{name} out of range: {coords[index]!r}", name)
        return value

    if system == "CART":
        xyz = (length(0, "x"), length(1, "y"), length(2, "z"))
    else:
        radius, angle, z = length(0, "r"), number(1, "angle"), length(2, "z")
        if angle_unit == "ANGDMS":
            fail("POL coordinates with UNITS angles in ANGDMS are not supported", "angle")
        theta = angle if angle_unit == "ANGRAD" else math.radians(angle)
        xyz = (radius * math.cos(theta), radius * math.sin(theta), z)

    ijk = None
    if kind == "POINT" or kind in _AXIS_TYPES or (kind == "LINE" and "UNBND" in modifiers):
        ijk = _direction(coords[3:6], fail)
    size = length(_DIAMETER_AT[kind], "diameter") if kind in _DIAMETER_AT else None
    return Feature(label, kind, values, xyz, ijk, size, when, line)


def _direction(
    values: Sequence[Value], fail: Callable[[str, str | None], NoReturn]
) -> tuple[float, float, float] | None:
    """Read an optional direction i, j, k: all three numbers, or none at all."""
    if all(value is None for value in values):
        return None
    names = ("i", "j", "k")
    for name, value in zip(names, values, strict=False):
        if isinstance(value, str):
            fail(f"{name} is not a number: {value!r}", name)
        if value is None:
            fail(f"incomplete direction: empty {name}", name)
    if len(values) < 3:
        missing = names[len(values)]
        fail(f"incomplete direction: missing {missing}", missing)
    return (float(values[0]), float(values[1]), float(values[2]))  # type: ignore[arg-type]


def _upper(value: Value) -> str:
    return value.upper() if isinstance(value, str) else ""


# ---------------------------------------------------------------------------
# Records


def _nan(value: float | None) -> float:
    return math.nan if value is None else value


@dataclass(frozen=True)
class _Row:
    step: str
    ball: str
    n: str
    xyz: tuple[float, float, float]
    seconds: float
    line: int
    diameter: float
    ijk: tuple[float, float, float]


def _records(path: str, kind: RecordKind, rows: list[_Row], **optional: object) -> Records:
    return Records(
        path=path,
        kind=kind,
        label=np.array([row.step for row in rows], dtype=np.str_),
        ball=np.array([row.ball for row in rows], dtype=np.str_),
        xyz_mm=np.array([row.xyz for row in rows], dtype=np.float64).reshape(-1, 3),
        time_s=np.array([row.seconds for row in rows], dtype=np.float64),
        time_kind="iso",
        line=np.array([row.line for row in rows], dtype=np.int64),
        **optional,  # type: ignore[arg-type]
    )
