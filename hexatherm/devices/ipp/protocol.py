"""I++ DME lines: the protocol's terms, the parsers of one line, numbers, whole lines from bytes.

See the package docstring for the protocol in short.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Literal, Protocol

from hexatherm.errors import (
    IppDmeError,
    IppProtocolError,
)

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
    {"ClearAllErrors", "GetErrStatusE", "GetXtdErrStatus", "StartSession", "AbortE"}
)
"""Methods the client still sends while the server is in an error state (6.2.5; a new
session clears the errors, 6.3.1.1). Not ``EndSession``: 6.2.5 does not allow it, and the
NIST server refuses it (0514); :meth:`IppClient.end_session` clears the errors first."""


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


# The lines a campaign exchanges by the thousand are calls with numbers for arguments:
# ``X(1), Y(2), IJK(0, 0, 1)`` (a PtMeas report), ``GoTo(X(1), Y(2), Z(3))`` (a command).
# One regular expression reads such a line whole; what it does not match whole goes
# through the tokenizer and its parser, which read every line (tests/devices/
# test_ipp_fastpath.py: the same values, or the same error, for both on many lines).
_NUM = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]{1,3})?"
_NUMS = rf"(?:[ \t]*{_NUM}[ \t]*(?:,[ \t]*{_NUM}[ \t]*)*|[ \t]*)"
_NAME = r"[A-Za-z][A-Za-z0-9]*(?:\.[A-Za-z][A-Za-z0-9]*)*"
_CALL = rf"({_NAME})[ \t]*\(({_NUMS})\)"
_CALLS_TEXT = rf"[ \t]*{_NAME}[ \t]*\({_NUMS}\)(?:[ \t]*,[ \t]*{_NAME}[ \t]*\({_NUMS}\))*[ \t]*"
_FAST_CALLS = re.compile(_CALLS_TEXT)
_FAST_CALL = re.compile(_CALL)
_FAST_COMMAND = re.compile(
    rf"[ \t]*([A-Za-z][A-Za-z0-9]*)[ \t]*\(((?:{_CALLS_TEXT})?|[ \t]*)\)[ \t]*"
)
_ILLEGAL = re.compile(r"[^\x20-\x7e]")


def _fast_calls(text: str) -> tuple[Call, ...] | None:
    """The calls of ``text`` if it is a list of calls with numbers (or none) for
    arguments, else None (then the general parser reads it)."""
    if _FAST_CALLS.fullmatch(text) is None:
        return None
    return tuple(
        Call(m[1], tuple(float(x) for x in m[2].split(",")) if m[2].strip(" \t") else ())
        for m in _FAST_CALL.finditer(text)
    )


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
    fast = _fast_calls(body)
    return fast if fast is not None else _parse_data(body)


def _parse_data(body: str) -> tuple[Value, ...]:
    """:func:`parse_data` by the tokenizer and the parser, whatever the line."""
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
    bad = _ILLEGAL.search(line)
    if bad is not None:
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
    fast = _FAST_COMMAND.fullmatch(rest)
    if fast is not None:
        args = _fast_calls(fast[2]) if fast[2].strip(" \t") else ()
        if args is not None:
            return tag, Call(fast[1], args)
    return tag, _command_call(rest)


def _command_call(rest: str) -> Call:
    """The method call of a command line's text after its tag, by the general parser."""
    values = _parse_data(rest)
    if len(values) != 1 or not isinstance(values[0], Call) or "." in values[0].name:
        raise IppProtocolError(f"expected one Method(args), got {rest[:40]!r}")
    return values[0]


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
