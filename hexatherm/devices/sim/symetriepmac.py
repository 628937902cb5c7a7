"""A simulated Symétrie ZONDA / JORAN / PUNA+ controller: the Power PMAC's ``gpascii``
over telnet, as :mod:`hexatherm.devices.symetriepmac` and CGSE's ``symetrie-hexapod``
speak it.

The session, as CGSE's ``AlphaPlusTelnetInterface`` (MIT, read to learn it) drives it:

1. telnet: the server offers ``IAC WILL ECHO``, ``IAC WILL SGA`` (a client that refuses
   still sees its lines echoed, as CGSE's replies show), then ``ppmac login: ``, echoes
   the user name, asks ``Password: ``, and on ``root`` / ``deltatau`` (the Power PMAC's
   factory login; ``credentials`` to change) gives the prompt ``ppmac# ``; a wrong pair:
   ``Login incorrect`` and the login prompt again;
2. ``gpascii -2`` starts the command interpreter: ``STDIN Open for ASCII Input``, no
   acknowledge (CGSE's ZONDA interface sends ``gpascii -2`` and ``echo7`` together and
   reads up to the first ``\\x06``: the one of ``echo7``); ``echo7`` makes answers bare
   values (before it: ``name=value``);
3. every line received is echoed (the terminal's echo), then its answers, one value a
   line, then ``\\x06`` (CR LF after every line). A line holds statements separated by
   blanks: ``name=value`` (a number or a ``C_*`` command constant), ``name`` or
   ``name(i)`` (a query), ``name,count,step`` (``count`` consecutive variables, e.g.
   ``s_uto_tx,6,1``, ``c_par(0),12,1``). An unknown name: ``stdin:N:1: error #20:
   ILLEGAL CMD: ...`` (then ``\\x06``).

Commands: writing ``c_cmd=C_NAME`` runs one (its parameters in ``c_par(i)``, ``c_cfg``
0 "get" / 1 "set"); ``c_cmd`` then reads ``1`` once (running), then the return code:
0 success, negative an error (:data:`hexatherm.devices.symetriepmac.RETURN_CODES`); a
"get" leaves its answer in ``c_par``. The numbers of the constants are the twin's own:
clients send the names. Served: ``C_MOVE_PTP`` (``c_par(0)`` 0 = absolute, 1 relative
in the object frame, 2 relative in the user frame (*choice*: ``T(step) T(now)``), then
the pose or the step, mm and deg, Symétrie convention), ``C_VALID_PTP`` (``vm=1``, ``cm``
0, 1 or 2, pose; the limits broken in ``c_par(0)``, bits of
:data:`~hexatherm.devices.symetriepmac.VALIDATION_LIMITS`), ``C_MOVE_SPECIFICPOS``
(``c_par(0)`` 1 user zero, 2 retracted: the lowest Tz the struts allow, 3 machine zero),
``C_CFG_LIMIT`` (get: ``c_par(1..12)`` the low then high limits of workspace
``c_par(0)`` 0 factory, 1 machine, 2 user; set 1 or 2; factory: -31) and
``C_CFG_LIMITENABLE`` (``c_par(1)``; machine and user limits start disabled: the twin's
struts are its limits), ``C_STOP``,
``C_CLEARERROR``, ``C_CONTROLON``, ``C_CONTROLOFF``, ``C_HOME``, ``C_VERSION``,
``C_CFG_CS`` (get: ``c_par(0..11)``, the user frame in the machine frame then the object
frame in the platform frame, mm and deg, Symétrie convention, zero at the start; set: the
same 12 from ``c_par``, as CGSE's ``configure_coordinates_systems`` sends them: every pose
on the wire is then the object's in the user frame, the platform standing at
``U X O^-1`` in the machine frame, as CGSE's simulator links the frames),
``C_CFG_SPEED`` (get). Status: ``s_hexa`` (general state bits), ``s_ax_1..6``,
``s_uto_tx..rz`` (the object in the user frame) and ``s_mtp_tx..rz`` (the platform in the
machine frame; mm, deg), ``s_pos_ax_1..6`` (the twin serves the IGM's leg lengths, mm; a real
controller's actuator positions may be counted from another zero), ``s_ai_1..6``,
``s_err_nr``. ``vers`` answers the firmware's version. ``C_JOG``, ``C_MAINTENANCE`` and
``C_CFG_DEFAULT`` are known and refused (-46, not served); an undefined constant
(``c_cmd=C_NO_SUCH``) is ``error #20`` and leaves ``c_cmd`` at -30 (unknown command
number, *choice*), so that a client never reads an earlier command's ``c_par`` as its
result.
"""

