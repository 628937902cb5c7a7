"""Live acquisition of a session: serial probe stream in, session folder out.

The acquisition walks the plan step by step and ball by ball (plan order, then
balls-file order) and gives every point the probe sends to the current step and
ball. Three files make it crash-safe:

``serial.log``
    Every byte received, with the time it arrived, and every event that changes
    how the bytes are assigned (a port lost or reopened, a resume, an operator's
    ``next``/``redo``, the mode and the unit). One line per entry,
    ``<time> <kind> <source> "<payload>"``, the payload's bytes escaped
    (``\\r``, ``\\n``, ``\\t``, ``\\\\``, ``\\"``, ``\\xNN``) so the file is
    ASCII text. It is written, flushed and fsync'd *before* the entry is acted
    on: it is the primary record.
``points.csv``
    Every accepted point (points CSV contract, ``label,ball,x,y,z,time``, ISO
    8601 UTC times), appended, flushed and fsync'd as it arrives. A point's time
    is the time the bytes that completed its line arrived (as logged).
``temperatures.csv``
    The lines of a thermocouple logger on a second port, when there is one.

:class:`Recorder` is the state machine that turns log entries into points: the
live loop and the replay of a log feed it the same entries, so a replay gives
the same ``points.csv`` byte for byte. ``--resume`` replays the session's own log
to rebuild the state (nothing lost, nothing doubled, even if the process died
between logging bytes and writing their points) and continues at the first
incomplete ball.
"""

from __future__ import annotations

import contextlib
import math
import os
import queue
import re
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np

from hexatherm.core.plan import Plan
from hexatherm.core.planning import format_pose, reference_gaps
from hexatherm.errors import FitError, HexathermError, InputError
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.config import Balls
from hexatherm.io.probestream import (
    UNITS_MM,
    LineSplitter,
    decode_line,
    format_number,
    parse_numbers,
    parse_record,
)
from hexatherm.io.records import iso_to_seconds, seconds_to_iso

LOG_NAME = "serial.log"
POINTS_NAME = "points.csv"
TEMPERATURES_NAME = "temperatures.csv"
LOG_MAGIC = "# hexatherm serial log 1"
POINTS_HEADER = "label,ball,x,y,z,time"
PROBE, TEMPERATURE = "probe", "temperature"
#: log entry kinds
KINDS = ("open", "rx", "lost", "reopen", "event", "mode", "config", "resume", "end", "note")
OPERATOR_EVENTS = ("next", "redo", "quit")

Level = Literal["info", "warn", "progress"]
Notify = Callable[[Level, str], None]
Mode = Literal["auto", "interactive"]


class AcquisitionError(HexathermError):
    """The acquisition cannot go on (a port that does not open, a session in the way, ...)."""


class IncompleteSession(AcquisitionError):
    """The acquisition stopped before the end of the plan; ``--resume`` continues it."""


def quiet(level: Level, message: str) -> None:
    """A notifier that says nothing (used while a log is replayed to resume)."""


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


def now_iso() -> str:
    """The current UTC time as the log writes it."""
    return seconds_to_iso(time.time())


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


# ---------------------------------------------------------------------- recorder
@dataclass(frozen=True)
class FitChecks:
    """Limits of the live sphere fit after each ball.

    Attributes
    ----------
    radius_tol_mm : float
        Warn when the fitted radius is further than this from the nominal one.
    form_tol_um : float
        Warn when the form error (max - min residual) is larger.
    min_points : int
        Warn when a ball has fewer points (4 fit a sphere, more check it).
    centre_distance_tol_mm : float
        Warn when the distance between two balls' fitted centres in one step is
        further than this from the balls file's (the wrong ball was probed).
    """

    radius_tol_mm: float = 0.02
    form_tol_um: float = 15.0
    min_points: int = 5
    centre_distance_tol_mm: float = 0.5


@dataclass(frozen=True)
class BallFit:
    """The live fit of one ball of one step."""

    label: str
    ball: str
    n: int
    centre_mm: tuple[float, float, float] | None
    radius_mm: float
    form_um: float
    warnings: tuple[str, ...]


@dataclass
class _Point:
    xyz: tuple[float, float, float]
    time: str
    line: str


@dataclass
class _TemperatureTable:
    columns: int = 0
    lines: list[str] = field(default_factory=list)


