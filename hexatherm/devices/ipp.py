"""I++ DME client: drive a CMM over TCP (I++ DME specification 1.4.3).

The protocol in short (spec sections in brackets)
-------------------------------------------------
- TCP, port 1294 by default [6.1]; printable ASCII lines ended by CR LF [6.1.1];
  lengths in mm, angles in degrees [6.1.2].
- A command is ``TAG Method(args)`` [6.2.2.1]; ``TAG`` is ``00001`` .. ``99999`` for the
  normal queue or ``E0001`` .. ``E9999`` for the fast (event) queue [6.2.1].
- Every response line starts with the tag of its command, a space and one of ``&`` (ack),
  ``#`` (data), ``%`` (transaction complete) or ``!`` (error,
  ``Error(severity, number, "method", "text")``) [6.2.2.2, 8.1]. A transaction is complete
  at its ``%`` [6.2.3]. Lines tagged ``E0000`` are unsolicited server events and may come at
  any time, between the data lines of an open transaction too [6.2.4].
- An error of severity >= 2 aborts the pending transactions; the server then only accepts
  ``ClearAllErrors()`` (and the error-status queries) until it gets one [6.2.5].
- ``PtMeas(X(x), Y(y), Z(z), IJK(i, j, k))`` probes one point: the probe goes to the
  approach position ``(x, y, z) + (approach + tip radius) ijk`` and searches along
  ``-ijk`` [6.3.2.13]; the report holds the fields set by ``OnPtMeasReport`` [6.3.2.6].
  hexatherm reads ``X Y Z`` as the probed **surface point** (the tool radius compensated,
  as in the spec's example 7.5: ``PtMeas(X(200), ...)`` answers ``X(199.998), ...``),
  ``IJK`` as the measured surface normal (out of the material) and ``ER`` as the effective
  tool radius, all in the CMM's active coordinate system, mm.

Layers of this module
---------------------
- :func:`parse_response`, :func:`parse_command`, :func:`parse_data`: pure parsers of one
  line (spaces allowed around commas and parentheses, numbers with exponents and signs).
- :class:`LineBuffer`: bytes in, whole lines out (lines split across reads).
- :class:`Recorder`: the protocol's state machine, without I/O. It is fed the lines sent,
  the lines received and the client's notes, in order, and groups them into per-tag
  transactions, events and probed points. The live client and :func:`replay_transcript`
  feed it the same entries, so a replay gives the same points, bit for bit.
- :class:`IppClient`: socket, reader thread, tags, timeouts, recovery policy, transcript.
- :func:`cap_touch_plan` and :func:`probe_cap`: touch points on a ball's upper cap with
  clearance moves, and their execution.

Transcript format
-----------------
UTF-8 text (in practice ASCII), one entry per line ended by LF::

    # hexatherm ipp transcript 1
    2024-05-01T10:00:00.123456+02:00 > "00001 StartSession()"
    2024-05-01T10:00:00.125002+02:00 < "00001 &"
    2024-05-01T10:00:00.125010+02:00 < "00001 %"
    2024-05-01T10:00:07.000000+02:00 * "abandon 00007 timeout after 5 s"

The first field is the local time with its UTC offset (ISO 8601, microseconds) at which the
line was sent or the received line was complete; the second is the direction: ``>`` a
command line sent, ``<`` a response line received, ``*`` a note of the client (``connect
HOST:PORT``, ``abandon TAG REASON``, ``lost REASON``, ``close``); the third is the line
without its CR LF, in double quotes, with ``\\\\``, ``\\"`` and ``\\xNN`` (bytes outside 32 ..
126) escaped. Entries are written in the order in which the client acted on them;
:func:`replay_transcript` feeds them to a new :class:`Recorder` and gets the same
transactions, events and points.

Examples
--------
>>> r = parse_response("00012 # X(1.5), Y(-2.25e-3), Z(3E+2), IJK(0,0,1), ER(1)")
>>> r.tag, r.kind, fields(r.data)["Z"], fields(r.data)["IJK"]
('00012', '#', (300.0,), (0.0, 0.0, 1.0))
>>> parse_response('00003 ! Error(3, 2500, "GoTo", "Machine limit encountered")').error
ErrorReport(severity=3, number=2500, method='GoTo', text='Machine limit encountered')
"""

from __future__ import annotations

import math
import os
import queue
import re
import socket
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import IO, Literal, Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.core.twin import cap_directions
from hexatherm.errors import (
    IppCommandError,
    IppConnectionLost,
    IppDmeError,
    IppErrorState,
    IppProtocolError,
    IppTimeout,
)
from hexatherm.typing import FloatArray

DEFAULT_PORT = 1294
"""The I++ DME application port [6.1]."""
MAX_LINE = 65536
"""Longest line accepted, characters without CR LF [6.2]."""
TRANSCRIPT_MAGIC = "# hexatherm ipp transcript 1"
"""First line of a transcript file."""
DEFAULT_REPORT = ("X", "Y", "Z")
"""``OnPtMeasReport`` fields in force after ``StartSession()`` [6.3.1.1]."""
REPORT_ARITY = {"X": 1, "Y": 1, "Z": 1, "IJK": 3, "ER": 1, "Q": 1, "R": 1}
"""Numbers carried by each ``PtMeas`` report field."""
ALLOWED_IN_ERROR = frozenset(
    {"ClearAllErrors", "GetErrStatusE", "GetXtdErrStatus", "StartSession", "EndSession", "AbortE"}
)
"""Methods the client still sends while the server is in an error state (6.2.5; a new
session clears the errors, 6.3.1.1)."""

Direction = Literal[">", "<", "*"]
Decision = Literal["retry", "raise"]


# ---------------------------------------------------------------------------- terms
class Word(str):
    """A bare name used as a value (``Switch``, ``PartCsy``, ``E0553``), not a quoted string."""

    __slots__ = ()

    def __repr__(self) -> str:
        return f"Word({str.__repr__(self)})"


@dataclass(frozen=True)
class Call:
    """``Name(args)``: a method or a property with its arguments.

    Attributes
    ----------
    name : str
        Dotted name (``X``, ``Tool.PtMeasPar.Speed``, ``ChangeToolAction``).
    args : tuple
        Arguments: ``float`` numbers, ``str`` strings, :class:`Word` names, nested calls.
    """

    name: str
    args: tuple[Value, ...] = ()

    def format(self) -> str:
        """The call as protocol text (numbers by :func:`format_number`)."""
        return f"{self.name}({', '.join(format_value(a) for a in self.args)})"


Value = float | str | Call
"""A parsed argument or data item: number, string (:class:`Word` for bare names) or call."""


@dataclass(frozen=True)
class ErrorReport:
    """One ``Error(F1, F2, F3, Text)`` of the server [8.1].

    Attributes
    ----------
    severity : int
        0 info, 1 warning (pending commands go on), 2 error the client can repair,
        3 error needing the operator, 9 fatal; >= 2 needs ``ClearAllErrors()``.
    number : int
        Error number (0000-4999 defined by I++ DME, e.g. 1006 surface not found).
    method : str
        The method that reported it.
    text : str
        The error's text.
    """

    severity: int
    number: int
    method: str
    text: str

    def format(self) -> str:
        """The error as protocol text.

        >>> ErrorReport(2, 1006, "PtMeas", "Surface not found").format()
        'Error(2, 1006, "PtMeas", "Surface not found")'
        """
        return f'Error({self.severity}, {self.number:04d}, "{self.method}", "{self.text}")'

    def __str__(self) -> str:
        return f"severity {self.severity} error {self.number:04d} in {self.method}: {self.text}"


