"""A simulated I++ DME server: a CMM probing balls, for tests and rehearsals.

:class:`IppSimServer` listens on 127.0.0.1 (port 0 picks a free one: :attr:`IppSimServer.port`)
and speaks the dialect of :mod:`hexatherm.devices.ipp` (I++ DME 1.4.3): ``&`` at once, the
data, then ``%``; errors as ``Error(severity, number, "method", "text")`` followed by ``%``;
after an error of severity >= 2 only ``ClearAllErrors()``, the error-status queries and the
session commands are executed (the others get error 0514) [6.2.5].

What it simulates
-----------------
- The machine: homed or not (moves need ``Home()``), a tool-centre position, a box of
  travel limits (error 2500), a tool table (``ChangeTool``, ``FindTool``, ``SetTool``,
  ``EnumTools``) with per-tool properties ``PtMeasPar.{Speed, Accel, Approach, Search,
  Retract}``, ``GoToPar.{Speed, Accel}``, ``AvrRadius`` (read only) and ``Name``.
- The balls, from a pluggable :class:`CmmBackend` asked at the time of each move or touch
  (``time_s``: seconds since the server started, or the caller's clock): every move
  (``GoTo`` and the moves inside ``PtMeas``) is checked against the balls grown by the tip
  radius; a crossing is a collision (error 2504, severity 3, the probe stays where it was).
- ``PtMeas(X(x), Y(y), Z(z), IJK(i, j, k))`` [6.3.2.13]: the tip centre goes to the approach
  position ``p + (Approach + r) u`` (``u`` the normalized IJK, ``r`` the tip radius) and
  searches along ``-u`` until ``Search`` mm past the nominal contact (tip centre at
  ``p + (r - Search) u``). At the first ball it touches it reports the touched surface
  point ``c + R n`` (``n`` the ball's outward normal there; with ``compensated=False`` the
  tip centre ``c + (R + r) n``), plus ``N(0, noise)`` along ``n``; ``IJK`` is ``n`` and
  ``ER`` the tip radius. Touching nothing is error 1006 "Surface not found" (severity 2).
  Then the tip retracts ``Retract`` mm along ``u`` (to the approach position if negative).
  Without IJK, ``u`` points from the nominal point to the current position (spec).

Fault injection (:class:`Fault`), deterministic: each fault fires once, on the ``nth``
command received by the server (all connections), or the ``nth`` of one method:

- ``error``: the command is not executed; ``&``, ``! Error(severity, number, ...)``, ``%``.
- ``event``: ``E0000`` lines interleaved with the response (after ``&``, between data lines,
  before ``%``).
- ``drop``: the connection is closed after ``after_lines`` lines of the response.
- ``split``: every response line of the command goes out in writes of ``chunk_bytes``.
- ``delay``: ``delay_s`` between ``&`` and the rest of the response.

Examples
--------
>>> balls = StaticBalls([[0.0, 0.0, 0.0]], [12.7])
>>> with IppSimServer(balls, tools={"Probe1": 2.0}) as server:
...     from hexatherm.devices.ipp import IppClient
...     with IppClient("127.0.0.1", server.port, timeout_s=30) as cmm:
...         cmm.start_session(); cmm.home(); cmm.change_tool("Probe1")
...         cmm.goto(0, 0, 30)
...         p = cmm.pt_meas(0, 0, 12.7, 0, 0, 1)
>>> p.point_mm
(0.0, 0.0, 12.7)
"""

from __future__ import annotations

import math
import re
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.devices.ipp import (
    DEFAULT_REPORT,
    REPORT_ARITY,
    Call,
    ErrorReport,
    LineBuffer,
    Value,
    Word,
    fields,
    format_number,
    parse_command,
)
from hexatherm.errors import (
    IppDmeError,
    IppProtocolError,
)
from hexatherm.typing import FloatArray

