"""The ``serial.log`` format: every byte received, with the time it arrived, as ASCII text.

One line per entry, ``<time> <kind> <source> "<payload>"``, the payload's bytes escaped
(``\\r``, ``\\n``, ``\\t``, ``\\\\``, ``\\"``, ``\\xNN``). Written, flushed and fsync'd
*before* the entry is acted on: it is the primary record of an acquisition. Also the
sinks that the accepted points are appended to (``points.csv``).
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from hexatherm.errors import InputError
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.records import seconds_to_iso

LOG_NAME = "serial.log"


POINTS_NAME = "points.csv"


TEMPERATURES_NAME = "temperatures.csv"


LOG_MAGIC = "# hexatherm serial log 1"


POINTS_HEADER = "label,ball,x,y,z,time"


REJECTED_NAME = "rejected.csv"


#: points not assigned: ``label,ball`` the ball the point was taken on or lies on
#: (empty when none), ``status`` ``rejected`` or ``set-aside``, ``reason`` in words
REJECTED_HEADER = "label,ball,x,y,z,time,status,reason"


PROBE, TEMPERATURE = "probe", "temperature"


#: log entry kinds
KINDS = ("open", "rx", "lost", "reopen", "skip", "event", "mode", "config", "resume", "end", "note")


# --------------------------------------------------------------------- log format
_ESCAPES = {0x5C: "\\\\", 0x22: '\\"', 0x0D: "\\r", 0x0A: "\\n", 0x09: "\\t"}


_UNESCAPE = re.compile(rb'\\(x[0-9a-fA-F]{2}|[\\"rnt])')


def escape_bytes(data: bytes) -> str:
    """Bytes as printable ASCII: ``\\r``, ``\\n``, ``\\t``, ``\\\\``, ``\\"`` and ``\\xNN``.

    >>> escape_bytes(b'X=1 "a"\\r\\n\\x00\\xff')
    'X=1 \\\\"a\\\\"\\\\r\\\\n\\\\x00\\\\xff'
    >>> unescape_bytes(escape_bytes(bytes(range(256)))) == bytes(range(256))
    True
    """
    out = []
    for byte in data:
        if byte in _ESCAPES:
            out.append(_ESCAPES[byte])
        elif 0x20 <= byte < 0x7F:
            out.append(chr(byte))
        else:
            out.append(f"\\x{byte:02x}")
    return "".join(out)


def unescape_bytes(text: str) -> bytes:
    """Inverse of :func:`escape_bytes` (ValueError on a bad escape)."""
    raw = text.encode("ascii")
    simple = {b"\\": b"\\", b'"': b'"', b"r": b"\r", b"n": b"\n", b"t": b"\t"}

    def sub(match: re.Match[bytes]) -> bytes:
        code = match.group(1)
        return bytes([int(code[1:], 16)]) if code[:1] == b"x" else simple[code]

    out = _UNESCAPE.sub(sub, raw)
    if b"\\" in _UNESCAPE.sub(b"", raw):
        raise ValueError("bad escape")
    return out


@dataclass(frozen=True)
class LogEntry:
    """One line of ``serial.log``.

    Attributes
    ----------
    time : str
        ISO 8601 UTC time with microseconds (``2024-05-01T10:00:00.123456``).
    kind : str
        One of :data:`KINDS`.
    source : str
        ``probe``, ``temperature``, ``operator`` or ``-``.
    payload : bytes
        Received bytes (``rx``), an operator event (``event``), a setting, a message.
    line : int
        Line of the log (0 for entries not read from a file).
    """

    time: str
    kind: str
    source: str
    payload: bytes
    line: int = 0

    def format(self) -> str:
        """The entry's line in the log (with its LF)."""
        return f'{self.time} {self.kind} {self.source} "{escape_bytes(self.payload)}"\n'

    @property
    def text(self) -> str:
        """The payload as text."""
        return self.payload.decode("utf-8", "replace")


_ENTRY = re.compile(r'(\S+) (\S+) (\S+) "(.*)"')


#: the wall clock read once, with the monotonic clock at the same moment
_CLOCK_ANCHOR = (time.time(), time.monotonic())