_TOKEN = re.compile(
    r"""(?P<space>[ \t]+)
      | (?P<string>"[^"]*")
      | (?P<number>[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]{1,3})?(?![0-9A-Za-z_.]))
      | (?P<name>[A-Za-z][A-Za-z0-9]*(?:\.[A-Za-z][A-Za-z0-9]*)*)
      | (?P<punct>[(),])""",
    re.VERBOSE,
)
_TAG = re.compile(r"[0-9]{5}|E[0-9]{4}")


def _tokens(text: str) -> list[tuple[str, str]]:
    out = []
    pos = 0
    while pos < len(text):
        match = _TOKEN.match(text, pos)
        if match is None:
            raise IppProtocolError(f"unexpected {text[pos : pos + 12]!r} at column {pos + 1}")
        kind = match.lastgroup or ""
        if kind != "space":
            out.append((kind, match.group()))
        pos = match.end()
    return out


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.toks = _tokens(text)
        self.i = 0

    def peek(self) -> tuple[str, str]:
        return self.toks[self.i] if self.i < len(self.toks) else ("end", "")

    def take(self, value: str) -> None:
        kind, tok = self.peek()
        if tok != value or kind not in ("punct",):
            raise IppProtocolError(f"expected {value!r}, got {tok or 'end of line'!r}")
        self.i += 1

    def values(self, closing: str | None) -> tuple[Value, ...]:
        items: list[Value] = []
        if self.peek()[1] == closing and closing is not None:
            return ()
        if closing is None and self.peek()[0] == "end":
            return ()
        while True:
            items.append(self.value())
            if self.peek()[1] == ",":
                self.i += 1
                continue
            return tuple(items)

    def value(self) -> Value:
        kind, tok = self.peek()
        self.i += 1
        if kind == "number":
            return float(tok)
        if kind == "string":
            return tok[1:-1]
        if kind == "name":
            if self.peek()[1] == "(":
                self.i += 1
                args = self.values(")")
                self.take(")")
                return Call(tok, args)
            return Word(tok)
        raise IppProtocolError(f"expected a value, got {tok or 'end of line'!r}")

    def done(self) -> None:
        if self.i != len(self.toks):
            raise IppProtocolError(f"unexpected {self.toks[self.i][1]!r} after the end")


def parse_data(body: str) -> tuple[Value, ...]:
    """The comma-separated items of a data line's body (or of an argument list).

    Parameters
    ----------
    body : str
        Text after ``TAG # ``.

    Returns
    -------
    tuple
        Numbers as ``float``, strings as ``str``, bare names as :class:`Word`, ``Name(...)``
        as :class:`Call`.

    Raises
    ------
    IppProtocolError
        On a syntax error (unbalanced parentheses, ``1.5.3``, a 4-digit exponent, ...).

    Examples
    --------
    >>> parse_data('X(-2.6E01), "Speed", Switch, 4.')
    (Call(name='X', args=(-26.0,)), 'Speed', Word('Switch'), 4.0)
    """
    parser = _Parser(body)
    items = parser.values(None)
    parser.done()
    return items


def fields(values: Iterable[Value]) -> dict[str, tuple[float, ...]]:
    """``{name: numbers}`` of data items that are all calls with numeric arguments.

    Raises
    ------
    IppProtocolError
        On an item that is not such a call, or a name given twice.

    Examples
    --------
    >>> fields(parse_data("X(1), IJK(0, 0.6, 0.8)"))
    {'X': (1.0,), 'IJK': (0.0, 0.6, 0.8)}
    """
    out: dict[str, tuple[float, ...]] = {}
    for item in values:
        if not isinstance(item, Call) or not all(isinstance(a, float) for a in item.args):
            raise IppProtocolError(f"expected Name(numbers), got {format_value(item)!r}")
        if item.name in out:
            raise IppProtocolError(f"{item.name} given twice")
        out[item.name] = tuple(float(a) for a in item.args)  # type: ignore[arg-type]
    return out


@dataclass(frozen=True)
class Response:
    """One parsed response line.

    Attributes
    ----------
    tag : str
        ``00001`` .. ``99999``, ``E0001`` .. ``E9999`` or ``E0000`` (unsolicited).
    kind : str
        ``&`` ack, ``#`` data, ``%`` complete, ``!`` error.
    body : str
        Text after ``kind`` and its space ('' for ``&`` and ``%``).
    data : tuple
        Parsed items of a ``#`` line (:func:`parse_data`), else ``()``.
    error : ErrorReport or None
        The error of a ``!`` line.
    """

    tag: str
    kind: str
    body: str
    data: tuple[Value, ...] = ()
    error: ErrorReport | None = None

    @property
    def is_event(self) -> bool:
        """True for an event tag (``E....``)."""
        return self.tag.startswith("E")


def _as_text(line: str | bytes) -> str:
    if isinstance(line, bytes):
        line = line.decode("latin-1")
    if line.endswith("\r\n"):
        line = line[:-2]
    bad = [c for c in line if not 32 <= ord(c) <= 126]
    if bad:
        raise IppProtocolError(f"illegal character {bad[0]!r} (only ASCII 32..126 allowed)")
    return line


def _split_tag(text: str) -> tuple[str, str]:
    tag = text[:5]
    if not _TAG.fullmatch(tag):
        raise IppProtocolError(f"bad tag {tag!r} (5 digits or E and 4 digits)")
    if tag == "00000":
        raise IppProtocolError("tag 00000 is not allowed")
    if text[5:6] != " ":
        raise IppProtocolError(f"no space after the tag in {text[:20]!r}")
    return tag, text[6:].lstrip(" ")


def _error_report(values: tuple[Value, ...]) -> ErrorReport:
    if len(values) != 1 or not isinstance(values[0], Call) or values[0].name != "Error":
        raise IppProtocolError("an error line must hold Error(F1, F2, F3, Text)")
    args = values[0].args
    if len(args) != 4:
        raise IppProtocolError(f"Error(...) needs 4 fields, got {len(args)}")
    sev, num, method, text = args
    if not (isinstance(sev, float) and sev.is_integer() and 0 <= sev <= 9):
        raise IppProtocolError(f"bad error severity {format_value(sev)!r}")
    if not (isinstance(num, float) and num.is_integer() and 0 <= num <= 9999):
        raise IppProtocolError(f"bad error number {format_value(num)!r}")
    if isinstance(method, Call) or isinstance(method, float) or not isinstance(text, str):
        raise IppProtocolError("error method must be a name or string and text a string")
    if isinstance(text, Word):
        raise IppProtocolError("error text must be a quoted string")
    return ErrorReport(int(sev), int(num), str(method), str(text))


def parse_response(line: str | bytes) -> Response:
    """Parse one response line (without or with its CR LF).

    Parameters
    ----------
    line : str or bytes
        ``TAG & | TAG % | TAG # data | TAG ! Error(F1, F2, F3, Text)``.

    Returns
    -------
    Response

    Raises
    ------
    IppProtocolError
        Bad tag, missing space, unknown kind, malformed data or error, illegal character.

    Examples
    --------
    >>> parse_response("E0000 # KeyPress(\\"F1\\")").data
    (Call(name='KeyPress', args=('F1',)),)
    >>> parse_response("00001 &").kind
    '&'
    """
    text = _as_text(line)
    tag, rest = _split_tag(text)
    kind, body = rest[:1], rest[1:]
    if kind in ("&", "%"):
        if body.strip():
            raise IppProtocolError(f"unexpected text after {kind!r}: {body.strip()[:20]!r}")
        return Response(tag, kind, "")
    if kind not in ("#", "!"):
        raise IppProtocolError(f"unknown response kind {kind!r} (expected & # % !)")
    if not body.startswith(" ") or not body.strip():
        raise IppProtocolError(f"{kind!r} must be followed by a space and data")
    body = body.strip(" ")
    values = parse_data(body)
    if kind == "!":
        return Response(tag, kind, body, error=_error_report(values))
    return Response(tag, kind, body, data=values)