_TAG = re.compile(r"[0-9]{5}|E[0-9]{4}")
FaultKind = Literal["error", "event", "drop", "split", "delay"]
DEFAULT_EVENTS = ('KeyPress("F1")', "GoTo(X(10), Y(-11.5), Z(3.25E+02))")
"""Bodies of the ``E0000 #`` lines an ``event`` fault sends by default (spec examples)."""
ERROR_TEXTS = {
    1: "Illegal tag",
    2: "No space at pos. 6",
    6: "Transaction aborted (Use ClearAllErrors To Continue)",
    8: "Protocol error",
    500: "Emergency stop",
    501: "Unsupported command",
    502: "Incorrect arguments",
    504: "Argument out of range",
    508: "Bad context",
    510: "Bad property",
    511: "Error processing method",
    514: "Use ClearAllErrors to continue",
    1005: "Error during home",
    1006: "Surface not found",
    1010: "Vector has no norm",
    1011: "Unable to move",
    1502: "Tool not found",
    1503: "Tool not defined",
    2500: "Machine limit encountered [Move Out Of Limits]",
    2504: "Collision",
}
"""Texts of the errors the simulator sends (spec section 8.2)."""
DEFAULT_FAULT_NUMBER = {2: 1011, 3: 2504}
"""Error number of an ``error`` fault without one, by severity (else 511)."""
PROPERTY_DEFAULTS = {
    "PtMeasPar.Speed": 10.0,
    "PtMeasPar.Accel": 100.0,
    "PtMeasPar.Approach": 2.0,
    "PtMeasPar.Search": 5.0,
    "PtMeasPar.Retract": 2.0,
    "GoToPar.Speed": 100.0,
    "GoToPar.Accel": 500.0,
}
"""Settable tool properties and their values for a new tool (mm, mm/s, mm/s^2)."""
_IN_ERROR_OK = frozenset(
    {"ClearAllErrors", "GetErrStatusE", "GetXtdErrStatus", "StartSession", "EndSession", "AbortE"}
)


class CmmBackend(Protocol):
    """What the simulated CMM probes: balls that may move with time."""

    def ball_centres_mm(self, t_s: float) -> FloatArray:
        """(k, 3) ball centres in the CMM frame at time ``t_s`` (s), mm."""
        ...

    def ball_radii_mm(self, t_s: float) -> FloatArray:
        """(k,) ball radii at time ``t_s``, mm."""
        ...


class StaticBalls:
    """Fixed spheres: a :class:`CmmBackend` for tests.

    Parameters
    ----------
    centres_mm : array_like, shape (k, 3)
        Ball centres in the CMM frame, mm.
    radii_mm : array_like, shape (k,) or scalar
        Ball radii, mm.
    """

    def __init__(self, centres_mm: npt.ArrayLike, radii_mm: npt.ArrayLike) -> None:
        centres = np.array(centres_mm, dtype=float)
        if centres.ndim != 2 or centres.shape[1] != 3 or centres.shape[0] < 1:
            raise IppDmeError(f"centres_mm must have shape (k, 3), k >= 1, got {centres.shape}")
        radii = np.broadcast_to(np.array(radii_mm, dtype=float), centres.shape[:1]).copy()
        if not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
            raise IppDmeError("ball centres must be finite and radii positive")
        self.centres_mm = centres
        self.radii_mm = radii

    def ball_centres_mm(self, t_s: float) -> FloatArray:
        """See :class:`CmmBackend`."""
        return self.centres_mm.copy()

    def ball_radii_mm(self, t_s: float) -> FloatArray:
        """See :class:`CmmBackend`."""
        return self.radii_mm.copy()


