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

A DMIS output ends with ``ENDFIL``: a file whose last statement is not ``ENDFIL``
was cut short, perhaps in the middle of a number that still reads as one, and is
refused, naming its last record and the field it may be cut in. With
``allow_truncated`` its last actual feature (and whatever follows it) is dropped
instead, with an :class:`~hexatherm.errors.InputWarning`. A ball measured twice in
one step and a point label seen twice are refused (see
:func:`~hexatherm.io.records.check_groups`; ``keep_later`` keeps the later group).
Every problem in what hexatherm reads raises :class:`~hexatherm.errors.InputError`
naming the file, the line where the statement starts and the field.
"""

from __future__ import annotations

import io
import math
import os
import re
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, date, datetime, time, timedelta
from typing import BinaryIO, NoReturn

import numpy as np

from hexatherm.errors import InputError, InputWarning
from hexatherm.io.files import open_bounded, read_bytes, refuse_utf16
from hexatherm.io.records import RecordKind, Records, check_groups

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
#: ``progress(lines_done, lines_total)``
Progress = Callable[[int, int], None]
#: statements between two calls of a progress callback
_PROGRESS_EVERY = 10_000


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
# A name part of a hexatherm label: [A-Za-z0-9-]+, where a DMIS label may write "-" as
# "__" (DMIS labels hold letters, digits and "_": ``plan --dmis`` writes O-2 as O__2)
_HEXATHERM_NAME = "(?:[A-Za-z0-9-]|__)+"
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


def read_dmis_features(
    path: str | os.PathLike[str],
    *,
    progress: Progress | None = None,
    allow_truncated: bool = False,
) -> list[Feature]:
    """Read every actual feature ``FA(...)`` of a DMIS output file, in file order.

    Parameters
    ----------
    path : str or path-like
        The DMIS file (UTF-8, CRLF or LF line ends).
    progress : callable, optional
        Called as ``progress(lines_done, lines_total)`` now and then while the
        statements are read (for a progress bar: large files take seconds).
    allow_truncated : bool, optional
        Read a file that does not end with ``ENDFIL`` without its last actual
        feature (and what follows it), with an :class:`InputWarning`, instead of
        refusing it.

    Returns
    -------
    list of Feature

    Raises
    ------
    InputError
        If the file is not a regular file of a sane size, cannot be read, is not
        UTF-8, does not end with ``ENDFIL`` (unless ``allow_truncated``), has a bad
        ``UNITS``, ``DATE`` or ``TIME`` statement, or an actual feature is malformed
        (non-numeric coordinate, missing field, ...).

    See Also
    --------
    features_from_text : the same from text already in memory.
    """
    return features_from_text(
        _read_text(path), path, progress=progress, allow_truncated=allow_truncated
    )


def read_dmis(
    path: str | os.PathLike[str],
    *,
    progress: Progress | None = None,
    allow_truncated: bool = False,
    keep_later: bool = False,
) -> list[Records]:
    """Read the hexatherm measurements of a DMIS output file.

    Sphere actuals ``FA(<label>_<ball>)=FEAT/SPHERE,...`` give ball centres,
    point actuals ``FA(<label>_<ball>_<n>)=FEAT/POINT,...`` give surface points;
    other actual features are read past.

    Parameters
    ----------
    path : str or path-like
        The DMIS file.
    progress : callable, optional
        As for :func:`read_dmis_features`.
    allow_truncated : bool, optional
        As for :func:`read_dmis_features`.
    keep_later : bool, optional
        Keep the later group of a ball measured twice in one step, with an
        :class:`InputWarning` (see :func:`~hexatherm.io.records.check_groups`).

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
        follow hexatherm's naming, a sphere or point has no ``DATE=`` and
        ``TIME=`` before it, a ball is measured twice in a step (unless
        ``keep_later``) or a point label is seen twice.
    """
    fast = _fast_file(os.fspath(path), allow_truncated)
    if fast is not None:
        records, dropped, lines = fast
        if dropped is not None:
            _warn_truncated(path, *dropped)
        if progress is not None:
            progress(lines, lines)
        return [check_groups(each, keep_later=keep_later) for each in records]
    features = features_from_text(
        _read_text(path), path, progress=progress, allow_truncated=allow_truncated
    )
    return records_from_features(features, path, keep_later=keep_later)


def features_from_text(
    text: str,
    path: str | os.PathLike[str] = "<string>",
    *,
    progress: Progress | None = None,
    allow_truncated: bool = False,
) -> list[Feature]:
    """Read the actual features of DMIS text (see :func:`read_dmis_features`).

    Parameters
    ----------
    text : str
        The content of a DMIS file.
    path : str or path-like, optional
        The file name used in error messages.
    progress : callable, optional
        As for :func:`read_dmis_features`.
    allow_truncated : bool, optional
        As for :func:`read_dmis_features`: text that does not end with ``ENDFIL`` is
        refused unless it is given.

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
    statements, unfinished = _split_statements(text)
    ended = unfinished is None and _is_endfil(statements)
    if not ended and allow_truncated:
        if unfinished is not None:
            statements.append(unfinished[:2])
        last = _last_actual(statements)
        if last is None and statements:
            last = len(statements) - 1  # no record: the last statement, which may be cut
        if last is not None:
            _warn_truncated(path, statements[last][0], _shown_label(statements[last][1]))
            statements = statements[:last]
    elif unfinished is not None:
        _raise_unfinished(unfinished, text, path)
    total = statements[-1][0] if statements else 0
    try:
        for count, (line, statement) in enumerate(statements):
            if progress is not None and count % _PROGRESS_EVERY == 0:
                progress(line, total)
            if _FA_START.match(statement):
                when = None if day is None or clock is None else datetime.combine(day, clock)
                features.append(_parse_actual(statement, line, path, scale, angle_unit, when))
            elif (match := _UNITS.match(statement)) is not None:
                scale, angle_unit = _parse_units(match.group(1), line, path)
            elif (match := _DATE.match(statement)) is not None:
                day = _parse_date(match.group(1), line, path)
            elif (match := _TIME.match(statement)) is not None:
                clock = _parse_time(match.group(1), line, path)
    except InputError as error:
        if ended or allow_truncated or error.line is None or error.line < total:
            raise
        raise InputError(
            f"{error.message} (the file does not end with ENDFIL: cut short? "
            "--allow-truncated drops its last record)",
            path=error.path,
            line=error.line,
            field=error.field,
        ) from None
    if not ended and not allow_truncated:
        _raise_not_ended(statements, path)
    if progress is not None:
        progress(total, total)
    return features