def parse_command(line: str | bytes) -> tuple[str, Call]:
    """Parse a command line: ``TAG Method(args)`` -> ``(tag, Call)``.

    >>> parse_command("00180 PtMeas(X(75.0), Y(50.0), Z(40.0), IJK(-1.0, 0.0, 0.0))")[1].args[3]
    Call(name='IJK', args=(-1.0, 0.0, 0.0))
    """
    text = _as_text(line)
    tag, rest = _split_tag(text)
    if tag == "E0000":
        raise IppProtocolError("E0000 is reserved for the server's events")
    values = parse_data(rest)
    if len(values) != 1 or not isinstance(values[0], Call) or "." in values[0].name:
        raise IppProtocolError(f"expected one Method(args), got {rest[:40]!r}")
    return tag, values[0]


def format_number(value: float) -> str:
    """A number as protocol text: at most 16 digits in all (the grammar's limit, 6.1.4.2).

    15 significant digits, fewer when leading zeros or the exponent would make more than 16.

    >>> format_number(100.0), format_number(-2.5e-05), format_number(0.1 + 0.2)
    ('100', '-2.5e-05', '0.3')
    >>> format_number(1 / 7000), format_number(-1e300 / 7)
    ('0.000142857142857', '-1.428571428571e+299')
    """
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"not a finite number: {value!r}")
    for digits in range(15, 0, -1):
        text = f"{v:.{digits}g}"
        if sum(c.isdigit() for c in text) <= 16:
            return text
    raise AssertionError("unreachable")  # pragma: no cover - 1 digit + 3 exponent digits


def format_value(value: Value) -> str:
    """A parsed value back as protocol text."""
    if isinstance(value, Call):
        return value.format()
    if isinstance(value, Word):
        return str(value)
    if isinstance(value, str):
        return f'"{value}"'
    return format_number(value)


# ------------------------------------------------------------------------ lines
class LineBuffer:
    """Bytes in, whole lines out: keeps a partial line until its LF arrives.

    Lines end with CR LF; the CR is dropped with the LF (a lone LF also ends a line).

    >>> buf = LineBuffer()
    >>> buf.feed(b"00001 &\\r"), buf.feed(b"\\n00001 # X(1"), buf.feed(b")\\r\\n")
    ([], [b'00001 &'], [b'00001 # X(1)'])
    """

    def __init__(self, max_line: int = MAX_LINE) -> None:
        self._pending = b""
        self.max_line = max_line

    @property
    def pending(self) -> bytes:
        """Bytes of an incomplete line."""
        return self._pending

    def feed(self, data: bytes) -> list[bytes]:
        """Add bytes; return the lines they complete (without CR LF).

        Raises
        ------
        IppProtocolError
            When a line grows longer than ``max_line`` characters.
        """
        self._pending += data
        *lines, self._pending = self._pending.split(b"\n")
        if len(self._pending) > self.max_line + 1:
            raise IppProtocolError(f"line longer than {self.max_line} characters")
        out = []
        for line in lines:
            if line.endswith(b"\r"):
                line = line[:-1]
            if len(line) > self.max_line:
                raise IppProtocolError(f"line longer than {self.max_line} characters")
            out.append(line)
        return out


# -------------------------------------------------------------------- transcript
def now_iso() -> str:
    """The local time with its UTC offset, microseconds (ISO 8601)."""
    return datetime.now().astimezone().isoformat(timespec="microseconds")


def _escape(text: str) -> str:
    out = []
    for ch in text:
        code = ord(ch)
        if ch in '\\"':
            out.append("\\" + ch)
        elif 32 <= code <= 126:
            out.append(ch)
        elif code <= 0xFF:
            out.append(f"\\x{code:02x}")
        else:
            raise ValueError(f"character {ch!r} cannot go in a transcript")
    return "".join(out)


_UNESCAPE = re.compile(r'\\(x[0-9a-f]{2}|["\\])?')


def _unescape(text: str) -> str:
    def sub(match: re.Match[str]) -> str:
        code = match.group(1)
        if code is None:
            raise ValueError("bad escape")
        return chr(int(code[1:], 16)) if len(code) == 3 else code

    return _UNESCAPE.sub(sub, text)


@dataclass(frozen=True)
class TranscriptEntry:
    """One transcript line: time, direction (``>`` sent, ``<`` received, ``*`` note), text."""

    time: str
    direction: Direction
    text: str

    def format(self) -> str:
        """The entry as a transcript line, with its LF.

        >>> TranscriptEntry("2024-05-01T10:00:00.000000+00:00", "<", '00001 # "a"').format()
        '2024-05-01T10:00:00.000000+00:00 < "00001 # \\\\"a\\\\""\\n'
        """
        return f'{self.time} {self.direction} "{_escape(self.text)}"\n'


_ENTRY = re.compile(r'(\S+) ([<>*]) "(.*)"')


def parse_transcript(text: str) -> list[TranscriptEntry]:
    """The entries of a transcript (its first line must be :data:`TRANSCRIPT_MAGIC`).

    A last line without its LF (the writer died while writing it) is left out.

    Raises
    ------
    IppDmeError
        Not a transcript, or a malformed line (with its line number).
    """
    lines = text.split("\n")
    lines.pop()  # '' after the last LF, or an incomplete last line
    if not lines or lines[0].rstrip("\r") != TRANSCRIPT_MAGIC:
        raise IppDmeError(f"not an I++ transcript (first line must be {TRANSCRIPT_MAGIC!r})")
    entries = []
    for number, line in enumerate(lines[1:], start=2):
        match = _ENTRY.fullmatch(line.rstrip("\r"))
        if match is None:
            raise IppDmeError(f"transcript line {number}: malformed {line[:60]!r}")
        try:
            body = _unescape(match.group(3))
        except ValueError:
            raise IppDmeError(f"transcript line {number}: bad escape") from None
        direction: Direction = match.group(2)  # type: ignore[assignment]
        entries.append(TranscriptEntry(match.group(1), direction, body))
    return entries


TranscriptSink = Callable[[str], object] | IO[str]
"""Where transcript lines go: a callable taking each line, or a text file (flushed)."""


class TranscriptFile:
    """A transcript file opened for appending (header written when new); a callable sink.

    Every line is flushed, and fsync'd when ``durable`` (the default), before the client acts
    on it, so that a crash loses nothing the client used.
    """

    def __init__(self, path: str | os.PathLike[str], *, durable: bool = True) -> None:
        self.path = os.fspath(path)
        self.durable = durable
        new = not os.path.exists(self.path) or os.path.getsize(self.path) == 0
        self._handle = open(self.path, "a", encoding="ascii", newline="\n")  # noqa: SIM115
        if new:
            self(TRANSCRIPT_MAGIC + "\n")

    def __call__(self, line: str) -> None:
        self._handle.write(line)
        self._handle.flush()
        if self.durable:
            os.fsync(self._handle.fileno())

    def close(self) -> None:
        """Close the file."""
        self._handle.close()