@dataclass(frozen=True)
class Fault:
    """One injected fault (see the module docstring).

    Attributes
    ----------
    kind : {"error", "event", "drop", "split", "delay"}
    nth : int
        Fires on the ``nth`` (1-based) command received, counting only ``method`` if given.
    method : str, optional
        Count only commands of this method (``"PtMeas"``).
    severity, number, text
        Of an ``error`` (number by default 1011 "Unable to move" for severity 2, 2504
        "Collision" for 3).
    events : tuple of str
        Bodies of the ``E0000 #`` lines of an ``event`` fault.
    after_lines : int
        Lines of the response sent before a ``drop`` closes the connection (1: after ``&``).
    chunk_bytes : int
        Size of the writes of a ``split``.
    delay_s : float
        Delay of a ``delay``, s.
    """

    kind: FaultKind
    nth: int
    method: str | None = None
    severity: int = 2
    number: int | None = None
    text: str | None = None
    events: tuple[str, ...] = DEFAULT_EVENTS
    after_lines: int = 1
    chunk_bytes: int = 3
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("error", "event", "drop", "split", "delay"):
            raise IppDmeError(f"unknown fault kind {self.kind!r}")
        if int(self.nth) != self.nth or self.nth < 1:
            raise IppDmeError(f"nth must be a positive integer, got {self.nth!r}")
        if not 0 <= self.severity <= 9:
            raise IppDmeError(f"severity must be 0..9, got {self.severity}")
        if self.after_lines < 0 or self.chunk_bytes < 1 or not self.delay_s >= 0:
            raise IppDmeError("after_lines >= 0, chunk_bytes >= 1 and delay_s >= 0 required")

    def error(self, method: str) -> ErrorReport:
        """The error an ``error`` fault sends for a command of ``method``."""
        number = (
            self.number if self.number is not None else DEFAULT_FAULT_NUMBER.get(self.severity, 511)
        )
        text = self.text if self.text is not None else ERROR_TEXTS.get(number, "Injected fault")
        return ErrorReport(self.severity, number, method, text)


class _Refusal(Exception):
    def __init__(self, severity: int, number: int, method: str) -> None:
        self.report = ErrorReport(severity, number, method, ERROR_TEXTS.get(number, "Error"))


@dataclass
class _Tool:
    name: str
    tip_radius_mm: float
    measures: bool = True
    props: dict[str, float] = field(default_factory=lambda: dict(PROPERTY_DEFAULTS))


@dataclass
class _Session:
    active: bool = False
    error: ErrorReport | None = None
    report: tuple[str, ...] = DEFAULT_REPORT