def _is_endfil(statements: Sequence[tuple[int, str]]) -> bool:
    return bool(statements) and statements[-1][1].strip().upper() == "ENDFIL"


def _last_actual(statements: Sequence[tuple[int, str]]) -> int | None:
    """Index of the last ``FA(...)`` statement, or None."""
    for index in range(len(statements) - 1, -1, -1):
        if _FA_START.match(statements[index][1]):
            return index
    return None


def _shown_label(statement: str) -> str:
    match = _FA_LABEL.match(statement)
    return f"FA({match.group(1).strip()})" if match else statement[:40]


_FIELD_NAMES = {
    ("SPHERE", "CART"): ("x", "y", "z", "diameter"),
    ("POINT", "CART"): ("x", "y", "z", "i", "j", "k"),
    ("SPHERE", "POL"): ("r", "angle", "z", "diameter"),
    ("POINT", "POL"): ("r", "angle", "z", "i", "j", "k"),
}


def _last_field(statement: str) -> str:
    """The field an actual feature statement ends in (where a cut would be)."""
    label = _FA_LABEL.match(statement)
    if label is None:
        return "label"
    feat = _FA_FEAT.fullmatch(statement, label.end())
    if feat is None:
        return "type"
    parts = [part.strip().upper() for part in feat.group(1).split(",")]
    systems = [n for n, part in enumerate(parts[1:], start=1) if part in _SYSTEMS]
    if not systems:
        return "type" if len(parts) == 1 else "coordinates"
    at = systems[0]
    count = len(parts) - at - 1
    if count == 0:
        return "coordinates"
    names = _FIELD_NAMES.get((parts[0], parts[at]), ("x", "y", "z"))
    return names[count - 1] if count <= len(names) else "values"


def _raise_not_ended(statements: Sequence[tuple[int, str]], path: str | os.PathLike[str]) -> None:
    last = _last_actual(statements)
    if last is None:
        raise InputError(
            "the file does not end with ENDFIL: cut short? (--allow-truncated reads it as it is)",
            path=path,
            line=statements[-1][0] if statements else 1,
        )
    line, statement = statements[last]
    field = _last_field(statement)
    raise InputError(
        f"the file does not end with ENDFIL: cut short? Its last record {_shown_label(statement)} "
        f"may be cut in field '{field}' (--allow-truncated drops it)",
        path=path,
        line=line,
        field=field,
    )


def _warn_truncated(path: str | os.PathLike[str], line: int, label: str) -> None:
    warnings.warn(
        InputWarning(
            f"{os.fspath(path)}:{line}: the file does not end with ENDFIL (cut short?): "
            f"its last {'record' if label.startswith('FA(') else 'statement'} {label} "
            "and what follows it dropped"
        ),
        stacklevel=3,
    )


_FA_LINE = re.compile(rb"^[ \t]*FA[ \t]*\(", re.IGNORECASE | re.MULTILINE)


def _ends_with_endfil(tail: bytes) -> bool:
    """Whether the last line with text is ``ENDFIL``, on bytes that hold that line whole
    (the fast lane's test: when it says so, so do the statements, for a file the fast
    lane reads; otherwise the general reader decides)."""
    tail = tail.rstrip(b" \t\r\n")
    return tail[tail.rfind(b"\n") + 1 :].strip(b" \t").upper() == b"ENDFIL"


def _cut_last_record(data: bytes) -> tuple[int, tuple[int, str] | None] | None:
    """Where to cut ``data`` before its last ``FA(`` line (or, with none, its last line with
    text) and what follows, and that line's number and label (None when there is no
    statement), for a file whose lines are its statements (no ``$``); None when the
    general reader must decide (a ``$``, a line after it that starts with ``,`` or that
    the general reader would take for an actual feature)."""
    if b"$" in data:
        return None
    last = deque(_FA_LINE.finditer(data), maxlen=1)
    if last:
        start = last[0].start()
        return _cut_before(data[start:], start, data.count(b"\n", 0, start) + 1)
    end = len(data.rstrip())
    if end == 0:
        return len(data), None
    start = data.rfind(b"\n", 0, end) + 1
    # every line: none may be an actual feature to the general reader
    text = data.decode("utf-8", "replace").removeprefix("\ufeff")
    lines = [line.strip() for line in text.split("\n")]
    first = lines[data.count(b"\n", 0, start)]
    if not first or first.startswith(","):
        return None
    if any(line.startswith(",") or _FA_START.match(line) for line in lines):
        return None
    return start, (data.count(b"\n", 0, start) + 1, _shown_label(first))