from __future__ import annotations

import re
import socket
import threading

import numpy as np

from hexatherm.core.geometry import Convention, pose_from_transform, transform_from_pose
from hexatherm.devices.controller import LineBuffer, convert_pose
from hexatherm.devices.sim.symetrie import (
    SimulatedController,
    SimulatedHexapod,
    _Drop,
)
from hexatherm.devices.sim.travel import single_axis_travel
from hexatherm.devices.sim.userframes import UserObjectFrames
from hexatherm.typing import FloatArray

IAC, WILL, WONT, DO, DONT, SB, SE = 255, 251, 252, 253, 254, 250, 240
ECHO, SGA = 1, 3
ACK = "\x06"

#: the twin's numbers of the command constants (a real controller has its own)
COMMANDS = {
    name: 100 + i
    for i, name in enumerate(
        (
            "STOP",
            "CLEARERROR",
            "CONTROLON",
            "CONTROLOFF",
            "HOME",
            "MOVE_PTP",
            "VALID_PTP",
            "VERSION",
            "CFG_CS",
            "CFG_SPEED",
            "MOVE_SPECIFICPOS",
            "CFG_LIMIT",
            "CFG_LIMITENABLE",
            "JOG",
            "MAINTENANCE",
            "CFG_DEFAULT",
        )
    )
}
_NAMES = {code: name for name, code in COMMANDS.items()}
_AXES = ("tx", "ty", "tz", "rx", "ry", "rz")
_STATEMENT = re.compile(
    r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*)(?:\((?P<index>\d+)\))?"
    r"(?:(?P<range>,\d+,\d+)|=(?P<value>\S+))?$"
)


def strip_telnet(data: bytes) -> tuple[bytes, bytes]:
    """``(text, partial)``: the bytes without telnet commands, and an unfinished one.

    >>> strip_telnet(bytes([255, 254, 1]) + b"root" + bytes([255]))
    (b'root', b'\\xff')
    """
    out = bytearray()
    i = 0
    while i < len(data):
        b = data[i]
        if b != IAC:
            out.append(b)
            i += 1
            continue
        if i + 1 >= len(data):
            return bytes(out), data[i:]
        op = data[i + 1]
        if op == IAC:
            out.append(IAC)
            i += 2
        elif op in (WILL, WONT, DO, DONT):
            if i + 2 >= len(data):
                return bytes(out), data[i:]
            i += 3
        elif op == SB:
            end = data.find(bytes([IAC, SE]), i + 2)
            if end < 0:
                return bytes(out), data[i:]
            i = end + 2
        else:
            i += 2
    return bytes(out), b""


class _Session:
    def __init__(self) -> None:
        self.phase = "login"
        self.user = ""
        self.bare = False  # echo7
        self.lines = 0