# ---------------------------------------------------------------------- recorder
@dataclass(frozen=True)
class ProbedPoint:
    """One point probed by ``PtMeas``, as the server reported it.

    Attributes
    ----------
    tag : str
        The ``PtMeas`` transaction's tag.
    time : str
        When its data line arrived (ISO 8601 with offset).
    nominal_mm : tuple of 3 float
        Commanded nominal point (mm); coordinates not commanded are NaN.
    nominal_ijk : tuple of 3 float or None
        Commanded approach direction (not normalized), if given.
    point_mm : tuple of 3 float
        Reported ``X, Y, Z`` (mm, the CMM's coordinate system).
    ijk : tuple of 3 float or None
        Reported ``IJK`` (as sent: not necessarily normalized), if in the report.
    er_mm : float or None
        Reported effective tool radius ``ER`` (mm), if in the report.
    """

    tag: str
    time: str
    nominal_mm: tuple[float, float, float]
    nominal_ijk: tuple[float, float, float] | None
    point_mm: tuple[float, float, float]
    ijk: tuple[float, float, float] | None
    er_mm: float | None

    @property
    def normal(self) -> FloatArray | None:
        """The reported ``IJK`` normalized (unit vector out of the material), or None."""
        if self.ijk is None:
            return None
        v = np.array(self.ijk, dtype=float)
        norm = float(np.linalg.norm(v))
        return v / norm if norm > 0 else None


@dataclass
class TransactionResult:
    """A completed transaction: the command and everything the server answered to it.

    Attributes
    ----------
    tag, command, method : str
        Tag, command text (``Method(args)``) and method name.
    sent_time : str
        When the command was sent.
    ack_time, done_time : str or None
        When its ``&`` and its ``%`` arrived.
    data : list of (str, tuple)
        Every ``#`` line: its time and parsed items.
    errors : list of ErrorReport
        Every ``!`` line (warnings included).
    protocol_error : str or None
        Why the answer breaks the protocol (e.g. a report that does not match the
        requested fields); such a result gives no point.
    point : ProbedPoint or None
        For a successful ``PtMeas``.
    report : tuple of str
        The ``OnPtMeasReport`` fields in force when the command was sent.
    """

    tag: str
    command: str
    method: str
    sent_time: str
    ack_time: str | None = None
    done_time: str | None = None
    data: list[tuple[str, tuple[Value, ...]]] = field(default_factory=list)
    errors: list[ErrorReport] = field(default_factory=list)
    protocol_error: str | None = None
    point: ProbedPoint | None = None
    report: tuple[str, ...] = DEFAULT_REPORT

    @property
    def failure(self) -> ErrorReport | None:
        """The first error of severity >= 2, if any."""
        return next((e for e in self.errors if e.severity >= 2), None)

    @property
    def warnings(self) -> list[ErrorReport]:
        """Errors of severity 0 and 1 (the transaction went on)."""
        return [e for e in self.errors if e.severity < 2]


@dataclass(frozen=True)
class IppEvent:
    """A response line not part of an open transaction of the client.

    ``E0000`` lines (unsolicited server events), lines of the client's event tags after their
    transaction completed (daemon reports), and lines of tags the client does not know.

    Attributes
    ----------
    time : str
        When it arrived.
    line : str
        The line as received.
    response : Response or None
        Parsed, or None when the line is malformed (``problem`` says why).
    problem : str or None
        Why the line could not be parsed.
    """

    time: str
    line: str
    response: Response | None
    problem: str | None = None


def _method_of(command: str) -> str:
    match = re.match(r"\s*([A-Za-z][A-Za-z0-9]*)", command)
    return match.group(1) if match else ""


def _point_from(
    result: TransactionResult, command: Call | None, stamp: str, values: tuple[Value, ...]
) -> ProbedPoint:
    items = list(values)
    names = [item.name if isinstance(item, Call) else format_value(item) for item in items]
    if tuple(names) != result.report:
        raise IppProtocolError(
            f"PtMeas report {', '.join(names)} does not match OnPtMeasReport "
            f"{', '.join(result.report)}"
        )
    got = fields(items)
    for name, numbers in got.items():
        if len(numbers) != REPORT_ARITY.get(name, len(numbers)):
            raise IppProtocolError(f"{name} must carry {REPORT_ARITY[name]} number(s)")
    nominal = [math.nan, math.nan, math.nan]
    nominal_ijk = None
    if command is not None:
        given = fields(command.args)
        for axis, name in enumerate("XYZ"):
            if name in given:
                nominal[axis] = given[name][0]
        if "IJK" in given:
            i, j, k = given["IJK"]
            nominal_ijk = (i, j, k)
    ijk = got.get("IJK")
    er = got.get("ER")
    return ProbedPoint(
        tag=result.tag,
        time=stamp,
        nominal_mm=(nominal[0], nominal[1], nominal[2]),
        nominal_ijk=nominal_ijk,
        point_mm=(got["X"][0], got["Y"][0], got["Z"][0]),
        ijk=None if ijk is None else (ijk[0], ijk[1], ijk[2]),
        er_mm=None if er is None else er[0],
    )


class Recorder:
    """The protocol's state machine, without I/O: lines in, transactions and points out.

    Feed it, in order, every line sent (:meth:`sent`), every line received
    (:meth:`received`) and the client's notes (:meth:`note`). It keeps the open transactions
    per tag, completes them at their ``%``, routes every other line to the events, follows
    the ``OnPtMeasReport`` fields in force and the server's error state, and turns every
    successful ``PtMeas`` into a :class:`ProbedPoint`.

    Attributes
    ----------
    results : list of TransactionResult
        Completed transactions, in order of completion.
    points : list of ProbedPoint
        Points of the successful ``PtMeas`` transactions, in order.
    events : list of IppEvent
        Lines routed to the event channel.
    error_state : ErrorReport or None
        The error of severity >= 2 the server is stuck on until ``ClearAllErrors()``.
    report : tuple of str
        ``OnPtMeasReport`` fields in force.
    open : dict of str to TransactionResult
        Transactions sent and not complete, by tag.
    abandoned : set of str
        Tags given up (timeout): their late lines are ignored.
    lost : str or None
        Why the connection ended, once it did.
    """

    def __init__(self) -> None:
        self.open: dict[str, TransactionResult] = {}
        self.abandoned: set[str] = set()
        self.results: list[TransactionResult] = []
        self.points: list[ProbedPoint] = []
        self.events: list[IppEvent] = []
        self.error_state: ErrorReport | None = None
        self.report: tuple[str, ...] = DEFAULT_REPORT
        self.lost: str | None = None

    def sent(self, stamp: str, line: str) -> None:
        """A command line was sent."""
        tag = line[:5]
        command = line[6:]
        self.abandoned.discard(tag)
        self.open[tag] = TransactionResult(
            tag, command, _method_of(command), stamp, report=self.report
        )

    def note(self, stamp: str, text: str) -> list[TransactionResult]:
        """A note of the client; returns the transactions it ends (abandoned or lost)."""
        word, _, rest = text.partition(" ")
        if word == "abandon":
            tag = rest[:5]
            dropped = self.open.pop(tag, None)
            self.abandoned.add(tag)
            return [dropped] if dropped is not None else []
        if word in ("lost", "close"):
            self.lost = rest or word
            dropped_all = list(self.open.values())
            self.open.clear()
            return dropped_all
        return []

    def received(self, stamp: str, line: str) -> tuple[TransactionResult | None, IppEvent | None]:
        """A response line arrived; returns the transaction it completes or the event it is."""
        try:
            response = parse_response(line)
        except IppProtocolError as exc:
            # A line we cannot read may belong to any open transaction: none of them can be
            # trusted any more (they still complete at their '%').
            for pending in self.open.values():
                pending.protocol_error = pending.protocol_error or f"malformed line {line!r}: {exc}"
            event = IppEvent(stamp, line, None, str(exc))
            self.events.append(event)
            return None, event
        if response.kind == "!" and response.error is not None and response.error.severity >= 2:
            self.error_state = response.error
        result = self.open.get(response.tag)
        if result is None:
            if response.tag in self.abandoned:
                return None, None
            event = IppEvent(stamp, line, response)
            self.events.append(event)
            return None, event
        if response.kind == "&":
            result.ack_time = stamp
        elif response.kind == "#":
            result.data.append((stamp, response.data))
        elif response.kind == "!" and response.error is not None:
            result.errors.append(response.error)
        elif response.kind == "%":
            result.done_time = stamp
            del self.open[response.tag]
            self._complete(result)
            self.results.append(result)
            return result, None
        return None, None

    def _complete(self, result: TransactionResult) -> None:
        ok = result.failure is None and result.protocol_error is None
        if result.method in ("ClearAllErrors", "StartSession") and ok:
            self.error_state = None
        if result.method == "StartSession" and ok:
            self.report = DEFAULT_REPORT
        if not ok:
            return
        try:
            command = parse_data(result.command)
            call = command[0] if len(command) == 1 and isinstance(command[0], Call) else None
        except IppProtocolError:
            call = None
        if result.method == "OnPtMeasReport" and call is not None:
            names = tuple(a.name for a in call.args if isinstance(a, Call))
            if names and len(names) == len(call.args):
                self.report = names
        if result.method == "PtMeas":
            try:
                if len(result.data) != 1:
                    raise IppProtocolError(
                        f"PtMeas answered {len(result.data)} data lines instead of 1"
                    )
                stamp, values = result.data[0]
                point = _point_from(result, call, stamp, values)
            except IppProtocolError as exc:
                result.protocol_error = str(exc)
                return
            result.point = point
            self.points.append(point)