def _cut_before(tail: bytes, start: int, line: int) -> tuple[int, tuple[int, str]] | None:
    """:func:`_cut_last_record` where ``tail``, the bytes from offset ``start`` (line
    ``line``) on, starts with the file's last ``FA(`` line."""
    text = tail.decode("utf-8", "replace")
    if start == 0:
        text = text.removeprefix("\ufeff")
    first, *others = (part.strip() for part in text.split("\n"))
    if not first or first.startswith(","):
        return None
    if any(part.startswith(",") or _FA_START.match(part) for part in others):
        return None
    return start, (line, _shown_label(first))


def records_from_features(
    features: Iterable[Feature],
    path: str | os.PathLike[str] = "<string>",
    *,
    keep_later: bool = False,
) -> list[Records]:
    """Turn hexatherm-named sphere and point features into measurement records.

    Parameters
    ----------
    features : iterable of Feature
        Actual features, as :func:`read_dmis_features` returns them.
    path : str or path-like, optional
        The file they came from (kept in the records, used in messages).
    keep_later : bool, optional
        As for :func:`read_dmis`.

    Returns
    -------
    list of Records
        See :func:`read_dmis`.

    Raises
    ------
    InputError
        As :func:`read_dmis` for labels, times, balls measured twice and point
        labels seen twice.

    Examples
    --------
    >>> text = '''DATE=2020/01/01
    ... TIME=00:00:10
    ... FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25.4
    ... FA(S1_B2_7)=FEAT/POINT,CART,4,5,6
    ... FA(Datum_A)=FEAT/PLANE,CART,0,0,0,0,0,1
    ... ENDFIL'''
    >>> centres, points = records_from_features(features_from_text(text))
    >>> centres.kind, centres.label.tolist(), centres.ball.tolist(), centres.diameter_mm.tolist()
    ('centres', ['S1'], ['B1'], [25.4])
    >>> points.kind, points.ijk.tolist(), points.time_s.tolist()
    ('points', [[nan, nan, nan]], [1577836810.0])
    """
    where = os.fspath(path)
    rows: dict[str, list[_Row]] = {"centres": [], "points": []}
    for feature in features:
        row = _feature_row(feature, where)
        if row is not None:
            rows[row[0]].append(row[1])
    return [
        check_groups(records, keep_later=keep_later)
        for records in _rows_to_records(where, rows["centres"], rows["points"])
    ]


def _feature_row(feature: Feature, where: str) -> tuple[str, _Row] | None:
    """The records row of a sphere or point feature (None for other types)."""
    if feature.type == "SPHERE":
        kind, match = "centres", _CENTRE_LABEL.fullmatch(feature.label)
    elif feature.type == "POINT":
        kind, match = "points", _POINT_LABEL.fullmatch(feature.label)
    else:
        return None
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
    return kind, _Row(
        step=match.group(1).replace("__", "-"),
        ball=match.group(2).replace("__", "-"),
        n=match.group(3).replace("__", "-") if kind == "points" else "",
        xyz=feature.xyz_mm,
        seconds=feature.time.replace(tzinfo=UTC).timestamp(),
        line=feature.line,
        diameter=_nan(feature.size_mm),
        ijk=feature.ijk if feature.ijk is not None else (math.nan,) * 3,
    )


def _rows_to_records(where: str, centres: list[_Row], points: list[_Row]) -> list[Records]:
    records: list[Records] = []
    if centres:
        diameter = np.array([row.diameter for row in centres], dtype=np.float64)
        records.append(_records(where, "centres", centres, diameter_mm=diameter))
    if points:
        ijk = np.array([row.ijk for row in points], dtype=np.float64).reshape(-1, 3)
        number = np.array([row.n for row in points], dtype=np.str_)
        records.append(_records(where, "points", points, ijk=ijk, extra={"n": number}))
    return records


# ---------------------------------------------------------------------------
# Reading the file and joining lines into statements


def _read_text(path: str | os.PathLike[str]) -> str:
    return _decode(_read_bytes(path), path)


def _read_bytes(path: str | os.PathLike[str]) -> bytes:
    data = read_bytes(path)
    refuse_utf16(data, path)
    return data


def _decode(data: bytes, path: str | os.PathLike[str]) -> str:
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
    statements, unfinished = _split_statements(text)
    if unfinished is not None:
        _raise_unfinished(unfinished, text, path)
    return statements


#: A statement the text ends inside: (first line, text so far, mode, lines of the text)
_Unfinished = tuple[int, str, int, int]


def _split_statements(text: str) -> tuple[list[tuple[int, str]], _Unfinished | None]:
    """The statements of DMIS text, and the one it ends inside (continued with ``$`` or
    ``,$$`` on its last line), if any."""
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
    if mode == _END:
        return statements, None
    return statements, (start, "".join(pieces).strip(), mode, len(lines))