class Recorder:
    """Assigns the points of a probe stream to the steps and balls of a plan.

    Feed it log entries with :meth:`apply`; it parses the bytes, assigns each
    point to the current ball, writes the points CSV lines to ``points``, fits
    each completed ball and reports through ``notify``. In ``auto`` mode it moves
    on when a ball has the plan's points per ball; in ``interactive`` mode the
    operator's ``next`` does (extra points go to the same ball) and ``redo``
    drops the current ball's points to probe it again.

    Parameters
    ----------
    plan : Plan
    balls : Balls
    points : Sink
        Receives the lines of ``points.csv`` (the header is written by the caller).
    temperatures : Sink
        Receives the lines of ``temperatures.csv`` (header first).
    notify : callable
        ``notify(level, message)``.
    checks : FitChecks
    max_gap_s : float
        Warn when a target and an adjacent reference are further apart.
    """

    def __init__(
        self,
        plan: Plan,
        balls: Balls,
        *,
        points: Sink,
        temperatures: Sink,
        notify: Notify = quiet,
        checks: FitChecks | None = None,
        max_gap_s: float = 600.0,
    ) -> None:
        self.plan = plan
        self.balls = balls
        self.points_sink = points
        self.temperature_sink = temperatures
        self.notify = notify
        self.checks = checks or FitChecks()
        self.max_gap_s = max_gap_s
        self.mode: Mode = "auto"
        self.unit = "mm"
        self.slots = [(i, j) for i in range(len(plan.labels)) for j in range(len(balls.names))]
        self.cursor = 0
        self.points: dict[int, list[_Point]] = {k: [] for k in range(len(self.slots))}
        self.fits: dict[int, BallFit] = {}
        self.step_times = np.full(len(plan.labels), np.nan)
        self.temperatures = _TemperatureTable()
        self.stopped = False
        self.skipped_lines = 0
        self._splitters = {PROBE: LineSplitter(), TEMPERATURE: LineSplitter()}
        self._pending: list[str] = []
        self._radius = np.array([_expected_radius(balls, j) for j in range(len(balls.names))])

    # ----------------------------------------------------------------- state
    @property
    def done(self) -> bool:
        """Every ball of every step has been measured."""
        return self.cursor >= len(self.slots)

    @property
    def point_lines(self) -> list[str]:
        """The lines of ``points.csv`` (header first), as they stand."""
        return [POINTS_HEADER] + [p.line for k in range(len(self.slots)) for p in self.points[k]]

    @property
    def n_points(self) -> int:
        """Number of points recorded."""
        return sum(len(v) for v in self.points.values())

    def where(self) -> str:
        """Where the acquisition stands, for messages."""
        if self.done:
            return "the end of the plan"
        i, j = self.slots[self.cursor]
        have = len(self.points[self.cursor])
        return (
            f"step {self.plan.labels[i]} ball {self.balls.names[j]} "
            f"({have}/{self.plan.points_per_ball} points)"
        )

    def announce(self) -> None:
        """Tell the operator what to do now (pose to command, ball to probe)."""
        if self.done:
            self.notify("info", "all steps measured")
            return
        i, j = self.slots[self.cursor]
        have = len(self.points[self.cursor])
        if j == 0 and have == 0:
            label, kind, pose = self.plan.labels[i], self.plan.kinds[i], self.plan.poses[i]
            self.notify(
                "info",
                f"step {i + 1}/{len(self.plan.labels)} {label} ({kind}): "
                f"command the hexapod to pose {format_pose(pose)}, then probe "
                f"{', '.join(self.balls.names)}",
            )
        remaining = self.plan.points_per_ball - have
        if remaining > 0:
            self.notify(
                "info",
                f"probe ball {self.balls.names[j]} of {self.plan.labels[i]}: "
                f"{remaining} point{'s' if remaining != 1 else ''} to go",
            )

    # ----------------------------------------------------------------- entries
    def apply(self, item: LogEntry) -> None:
        """Act on one log entry."""
        kind = item.kind
        if kind == "rx":
            splitter = self._splitters.get(item.source)
            if splitter is None:
                return
            for line in splitter.feed(item.payload):
                if item.source == PROBE:
                    self._probe_line(line, item.time)
                else:
                    self._temperature_line(line, item.time)
        elif kind in ("lost", "open", "reopen"):
            splitter = self._splitters.get(item.source)
            dropped = splitter.reset() if splitter is not None else b""
            if dropped:
                self.notify(
                    "warn",
                    f"{item.source}: partial line {decode_line(dropped)!r} "
                    f"dropped ({'port lost' if kind == 'lost' else kind})",
                )
            if kind == "lost":
                self.notify("warn", f"{item.source} port lost ({item.text}); reopening it")
            elif kind == "reopen":
                self.notify("info", f"{item.source} port reopened")
        elif kind == "resume":
            for splitter in self._splitters.values():
                dropped = splitter.reset()
                if dropped:
                    self.notify(
                        "warn",
                        f"partial line {decode_line(dropped)!r} of the interrupted run dropped",
                    )
        elif kind == "mode":
            mode = item.text
            if mode not in ("auto", "interactive"):
                raise InputError(f"unknown mode {mode!r}", line=item.line or None)
            self.mode = mode  # type: ignore[assignment]
            if self.mode == "auto" and not self.done and self._ball_full():
                self._advance()
        elif kind == "config":
            for setting in item.text.split():
                key, _, value = setting.partition("=")
                if key == "units":
                    if value not in UNITS_MM:
                        raise InputError(f"unknown unit {value!r}", line=item.line or None)
                    self.unit = value
        elif kind == "event":
            self._event(item.text)
        self._flush()

    def _flush(self) -> None:
        if self._pending:
            self.points_sink.append(self._pending)
            self._pending = []

    def _event(self, name: str) -> None:
        if name == "quit":
            self.stopped = True
        elif self.done:
            self.notify("info", "all steps are measured already")
        elif name == "next":
            if self._ball_full():
                self._advance()
            else:
                need = self.plan.points_per_ball - len(self.points[self.cursor])
                self.notify("warn", f"{self.where()}: {need} more point(s) before moving on")
        elif name == "redo":
            dropped = len(self.points[self.cursor])
            self.points[self.cursor] = []
            self.fits.pop(self.cursor, None)
            self._pending = []
            self.points_sink.rewrite(self.point_lines)
            self.notify("info", f"{dropped} point(s) dropped; probe the ball again")
            self.announce()

    def _ball_full(self) -> bool:
        return len(self.points[self.cursor]) >= self.plan.points_per_ball

    # ----------------------------------------------------------------- probe
    def _probe_line(self, line: bytes, when: str) -> None:
        record = parse_record(line, self.unit)
        if record.kind == "blank":
            return
        if record.kind != "point":
            self.skipped_lines += 1
            level: Level = "progress" if record.kind == "text" else "warn"
            self.notify(level, f"skipped {record.kind} line {record.text[:60]!r}: {record.reason}")
            return
        assert record.xyz_mm is not None
        if self.done:
            self.notify("warn", f"point {record.text!r} after the end of the plan: not recorded")
            return
        i, j = self.slots[self.cursor]
        x, y, z = (format_number(v) for v in record.xyz_mm)
        text = f"{self.plan.labels[i]},{self.balls.names[j]},{x},{y},{z},{when}"
        self.points[self.cursor].append(_Point(record.xyz_mm, when, text))
        self._pending.append(text)
        have = len(self.points[self.cursor])
        self.notify(
            "progress",
            f"{self.plan.labels[i]} {self.balls.names[j]} point {have}/"
            f"{self.plan.points_per_ball}: {x}, {y}, {z}",
        )
        if have >= self.plan.points_per_ball:
            self._fit(self.cursor)
            if self.mode == "auto":
                self._advance()
            elif have == self.plan.points_per_ball:
                self.notify(
                    "info",
                    "Enter (or 'next'): next ball; 'redo': probe this ball "
                    "again; 'quit': stop (continue later with --resume)",
                )

    def _fit(self, slot: int) -> BallFit:
        from hexatherm.core.spherefit import fit_spheres

        i, j = self.slots[slot]
        label, ball = self.plan.labels[i], self.balls.names[j]
        pts = np.array([p.xyz for p in self.points[slot]])
        warnings: list[str] = []
        nominal = float(self._radius[j])
        centre: tuple[float, float, float] | None = None
        radius, form = math.nan, math.nan
        if len(pts) < self.checks.min_points:
            warnings.append(
                f"too few points: {len(pts)} (at least {self.checks.min_points} "
                "to fit and check a sphere)"
            )
        if len(pts) >= 4:
            try:
                fit = fit_spheres(pts)
            except FitError as exc:
                warnings.append(f"sphere fit failed: {exc}")
            else:
                c = fit.centre_mm[0]
                centre = (float(c[0]), float(c[1]), float(c[2]))
                radius, form = float(fit.radius_mm[0]), float(fit.form_um[0])
                if abs(radius - nominal) > self.checks.radius_tol_mm:
                    warnings.append(
                        f"radius {radius:.4f} mm is {1e3 * (radius - nominal):+.1f} "
                        f"um off the nominal {nominal:.4f} mm"
                    )
                if form > self.checks.form_tol_um:
                    warnings.append(f"form error {form:.1f} um > {self.checks.form_tol_um:g} um")
                warnings += self._distance_warnings(slot, np.array(centre))
        result = BallFit(
            label,
            ball,
            len(pts),
            centre,
            radius,
            form,
            tuple(warnings),
        )
        self.fits[slot] = result
        summary = f"{label} {ball}: {len(pts)} points"
        if centre is not None:
            summary += (
                f", centre {', '.join(f'{v:.4f}' for v in centre)} mm, radius "
                f"{radius:.4f} mm (nominal {nominal:.4f}), form {form:.1f} um"
            )
        self.notify("info", summary)
        for warning in warnings:
            self.notify(
                "warn",
                f"{label} {ball}: {warning}"
                + ("; 'redo' to probe it again" if self.mode == "interactive" else ""),
            )
        return result

    def _distance_warnings(self, slot: int, centre: np.ndarray) -> list[str]:
        i, j = self.slots[slot]
        out = []
        for other in range(len(self.slots)):
            oi, oj = self.slots[other]
            fit = self.fits.get(other)
            if oi != i or oj == j or fit is None or fit.centre_mm is None:
                continue
            measured = float(np.linalg.norm(centre - np.array(fit.centre_mm)))
            nominal = float(np.linalg.norm(self.balls.centres_mm[j] - self.balls.centres_mm[oj]))
            if abs(measured - nominal) > self.checks.centre_distance_tol_mm:
                out.append(
                    f"{measured:.3f} mm from {self.balls.names[oj]}, the balls file says "
                    f"{nominal:.3f} mm: was the right ball probed?"
                )
        return out

    def _advance(self) -> None:
        i, _ = self.slots[self.cursor]
        self.cursor += 1
        if self.done or self.slots[self.cursor][0] != i:
            self._step_complete(i)
        self.announce()

    def _step_complete(self, i: int) -> None:
        times = [
            iso_to_seconds(p.time)
            for k, (si, _) in enumerate(self.slots)
            if si == i
            for p in self.points[k]
        ]
        self.step_times[i] = float(np.mean(times)) if times else np.nan
        for gap in reference_gaps(self.plan, self.step_times):
            if self.plan.labels[i] in (gap.target, gap.reference) and gap.gap_s > self.max_gap_s:
                self.notify(
                    "warn",
                    f"{gap.target} and its reference {gap.reference} are "
                    f"{gap.gap_s / 60:.1f} min apart (allowed "
                    f"{self.max_gap_s / 60:.1f} min): the thermal state may "
                    "have changed in between",
                )

    # ----------------------------------------------------------- temperatures
    def _temperature_line(self, line: bytes, when: str) -> None:
        values = parse_numbers(line, 6)
        table = self.temperatures
        if values is None:
            self.notify(
                "warn",
                f"temperature line skipped (not six or more numbers): {decode_line(line)[:60]!r}",
            )
            return
        if table.columns == 0:
            table.columns = len(values)
            header = ["time"] + [f"leg{k}" for k in range(1, 7)]
            header += [f"ch{k}" for k in range(7, len(values) + 1)]
            table.lines.append(",".join(header))
            self.temperature_sink.append([table.lines[0]])
        if len(values) != table.columns:
            self.notify(
                "warn",
                f"temperature line with {len(values)} numbers skipped (the "
                f"first had {table.columns})",
            )
            return
        text = ",".join([when] + [format_number(v) for v in values])
        table.lines.append(text)
        self.temperature_sink.append([text])