@dataclass(frozen=True)
class Replay:
    """What :func:`replay_transcript` rebuilt."""

    results: list[TransactionResult]
    points: list[ProbedPoint]
    events: list[IppEvent]
    entries: list[TranscriptEntry]


def replay_transcript(text: str) -> Replay:
    """Feed a transcript to a new :class:`Recorder`: the transactions, points and events.

    The live client fed its recorder the same entries in the same order, so the points are
    the same, bit for bit (see :func:`format_points`).

    Examples
    --------
    >>> t = "\\n".join([TRANSCRIPT_MAGIC,
    ...     '2024-05-01T10:00:00.000000+00:00 > "00007 PtMeas(X(1), Y(2), Z(3), IJK(0,0,1))"',
    ...     '2024-05-01T10:00:00.100000+00:00 < "00007 &"',
    ...     '2024-05-01T10:00:00.200000+00:00 < "00007 # X(1.0005), Y(2), Z(2.5e0)"',
    ...     '2024-05-01T10:00:00.300000+00:00 < "00007 %"', ""])
    >>> replay_transcript(t).points[0].point_mm
    (1.0005, 2.0, 2.5)
    """
    entries = parse_transcript(text)
    recorder = Recorder()
    for entry in entries:
        if entry.direction == ">":
            recorder.sent(entry.time, entry.text)
        elif entry.direction == "<":
            recorder.received(entry.time, entry.text)
        else:
            recorder.note(entry.time, entry.text)
    return Replay(recorder.results, recorder.points, recorder.events, entries)


def format_points(points: Sequence[ProbedPoint]) -> str:
    """Points as CSV text, every float written exactly (``repr``), for byte comparisons.

    Columns ``tag,time,x,y,z,i,j,k,er`` (mm; empty when not reported).
    """
    lines = ["tag,time,x,y,z,i,j,k,er"]
    for p in points:
        ijk = p.ijk if p.ijk is not None else ("", "", "")
        values = [*p.point_mm, *ijk, "" if p.er_mm is None else p.er_mm]
        lines.append(",".join([p.tag, p.time, *(repr(v) if v != "" else "" for v in values)]))
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------ policy
class RecoveryPolicy(Protocol):
    """Decides what the client does about an error of severity >= 2."""

    def decide(self, error: ErrorReport, command: str, attempt: int) -> Decision:
        """``"retry"`` (send ``ClearAllErrors()`` then the command again) or ``"raise"``.

        ``attempt`` is the number of recoveries already made for this command.
        """
        ...


@dataclass(frozen=True)
class ClearAndRetry:
    """Clear and retry errors up to ``max_severity`` at most ``retries`` times; raise others.

    The default (severity 2 once) repairs what the spec calls errors the client can repair
    (a lost touch, a transaction aborted) and stops on everything needing the operator
    (severity 3: collision, emergency stop, machine limits) or fatal (9).

    >>> p = ClearAndRetry()
    >>> e2, e3 = ErrorReport(2, 1006, "PtMeas", "x"), ErrorReport(3, 2504, "GoTo", "x")
    >>> p.decide(e2, "PtMeas()", 0), p.decide(e2, "PtMeas()", 1), p.decide(e3, "GoTo()", 0)
    ('retry', 'raise', 'raise')
    """

    retries: int = 1
    max_severity: int = 2

    def decide(self, error: ErrorReport, command: str, attempt: int) -> Decision:
        """See :class:`RecoveryPolicy`."""
        if error.severity <= self.max_severity and attempt < self.retries:
            return "retry"
        return "raise"


class _Waiter:
    def __init__(self, tag: str, command: str) -> None:
        self.tag = tag
        self.command = command
        self.done = threading.Event()
        self.result: TransactionResult | None = None
        self.error: IppDmeError | None = None