def _raise_unfinished(unfinished: _Unfinished, text: str, path: str | os.PathLike[str]) -> None:
    start, _, mode, count = unfinished
    mark = "'$'" if mode == _RAW else "',$$'"
    raise InputError(
        f"the file ends inside a statement continued with {mark} (last line {count}): "
        "cut short? (--allow-truncated drops its last record)",
        path=path,
        line=start,
    )


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
        time_aware=False,
        **optional,  # type: ignore[arg-type]
    )


# ---------------------------------------------------------------------------
# The fast lane of read_dmis
#
# A DMIS file of a hexatherm session holds tens of thousands of points, one
# ``FA(<step>_<ball>_<n>)=FEAT/POINT,CART,x,y,z,i,j,k`` line each, between ``DATE=``
# and ``TIME=`` lines. When a file has no continuations and no comments (no ``$``,
# no line starting with a comma) every non-blank line is one statement, and the
# lines are sorted out with numpy on the file's bytes: the canonical point lines
# (exactly as above, no blanks) are checked byte by byte as arrays and read by
# pandas' C parser (numbers correctly rounded, as ``float``); the canonical
# ``DATE=YYYY/MM/DD`` and ``TIME=HH:MM:SS`` lines are decoded as arrays.
# Every other line that matters (spheres, other features, ``UNITS``, other
# spellings, leading or trailing blanks) goes through the general parser one by
# one, in its context. Whenever something is off (a value the general reader
# would refuse, a feature without a time, ...) the fast lane gives up and the
# general reader reads the whole file, so that results and errors are exactly
# those of :func:`records_from_features` of :func:`features_from_text`.
#
# The fast lane reads the file a chunk of whole lines at a time (about
# :data:`_CHUNK_BYTES`), carrying the UNITS, DATE and TIME in effect from one chunk to
# the next, and puts each chunk's points into columns grown in place
# (:class:`_Column`): its memory is the records' and one chunk's work, not the file's
# text (a scanning session's 268 MB file: 3.0 GB -> 0.44 GB peak). Whether the file
# ends with ENDFIL is told from the last chunk with text; a file cut short is read
# again up to its cut (:func:`_find_cut`).

# First and last bytes of lines that are statements as they are, with no blanks to strip:
# printable ASCII (bytes >= 0x80 may be blanks too), and not ',' first (a continuation)
_REGULAR_FIRST = np.zeros(256, dtype=bool)
_REGULAR_FIRST[0x21:0x7F] = True
_REGULAR_FIRST[ord(",")] = False
_REGULAR_LAST = np.zeros(256, dtype=bool)
_REGULAR_LAST[0x21:0x7F] = True
# First bytes of statements that could matter (FA(, UNITS/, DATE=, TIME= in any case)
_MAYBE_RELEVANT = np.zeros(256, dtype=bool)
_MAYBE_RELEVANT[list(b"FfUuDdTt")] = True
_MICROSECONDS_PER_DAY = 86_400_000_000
_EPOCH_ORDINAL = date(1970, 1, 1).toordinal()


class _GiveUp(Exception):
    """The fast lane cannot read this file the way the general reader would."""


#: bytes the fast lane reads at a time (then up to the next line end: lines stay whole)
_CHUNK_BYTES = 1 << 22
_BOM = b"\xef\xbb\xbf"
_POINT_COLUMNS = ("line", "step", "ball", "n", "xyz", "ijk", "seconds")
#: the room first reserved for a column of points, bytes (see :class:`_Column`)
_COLUMN_BYTES = 1 << 26
#: what :func:`_fast_read` returns: the records, the record dropped from a file cut short
#: (its line and label) and the number of lines of the file
_FastRead = tuple[list[Records], tuple[int, str] | None, int]


@dataclass(frozen=True)
class _InEffect:
    """The last ``UNITS`` (scale to mm, angle unit), ``DATE`` and ``TIME`` read so far."""

    unit: tuple[float, str] | None = None
    day: date | None = None
    clock: time | None = None