class IppSimServer:
    """A simulated I++ DME server on a local TCP port (threads; a context manager).

    Parameters
    ----------
    backend : CmmBackend
        The balls.
    host : str
        Address to listen on (127.0.0.1).
    port : int
        Port, 0 for a free one (see :attr:`port`).
    tools : mapping of str to float, optional
        Tool names and their tip diameters, mm (default ``{"Probe1": 2.0}``); ``NoTool``
        (moves, cannot measure) is always there and active at start.
    noise_um : float
        Standard deviation of the probing noise along the surface normal, um.
    seed : int
        Seed of the noise (the n-th touch gets the n-th draw).
    faults : sequence of Fault
        Injected faults.
    compensated : bool
        Report surface points (True) or tip centres.
    number_format : callable
        Formats the numbers of the responses (default 15 significant digits).
    time_s : callable, optional
        The backend's clock, s (default: seconds since the server started).
    home_mm : sequence of 3 float
        Tool-centre position after ``Home()``, mm.
    limits_mm : pair of sequences of 3 float
        Lower and upper corners of the travel box, mm.

    Attributes
    ----------
    commands : list of str
        Every command line received, in order (all connections).
    touches : int
        Number of touches made (``PtMeas`` that found a surface).
    """

    def __init__(
        self,
        backend: CmmBackend,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        tools: Mapping[str, float] | None = None,
        noise_um: float = 0.0,
        seed: int = 0,
        faults: Sequence[Fault] = (),
        compensated: bool = True,
        number_format: Callable[[float], str] = format_number,
        time_s: Callable[[], float] | None = None,
        home_mm: Sequence[float] = (0.0, 0.0, 500.0),
        limits_mm: tuple[Sequence[float], Sequence[float]] = ((-1e3, -1e3, -1e3), (1e3, 1e3, 1e3)),
    ) -> None:
        if not (math.isfinite(noise_um) and noise_um >= 0):
            raise IppDmeError(f"noise_um must be >= 0, got {noise_um!r}")
        table = {"Probe1": 2.0} if tools is None else dict(tools)
        self._tools = {"NoTool": _Tool("NoTool", 0.0, measures=False)}
        for name, diameter in table.items():
            if not (math.isfinite(diameter) and diameter > 0) or '"' in name or not name:
                raise IppDmeError(f"tool {name!r}: the tip diameter must be positive")
            self._tools[name] = _Tool(name, 0.5 * float(diameter))
        self.backend = backend
        self.noise_mm = 1e-3 * float(noise_um)
        self._rng = np.random.default_rng(seed)
        self._faults = list(faults)
        self._fired: set[int] = set()
        self.compensated = bool(compensated)
        self._num = number_format
        start = time.monotonic()
        self._time_s = time_s if time_s is not None else (lambda: time.monotonic() - start)
        self.home_mm = np.array(home_mm, dtype=float)
        self.limits_mm = (np.array(limits_mm[0], dtype=float), np.array(limits_mm[1], dtype=float))
        self.position_mm = self.home_mm.copy()
        self.homed = False
        self.active_tool = "NoTool"
        self.found_tool: str | None = None
        self.commands: list[str] = []
        self.touches = 0
        self._counts: Counter[str] = Counter()
        self._total = 0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._conns: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._listener = socket.create_server((host, port))
        self._listener.settimeout(0.2)
        self.host, self.port = self._listener.getsockname()[:2]
        accept = threading.Thread(target=self._accept_loop, name="ipp-sim-accept", daemon=True)
        self._threads.append(accept)
        accept.start()

    @property
    def url(self) -> str:
        """``ipp://HOST:PORT`` of the server."""
        return f"ipp://{self.host}:{self.port}"

    def __enter__(self) -> IppSimServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop listening, close every connection, stop the threads."""
        self._stop.set()
        for sock in [self._listener, *self._conns]:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            sock.close()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(timeout=5.0)

    # ----------------------------------------------------------------- network
    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(None)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conns.append(conn)
            thread = threading.Thread(
                target=self._serve, args=(conn,), name="ipp-sim-conn", daemon=True
            )
            self._threads.append(thread)
            thread.start()

    def _serve(self, conn: socket.socket) -> None:
        session = _Session()
        buffer = LineBuffer()
        try:
            while not self._stop.is_set():
                data = conn.recv(65536)
                if not data:
                    return
                for raw in buffer.feed(data):
                    if not self._handle(conn, session, raw.decode("latin-1")):
                        return
        except (OSError, IppProtocolError):
            return
        finally:
            try:
                conn.close()
            except OSError:
                pass

    def _handle(self, conn: socket.socket, session: _Session, line: str) -> bool:
        """Answer one command line; False when the connection was dropped."""
        with self._lock:
            self.commands.append(line)
            try:
                tag, call = parse_command(line)
            except IppProtocolError:
                tag = line[:5]
                if not _TAG.fullmatch(tag) or tag in ("00000", "E0000"):
                    report = ErrorReport(2, 1, "Parse", ERROR_TEXTS[1])
                    self._send(conn, [f"E0000 ! {report.format()}"], None)
                elif line[5:6] != " ":
                    report = ErrorReport(2, 2, "Parse", ERROR_TEXTS[2])
                    self._send(conn, [f"{tag} ! {report.format()}"], None)
                else:
                    error = self._error_line(tag, session, 3, 502, "Parse")
                    self._send(conn, [f"{tag} &", error, f"{tag} %"], None)
                return True
            fault = self._fault_for(call.name)
            if fault is not None and fault.kind == "error":
                report = fault.error(call.name)
                if report.severity >= 2:
                    session.error = report
                lines = [f"{tag} &", f"{tag} ! {report.format()}", f"{tag} %"]
            else:
                lines = [f"{tag} &", *self._execute(tag, session, call), f"{tag} %"]
        return self._send(conn, lines, fault)

    def _fault_for(self, method: str) -> Fault | None:
        self._total += 1
        self._counts[method] += 1
        chosen = None
        for index, fault in enumerate(self._faults):
            count = self._total if fault.method is None else self._counts[fault.method]
            if index in self._fired or (fault.method is not None and fault.method != method):
                continue
            if count == fault.nth and chosen is None:
                self._fired.add(index)
                chosen = fault
        return chosen

    def _send(self, conn: socket.socket, lines: list[str], fault: Fault | None) -> bool:
        if fault is not None and fault.kind == "event":
            events = [f"E0000 # {body}" for body in fault.events]
            out = [lines[0]]
            for line in lines[1:-1]:
                if events:
                    out.append(events.pop(0))
                out.append(line)
            lines = [*out, *events, lines[-1]]
        try:
            for index, line in enumerate(lines):
                if fault is not None and fault.kind == "drop" and index == fault.after_lines:
                    conn.shutdown(socket.SHUT_RDWR)
                    conn.close()
                    return False
                if fault is not None and fault.kind == "delay" and index == 1:
                    if self._stop.wait(fault.delay_s):
                        return False
                data = line.encode("ascii") + b"\r\n"
                if fault is not None and fault.kind == "split":
                    for start in range(0, len(data), fault.chunk_bytes):
                        conn.sendall(data[start : start + fault.chunk_bytes])
                else:
                    conn.sendall(data)
        except OSError:
            return False
        return True

    # ---------------------------------------------------------------- commands
    def _error_line(
        self, tag: str, session: _Session, severity: int, number: int, method: str
    ) -> str:
        report = ErrorReport(severity, number, method, ERROR_TEXTS.get(number, "Error"))
        if severity >= 2:
            session.error = report
        return f"{tag} ! {report.format()}"

    def _execute(self, tag: str, session: _Session, call: Call) -> list[str]:
        name = call.name
        if not session.active and name not in ("StartSession", "EndSession"):
            return [self._error_line(tag, session, 3, 8, name)]
        if session.error is not None and name not in _IN_ERROR_OK:
            return [self._error_line(tag, session, 2, 514, name)]
        handler = getattr(self, f"_do_{name}", None)
        if handler is None:
            return [self._error_line(tag, session, 3, 501, name)]
        try:
            data = handler(session, call)
        except _Refusal as refusal:
            report = refusal.report
            return [self._error_line(tag, session, report.severity, report.number, name)]
        except IppProtocolError:
            return [self._error_line(tag, session, 3, 502, name)]
        return [f"{tag} # {body}" for body in data]

    def _do_StartSession(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        if session.active:
            raise _Refusal(3, 8, "StartSession")
        session.active, session.error, session.report = True, None, DEFAULT_REPORT
        return []

    def _do_EndSession(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        session.active = False
        return []

    def _do_ClearAllErrors(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        session.error = None
        return []

    def _do_AbortE(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        session.error = ErrorReport(2, 6, "AbortE", ERROR_TEXTS[6])
        return []

    def _do_GetErrStatusE(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        return [f"ErrStatus({int(session.error is not None)})"]

    def _do_GetDMEVersion(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        return ['DMEVersion("1.4.3")']

    def _do_Home(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        self.position_mm = self.home_mm.copy()
        self.homed = True
        return []

    def _do_IsHomed(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        return [f"IsHomed({int(self.homed)})"]

    def _do_EnumTools(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        return [f'"{name}"' for name in self._tools]

    def _tool_arg(self, call: Call) -> str:
        if (
            len(call.args) != 1
            or not isinstance(call.args[0], str)
            or isinstance(call.args[0], Word)
        ):
            raise IppProtocolError("expected one tool name string")
        if call.args[0] not in self._tools:
            raise _Refusal(3, 1502, call.name)
        return call.args[0]

    def _do_ChangeTool(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        self.active_tool = self._tool_arg(call)
        return []

    _do_SetTool = _do_ChangeTool

    def _do_FindTool(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        self.found_tool = self._tool_arg(call)
        return []

    def _property(self, name: str, method: str) -> tuple[_Tool, str]:
        head, _, rest = name.partition(".")
        if head == "Tool":
            tool = self._tools[self.active_tool]
        elif head == "FoundTool":
            if self.found_tool is None:
                raise _Refusal(3, 1503, method)
            tool = self._tools[self.found_tool]
        else:
            raise _Refusal(3, 510, method)
        if rest not in tool.props and rest not in ("Name", "AvrRadius"):
            raise _Refusal(3, 510, method)
        return tool, rest

    def _do_GetProp(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        items = []
        for arg in _calls(call.args, 0):
            tool, prop = self._property(arg.name, "GetProp")
            if prop == "Name":
                items.append(f'{arg.name}("{tool.name}")')
            else:
                value = tool.tip_radius_mm if prop == "AvrRadius" else tool.props[prop]
                items.append(f"{arg.name}({self._num(value)})")
        return [", ".join(items)]

    def _do_SetProp(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        updates = []
        for arg in _calls(call.args, 1):
            tool, prop = self._property(arg.name, "SetProp")
            value = float(arg.args[0])  # type: ignore[arg-type]
            if prop in ("Name", "AvrRadius"):
                raise _Refusal(3, 510, "SetProp")
            if prop in ("PtMeasPar.Approach", "PtMeasPar.Search") and not value > 0:
                raise _Refusal(3, 504, "SetProp")
            updates.append((tool, prop, value))
        for tool, prop, value in updates:
            tool.props[prop] = value
        return []

    def _do_OnPtMeasReport(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        names = tuple(arg.name for arg in _calls(call.args, 0))
        if not names or len(set(names)) != len(names):
            raise _Refusal(3, 502, "OnPtMeasReport")
        if any(n not in REPORT_ARITY or n == "R" for n in names):
            raise _Refusal(3, 510, "OnPtMeasReport")
        session.report = names
        return []

    def _do_Get(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        names = [arg.name for arg in _calls(call.args, 0)]
        if not names or any(n not in "XYZ" or len(n) != 1 for n in names):
            raise _Refusal(3, 510, "Get")
        return [", ".join(f"{n}({self._num(self.position_mm['XYZ'.index(n)])})" for n in names)]

    def _target(
        self, call: Call, allowed: Iterable[str]
    ) -> tuple[FloatArray, dict[str, tuple[float, ...]]]:
        given = fields(call.args)
        if not given or set(given) - set(allowed):
            raise IppProtocolError("bad arguments")
        target = self.position_mm.copy()
        for axis, n in enumerate("XYZ"):
            if n in given:
                if len(given[n]) != 1:
                    raise IppProtocolError("bad arguments")
                target[axis] = given[n][0]
        return target, given

    def _move(self, target: FloatArray, method: str) -> None:
        if not self.homed:
            raise _Refusal(3, 508, method)
        low, high = self.limits_mm
        if np.any(target < low) or np.any(target > high):
            raise _Refusal(3, 2500, method)
        t = self._time_s()
        centres = self.backend.ball_centres_mm(t)
        rho = self.backend.ball_radii_mm(t) + self._tools[self.active_tool].tip_radius_mm
        if segment_hits(self.position_mm, target, centres, rho).any():
            raise _Refusal(3, 2504, method)
        self.position_mm = np.array(target, dtype=float)

    def _do_GoTo(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        target, _ = self._target(call, "XYZ")
        self._move(target, "GoTo")
        return []

    def _do_PtMeas(self, session: _Session, call: Call) -> list[str]:  # noqa: N802
        tool = self._tools[self.active_tool]
        if not tool.measures:
            raise _Refusal(3, 1503, "PtMeas")
        nominal, given = self._target(call, ("X", "Y", "Z", "IJK"))
        if not any(n in given for n in "XYZ"):
            raise IppProtocolError("IJK alone is not allowed")
        if "IJK" in given:
            if len(given["IJK"]) != 3:
                raise IppProtocolError("IJK needs 3 numbers")
            direction = np.array(given["IJK"])
        else:
            direction = self.position_mm - nominal
        norm = float(np.linalg.norm(direction))
        if not norm > 0:
            raise _Refusal(2, 1010, "PtMeas")
        u = direction / norm
        r = tool.tip_radius_mm
        approach, search = tool.props["PtMeasPar.Approach"], tool.props["PtMeasPar.Search"]
        retract = tool.props["PtMeasPar.Retract"]
        start = nominal + (approach + r) * u
        self._move(start, "PtMeas")
        t = self._time_s()
        centres = self.backend.ball_centres_mm(t)
        radii = self.backend.ball_radii_mm(t)
        s, ball = first_contact(start, -u, approach + search, centres, radii + r)
        if ball < 0:
            raise _Refusal(2, 1006, "PtMeas")
        tip = start - s * u
        normal = (tip - centres[ball]) / np.linalg.norm(tip - centres[ball])
        surface = centres[ball] + (radii[ball] if self.compensated else radii[ball] + r) * normal
        noise = self._rng.normal(0.0, self.noise_mm) if self.noise_mm > 0 else 0.0
        reported = surface + noise * normal
        self.touches += 1
        self.position_mm = tip + retract * u if retract >= 0 else start
        values = {
            "X": (reported[0],),
            "Y": (reported[1],),
            "Z": (reported[2],),
            "IJK": tuple(normal),
            "ER": (r,),
            "Q": (0.0,),
        }
        items = [
            f"{n}({', '.join(self._num(float(v)) for v in values[n])})" for n in session.report
        ]
        return [", ".join(items)]


def _calls(args: tuple[Value, ...], arity: int) -> list[Call]:
    out = []
    for arg in args:
        if not isinstance(arg, Call) or len(arg.args) != arity:
            raise IppProtocolError("bad arguments")
        if arity and not all(isinstance(a, float) for a in arg.args):
            raise IppProtocolError("bad arguments")
        out.append(arg)
    if not out:
        raise IppProtocolError("no arguments")
    return out


def segment_hits(
    start_mm: npt.ArrayLike,
    end_mm: npt.ArrayLike,
    centres_mm: npt.ArrayLike,
    radii_mm: npt.ArrayLike,
) -> npt.NDArray[np.bool_]:
    """Which spheres the straight segment from ``start`` to ``end`` enters (mm).

    A segment that only grazes a sphere (distance = radius, within 1 nm) does not enter it.

    >>> segment_hits([-20, 0, 0], [20, 0, 0], [[0, 0, 0], [0, 30, 0]], [12.7, 12.7]).tolist()
    [True, False]
    """
    p0 = np.asarray(start_mm, dtype=float)
    d = np.asarray(end_mm, dtype=float) - p0
    c = np.asarray(centres_mm, dtype=float)
    length2 = float(d @ d)
    t = np.zeros(len(c)) if length2 == 0 else np.clip((c - p0) @ d / length2, 0.0, 1.0)
    closest = p0 + t[:, None] * d
    return np.linalg.norm(c - closest, axis=1) < np.asarray(radii_mm, dtype=float) - 1e-6


def first_contact(
    start_mm: npt.ArrayLike,
    direction: npt.ArrayLike,
    length_mm: float,
    centres_mm: npt.ArrayLike,
    radii_mm: npt.ArrayLike,
) -> tuple[float, int]:
    """Distance along a unit direction at which a point first reaches one of the spheres.

    Parameters
    ----------
    start_mm : array_like, shape (3,)
        Start (outside every sphere), mm.
    direction : array_like, shape (3,)
        Unit direction of travel.
    length_mm : float
        Length of travel, mm.
    centres_mm, radii_mm : array_like, shapes (k, 3) and (k,)
        Spheres (the balls grown by the tip radius), mm.

    Returns
    -------
    distance_mm : float
        Travel to the first contact (inf if none).
    index : int
        The sphere touched, -1 if none within ``length_mm``.

    Examples
    --------
    >>> s, index = first_contact([0, 0, 20], [0, 0, -1], 10.0, [[0, 0, 0]], [13.7])
    >>> round(s, 9), index
    (6.3, 0)
    """
    p = np.asarray(start_mm, dtype=float)
    u = np.asarray(direction, dtype=float)
    d = p - np.asarray(centres_mm, dtype=float)
    rho = np.asarray(radii_mm, dtype=float)
    b = d @ u
    c = np.einsum("ij,ij->i", d, d) - rho**2
    disc = b**2 - c
    with np.errstate(invalid="ignore"):
        s = -b - np.sqrt(disc)
    ok = (disc >= 0) & (c > 0) & (s >= 0) & (s <= length_mm)
    if not ok.any():
        return math.inf, -1
    s = np.where(ok, s, np.inf)
    index = int(np.argmin(s))
    return float(s[index]), index