# ------------------------------------------------------------------------ client
class IppClient:
    """A client of an I++ DME server (one TCP connection).

    Parameters
    ----------
    host : str
        Server address.
    port : int
        Server port (1294 by default).
    timeout_s : float
        Default time a transaction may take from sending to its ``%``, s.
    connect_timeout_s : float
        Time to open the connection, s.
    transcript : callable or text file, optional
        Every line sent and received, and the client's notes, in the transcript format of
        the module docstring (the caller writes :data:`TRANSCRIPT_MAGIC` first, or uses a
        :class:`TranscriptFile`).
    on_event : callable, optional
        Called (from the reader thread) with every :class:`IppEvent`; without it the events
        go to the queue :attr:`events`. If it raises, the next command raises instead of
        being sent.
    policy : RecoveryPolicy, optional
        What to do about errors of severity >= 2 (default :class:`ClearAndRetry`).
    clock : callable, optional
        Timestamps (default :func:`now_iso`).

    Notes
    -----
    Commands are sent one at a time: each method sends its command with a fresh tag and waits
    for its ``%``. A reader thread splits the stream into lines, stamps, logs and feeds them to
    the :class:`Recorder` under one lock (so the transcript order is the order acted on), and
    wakes the waiting command. Events never complete or disturb a transaction.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        timeout_s: float = 60.0,
        connect_timeout_s: float = 10.0,
        transcript: TranscriptSink | None = None,
        on_event: Callable[[IppEvent], object] | None = None,
        policy: RecoveryPolicy | None = None,
        clock: Callable[[], str] = now_iso,
    ) -> None:
        if not (isinstance(port, int) and 0 < port < 65536):
            raise IppDmeError(f"port must be an integer in 1..65535, got {port!r}")
        if not (timeout_s > 0 and connect_timeout_s > 0):
            raise IppDmeError("timeouts must be positive")
        self.host, self.port = host, port
        self.timeout_s = float(timeout_s)
        self.policy: RecoveryPolicy = policy if policy is not None else ClearAndRetry()
        self.events: queue.SimpleQueue[IppEvent] = queue.SimpleQueue()
        self._on_event = on_event
        self._clock = clock
        self._sink = transcript
        self._lock = threading.Lock()
        self.recorder = Recorder()
        self._waiters: dict[str, _Waiter] = {}
        self._next_tag = 1
        self._next_etag = 1
        self._closing = False
        self.callback_error: Exception | None = None
        try:
            self._sock = socket.create_connection((host, port), timeout=connect_timeout_s)
        except OSError as exc:
            raise IppDmeError(f"cannot connect to the CMM at {host}:{port}: {exc}") from None
        self._sock.settimeout(None)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self._lock:
            self._log("*", f"connect {host}:{port}")
        self._reader = threading.Thread(target=self._read_loop, name="ipp-reader", daemon=True)
        self._reader.start()

    # -- plumbing
    def __enter__(self) -> IppClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def points(self) -> list[ProbedPoint]:
        """Every point probed so far (successful ``PtMeas``), in order."""
        return self.recorder.points

    @property
    def error_state(self) -> ErrorReport | None:
        """The error the server is stuck on (severity >= 2, until ``ClearAllErrors()``)."""
        return self.recorder.error_state

    def _log(self, direction: Direction, text: str) -> str:
        stamp = self._clock()
        if self._sink is not None:
            line = TranscriptEntry(stamp, direction, text).format()
            if callable(self._sink):
                self._sink(line)
            else:
                self._sink.write(line)
                self._sink.flush()
        return stamp

    def close(self) -> None:
        """End the connection (pending transactions fail with :class:`IppConnectionLost`)."""
        with self._lock:
            if self._closing:
                return
            self._closing = True
            if self.recorder.lost is None:
                stamp = self._log("*", "close")
                dropped = self.recorder.note(stamp, "close")
                self._fail(dropped, "the client closed the connection")
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        if threading.current_thread() is not self._reader:
            self._reader.join(timeout=5.0)

    def _fail(self, dropped: list[TransactionResult], reason: str) -> None:
        for result in dropped:
            waiter = self._waiters.pop(result.tag, None)
            if waiter is not None:
                waiter.error = IppConnectionLost(
                    f"connection to the CMM at {self.host}:{self.port} lost ({reason}) while "
                    f"waiting for {waiter.tag} {waiter.command}"
                )
                waiter.done.set()

    def _lose(self, reason: str) -> None:
        with self._lock:
            if self.recorder.lost is not None:
                return
            try:
                stamp = self._log("*", f"lost {reason}")
            except Exception:  # noqa: BLE001 - the transcript itself may be what failed
                stamp = self._clock()
            dropped = self.recorder.note(stamp, f"lost {reason}")
            self._fail(dropped, reason)

    def _read_loop(self) -> None:
        buffer = LineBuffer()
        while True:
            try:
                data = self._sock.recv(65536)
            except OSError as exc:
                if not self._closing:
                    self._lose(f"socket error: {exc}")
                return
            if not data:
                if not self._closing:
                    pending = buffer.pending
                    tail = f" ({len(pending)} bytes of an unfinished line)" if pending else ""
                    self._lose(f"connection closed by the server{tail}")
                return
            try:
                lines = buffer.feed(data)
            except IppProtocolError as exc:
                self._lose(f"protocol error: {exc}")
                return
            for raw in lines:
                try:
                    self._on_line(raw.decode("latin-1"))
                except Exception as exc:  # noqa: BLE001 - e.g. the transcript cannot be written
                    self._lose(f"{type(exc).__name__} while recording a line: {exc}")
                    return

    def _on_line(self, line: str) -> None:
        with self._lock:
            stamp = self._log("<", line)
            result, event = self.recorder.received(stamp, line)
            waiter = self._waiters.pop(result.tag, None) if result is not None else None
            if waiter is not None:
                waiter.result = result
                waiter.done.set()
        if event is not None:
            if self._on_event is None:
                self.events.put(event)
                return
            try:
                self._on_event(event)
            except Exception as exc:  # noqa: BLE001 - handed to the caller, see transact()
                with self._lock:
                    if self.callback_error is None:
                        self.callback_error = exc

    def _new_tag(self, event: bool) -> str:
        for _ in range(100000):
            if event:
                tag = f"E{self._next_etag:04d}"
                self._next_etag = self._next_etag % 9999 + 1
            else:
                tag = f"{self._next_tag:05d}"
                self._next_tag = self._next_tag % 99999 + 1
            if tag not in self.recorder.open and tag not in self.recorder.abandoned:
                return tag
        raise IppDmeError("no free tag")  # pragma: no cover - 99999 open transactions

    # -- transactions
    def transact(
        self, command: str, *, timeout_s: float | None = None, event: bool = False
    ) -> TransactionResult:
        """Send one command with a fresh tag and wait for its ``%`` (no recovery).

        Parameters
        ----------
        command : str
            ``Method(args)``.
        timeout_s : float, optional
            Time from sending to ``%`` (default: the client's).
        event : bool
            Send it on the fast queue with an ``E`` tag.

        Returns
        -------
        TransactionResult
            Errors included (see :attr:`TransactionResult.failure`).

        Raises
        ------
        IppTimeout
            No ``%`` in time: the tag is abandoned (its late lines are logged and ignored).
        IppConnectionLost
            The connection was or got lost; the message names the pending command. A line
            that cannot be recorded (the transcript sink raised) also ends the connection:
            nothing is acted on that is not in the transcript.
        IppDmeError
            The event callback raised since the last command (chained).
        """
        limit = self.timeout_s if timeout_s is None else float(timeout_s)
        if not limit > 0:
            raise IppDmeError(f"timeout_s must be positive, got {timeout_s!r}")
        if "\r" in command or "\n" in command:
            raise IppDmeError("a command cannot contain CR or LF")
        with self._lock:
            if self.recorder.lost is not None or self._closing:
                raise IppConnectionLost(
                    f"connection to the CMM at {self.host}:{self.port} is closed "
                    f"({self.recorder.lost or 'closed'}); cannot send {command}"
                )
            tag = self._new_tag(event)
            line = f"{tag} {command}"
            if self.callback_error is not None:
                exc, self.callback_error = self.callback_error, None
                raise IppDmeError(f"the event callback raised {type(exc).__name__}: {exc}") from exc
            stamp = self._log(">", line)
            waiter = _Waiter(tag, command)
            self._waiters[tag] = waiter
            self.recorder.sent(stamp, line)
            try:
                self._sock.sendall(line.encode("ascii") + b"\r\n")
            except OSError as exc:
                reason = f"socket error while sending: {exc}"
                stamp = self._log("*", f"lost {reason}")
                self._fail(self.recorder.note(stamp, f"lost {reason}"), reason)
        if not waiter.done.wait(limit):
            with self._lock:
                if not waiter.done.is_set():
                    self._waiters.pop(tag, None)
                    stamp = self._log("*", f"abandon {tag} timeout after {limit:g} s")
                    self.recorder.note(stamp, f"abandon {tag} timeout after {limit:g} s")
                    raise IppTimeout(f"the CMM did not complete {tag} {command} within {limit:g} s")
        if waiter.error is not None:
            raise waiter.error
        assert waiter.result is not None
        return waiter.result

    def call(self, command: str, *, timeout_s: float | None = None) -> TransactionResult:
        """Send a command and recover from errors by the policy.

        Errors of severity 0 and 1 are kept in the result's ``warnings``. On an error of
        severity >= 2, or when the server is already in an error state, the policy decides:
        ``ClearAllErrors()`` and the command again with a new tag, or raise.

        Raises
        ------
        IppCommandError
            The command failed and the policy said raise (the error and result attached).
        IppErrorState
            The server is in an error state and the policy does not clear it.
        IppProtocolError
            The answer breaks the protocol.
        IppTimeout, IppConnectionLost
            As for :meth:`transact`.
        """
        attempt = 0
        method = _method_of(command)
        while True:
            state = self.error_state
            if state is not None and method not in ALLOWED_IN_ERROR:
                if self.policy.decide(state, command, attempt) != "retry":
                    raise IppErrorState(
                        f"the CMM is in an error state ({state}); {command} not sent. "
                        "Clear it with ClearAllErrors() once the cause is removed",
                        error=state,
                    )
                self.clear_all_errors()
                attempt += 1
                continue
            result = self.transact(command, timeout_s=timeout_s)
            if result.protocol_error is not None:
                raise IppProtocolError(f"{result.tag} {command}: {result.protocol_error}")
            failure = result.failure
            if failure is None:
                return result
            if self.policy.decide(failure, command, attempt) != "retry":
                raise IppCommandError(
                    f"the CMM refused {result.tag} {command}: {failure}"
                    + (f" (after {attempt} recovery)" if attempt else ""),
                    error=failure,
                    result=result,
                )
            self.clear_all_errors()
            attempt += 1

    # -- commands
    def start_session(self) -> None:
        """``StartSession()`` (resets the report to ``X(), Y(), Z()`` and clears errors)."""
        self.call("StartSession()")

    def end_session(self) -> None:
        """``EndSession()``."""
        self.call("EndSession()")

    def clear_all_errors(self) -> None:
        """``ClearAllErrors()``, sent whatever the state; raises if it fails."""
        result = self.transact("ClearAllErrors()")
        if result.failure is not None:
            raise IppCommandError(
                f"ClearAllErrors() failed: {result.failure}", error=result.failure, result=result
            )

    def home(self, *, timeout_s: float | None = 600.0) -> None:
        """``Home()`` (moves the machine to its home position; 10 min by default)."""
        self.call("Home()", timeout_s=timeout_s)

    def is_homed(self) -> bool:
        """``IsHomed()``."""
        value = self._single(self.call("IsHomed()"), "IsHomed")
        return bool(value[0])

    def get_err_status(self) -> bool:
        """``GetErrStatusE()`` on the fast queue: True when the server is in error."""
        result = self.transact("GetErrStatusE()", event=True)
        return bool(self._single(result, "ErrStatus")[0])

    def change_tool(self, name: str, *, timeout_s: float | None = 300.0) -> None:
        """``ChangeTool("name")``."""
        self.call(f'ChangeTool("{_check_string(name)}")', timeout_s=timeout_s)

    def find_tool(self, name: str) -> None:
        """``FindTool("name")`` (makes ``FoundTool`` point at it)."""
        self.call(f'FindTool("{_check_string(name)}")')

    def set_prop(self, values: Mapping[str, float]) -> None:
        """``SetProp(Name(value), ...)``, e.g. ``{"Tool.PtMeasPar.Approach": 2.0}`` (mm, mm/s)."""
        if not values:
            raise IppDmeError("set_prop needs at least one property")
        args = ", ".join(f"{_check_name(k)}({format_number(v)})" for k, v in values.items())
        self.call(f"SetProp({args})")

    def get_prop(self, *names: str) -> dict[str, tuple[Value, ...]]:
        """``GetProp(Name(), ...)``: ``{name: values}`` as the server reported them."""
        if not names:
            raise IppDmeError("get_prop needs at least one property")
        result = self.call(f"GetProp({', '.join(f'{_check_name(n)}()' for n in names)})")
        out: dict[str, tuple[Value, ...]] = {}
        for _, values in result.data:
            for item in values:
                if isinstance(item, Call):
                    out[item.name] = item.args
        missing = [n for n in names if n not in out]
        if missing:
            raise IppProtocolError(f"GetProp answer lacks {', '.join(missing)}")
        return out

    def on_pt_meas_report(self, *names: str) -> None:
        """``OnPtMeasReport(X(), Y(), Z(), IJK(), ER())`` (the default) or the given fields."""
        chosen = names or ("X", "Y", "Z", "IJK", "ER")
        unknown = [n for n in chosen if n not in REPORT_ARITY]
        if unknown or len(set(chosen)) != len(chosen):
            raise IppDmeError(f"report fields must be distinct among {sorted(REPORT_ARITY)}")
        if not {"X", "Y", "Z"} <= set(chosen):
            raise IppDmeError("the report must hold X, Y and Z")
        self.call(f"OnPtMeasReport({', '.join(f'{n}()' for n in chosen)})")

    def goto(self, x: float, y: float, z: float, *, timeout_s: float | None = None) -> None:
        """``GoTo(X(x), Y(y), Z(z))``: move the active tool's centre there (mm)."""
        self.call(f"GoTo({_xyz(x, y, z)})", timeout_s=timeout_s)

    def get_position(self) -> tuple[float, float, float]:
        """``Get(X(), Y(), Z())``: the active tool's centre, mm."""
        result = self.call("Get(X(), Y(), Z())")
        if len(result.data) != 1:
            raise IppProtocolError(f"Get answered {len(result.data)} data lines instead of 1")
        got = fields(result.data[0][1])
        return got["X"][0], got["Y"][0], got["Z"][0]

    def pt_meas(
        self,
        x: float,
        y: float,
        z: float,
        i: float,
        j: float,
        k: float,
        *,
        timeout_s: float | None = None,
    ) -> ProbedPoint:
        """``PtMeas(X(x), Y(y), Z(z), IJK(i, j, k))``: probe one point.

        Parameters
        ----------
        x, y, z : float
            Nominal surface point, mm.
        i, j, k : float
            Approach direction, pointing out of the material (the probe moves along minus it).

        Returns
        -------
        ProbedPoint
            ``point_mm`` and, if reported, ``ijk`` (``normal`` normalized) and ``er_mm``.
        """
        n = math.sqrt(float(i) ** 2 + float(j) ** 2 + float(k) ** 2)
        if not (math.isfinite(n) and n > 0):
            raise IppDmeError(f"IJK must be a finite non-zero vector, got ({i}, {j}, {k})")
        ijk = f"IJK({format_number(i)}, {format_number(j)}, {format_number(k)})"
        result = self.call(f"PtMeas({_xyz(x, y, z)}, {ijk})", timeout_s=timeout_s)
        if result.point is None:  # pragma: no cover - protocol errors raise in call()
            raise IppProtocolError(f"{result.tag} PtMeas gave no point")
        return result.point

    @staticmethod
    def _single(result: TransactionResult, name: str) -> tuple[float, ...]:
        for _, values in result.data:
            for item in values:
                if isinstance(item, Call) and item.name == name:
                    return fields([item])[name]
        raise IppProtocolError(f"{result.tag} {result.command}: no {name}(...) in the answer")


def _xyz(x: float, y: float, z: float) -> str:
    return f"X({format_number(x)}), Y({format_number(y)}), Z({format_number(z)})"


def _check_string(text: str) -> str:
    if '"' in text or any(not 32 <= ord(c) <= 126 for c in text) or not text:
        raise IppDmeError(f"not a valid I++ string: {text!r}")
    return text


def _check_name(name: str) -> str:
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9]*(\.[A-Za-z][A-Za-z0-9]*)*", name):
        raise IppDmeError(f"not a valid I++ property name: {name!r}")
    return name


