"""Records in the byte stream of a touch probe, a DRO or a CMM controller.

Pure parsing, no serial port: :class:`LineSplitter` cuts a byte stream into
lines, whatever the chunks it arrives in, and :func:`parse_record` reads one
line. Accepted records (any case, blanks optional):

* ``X+0123.4567 Y-0001.2345 Z+0456.7890`` (also ``X:1.2``, separators ``,`` ``;``);
* ``X=1.2 Y=3.4 Z=5.6``;
* ``1.2,3.4,5.6`` (or separated by ``;``, tabs or blanks);
* an optional unit after each number or once at the end of the line: ``mm``
  (the default), ``um``/``µm``, ``in``/``inch``/``"``; all numbers of a line in
  one unit.

Lines end with CR, LF or CRLF; control characters around a line (STX/ETX
framing, XON/XOFF, NUL padding) are dropped. Anything else is not a record:
lines without a digit (prompts, ``OK``, echoed commands) are *text*, the others
*garbage*; both are skipped by the caller and never fatal. A number that overflows a
float (``1e400``) makes the line garbage: no record holds a non-finite value. A line that grows
beyond :data:`MAX_LINE` bytes without an end (a stream of noise) is cut there.

>>> splitter = LineSplitter()
>>> splitter.feed(b"X+0123.4567 Y-0001.2345 Z+04"), splitter.pending
([], b'X+0123.4567 Y-0001.2345 Z+04')
>>> [parse_record(line).xyz_mm for line in splitter.feed(b"56.7890\\r\\nX=1 Y=2 Z=3 in\\n")]
[(123.4567, -1.2345, 456.789), (25.4, 50.8, 76.19999999999999)]
>>> parse_record(b"?POS").kind, parse_record(b"\\xff\\xfe12#").kind
('text', 'garbage')
>>> parse_record(b"X=1e400 Y=0 Z=0").reason  # never an infinite point
'a number overflows (not finite)'
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal

#: longest line kept without a line end, bytes
MAX_LINE = 4096
#: unit suffixes and their size in mm
UNITS_MM: dict[str, float] = {
    "mm": 1.0,
    "um": 1e-3,
    "µm": 1e-3,
    "in": 25.4,
    "inch": 25.4,
    '"': 25.4,
}
_CONTROL = "".join(chr(c) for c in range(32)) + "\x7f "

_NUM = r"[+-]?[ \t]*(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_UNIT = r'(?:inch|in|mm|um|µm|")'
_AXIS = r"[ \t]*[:=]?[ \t]*"
_LETTERED = re.compile(
    rf"X{_AXIS}(?P<x>{_NUM})[ \t]*(?P<ux>{_UNIT})?[ \t,;]*"
    rf"Y{_AXIS}(?P<y>{_NUM})[ \t]*(?P<uy>{_UNIT})?[ \t,;]*"
    rf"Z{_AXIS}(?P<z>{_NUM})[ \t]*(?P<uz>{_UNIT})?",
    re.IGNORECASE,
)
_SEP = r"[ \t]*[,;\t ][ \t]*"
_PLAIN = re.compile(
    rf"(?P<x>{_NUM})[ \t]*(?P<ux>{_UNIT})?{_SEP}"
    rf"(?P<y>{_NUM})[ \t]*(?P<uy>{_UNIT})?{_SEP}"
    rf"(?P<z>{_NUM})[ \t]*(?P<uz>{_UNIT})?",
    re.IGNORECASE,
)
_NUMBER_TOKEN = re.compile(rf"(?P<v>{_NUM})(?:[ \t]*°?C)?", re.IGNORECASE)

RecordKind = Literal["point", "blank", "text", "garbage"]


class LineSplitter:
    """Cut a byte stream into lines at CR, LF or CRLF, keeping a partial line.

    Empty lines are not returned (so CRLF, LFCR and blank lines are all one
    line end), which makes the lines independent of how the stream was
    chunked: a CR at the end of one chunk and the LF at the start of the next
    give one line end, exactly as if they had come together.

    Examples
    --------
    >>> s = LineSplitter()
    >>> s.feed(b"a\\r"), s.feed(b"\\nb\\n\\nc"), s.reset(), s.pending
    ([b'a'], [b'b'], b'c', b'')
    """

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self.max_line = max_line
        self._buffer = bytearray()

    @property
    def pending(self) -> bytes:
        """The partial line received so far (bytes after the last line end)."""
        return bytes(self._buffer)

    def feed(self, data: bytes) -> list[bytes]:
        """Add ``data``; return the lines it completed (without their line ends)."""
        lines: list[bytes] = []
        for byte in data:
            if byte in (10, 13):
                if self._buffer:
                    lines.append(bytes(self._buffer))
                    self._buffer.clear()
            else:
                self._buffer.append(byte)
                if len(self._buffer) >= self.max_line:
                    lines.append(bytes(self._buffer))
                    self._buffer.clear()
        return lines

    def reset(self) -> bytes:
        """Forget the partial line (a port was lost or reopened); return what was dropped."""
        dropped = bytes(self._buffer)
        self._buffer.clear()
        return dropped


@dataclass(frozen=True)
class Record:
    """One parsed line of a probe stream.

    Attributes
    ----------
    kind : {"point", "blank", "text", "garbage"}
    text : str
        The line, decoded (UTF-8, else Latin-1) and stripped of control characters.
    xyz_mm : tuple of 3 floats or None
        The point, mm, for ``kind == "point"``.
    reason : str
        Why a line is not a point.
    """

    kind: RecordKind
    text: str
    xyz_mm: tuple[float, float, float] | None = None
    reason: str = ""


def decode_line(line: bytes | str) -> str:
    """A line as text: UTF-8 if it is, else Latin-1 (never fails), stripped of controls.

    >>> decode_line(b"\\x02X=1 Y=2 Z=3\\x03\\x00"), decode_line(b"caf\\xe9")
    ('X=1 Y=2 Z=3', 'café')
    """
    if isinstance(line, bytes):
        try:
            text = line.decode("utf-8")
        except UnicodeDecodeError:
            text = line.decode("latin-1")
    else:
        text = line
    return text.strip(_CONTROL)


def _unit_scale(units: list[str | None], default_unit: str) -> float | None:
    """Scale to mm of a line's numbers, None when their units disagree."""
    given = [u.lower() for u in units if u is not None]
    if not given:
        return UNITS_MM[default_unit]
    if len(given) == len(units) and len(set(given)) == 1:
        return UNITS_MM[given[0]]
    if len(given) == 1 and units[-1] is not None:  # one unit at the end of the line
        return UNITS_MM[given[0]]
    return None