def now_iso() -> str:
    """The current UTC time as the log writes it, from a clock that never goes back.

    The wall clock is read once (when the module is imported) and advanced by the
    monotonic clock: an NTP step or a clock set by hand during an acquisition cannot
    give a later entry an earlier time (references in reverse time order would make
    the session unprocessable). Over a working day the two clocks part by
    milliseconds at most (the monotonic clock is slewed by NTP like the wall clock).
    """
    wall, mono = _CLOCK_ANCHOR
    return seconds_to_iso(wall + (time.monotonic() - mono))


def entry(
    kind: str, source: str = "-", payload: bytes | str = b"", when: str | None = None
) -> LogEntry:
    """A new log entry stamped now (or at ``when``)."""
    data = payload.encode("utf-8") if isinstance(payload, str) else payload
    return LogEntry(when or now_iso(), kind, source, data)


def parse_log(raw: bytes, path: str) -> tuple[list[LogEntry], int]:
    """Read the entries of a serial log.

    Parameters
    ----------
    raw : bytes
        The file's content.
    path : str
        For messages.

    Returns
    -------
    entries : list of LogEntry
    complete : int
        Length in bytes of the complete lines. A last line without its LF (the
        process died while writing it) is left out; its bytes were never acted on.

    Raises
    ------
    InputError
        When the file is not a hexatherm serial log or a complete line is malformed.
    """
    end = raw.rfind(b"\n") + 1
    lines = raw[:end].split(b"\n")[:-1]
    if not lines or lines[0].rstrip(b"\r").decode("ascii", "replace") != LOG_MAGIC:
        raise InputError(
            f"not a hexatherm serial log (first line must be {LOG_MAGIC!r})", path=path, line=1
        )
    entries = []
    for number, line in enumerate(lines[1:], start=2):
        try:
            text = line.decode("ascii").rstrip("\r")
        except UnicodeDecodeError:
            raise InputError("non-ASCII byte in a log line", path=path, line=number) from None
        match = _ENTRY.fullmatch(text)
        if match is None or match.group(2) not in KINDS:
            raise InputError(f"malformed log line {text[:60]!r}", path=path, line=number)
        try:
            payload = unescape_bytes(match.group(4))
        except ValueError:
            raise InputError("bad escape in the payload", path=path, line=number) from None
        entries.append(LogEntry(match.group(1), match.group(2), match.group(3), payload, number))
    return entries, end


class SerialLog:
    """``serial.log`` opened for appending; every entry is flushed and fsync'd."""

    def __init__(self, path: Path, *, create: bool) -> None:
        self.path = path
        if create:
            with open(path, "xb") as handle:
                handle.write((LOG_MAGIC + "\n").encode("ascii"))
                handle.flush()
                os.fsync(handle.fileno())
        self._handle = open(path, "ab")  # noqa: SIM115 - closed by close()

    def append(self, item: LogEntry) -> None:
        """Write one entry and make it durable."""
        self._handle.write(item.format().encode("ascii"))
        self._handle.flush()
        os.fsync(self._handle.fileno())

    def close(self) -> None:
        """Close the file."""
        self._handle.close()


# ------------------------------------------------------------------------- sinks
class Sink(Protocol):
    """Where the recorder's CSV lines go."""

    def append(self, lines: Sequence[str]) -> None:
        """Add lines at the end."""

    def rewrite(self, lines: Sequence[str]) -> None:
        """Replace the whole content."""


class MemorySink:
    """Lines kept in memory (replay of a log to resume)."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def append(self, lines: Sequence[str]) -> None:
        self.lines.extend(lines)

    def rewrite(self, lines: Sequence[str]) -> None:
        self.lines = list(lines)


class FileSink:
    """A CSV file appended line by line, each write flushed and fsync'd.

    The file is created on the first write. :meth:`rewrite` replaces it
    atomically (temporary file, fsync, rename).
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._handle: Any = None

    def append(self, lines: Sequence[str]) -> None:
        if not lines:
            return
        if self._handle is None:
            self._handle = open(self.path, "a", encoding="utf-8", newline="")  # noqa: SIM115
        self._handle.write("".join(line + "\n" for line in lines))
        self._handle.flush()
        os.fsync(self._handle.fileno())

    def rewrite(self, lines: Sequence[str]) -> None:
        self.close()
        atomic_write_text(self.path, "".join(line + "\n" for line in lines))

    def close(self) -> None:
        """Close the file (it reopens on the next write)."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