def parse_ipp_url(url: str) -> tuple[str, int]:
    """``ipp://HOST[:PORT]`` -> ``(host, port)`` (port 1294 by default).

    >>> parse_ipp_url("ipp://127.0.0.1:4711"), parse_ipp_url("ipp://cmm-lab")
    (('127.0.0.1', 4711), ('cmm-lab', 1294))
    """
    match = re.fullmatch(r"ipp://(\[[0-9A-Fa-f:.]+\]|[^:/\s]+)(?::([0-9]{1,5}))?/?", url.strip())
    if match is None:
        raise IppDmeError(f"not an I++ address: {url!r} (expected ipp://HOST:PORT)")
    port = int(match.group(2)) if match.group(2) else DEFAULT_PORT
    if not 0 < port < 65536:
        raise IppDmeError(f"port out of range in {url!r}")
    return match.group(1).strip("[]"), port


# ------------------------------------------------------------------- touch plans
@dataclass(frozen=True)
class CapTouchPlan:
    """Touch points on the upper caps of balls, with their clearance moves (CMM frame, mm).

    Shapes for ``m`` balls (any leading shape ``...``) and ``n`` points per ball. Positions
    named ``*_mm`` of the probe are of its tip centre (what ``GoTo`` moves).

    Attributes
    ----------
    points_mm : ndarray, shape (..., n, 3)
        Nominal surface points (``PtMeas`` targets).
    ijk : ndarray, shape (..., n, 3)
        Unit outward normals at the points (``PtMeas`` IJK; the probe moves along minus it).
    approach_mm : ndarray, shape (..., n, 3)
        Tip centre ``approach`` mm off the surface along the normal (``GoTo`` before each
        ``PtMeas``).
    above_mm : ndarray, shape (..., n, 3)
        Tip centre at the safe height straight above each approach position.
    safe_mm : ndarray, shape (..., 3)
        Tip centre at the safe height straight above the ball's centre.
    """

    points_mm: FloatArray
    ijk: FloatArray
    approach_mm: FloatArray
    above_mm: FloatArray
    safe_mm: FloatArray

    def ball(self, index: int | tuple[int, ...]) -> CapTouchPlan:
        """The plan of one ball of a multi-ball plan."""
        return CapTouchPlan(
            self.points_mm[index],
            self.ijk[index],
            self.approach_mm[index],
            self.above_mm[index],
            self.safe_mm[index],
        )