def _number(text: str) -> float:
    return float(text.replace(" ", "").replace("\t", ""))


def parse_record(line: bytes | str, default_unit: str = "mm") -> Record:
    """Parse one line of a probe stream.

    Parameters
    ----------
    line : bytes or str
        The line without its line end.
    default_unit : str
        Unit of numbers without a suffix (a key of :data:`UNITS_MM`).

    Returns
    -------
    Record

    Examples
    --------
    >>> parse_record("X=1.2 Y=3.4 Z=5.6").xyz_mm
    (1.2, 3.4, 5.6)
    >>> parse_record("1.2;3.4;5.6 mm").xyz_mm, parse_record("1000um 0um 1um").xyz_mm
    ((1.2, 3.4, 5.6), (1.0, 0.0, 0.001))
    >>> parse_record("1.2,3.4,5.6,7.8").kind, parse_record("1mm 2in 3mm").reason
    ('garbage', 'numbers in different units')
    """
    if default_unit not in UNITS_MM:
        raise ValueError(f"unknown unit {default_unit!r}; expected one of {', '.join(UNITS_MM)}")
    text = decode_line(line)
    if not text:
        return Record("blank", text, reason="empty line")
    match = _LETTERED.fullmatch(text) or _PLAIN.fullmatch(text)
    if match is not None:
        scale = _unit_scale([match.group("ux"), match.group("uy"), match.group("uz")], default_unit)
        if scale is None:
            return Record("garbage", text, reason="numbers in different units")
        x, y, z = (_number(match.group(a)) * scale for a in "xyz")
        if not all(math.isfinite(v) for v in (x, y, z)):
            return Record("garbage", text, reason="a number overflows (not finite)")
        return Record("point", text, (x + 0.0, y + 0.0, z + 0.0))
    if not any(c.isdigit() for c in text):
        return Record("text", text, reason="no number (a prompt, status or echoed command)")
    if any(c in _CONTROL[:-2] or c == "\ufffd" for c in text):
        return Record("garbage", text, reason="control characters or undecodable bytes")
    return Record("garbage", text, reason="not a record X.. Y.. Z.. or x,y,z")


def parse_numbers(line: bytes | str, minimum: int = 6) -> tuple[float, ...] | None:
    """The numbers of a line of ``minimum`` or more numbers (a thermocouple logger's line).

    Numbers are separated by ``,``, ``;``, tabs or blanks and may end in ``C``
    or ``°C``. Returns None when the line is anything else (a number that overflows
    a float, ``1e400``, included).

    Examples
    --------
    >>> parse_numbers("20.1, 20.2, 20.3, 20.4, 20.5, 20.6, 19.9")
    (20.1, 20.2, 20.3, 20.4, 20.5, 20.6, 19.9)
    >>> parse_numbers("T 20.1 20.2") is None
    True
    """
    text = decode_line(line)
    tokens = [t for t in re.split(r"[,;\s]+", text) if t]
    values = []
    for token in tokens:
        match = _NUMBER_TOKEN.fullmatch(token)
        if match is None:
            return None
        value = _number(match.group("v"))
        if not math.isfinite(value):
            return None
        values.append(value)
    return tuple(values) if len(values) >= minimum else None


def format_number(value: float) -> str:
    """Shortest text that reads back to the same float (how points.csv writes numbers).

    >>> format_number(123.4567), format_number(-0.0), format_number(25.4 * 3)
    ('123.4567', '0.0', '76.19999999999999')
    """
    return repr(float(value) + 0.0)