class _Column:
    """A column of the points read, grown in place as chunks add to it.

    Joining the chunks' pieces at the end would hold every column twice (the pieces
    and the whole), and the allocator keeps the pages of the freed pieces: the peak
    memory would be about twice the records'. Instead the column is one array, made
    large (:data:`_COLUMN_BYTES`, reserved, not touched: the system allocates such a
    block apart, as a mapping) and resized in place when full and at the end (numpy's
    ``resize``: ``realloc``, which moves a mapping's pages rather than copying them)."""

    def __init__(self) -> None:
        self.array: np.ndarray | None = None
        self.size = 0

    def append(self, piece: np.ndarray) -> None:
        array, size, end = self.array, self.size, self.size + len(piece)
        if array is None or array.dtype.itemsize < piece.dtype.itemsize:  # longer labels
            row = piece.dtype.itemsize * math.prod(piece.shape[1:])
            rows = max(2 * end, _COLUMN_BYTES // max(row, 1))
            wider = np.empty((rows, *piece.shape[1:]), dtype=piece.dtype)
            if array is not None:
                wider[:size] = array[:size]
            array = wider
        if end > len(array):
            array.resize((end + 4 * len(piece), *array.shape[1:]), refcheck=False)
        array[size:end] = piece
        self.array, self.size = array, end

    def finish(self) -> np.ndarray:
        """The column, its spare rows given back."""
        array = self.array
        assert array is not None
        array.resize((self.size, *array.shape[1:]), refcheck=False)
        self.array = None
        return array


class _Lane:
    """What the fast lane has read of a file so far, a chunk of lines at a time: the
    sphere rows, the point columns, what is in effect where the next chunk starts, the
    line ends seen and the last chunk with text (its last line is the file's last line
    with text, whole)."""

    def __init__(self) -> None:
        self.centres: list[_Row] = []
        self.points = {name: _Column() for name in _POINT_COLUMNS}
        self.in_effect = _InEffect()
        self.line_ends = 0
        self.last_text = b""

    def records(self, where: str) -> list[Records]:
        """The records read."""
        records: list[Records] = []
        if self.centres:
            records.extend(_rows_to_records(where, self.centres, []))
        if self.points["line"].size:
            columns = {name: column.finish() for name, column in self.points.items()}
            records.append(
                Records(
                    path=where,
                    kind="points",
                    label=columns["step"],
                    ball=columns["ball"],
                    xyz_mm=columns["xyz"],
                    time_s=columns["seconds"],
                    time_kind="iso",
                    line=columns["line"],
                    ijk=columns["ijk"],
                    extra={"n": columns["n"]},
                    time_aware=False,
                )
            )
        return records


def _fast_file(where: str, allow_truncated: bool) -> _FastRead | None:
    """:func:`read_dmis` of a file by the fast lane, which reads it a chunk of lines at a
    time (memory: the records and a chunk, not the file's text); None when the general
    reader must read it."""
    return _fast_read(lambda: open_bounded(where), where, allow_truncated)


def _fast_records(data: bytes, path: str | os.PathLike[str]) -> list[Records] | None:
    """The fast lane's records of a whole file's bytes; None when the general reader must."""
    read = _fast_read(lambda: io.BytesIO(data), os.fspath(path), allow_truncated=False)
    return None if read is None else read[0]


def _fast_read(
    open_stream: Callable[[], BinaryIO], where: str, allow_truncated: bool
) -> _FastRead | None:
    """:func:`read_dmis` by the fast lane, the file opened by ``open_stream``; None when
    the general reader must (which then says what is wrong, if anything)."""
    try:
        with open_stream() as stream:
            lane = _fast_stream(stream, where)
        if _ends_with_endfil(lane.last_text):
            return lane.records(where), None, lane.line_ends + 1
        if not allow_truncated:
            return None
        line_ends = lane.line_ends
        del lane
        cut = _find_cut(open_stream)
        if cut is None:
            return None
        with open_stream() as stream:
            lane = _fast_stream(stream, where, stop=cut[0])
        return lane.records(where), cut[1], line_ends + 1
    except Exception:  # _GiveUp, the general parser's InputError, anything unforeseen
        return None


def _line_chunks(stream: BinaryIO, stop: int | None = None) -> Iterator[tuple[bytes, int]]:
    """The bytes of ``stream`` (its first ``stop``) in chunks of whole lines of about
    :data:`_CHUNK_BYTES` (the last one may lack its line end), each with the number of
    its first line."""
    parts: list[bytes] = []
    line = 1
    left = math.inf if stop is None else stop
    while True:
        block = stream.read(int(min(_CHUNK_BYTES, left))) if left > 0 else b""
        left -= len(block)
        cut = block.rfind(b"\n") + 1
        if not block or cut == 0:
            if block:
                parts.append(block)
                continue
            if parts:
                yield b"".join(parts), line
            return
        chunk = b"".join((*parts, block[:cut])) if parts else block[:cut]
        parts = [block[cut:]] if cut < len(block) else []
        yield chunk, line
        line += chunk.count(b"\n")


def _fast_stream(stream: BinaryIO, where: str, stop: int | None = None) -> _Lane:
    """The fast lane over the first ``stop`` bytes of ``stream`` (all by default)."""
    lane = _Lane()
    for chunk, first in _line_chunks(stream, stop):
        lane.line_ends += chunk.count(b"\n")
        if chunk.rstrip(b" \t\r\n"):
            lane.last_text = chunk
        data = chunk
        if first == 1:
            refuse_utf16(data, where)  # the general reader says so
            data = data.removeprefix(_BOM)
        if not data.isascii():
            data.decode("utf-8")  # not UTF-8: the general reader says where
        _fast_chunk(data, where, first, lane)
    return lane


def _find_cut(open_stream: Callable[[], BinaryIO]) -> tuple[int, tuple[int, str] | None] | None:
    """:func:`_cut_last_record` of the file, read a chunk at a time when it has an
    ``FA(`` line (the last one and what follows are kept), whole otherwise."""
    found: tuple[int, int] | None = None
    tail: list[bytes] = []
    offset = 0
    with open_stream() as stream:
        for chunk, first in _line_chunks(stream):
            if b"$" in chunk:
                return None
            last = deque(_FA_LINE.finditer(chunk), maxlen=1)
            if last:
                at = last[0].start()
                found, tail = (offset + at, first + chunk.count(b"\n", 0, at)), [chunk[at:]]
            elif found is not None:
                tail.append(chunk)
            offset += len(chunk)
    if found is not None:
        return _cut_before(b"".join(tail), *found)
    with open_stream() as stream:
        return _cut_last_record(stream.read())


def _prefixed(padded: np.ndarray, starts: np.ndarray, prefix: bytes) -> np.ndarray:
    mask = np.ones(starts.size, dtype=bool)
    for k, byte in enumerate(prefix):
        mask &= padded[starts + k] == byte
    return mask


def _fast_chunk(data: bytes, where: str, first: int, lane: _Lane) -> None:
    """Read a chunk of whole lines (``first``: the number of its first) into ``lane``."""
    if b"$" in data:
        raise _GiveUp
    if not data:
        return
    arr = np.frombuffer(data, dtype=np.uint8)
    size = arr.size
    carriage = np.flatnonzero(arr == 13)
    if carriage.size and (carriage[-1] + 1 >= size or np.any(arr[carriage + 1] != 10)):
        raise _GiveUp  # a CR that does not end a line
    newlines = np.flatnonzero(arr == 10)
    starts = np.concatenate(([0], newlines + 1))
    ends = np.concatenate((newlines, [size]))  # exclusive, without the LF
    spans = ends - starts
    ends = ends - ((spans > 0) & (arr[np.maximum(ends - 1, 0)] == 13))  # without the CR
    lengths = ends - starts
    padded = np.concatenate((arr, np.zeros(8, dtype=np.uint8)))
    nonempty = lengths > 0
    regular = (
        nonempty & _REGULAR_FIRST[padded[starts]] & _REGULAR_LAST[padded[np.maximum(ends - 1, 0)]]
    )
    line_no = np.arange(first, first + starts.size)

    is_point = regular & _prefixed(padded, starts, b"FA(")
    is_date = regular & _prefixed(padded, starts, b"DATE=") & (lengths == 15)
    is_time = regular & _prefixed(padded, starts, b"TIME=") & (lengths == 13)
    if is_time.any():  # TIME=HH:MM:SS exactly, else the general parser
        at = starts[is_time][:, None] + np.arange(5, 13)
        chars = padded[at]
        digits = chars[:, [0, 1, 3, 4, 6, 7]]
        strict = (
            np.all((digits >= 48) & (digits <= 57), axis=1)
            & (chars[:, 2] == 58)
            & (chars[:, 5] == 58)
        )
        is_time[np.flatnonzero(is_time)[~strict]] = False
    # Lines read one by one: irregular ones, and regular ones that may be relevant.
    special = nonempty & ~regular
    special |= regular & ~(is_point | is_date | is_time) & _MAYBE_RELEVANT[padded[starts]]
    # What the lines before the chunk left in effect, as if stated on the line before it.
    before, carried = first - 1, lane.in_effect
    units: list[tuple[int, float, str]] = [] if carried.unit is None else [(before, *carried.unit)]
    dates: list[tuple[int, date]] = [] if carried.day is None else [(before, carried.day)]
    times: list[tuple[int, time]] = [] if carried.clock is None else [(before, carried.clock)]
    actuals: list[tuple[int, str]] = []
    for index in np.flatnonzero(special).tolist():
        statement = data[starts[index] : ends[index]].decode("utf-8").strip()
        if not statement:
            continue
        if statement.startswith(","):
            raise _GiveUp  # a continuation
        line = index + first
        if _FA_START.match(statement):
            actuals.append((line, statement))
        elif (match := _UNITS.match(statement)) is not None:
            units.append((line, *_parse_units(match.group(1), line, where)))
        elif (match := _DATE.match(statement)) is not None:
            dates.append((line, _parse_date(match.group(1), line, where)))
        elif (match := _TIME.match(statement)) is not None:
            times.append((line, _parse_time(match.group(1), line, where)))

    # Context: UNITS, DATE and TIME in effect at each line.
    date_lines, date_days = _fast_dates(data, starts, line_no, is_date, dates, where)
    time_lines = np.concatenate((line_no[is_time], [line for line, _ in times])).astype(np.int64)
    time_us = np.empty(time_lines.size, dtype=np.int64)
    if is_time.any():
        chars = padded[starts[is_time][:, None] + np.array([5, 6, 8, 9, 11, 12])].astype(np.int64)
        chars -= 48
        hour, minute, second = (
            chars[:, 0] * 10 + chars[:, 1],
            chars[:, 2] * 10 + chars[:, 3],
            chars[:, 4] * 10 + chars[:, 5],
        )
        if np.any(hour > 23) or np.any(minute > 59) or np.any(second > 59):
            raise _GiveUp  # time() refuses them: the general reader says so
        time_us[: hour.size] = (hour * 3600 + minute * 60 + second) * 1_000_000
    time_us[time_us.size - len(times) :] = [
        ((c.hour * 60 + c.minute) * 60 + c.second) * 1_000_000 + c.microsecond for _, c in times
    ]
    order = np.argsort(time_lines, kind="stable")
    time_lines, time_us = time_lines[order], time_us[order]
    unit_lines = np.array([u[0] for u in units], dtype=np.int64)
    lane.in_effect = _InEffect(
        unit=units[-1][1:] if units else None,
        day=date.fromordinal(int(date_days[-1]) + _EPOCH_ORDINAL) if date_days.size else None,
        clock=_clock(int(time_us[-1])) if time_us.size else None,
    )

    def context(lines: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At each line: index of the UNITS in effect (-1: none), POSIX microseconds of
        the DATE and TIME in effect, and whether both were given."""
        u = np.searchsorted(unit_lines, lines) - 1
        d = np.searchsorted(date_lines, lines) - 1
        t = np.searchsorted(time_lines, lines) - 1
        known = (d >= 0) & (t >= 0)
        day = np.append(date_days, 0)[d]  # index -1: the appended 0, masked below
        clock = np.append(time_us, 0)[t]
        return u, np.where(known, day * _MICROSECONDS_PER_DAY + clock, 0), known

    # Canonical point lines, all at once.
    point_lines = line_no[is_point]
    steps = balls = numbers = np.empty(0, dtype=np.str_)
    values = np.empty((0, 6))
    if point_lines.size:
        keep = np.repeat(is_point, np.concatenate((spans[:-1] + 1, spans[-1:])))
        keep[carriage] = False
        blob = arr[keep]
        if blob[-1] == 10:
            blob = blob[:-1]
        canonical, steps, balls, numbers, values = _canonical_points(blob)
        if not canonical.all():  # FA( lines that are not canonical points: one by one
            for index in (point_lines[~canonical] - first).tolist():
                actuals.append((index + first, data[starts[index] : ends[index]].decode("utf-8")))
            point_lines = point_lines[canonical]
    u, stamp, known = context(point_lines)
    if not known.all():
        raise _GiveUp  # a point without DATE= and TIME= before it
    scale = np.array([1.0] + [s for _, s, _ in units])[u + 1]
    with np.errstate(over="ignore"):  # an overflow is refused below
        xyz = values[:, :3] * scale[:, None]
    ijk = values[:, 3:]
    if not np.isfinite(xyz).all():
        raise _GiveUp
    given = np.isfinite(ijk)
    if not np.all(given.all(axis=1) | np.isnan(ijk).all(axis=1)):
        raise _GiveUp  # an incomplete or infinite direction
    if np.abs(stamp).max(initial=0) >= 2**53:
        raise _GiveUp  # POSIX microseconds that a double cannot hold exactly
    seconds = stamp.astype(np.float64) / 1e6

    # The other actual features, one by one, each in its context.
    centre_rows: list[_Row] = []
    point_rows: list[_Row] = []
    if actuals:
        actuals.sort()  # in file order
        lines = np.array([line for line, _ in actuals], dtype=np.int64)
        u_other, stamp_other, known_other = context(lines)
        for (line, statement), ui, us, ok in zip(
            actuals, u_other.tolist(), stamp_other.tolist(), known_other.tolist(), strict=True
        ):
            scale_here, angle = (1.0, "ANGDEC") if ui < 0 else units[ui][1:]
            when = None
            if ok:
                when = datetime(1970, 1, 1) + timedelta(microseconds=us)
            row = _feature_row(
                _parse_actual(statement, line, where, scale_here, angle, when), where
            )
            if row is not None:
                (centre_rows if row[0] == "centres" else point_rows).append(row[1])

    lane.centres.extend(centre_rows)
    if point_lines.size or point_rows:
        lines = point_lines
        if point_rows:
            lines = np.concatenate((lines, [r.line for r in point_rows]))
            steps, balls, numbers = (
                np.concatenate((column, np.array(more, dtype=np.str_)))
                for column, more in (
                    (steps, [r.step for r in point_rows]),
                    (balls, [r.ball for r in point_rows]),
                    (numbers, [r.n for r in point_rows]),
                )
            )
            xyz = np.concatenate((xyz, [r.xyz for r in point_rows]))
            ijk = np.concatenate((ijk, [r.ijk for r in point_rows]))
            seconds = np.concatenate((seconds, [r.seconds for r in point_rows]))
        order = np.argsort(lines, kind="stable")
        columns = (lines.astype(np.int64), steps, balls, numbers, xyz, ijk, seconds)
        for name, column in zip(_POINT_COLUMNS, columns, strict=True):
            lane.points[name].append(column[order])


def _clock(microseconds: int) -> time:
    """The time of day ``microseconds`` after midnight."""
    seconds, micro = divmod(microseconds, 1_000_000)
    return time(seconds // 3600, seconds // 60 % 60, seconds % 60, micro)


def _fast_dates(
    data: bytes,
    starts: np.ndarray,
    line_no: np.ndarray,
    is_date: np.ndarray,
    dates: list[tuple[int, date]],
    where: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Lines of the DATE= statements, in order, and their days since 1970-01-01."""
    lines = line_no[is_date]
    days = np.empty(lines.size, dtype=np.int64)
    if lines.size:
        padded = np.frombuffer(data + b"\0" * 16, dtype=np.uint8)
        values = padded[starts[is_date][:, None] + np.arange(5, 15)]
        unique, inverse = np.unique(values.view("S10")[:, 0], return_inverse=True)
        first = np.zeros(unique.size, dtype=np.int64)
        first[inverse[::-1]] = np.arange(lines.size)[::-1]
        ordinals = np.array(
            [
                _parse_date(text.decode("utf-8"), int(lines[k]), where).toordinal()
                for text, k in zip(unique.tolist(), first.tolist(), strict=True)
            ],
            dtype=np.int64,
        )
        days = ordinals[inverse.ravel()] - _EPOCH_ORDINAL
    all_lines = np.concatenate((lines, [line for line, _ in dates])).astype(np.int64)
    all_days = np.concatenate((days, [d.toordinal() - _EPOCH_ORDINAL for _, d in dates]))
    order = np.argsort(all_lines, kind="stable")
    return all_lines[order], all_days[order].astype(np.int64)


_POINT_TOKEN = np.frombuffer(b")=FEAT/POINT,CART,", dtype=np.uint8)
# Per byte, as a bytes.translate table: bit 0 set when it does not belong in a label
# ([A-Za-z0-9-] and _), bit 1 when it does not belong in the numbers (digits, "eE+-.",
# blanks and commas).
_BAD_IN = np.full(256, 3, dtype=np.uint8)
_BAD_IN[list(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz_")] = 2
_BAD_IN[list(b"0123456789-")] = 0
_BAD_IN[list(b"eE")] = 0
_BAD_IN[list(b"+. ,")] = 1
_BAD_IN_TABLE = _BAD_IN.tobytes()


def _canonical_points(
    blob: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Parse lines ``FA(<step>_<ball>_<n>)=FEAT/POINT,CART,x,y,z[,i,j,k]`` all at once.

    ``blob`` holds the bytes of lines that start with ``FA(``, joined by LF. Returns
    which lines are such canonical points (the others are left to the general
    parser), and for those the step, ball and point labels and the numbers (n, 6)
    (NaN where a line has fewer than six). A line counts as canonical when its label
    is three non-empty ``[A-Za-z0-9-]+`` parts joined by ``_``, ``)=FEAT/POINT,CART,``
    follows it, and 3 to 6 comma-separated fields made of digits, ``eE+-.`` and
    blanks come after that; pandas' C parser reads the numbers (correctly rounded,
    as ``float``), and a malformed number makes the whole lane give up.
    """
    import pandas as pd

    size = blob.size
    newlines = np.flatnonzero(blob == 10)
    first = np.concatenate(([0], newlines + 1))
    last = np.concatenate((newlines, [size]))
    padded = np.concatenate((blob, np.zeros(_POINT_TOKEN.size + 1, dtype=np.uint8)))
    parens = np.flatnonzero(blob == 41)
    paren = np.append(parens, size)[np.searchsorted(parens, first + 3)]  # first ')' (or none)
    ok = paren + _POINT_TOKEN.size <= last
    ok &= np.all(
        padded[np.minimum(paren, size)[:, None] + np.arange(_POINT_TOKEN.size)] == _POINT_TOKEN,
        axis=1,
    )
    # Per byte of the lines still ok: 1 in the label, 2 in the numbers (with the comma
    # before them), 0 elsewhere.
    label_start, number_start = first + 3, paren + _POINT_TOKEN.size - 1

    def regions() -> np.ndarray:
        edges = np.column_stack((label_start, paren, number_start, last))[ok].ravel()
        lengths = np.diff(np.concatenate(([0], edges, [size])))
        codes = np.tile(np.array([0, 1, 0, 2], dtype=np.uint8), edges.size // 4 + 1)
        return np.repeat(codes[: lengths.size], lengths)

    def line_of(positions: np.ndarray) -> np.ndarray:
        return np.searchsorted(first, positions, side="right") - 1

    bad_in = np.frombuffer(blob.tobytes().translate(_BAD_IN_TABLE), dtype=np.uint8)
    ok[line_of(np.flatnonzero(bad_in & regions()))] = False
    # Exactly two "_" (the label is the only place they may be), not first, not last,
    # not side by side; 3 to 6 fields after the token (which holds two commas).
    bounds = np.append(first, size)
    underscores = np.flatnonzero(blob == 95)
    ok &= np.diff(np.searchsorted(underscores, bounds)) == 2
    ok &= (padded[label_start] != 95) & (padded[np.maximum(paren - 1, 0)] != 95)
    ok[line_of(underscores[:-1][np.diff(underscores) == 1])] = False
    commas = np.diff(np.searchsorted(np.flatnonzero(blob == 44), bounds)) - 2
    ok &= (commas >= 2) & (commas <= 5)
    if not ok.any():
        empty = np.empty(0, dtype=np.str_)
        return ok, empty, empty, empty, np.empty((0, 6))
    # The canonical lines as CSV: "step,ball,n,x,y,z[,i,j,k]" (the label's "_" made commas)
    keep = regions() > 0
    keep[newlines[ok[:-1]]] = True
    text = blob[keep].tobytes().replace(b"_", b",")
    labels, numbers = ["step", "ball", "n"], ["x", "y", "z", "i", "j", "k"]
    frame = pd.read_csv(
        io.BytesIO(text),
        header=None,
        names=labels + numbers,
        engine="c",
        dtype={**dict.fromkeys(labels, object), **dict.fromkeys(numbers, float)},
        keep_default_na=False,
        na_values=dict.fromkeys(numbers, [""]),
    )
    if len(frame) != int(ok.sum()):
        raise _GiveUp
    step, ball, n = (frame[name].to_numpy().astype(np.str_) for name in labels)
    return ok, step, ball, n, frame[numbers].to_numpy(dtype=np.float64)