def cap_touch_plan(
    centre_mm: npt.ArrayLike,
    ball_diameter_mm: float,
    tip_diameter_mm: float,
    n_points: int,
    cap_angle_deg: float,
    *,
    approach_mm: float = 2.0,
    clearance_mm: float = 5.0,
) -> CapTouchPlan:
    """Touch points on the upper cap (CMM +Z) of balls around their predicted centres.

    The points follow a golden-angle spiral of equal areas from near the pole to the cap's
    rim (:func:`hexatherm.core.twin.cap_directions`). The moves that go with them, for each
    point: ``above`` (safe height) -> ``approach`` -> ``PtMeas`` -> ``above``; between points
    the probe travels at the safe height, ``clearance`` above the ball's top, so it never
    crosses the ball: the vertical descent to an approach position at polar angle ``theta``
    stays at least ``radius + tip radius + approach`` from the centre as long as
    ``theta <= 90`` deg, and the horizontal travel is above the ball.

    Parameters
    ----------
    centre_mm : array_like, shape (..., 3)
        Predicted ball centres in the CMM frame, mm.
    ball_diameter_mm, tip_diameter_mm : float
        Ball and probe tip diameters, mm.
    n_points : int
        Points per ball (>= 1; a free-radius sphere fit needs 4).
    cap_angle_deg : float
        Half-angle of the probed cap from +Z, deg, in (0, 90].
    approach_mm : float
        Distance of the approach positions from the surface, mm (> 0); the prediction's
        error along the normal must stay below it plus the server's search distance.
    clearance_mm : float
        Height of the safe plane above the ball's top (tip surface), mm (>= approach_mm).

    Returns
    -------
    CapTouchPlan

    Raises
    ------
    IppDmeError
        On a bad argument.

    Examples
    --------
    >>> plan = cap_touch_plan([[0, 0, 100.0], [50, 0, 100.0]], 25.4, 2.0, 5, 60.0)
    >>> plan.points_mm.shape, plan.safe_mm[1].tolist()
    ((2, 5, 3), [50.0, 0.0, 118.7])
    >>> d = np.linalg.norm(plan.points_mm - np.array([[[0, 0, 100.0]], [[50, 0, 100.0]]]), axis=-1)
    >>> bool(np.allclose(d, 12.7)), bool(np.all(plan.ijk[..., 2] >= 0.5 - 1e-12))
    (True, True)
    """
    centres = np.asarray(centre_mm, dtype=float)
    if centres.ndim < 1 or centres.shape[-1] != 3:
        raise IppDmeError(f"centre_mm must have shape (..., 3), got {centres.shape}")
    if not np.all(np.isfinite(centres)):
        raise IppDmeError("centre_mm has non-finite values")
    for name, value in (
        ("ball_diameter_mm", ball_diameter_mm),
        ("tip_diameter_mm", tip_diameter_mm),
    ):
        if not (math.isfinite(value) and value > 0):
            raise IppDmeError(f"{name} must be positive, got {value!r}")
    if int(n_points) != n_points or n_points < 1:
        raise IppDmeError(f"n_points must be a positive integer, got {n_points!r}")
    if not (math.isfinite(cap_angle_deg) and 0 < cap_angle_deg <= 90):
        raise IppDmeError(f"cap_angle_deg must be in (0, 90], got {cap_angle_deg!r}")
    if not (math.isfinite(approach_mm) and approach_mm > 0):
        raise IppDmeError(f"approach_mm must be positive, got {approach_mm!r}")
    if not (math.isfinite(clearance_mm) and clearance_mm >= approach_mm):
        raise IppDmeError(
            f"clearance_mm must be at least approach_mm ({approach_mm}), got {clearance_mm!r}"
        )
    radius = 0.5 * float(ball_diameter_mm)
    tip = 0.5 * float(tip_diameter_mm)
    u = cap_directions(int(n_points), float(cap_angle_deg))
    c = centres[..., None, :]
    points = c + radius * u
    approach = c + (radius + tip + approach_mm) * u
    safe_z = centres[..., 2] + radius + tip + clearance_mm
    above = approach.copy()
    above[..., 2] = safe_z[..., None]
    safe = centres.copy()
    safe[..., 2] = safe_z
    ijk = np.broadcast_to(u, points.shape).copy()
    return CapTouchPlan(points, ijk, approach, above, safe)


@dataclass(frozen=True)
class CapMeasurement:
    """Points probed on one ball by :func:`probe_cap`.

    Attributes
    ----------
    points_mm : ndarray, shape (n, 3)
        Reported points, mm.
    ijk : ndarray, shape (n, 3)
        Reported IJK (NaN when not in the report).
    er_mm : ndarray, shape (n,)
        Reported effective tool radius (NaN when not in the report), mm.
    probed : tuple of ProbedPoint
        The points as reported (tags, times).
    """

    points_mm: FloatArray
    ijk: FloatArray
    er_mm: FloatArray
    probed: tuple[ProbedPoint, ...]


def probe_cap(client: IppClient, plan: CapTouchPlan) -> CapMeasurement:
    """Probe one ball's cap: safe height, then for each point above -> approach -> PtMeas -> above.

    The move to the first safe position is a straight ``GoTo`` from wherever the probe is:
    the caller brings it to a travel height free of obstacles first.

    Parameters
    ----------
    client : IppClient
        Connected, in a session, homed, with a tool and a report holding X, Y, Z.
    plan : CapTouchPlan
        Of one ball (``points_mm`` of shape (n, 3); :meth:`CapTouchPlan.ball`).

    Returns
    -------
    CapMeasurement
    """
    if plan.points_mm.ndim != 2:
        raise IppDmeError(
            f"probe_cap takes the plan of one ball (points (n, 3)), got {plan.points_mm.shape}"
        )
    client.goto(*plan.safe_mm)
    probed = []
    for k in range(plan.points_mm.shape[0]):
        client.goto(*plan.above_mm[k])
        client.goto(*plan.approach_mm[k])
        probed.append(client.pt_meas(*plan.points_mm[k], *plan.ijk[k]))
        client.goto(*plan.above_mm[k])
    client.goto(*plan.safe_mm)
    nan3 = (math.nan, math.nan, math.nan)
    return CapMeasurement(
        points_mm=np.array([p.point_mm for p in probed], dtype=float).reshape(-1, 3),
        ijk=np.array([p.ijk or nan3 for p in probed], dtype=float).reshape(-1, 3),
        er_mm=np.array([math.nan if p.er_mm is None else p.er_mm for p in probed], dtype=float),
        probed=tuple(probed),
    )