class SymetriePmacSimulator(UserObjectFrames, SimulatedController):
    """The twin's gpascii server (see the module docstring).

    Examples
    --------
    >>> from hexatherm.core.hexapod import Hexapod
    >>> hexapod = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
    ...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200,
    ...     stroke_mm=(150, 300))
    >>> with SymetriePmacSimulator(SimulatedHexapod(hexapod)) as sim:
    ...     sim.url.startswith("symetrie-pmac://127.0.0.1:")
    True
    """

    model: SimulatedHexapod
    scheme = "symetrie-pmac"
    native_convention: Convention = "symetrie"
    line_end = "\r\n"

    def __init__(
        self,
        model: SimulatedHexapod,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        credentials: tuple[str, str] = ("root", "deltatau"),
    ) -> None:
        self.credentials = credentials
        self.c_par = np.zeros(20)
        self.c_cfg = 0
        self.c_cmd = 0
        self._running_reads = 0
        self.control_on = True
        self.homed = True
        self.error = False
        self.emergency_stop = False
        self.speeds = np.array([1.0, 1.0, 0.01, 0.01, 5.0, 5.0])
        #: workspace limits (low 6, high 6; mm, deg): 0 factory, 1 machine, 2 user; the
        #: single-axis travel the struts allow until set, disabled until enabled (the
        #: twin's struts are its limits)
        travel = np.concatenate(single_axis_travel(model))
        self.limits = {k: travel.copy() for k in (0, 1, 2)}
        self.limits_enabled = {1: False, 2: False}
        self.frames = np.zeros(12)
        self._state_lock = threading.RLock()
        super().__init__(model, host, port)

    # ------------------------------------------------------------- plumbing
    def _raw(self, sock: socket.socket, text: str) -> None:
        data = text.encode("latin-1")
        if self.faults.split_writes:
            for i in range(0, len(data), 2):
                sock.sendall(data[i : i + 2])
        else:
            sock.sendall(data)

    def _serve(self, sock: socket.socket) -> None:
        self._accepted(sock)
        session = _Session()
        buffer, partial = LineBuffer(), b""
        try:
            sock.sendall(bytes([IAC, WILL, ECHO, IAC, WILL, SGA]))
            self._raw(sock, "\r\nppmac login: ")
            while True:
                data = sock.recv(4096)
                if not data:
                    return
                text, partial = strip_telnet(partial + data)
                for line in buffer.feed(text):
                    line = line.strip().strip("\x00")
                    with self._lock:
                        self.received.append(line)
                    if not self._line(sock, session, line):
                        return
        except (_Drop, OSError):
            return
        finally:
            self._finished(sock)

    def _line(self, sock: socket.socket, session: _Session, line: str) -> bool:
        """Answer one line; False to close the connection."""
        if session.phase == "login":
            session.user, session.phase = line, "password"
            self._raw(sock, f"{line}\r\nPassword: ")
        elif session.phase == "password":
            if (session.user, line) == self.credentials:
                session.phase = "shell"
                self._raw(sock, "\r\nppmac# ")
            else:
                session.phase = "login"
                self._raw(sock, "\r\nLogin incorrect\r\nppmac login: ")
        elif session.phase == "shell":
            if line == "gpascii -2":
                session.phase = "gpascii"
                self._write(sock, [line, "STDIN Open for ASCII Input"])  # no acknowledge
            elif line in ("exit", "logout"):
                self._raw(sock, f"{line}\r\n")
                return False
            else:
                word = line.split()[0] if line.split() else line
                self._raw(sock, f"{line}\r\n-sh: {word}: not found\r\nppmac# ")
        else:
            session.lines += 1
            with self._state_lock:
                answer = self.respond_in(session, line)
            self._write(sock, [line, *answer, ACK])
        return True

    # ------------------------------------------------------------ variables
    def press_emergency_stop(self) -> None:
        """The operator's emergency stop: the motion stops, error and e-stop bits set."""
        with self._state_lock:
            self.emergency_stop = True
            self.model.stop()

    def _status_word(self) -> int:
        m = self.model
        bits = {1, 8, 11, 12, 13}  # initialised, phase found, power on
        if self.error or self.emergency_stop:
            bits.add(0)
        if self.emergency_stop:
            bits.add(14)
        if self.control_on:
            bits.add(2)
        if self.homed:
            bits.add(6)
        if m.in_position():
            bits.add(3)
        if m.moving():
            bits.add(4)
        return sum(1 << b for b in bits)

    def _variables(self) -> dict[str, list[float]]:
        """Groups of consecutive variables, by the name of each member."""
        m = self.model
        pose = self._wire_pose()
        axis = (1 << 1) | (1 << 5) | (1 << 6)  # control on, home complete, phase found
        axis |= (1 << 2) if m.in_position() else 0
        axis |= (1 << 3) if m.moving() else 0
        temps = m.temperatures()
        ai = np.zeros(6) if temps is None else np.resize(temps, 6)
        groups = {
            "s_uto": ([f"s_uto_{a}" for a in _AXES], list(pose)),
            "s_mtp": ([f"s_mtp_{a}" for a in _AXES], list(self._platform_pose())),
            "s_ax": ([f"s_ax_{i}" for i in range(1, 7)], [float(axis)] * 6),
            "s_pos_ax": ([f"s_pos_ax_{i}" for i in range(1, 7)], list(m.actuators_mm())),
            "s_ai": ([f"s_ai_{i}" for i in range(1, 7)], list(ai)),
        }
        out: dict[str, list[float]] = {}
        for names, values in groups.values():
            for k, name in enumerate(names):
                out[name] = [float(v) for v in values[k:]]
        out["s_hexa"] = [float(self._status_word())]
        out["s_err_nr"] = [1.0 if self.error else 0.0]
        out["c_cfg"] = [float(self.c_cfg)]
        return out

    @staticmethod
    def _format(value: float) -> str:
        return str(int(value)) if float(value).is_integer() else f"{value:.12g}"

    def respond_in(self, session: _Session, line: str) -> list[str]:
        """The answer lines of one gpascii line (before the acknowledge)."""
        out: list[str] = []
        if re.fullmatch(r"echo\d+", line):
            session.bare = int(line[4:]) != 0
            return out
        if line.lower() == "vers":  # the firmware's version (C_VERSION's software numbers)
            return ["5.3.0.0"]
        for stmt in line.split():
            match = _STATEMENT.match(stmt)
            if match is None or not self._statement(session, match, out):
                return [*out, f"stdin:{session.lines}:1: error #20: ILLEGAL CMD: {stmt}"]
        return out

    def _statement(self, session: _Session, match: re.Match[str], out: list[str]) -> bool:
        name, index, rng, value = match["name"], match["index"], match["range"], match["value"]
        if value is not None:
            return self._assign(name, index, value)
        count = int(rng.split(",")[1]) if rng else 1
        if name == "c_par":
            start = int(index or 0)
            values = [float(v) for v in self.c_par[start : start + count]]
        elif name == "c_cmd" and index is None:
            values = [float(self._read_c_cmd())]
        else:
            if index is not None:
                return False
            if name == "s_hexa":
                self._drop_if_moving()
            table = self._variables()
            if name not in table:
                return False
            values = table[name][:count]
        if len(values) < count:
            return False
        for k, v in enumerate(values):
            text = self._format(v)
            out.append(text if session.bare else f"{name}{'' if k == 0 else f'+{k}'}={text}")
        return True

    def _assign(self, name: str, index: str | None, value: str) -> bool:
        if name == "c_cmd" and index is None:
            code = COMMANDS.get(value.removeprefix("C_")) if value.startswith("C_") else None
            if code is None:
                try:
                    code = int(value)
                except ValueError:
                    # an undefined constant: the statement is illegal, and c_cmd reads
                    # -30 (unknown command number) so that no client takes the c_par
                    # of an earlier command for this one's result (*choice*)
                    self.c_cmd, self._running_reads = -30, 0
                    return False
            self._run(code)
            return True
        try:
            number = float(value)
        except ValueError:
            return False
        if name == "c_par" and index is not None and int(index) < self.c_par.size:
            self.c_par[int(index)] = number
        elif name == "c_cfg" and index is None:
            self.c_cfg = int(number)
        elif name == "c_ax" and index is None:
            pass
        else:
            return False
        return True

    def _read_c_cmd(self) -> int:
        if self._running_reads > 0:
            self._running_reads -= 1
            return 1
        return self.c_cmd

    # ------------------------------------------------------------- commands
    def _run(self, code: int) -> None:
        name = _NAMES.get(code)
        injected = self.faults.take_error(name) if name else None
        self._running_reads = 1
        if name is None:
            self.c_cmd = -30  # unknown command number
        elif injected is not None:
            self.c_cmd = injected
        else:
            self.c_cmd = self._execute(name)

    def _execute(self, name: str) -> int:
        m, p = self.model, self.c_par
        if name == "STOP":
            m.stop()
            return 0
        if name == "CLEARERROR":
            self.error = False
            return 0
        if name in ("CONTROLON", "CONTROLOFF"):
            self.control_on = name == "CONTROLON"
            return 0
        if name == "HOME":
            self.homed = True
            return 0
        if name == "VERSION":
            p[:12] = [0, 5, 3, 0, 0, 2, 7, 1, 0, 0, 0, 1]  # software 5.3.0.0, API 2.7.1.0
            return 0
        if name == "CFG_CS":
            if self.c_cfg == 0:
                p[:12] = self.frames
                return 0
            if not np.all(np.isfinite(p[:12])):
                return -11
            self.frames = p[:12].copy()
            return 0
        if name == "CFG_SPEED":
            if self.c_cfg == 0:
                p[:6] = self.speeds
            return 0
        if name == "VALID_PTP":
            if p[0] != 1:
                return -10
            if p[1] not in (0, 1, 2):
                return -11
            p[0] = self._broken(self._target(int(p[1]), p[2:8]))
            return 0
        if name in ("CFG_LIMIT", "CFG_LIMITENABLE"):
            return self._limits(name)
        if name == "MOVE_SPECIFICPOS":  # 1 user zero, 2 retracted, 3 machine zero
            if p[0] not in (1, 2, 3):
                return -10
            retracted = np.zeros(6)
            retracted[2] = self.limits[0][2]  # the lowest Tz the struts allow
            machine = convert_pose(
                retracted if p[0] == 2 else np.zeros(6), "symetrie", m.convention
            )
            # user zero: the object at the user frame's origin; the others: platform poses
            p[1:7] = np.zeros(6) if p[0] == 1 else self._object_pose(machine)
            p[0] = 0
        if name in ("MOVE_PTP", "MOVE_SPECIFICPOS"):
            if p[0] not in (0, 1, 2):
                return -10
            if self.emergency_stop:
                return -37
            if self.error:
                return -44
            if not self.homed:
                return -45
            if not self.control_on:
                return -35
            if m.moving():
                return -38
            wire = self._target(int(p[0]), p[1:7])
            if self._broken(wire):
                return -40
            m.start_move(self._model_pose(wire))
            return 0
        return -46  # JOG, MAINTENANCE, CFG_DEFAULT: not served by the twin

    def _target(self, mode: int, pose: FloatArray) -> FloatArray:
        """The absolute pose (wire) of a move in ``mode`` from where the twin is going
        (:func:`move_target`)."""
        return move_target(mode, self._object_pose(self.model.target), pose)

    def _broken(self, wire: FloatArray) -> int:
        """The validation bits a pose breaks (0: it can be reached): machine and user
        workspace limits when enabled, the rule (user), the struts (actuators)."""
        stroke_ok, rule_ok = self.model.check(self._model_pose(wire.copy()))
        bits = (0 if rule_ok else 1 << 2) | (0 if stroke_ok else 1 << 3)
        for k, bit in ((1, 1), (2, 2)):
            low, high = self.limits[k][:6], self.limits[k][6:]
            if self.limits_enabled[k] and not np.all((wire >= low) & (wire <= high)):
                bits |= 1 << bit
        return bits

    def _limits(self, name: str) -> int:
        """``C_CFG_LIMIT`` (get: ``c_par(1..12)`` the low then high limits of workspace
        ``c_par(0)``, 0 factory, 1 machine, 2 user; set: 1 or 2 from ``c_par(1..12)``) and
        ``C_CFG_LIMITENABLE`` (get: ``c_par(1)``; set: ``c_par(1)`` 0 or 1)."""
        p, lim = self.c_par, int(self.c_par[0])
        if p[0] not in (0, 1, 2):
            return -10
        if name == "CFG_LIMIT":
            if self.c_cfg == 0:
                p[1:13] = self.limits[lim]
                return 0
            if lim == 0:
                return -31  # the factory limits are "get" only
            low, high = p[1:7].copy(), p[7:13].copy()
            if np.any(low > high):
                return -11
            self.limits[lim] = np.concatenate([low, high])
            return 0
        if lim == 0:
            return -10
        if self.c_cfg == 0:
            p[1] = float(self.limits_enabled[lim])
            return 0
        if p[1] not in (0, 1):
            return -11
        self.limits_enabled[lim] = bool(p[1])
        return 0


