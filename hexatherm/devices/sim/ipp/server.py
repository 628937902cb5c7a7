"""The simulated I++ DME server: a threaded TCP server on 127.0.0.1 in the client's dialect."""

from __future__ import annotations

import math
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence

import numpy as np

from hexatherm.devices.ipp import (
    DEFAULT_REPORT,
    REPORT_ARITY,
    Call,
    ErrorReport,
    LineBuffer,
    Word,
    fields,
    format_number,
    parse_command,
)
from hexatherm.devices.sim.ipp.contact import _calls, first_contact, segment_hits
from hexatherm.devices.sim.ipp.model import (
    _IN_ERROR_OK,
    _TAG,
    CMM_DIALECTS,
    ERROR_TEXTS,
    CmmBackend,
    Fault,
    _Refusal,
    _Session,
    _Tool,
)
from hexatherm.errors import (
    IppDmeError,
    IppProtocolError,
)
from hexatherm.typing import FloatArray


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
    dialect : {"dme-1.4.3", "dme-1.4"}
        How the server speaks (see :data:`CMM_DIALECTS`).

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
        dialect: str = "dme-1.4.3",
    ) -> None:
        if dialect not in CMM_DIALECTS:
            raise IppDmeError(
                f"CMM dialect must be one of {', '.join(CMM_DIALECTS)}, got {dialect!r}"
            )
        self.dialect = dialect
        # a plain DME 1.4 server keeps its session when the client goes away
        self._kept_session = _Session() if dialect == "dme-1.4" else None
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
        session = self._kept_session if self._kept_session is not None else _Session()
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
                warning = [f"{tag} ! {report.format()}"]
                if report.severity >= 2:
                    session.error = report
                    lines = [f"{tag} &", *warning, f"{tag} %"]
                else:  # a warning: the command is carried out all the same
                    lines = [f"{tag} &", *warning, *self._execute(tag, session, call), f"{tag} %"]
            else:
                lines = [f"{tag} &", *self._execute(tag, session, call), f"{tag} %"]
            if fault is not None and fault.kind == "event":
                self._tool_events(fault.events)
        return self._send(conn, lines, fault)

    def _tool_events(self, bodies: Iterable[str]) -> None:
        """A ``ChangeTool("name")`` event of a known tool is the machine's own change (an
        operator's, a tool changer's): the tool is active from the next command on."""
        for body in bodies:
            try:
                _, call = parse_command(f"00001 {body}")
            except IppProtocolError:
                continue
            if call.name == "ChangeTool" and len(call.args) == 1 and call.args[0] in self._tools:
                self.active_tool = str(call.args[0])

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
            # a body "! Error(...)" is an error event; the others are data ("#") events
            events = [f"E0000 {body if body[:2] == '! ' else '# ' + body}" for body in fault.events]
            out = [lines[0]]
            for line in lines[1:-1]:
                if events:
                    out.append(events.pop(0))
                out.append(line)
            lines = [*out, *events, lines[-1]]
        try:
            if fault is None:  # the response in one write: the same bytes, fewer wake-ups
                conn.sendall(b"".join(line.encode("latin-1") + b"\r\n" for line in lines))
                return True
            for index, line in enumerate(lines):
                if fault is not None and fault.kind == "drop" and index == fault.after_lines:
                    conn.shutdown(socket.SHUT_RDWR)
                    conn.close()
                    return False
                if fault is not None and fault.kind == "delay" and index == 1:
                    if self._stop.wait(fault.delay_s):
                        return False
                # ASCII but for an injected event's text (a European CMM's Latin-1 message)
                data = line.encode("latin-1") + b"\r\n"
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
            raise _Refusal(3, 507 if self.dialect == "dme-1.4" else 8, "StartSession")
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
        return ['DMEVersion("1.4")' if self.dialect == "dme-1.4" else 'DMEVersion("1.4.3")']

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
        try:
            self.found_tool = self._tool_arg(call)
        except _Refusal:
            if self.dialect != "dme-1.4":
                raise
            # the lax FindTool of the NIST server: no error, FoundTool left as it was
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
        if rest == "AvrRadius" and self.dialect == "dme-1.4":
            raise _Refusal(3, 502, method)  # AvrRadius came with 1.4.2
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
        order = session.report
        if self.dialect == "dme-1.4":  # its own order, whatever was asked
            order = tuple(n for n in ("ER", "IJK", "X", "Y", "Z", "Q") if n in session.report)
        items = [f"{n}({', '.join(self._num(float(v)) for v in values[n])})" for n in order]
        return [", ".join(items)]