def _expected_radius(balls: Balls, j: int) -> float:
    from hexatherm.core.spherefit import probe_radius_mm

    return probe_radius_mm(
        float(balls.diameters_mm[j]), balls.tip_diameter_mm, balls.probe_compensated
    )


# ------------------------------------------------------------------------- ports
@dataclass(frozen=True)
class PortSettings:
    """How to open a serial port with :func:`serial.serial_for_url`.

    ``url`` is a device (``/dev/ttyUSB0``, ``COM3``) or a pyserial URL
    (``socket://host:port``, ``rfc2217://host:port``, ``loop://``).
    """

    url: str
    baudrate: int = 9600
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1
    xonxoff: bool = False
    rtscts: bool = False
    dsrdtr: bool = False
    timeout_s: float = 0.1

    def open(self) -> Any:
        """Open the port (AcquisitionError with the reason when it does not open)."""
        import serial

        stopbits: float = int(self.stopbits) if float(self.stopbits).is_integer() else self.stopbits
        try:
            return serial.serial_for_url(
                self.url,
                baudrate=self.baudrate,
                bytesize=self.bytesize,
                parity=self.parity,
                stopbits=stopbits,
                xonxoff=self.xonxoff,
                rtscts=self.rtscts,
                dsrdtr=self.dsrdtr,
                timeout=self.timeout_s,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise AcquisitionError(f"cannot open port {self.url}: {exc}") from None

    def describe(self) -> str:
        """The settings, for the log."""
        return (
            f"{self.url} {self.baudrate} {self.bytesize}{self.parity}{self.stopbits:g}"
            + (" xonxoff" if self.xonxoff else "")
            + (" rtscts" if self.rtscts else "")
            + (" dsrdtr" if self.dsrdtr else "")
        )


class PortReader(threading.Thread):
    """Reads a port into a queue; reopens it when it is lost.

    Puts ``("rx", source, time, bytes)``, ``("lost", source, time, reason)`` and
    ``("reopen", source, time, url)`` items; the main loop logs and applies them.
    """

    def __init__(
        self,
        source: str,
        settings: PortSettings,
        port: Any,
        out: queue.Queue[Any],
        stop: threading.Event,
        reopen_interval_s: float = 1.0,
    ) -> None:
        super().__init__(name=f"hexatherm-{source}", daemon=True)
        self.source = source
        self.settings = settings
        self.port = port
        self.out = out
        self.stop = stop
        self.reopen_interval_s = reopen_interval_s

    def run(self) -> None:
        import serial

        try:
            while not self.stop.is_set():
                try:
                    data = self.port.read(1)
                    while data and len(data) < 65536 and (waiting := self.port.in_waiting):
                        data += self.port.read(waiting)
                except (serial.SerialException, OSError) as exc:
                    self.out.put(("lost", self.source, now_iso(), str(exc)))
                    self._close()
                    self._reopen()
                    continue
                if data:
                    self.out.put(("rx", self.source, now_iso(), bytes(data)))
        finally:
            self._close()

    def _close(self) -> None:
        if self.port is not None:
            with contextlib.suppress(Exception):
                self.port.close()
            self.port = None

    def _reopen(self) -> None:
        while not self.stop.wait(self.reopen_interval_s):
            try:
                self.port = self.settings.open()
            except AcquisitionError:
                continue
            self.out.put(("reopen", self.source, now_iso(), self.settings.url))
            return


class InputReader(threading.Thread):
    """Reads the operator's commands, one per line, into the queue (interactive mode)."""

    def __init__(self, lines: Iterable[str], out: queue.Queue[Any]) -> None:
        super().__init__(name="hexatherm-input", daemon=True)
        self.lines = lines
        self.out = out

    def run(self) -> None:
        for line in self.lines:
            self.out.put(("input", now_iso(), line))
        self.out.put(("input-eof", now_iso(), ""))


def operator_command(line: str) -> str | None:
    """The event an operator's line means (None: not a command).

    >>> [operator_command(x) for x in ["", "n", "redo", " Q ", "hello"]]
    ['next', 'next', 'redo', 'quit', None]
    """
    word = line.strip().lower()
    table = {
        "": "next",
        "n": "next",
        "next": "next",
        "r": "redo",
        "redo": "redo",
        "q": "quit",
        "quit": "quit",
    }
    return table.get(word)


# -------------------------------------------------------------------- sessions
@dataclass(frozen=True)
class SessionFiles:
    """The configuration an acquisition runs with (already validated).

    Attributes
    ----------
    plan : Plan
    balls : Balls
    plan_text, hexapod_text, balls_text : str
        The files' text, copied into the session folder.
    """

    plan: Plan
    balls: Balls
    plan_text: str
    hexapod_text: str
    balls_text: str


def load_files(plan_path: Path, hexapod_path: Path, balls_path: Path) -> SessionFiles:
    """Read and validate the plan, hexapod and balls files."""
    from hexatherm.io.config import read_balls, read_hexapod, read_plan
    from hexatherm.io.csvfile import read_text

    plan = read_plan(plan_path)
    read_hexapod(hexapod_path)
    balls = read_balls(balls_path)
    return SessionFiles(
        plan, balls, read_text(plan_path), read_text(hexapod_path), read_text(balls_path)
    )


def check_same_files(given: SessionFiles, folder: Path) -> None:
    """Refuse to resume a session with a different plan or balls file than it started with."""
    from hexatherm.io.config import plan_to_yaml, read_balls, read_plan

    plan_copy = read_plan(folder / "plan.yaml")
    if plan_to_yaml(plan_copy) != plan_to_yaml(given.plan):
        raise AcquisitionError(
            f"the plan differs from the session's {folder / 'plan.yaml'}; "
            "resume with the plan the session started with"
        )
    balls_copy = read_balls(folder / "balls.yaml")
    same = (
        balls_copy.names == given.balls.names
        and np.array_equal(balls_copy.centres_mm, given.balls.centres_mm)
        and np.array_equal(balls_copy.diameters_mm, given.balls.diameters_mm)
        and balls_copy.probe_compensated == given.balls.probe_compensated
        and balls_copy.tip_diameter_mm == given.balls.tip_diameter_mm
    )
    if not same:
        raise AcquisitionError(f"the balls file differs from the session's {folder / 'balls.yaml'}")


def write_copies(folder: Path, files: SessionFiles) -> None:
    """Copy the plan, hexapod and balls files into the session folder."""
    for name, text in (
        ("plan.yaml", files.plan_text),
        ("hexapod.yaml", files.hexapod_text),
        ("balls.yaml", files.balls_text),
    ):
        atomic_write_text(folder / name, text)


def finish_session(folder: Path, notify: Notify, temperatures_file: Path | None = None) -> Path:
    """Write ``session.yaml`` so that ``hexatherm process`` takes the folder as it is.

    A thermocouple log (``temperatures_file`` copied in, or the one recorded
    from a second port) is attached when it reads as a temperatures file with
    ISO times like the points; otherwise a warning says why it was left out.
    """
    from hexatherm.io.config import session_to_yaml
    from hexatherm.io.csvfile import read_temperatures

    target = folder / TEMPERATURES_NAME
    if temperatures_file is not None:
        try:
            data = Path(temperatures_file).read_bytes()
        except OSError as exc:
            notify(
                "warn",
                f"cannot read {temperatures_file}: {exc.strerror}; session without temperatures",
            )
        else:
            atomic_write_text(target, data.decode("utf-8-sig", "replace"))
    temperatures = None
    if target.is_file():
        try:
            table = read_temperatures(target)
        except InputError as exc:
            notify("warn", f"temperatures left out of the session: {exc}")
        else:
            if table.time_kind != "iso":
                notify(
                    "warn",
                    f"temperatures left out of the session: {target} has times in "
                    "seconds but the points have ISO 8601 times",
                )
            else:
                temperatures = TEMPERATURES_NAME
    path = folder / "session.yaml"
    atomic_write_text(
        path,
        session_to_yaml(
            folder.name, "hexapod.yaml", "balls.yaml", "plan.yaml", [POINTS_NAME], temperatures
        ),
    )
    return path


@contextlib.contextmanager
def session_lock(folder: Path) -> Any:
    """Hold an exclusive lock on the session folder (POSIX; released if the process dies)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    handle = open(folder / ".acquire.lock", "a")  # noqa: SIM115
    try:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise AcquisitionError(f"another hexatherm acquire is recording {folder}") from None
        yield
    finally:
        handle.close()


# ---------------------------------------------------------------------- live run
@dataclass(frozen=True)
class AcquireOptions:
    """Options of a live acquisition (see ``hexatherm acquire --help``)."""

    session: Path
    probe: PortSettings
    temperature_port: PortSettings | None = None
    temperatures_file: Path | None = None
    auto: bool = False
    resume: bool = False
    unit: str = "mm"
    idle_timeout_s: float | None = None
    reopen_interval_s: float = 1.0
    checks: FitChecks = field(default_factory=FitChecks)
    max_gap_s: float = 600.0


@dataclass(frozen=True)
class AcquireResult:
    """What an acquisition (or a replay) produced."""

    session: Path
    complete: bool
    n_points: int
    fits: tuple[BallFit, ...]
    session_file: Path | None


def _reconcile(sink_path: Path, lines: list[str], notify: Notify, what: str) -> None:
    """Make ``sink_path`` hold exactly ``lines`` (rebuilt from the log)."""
    expected = "".join(line + "\n" for line in lines)
    current = sink_path.read_text(encoding="utf-8") if sink_path.is_file() else ""
    if current == expected:
        return
    if expected.startswith(current):
        missing = expected.count("\n") - current.count("\n")
        notify(
            "info",
            f"{what}: {missing} line(s) received before the interruption restored from serial.log",
        )
        with open(sink_path, "a", encoding="utf-8", newline="") as handle:
            handle.write(expected[len(current) :])
            handle.flush()
            os.fsync(handle.fileno())
        return
    if not lines:
        return
    notify(
        "warn",
        f"{sink_path} did not match serial.log (edited, or a redo was "
        "interrupted); rewritten from serial.log",
    )
    atomic_write_text(sink_path, expected)


def acquire(
    files: SessionFiles,
    options: AcquireOptions,
    notify: Notify,
    operator_lines: Iterable[str] | None = None,
) -> AcquireResult:
    """Run a live acquisition into ``options.session`` (see the module docstring).

    Parameters
    ----------
    files : SessionFiles
        Plan, hexapod and balls.
    options : AcquireOptions
    notify : callable
        ``notify(level, message)`` for the operator.
    operator_lines : iterable of str, optional
        The operator's commands (standard input) in interactive mode.

    Returns
    -------
    AcquireResult

    Raises
    ------
    IncompleteSession
        When the acquisition stops before the end of the plan (idle timeout,
        the operator's ``quit``, end of the operator's input).
    AcquisitionError
        When a port does not open or the session folder is in the way.
    """
    folder = options.session
    log_path = folder / LOG_NAME
    if options.resume:
        if not log_path.is_file():
            raise AcquisitionError(f"nothing to resume: {log_path} does not exist")
    elif log_path.exists():
        raise AcquisitionError(
            f"{folder} already holds a recording ({LOG_NAME}); continue it "
            "with --resume, or choose another --session"
        )
    elif folder.exists() and not folder.is_dir():
        raise AcquisitionError(f"{folder} exists and is not a folder")
    if options.temperature_port is not None and options.temperatures_file is not None:
        raise AcquisitionError("give --temperatures or --temperature-port, not both")

    probe_port = options.probe.open()
    temperature_port = None
    try:
        if options.temperature_port is not None:
            temperature_port = options.temperature_port.open()
        folder.mkdir(parents=True, exist_ok=True)
        with session_lock(folder):
            return _run(files, options, notify, operator_lines, probe_port, temperature_port)
    finally:
        for port in (probe_port, temperature_port):
            if port is not None:
                with contextlib.suppress(Exception):
                    port.close()


def _run(
    files: SessionFiles,
    options: AcquireOptions,
    notify: Notify,
    operator_lines: Iterable[str] | None,
    probe_port: Any,
    temperature_port: Any,
) -> AcquireResult:
    folder = options.session
    log_path = folder / LOG_NAME
    points_sink, temperature_sink = (
        FileSink(folder / POINTS_NAME),
        FileSink(folder / TEMPERATURES_NAME),
    )
    recorder = Recorder(
        files.plan,
        files.balls,
        points=MemorySink(),
        temperatures=MemorySink(),
        notify=quiet,
        checks=options.checks,
        max_gap_s=options.max_gap_s,
    )
    if options.resume:
        check_same_files(files, folder)
        raw = log_path.read_bytes()
        entries, complete = parse_log(raw, os.fspath(log_path))
        if complete < len(raw):
            notify(
                "warn",
                f"{LOG_NAME}: an unfinished last line ({len(raw) - complete} bytes) "
                "of the interrupted run dropped",
            )
            os.truncate(log_path, complete)
        for item in entries:
            recorder.apply(item)
        _reconcile(folder / POINTS_NAME, recorder.point_lines, notify, POINTS_NAME)
        _reconcile(
            folder / TEMPERATURES_NAME, recorder.temperatures.lines, notify, TEMPERATURES_NAME
        )
        notify("info", f"resuming: {recorder.n_points} points recorded, at {recorder.where()}")
        log = SerialLog(log_path, create=False)
    else:
        write_copies(folder, files)
        log = SerialLog(log_path, create=True)
        points_sink.rewrite([POINTS_HEADER])
    recorder.points_sink, recorder.temperature_sink = points_sink, temperature_sink
    recorder.stopped = False

    def record(item: LogEntry) -> None:
        log.append(item)
        recorder.apply(item)

    stop = threading.Event()
    items: queue.Queue[Any] = queue.Queue()
    readers = [PortReader(PROBE, options.probe, probe_port, items, stop, options.reopen_interval_s)]
    if temperature_port is not None:
        assert options.temperature_port is not None
        readers.append(
            PortReader(
                TEMPERATURE,
                options.temperature_port,
                temperature_port,
                items,
                stop,
                options.reopen_interval_s,
            )
        )
    outcome = "complete"
    recorder.notify = notify
    try:
        if options.resume:
            record(entry("resume"))
        record(entry("config", "-", f"units={options.unit}"))
        record(entry("mode", "-", "auto" if options.auto else "interactive"))
        record(entry("open", PROBE, options.probe.describe()))
        if options.temperature_port is not None:
            record(entry("open", TEMPERATURE, options.temperature_port.describe()))
        recorder.announce()
        for reader in readers:
            reader.start()
        if not options.auto and operator_lines is not None:
            InputReader(operator_lines, items).start()
        outcome = _loop(recorder, record, items, options, notify)
    finally:
        stop.set()
        for reader in readers:
            reader.join(timeout=5.0)
        with contextlib.suppress(Exception):
            log.append(
                entry(
                    "end", "-", outcome if recorder.done or outcome != "complete" else "interrupted"
                )
            )
        log.close()
        points_sink.close()
        temperature_sink.close()
    fits = tuple(recorder.fits[k] for k in sorted(recorder.fits))
    if not recorder.done:
        raise IncompleteSession(
            f"acquisition stopped ({outcome}) at {recorder.where()}: "
            f"{recorder.n_points} points recorded in {folder}; continue "
            "with --resume"
        )
    session_file = finish_session(folder, notify, options.temperatures_file)
    return AcquireResult(folder, True, recorder.n_points, fits, session_file)


def _loop(
    recorder: Recorder,
    record: Callable[[LogEntry], None],
    items: queue.Queue[Any],
    options: AcquireOptions,
    notify: Notify,
) -> str:
    """Log and apply the queue's items until the plan is done or the run stops."""
    last_data = time.monotonic()
    while not recorder.done:
        if recorder.stopped:
            return "quit"
        try:
            item = items.get(timeout=0.1)
        except queue.Empty:
            if (
                options.idle_timeout_s is not None
                and time.monotonic() - last_data > options.idle_timeout_s
            ):
                notify("warn", f"no data from the probe for {options.idle_timeout_s:g} s")
                return "idle"
            continue
        kind = item[0]
        if kind == "rx":
            _, source, when, data = item
            if source == PROBE:
                last_data = time.monotonic()
            record(LogEntry(when, "rx", source, data))
        elif kind in ("lost", "reopen"):
            _, source, when, text = item
            last_data = time.monotonic()
            record(LogEntry(when, kind, source, text.encode("utf-8", "replace")))
        elif kind == "input":
            _, when, line = item
            event = operator_command(line)
            if event is None:
                notify("warn", f"unknown command {line.strip()!r}: Enter or 'next', 'redo', 'quit'")
                continue
            record(LogEntry(when, "event", "operator", event.encode()))
        elif kind == "input-eof":
            notify("warn", "end of the operator's input")
            return "input closed"
    return "complete"


# ------------------------------------------------------------------------- replay
def replay(
    files: SessionFiles,
    log_file: Path,
    session: Path,
    notify: Notify,
    temperatures_file: Path | None = None,
) -> AcquireResult:
    """Re-run the parser and the assignment on a recorded ``serial.log``.

    Writes a new session folder ``session`` with the configuration copies, a
    copy of the log's complete lines, ``points.csv`` (the same bytes as the
    recording's) and, when the recording covers the whole plan, ``session.yaml``.
    """
    log_file = Path(log_file)
    try:
        raw = log_file.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=os.fspath(log_file)) from None
    entries, complete = parse_log(raw, os.fspath(log_file))
    if session.exists() and (not session.is_dir() or any(session.iterdir())):
        raise AcquisitionError(f"{session} exists and is not empty; replay into a new folder")
    session.mkdir(parents=True, exist_ok=True)
    write_copies(session, files)
    with open(session / LOG_NAME, "xb") as handle:
        handle.write(raw[:complete])
    points_sink = FileSink(session / POINTS_NAME)
    temperature_sink = FileSink(session / TEMPERATURES_NAME)
    points_sink.rewrite([POINTS_HEADER])
    recorder = Recorder(
        files.plan, files.balls, points=points_sink, temperatures=temperature_sink, notify=notify
    )
    try:
        for item in entries:
            recorder.apply(item)
    finally:
        points_sink.close()
        temperature_sink.close()
    fits = tuple(recorder.fits[k] for k in sorted(recorder.fits))
    session_file = None
    if recorder.done:
        session_file = finish_session(session, notify, temperatures_file)
    else:
        notify(
            "warn",
            f"the recording ends at {recorder.where()}: the session is incomplete "
            "(no session.yaml)",
        )
    return AcquireResult(session, recorder.done, recorder.n_points, fits, session_file)