def move_target(mode: int, now: FloatArray, step: FloatArray) -> FloatArray:
    """The absolute pose (wire: the object's in the user frame, mm, deg, Symétrie
    convention) of a move in ``mode`` from the object pose ``now``: 0 absolute (``step``
    itself); 1 relative in the object frame, ``T = T(now) T(step)``; 2 relative in the
    user frame: the step's translation along the user frame's axes, its rotation about
    the object's own axes (``t = t(now) + t(step)``, ``R = R(now) R(step)``), as CGSE's
    simulator moves, and as the poses CGSE's own test expects from a controller
    (``test_puna_simulator.py``, 10 digits; docs/formats.md, section 9.7).

    >>> now, step = np.array([1.0, 2, 0.5, 0, 0, 15]), np.array([1.0, 0, 0, 0, 0, 5])
    >>> move_target(2, now, step).round(9) + 0.0
    array([ 2. ,  2. ,  0.5,  0. ,  0. , 20. ])
    """
    step = np.array(step, dtype=float)
    if mode == 0:
        return step
    a = transform_from_pose(np.asarray(now, float), "symetrie")
    b = transform_from_pose(step, "symetrie")
    if mode == 1:
        frame = a @ b
    else:
        frame = np.eye(4)
        frame[:3, :3] = a[:3, :3] @ b[:3, :3]
        frame[:3, 3] = a[:3, 3] + b[:3, 3]
    return np.asarray(pose_from_transform(frame, "symetrie"), dtype=float)
