"""I++ DME transcripts and the protocol's state machine without I/O.

The live client and :func:`replay_transcript` feed a :class:`Recorder` the same entries, so a
replay gives the same transactions, events and points, bit for bit.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import IO

import numpy as np

from hexatherm.devices.ipp.protocol import (
    _TAG,
    DEFAULT_REPORT,
    REPORT_ARITY,
    TRANSCRIPT_MAGIC,
    Call,
    Direction,
    ErrorReport,
    Response,
    Value,
    fields,
    parse_data,
    parse_response,
)
from hexatherm.errors import (
    IppDmeError,
    IppProtocolError,
)
from hexatherm.typing import FloatArray


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
    # every field is named (spec 6.1.3): read them by name, in any order (the NIST server
    # answers ER, IJK, X, Y, Z whatever was asked); a field given twice (fields() refuses
    # it) or one asked for and missing is refused, one not asked for is kept
    got = fields(values)
    missing = [name for name in result.report if name not in got]
    if missing:
        raise IppProtocolError(
            f"PtMeas report {', '.join(got)} lacks {', '.join(missing)} "
            f"(OnPtMeasReport asked for {', '.join(result.report)})"
        )
    if not {"X", "Y", "Z"} <= set(got):
        raise IppProtocolError(f"PtMeas report {', '.join(got)} lacks X, Y or Z")
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
            tag = line[:5]
            if _TAG.fullmatch(tag) and line[5:6] == " " and tag not in self.open:
                # an event line (E0000, a server's informational text in Latin-1) or a line
                # of a tag no transaction has open: whose it is can be read, and it is none
                # of the open transactions', so it disturbs none of them (a warning, kept in
                # the transcript); an abandoned tag's late line is ignored as ever
                if tag in self.abandoned:
                    return None, None
                event = IppEvent(stamp, line, None, str(exc))
                self.events.append(event)
                return None, event
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
