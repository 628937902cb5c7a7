"""Symétrie ZONDA, JORAN and PUNA+ controllers: the Power PMAC's ``gpascii`` over telnet.

The dialect as KU Leuven's CGSE ``symetrie-hexapod`` package (MIT; version 0.25.11
read, nothing copied) drives these controllers, port 23:

* telnet: telnet option requests are refused (``DO`` -> ``WONT``, ``WILL`` -> ``DONT``)
  and stripped; at ``login: `` the user (``root``), at ``Password: `` the password
  (``deltatau``, the Power PMAC's factory login), then at the ``# `` prompt
  ``gpascii -2`` (the command interpreter) and ``echo7`` (bare values in answers, no
  names), read up to the acknowledge line ``\\x06`` after the echo of ``echo7``. ``Login incorrect``
  refuses the connection.
* Every line sent ends with CR LF; the controller echoes it, answers one value a line,
  and ends with a line ``\\x06``; lines before the echo (the answer of a query left
  unread, after Ctrl-C) are skipped. An answer holding ``error #`` is an error of the
  interpreter (an unknown variable, a malformed statement).
* A command: ``c_par(0)=... c_par(1)=... c_cmd=C_NAME`` (``c_cfg=0`` before a
  configuration "get", ``1`` before a "set"); then ``c_cmd`` is read until it is 0
  (done) or negative (an error, :data:`RETURN_CODES`); 1 or more means running. A
  "get" leaves its answer in ``c_par``, read as ``c_par(0),N,1``.
* Before a move (and in ``validate``): ``s_hexa`` (:data:`GENERAL_STATE` bits) must show
  no error and no emergency stop, home complete, control on and no motion task; then
  ``C_VALID_PTP`` with ``vm=1, cm=0`` and the pose: ``c_par(0)`` 0 the pose can be
  reached, else the limits it breaks (:data:`VALIDATION_LIMITS`).
* ``C_MOVE_PTP`` with ``c_par(0)=0`` (absolute) and the object pose in the user frame,
  **mm and deg**, Symétrie convention (fixed axes, ``R = Rz Ry Rx``); ``c_cmd`` 0 once
  the motion is launched. In position: ``s_hexa`` bit 3, moving: bit 4.
* Read-backs: ``s_uto_tx,6,1`` (object pose in the user frame), ``s_pos_ax_1,6,1``
  (actuator lengths, mm). Controller temperatures: none (``s_ai_*`` are analogue
  inputs CGSE itself marks as untested on real hardware; not read).
* Stop: ``c_cmd=C_STOP``, then ``c_cmd`` until done.
* On connection ``C_VERSION`` (``c_par(1..4)`` software, ``(5..8)`` API version) and
  ``C_CFG_CS`` "get" (user frame in the machine frame, object frame in the platform
  frame, 6 + 6, mm and deg) are read into ``info``.

>>> describe_general_state(0b1001110)
'system initialized, control on, in position, home complete'
>>> format_command("MOVE_PTP", [0, 1.5, 0, 0, 0, 0, 0.25])[:35]
'c_par(0)=0 c_par(1)=1.500000000000 '
"""

from __future__ import annotations

import re

import numpy as np

from hexatherm.core.geometry import Convention
from hexatherm.devices.controller import ControllerState, SocketController, format_pose
from hexatherm.devices.symetrie import format_frames
from hexatherm.errors import (
    ControllerConnectionError,
    ControllerError,
    ControllerReplyError,
    ControllerTimeoutError,
    PoseRefusedError,
)
from hexatherm.typing import FloatArray

IAC, WILL, WONT, DO, DONT, SB, SE = 255, 251, 252, 253, 254, 250, 240

#: bits of ``s_hexa``, in words
GENERAL_STATE = (
    "error",
    "system initialized",
    "control on",
    "in position",
    "motion task running",
    "home task running",
    "home complete",
    "home virtual",
    "phase found",
    "brake on",
    "motion restricted",
    "power on encoders",
    "power on limit switches",
    "power on drives",
    "emergency stop",
)
BIT_ERROR, BIT_INITIALIZED, BIT_CONTROL_ON, BIT_IN_POSITION, BIT_MOVING = 0, 1, 2, 3, 4
BIT_HOME_COMPLETE, BIT_EMERGENCY_STOP = 6, 14

#: bits of the C_VALID_PTP answer, in words
VALIDATION_LIMITS = (
    "factory workspace limits",
    "machine workspace limits",
    "user workspace limits",
    "actuator limits",
    "joint limits",
    "backlash compensation",
)

#: return codes of a command (``c_cmd`` after it), in words (CGSE's list, abridged)
RETURN_CODES: dict[int, str] = {
    -1: "undefined error",
    **{-10 - i: f"wrong value for parameter {i}" for i in range(20)},
    -30: "unknown command number",
    -31: "a 'get' only configuration command",
    -32: "a 'set' only configuration command",
    -33: "no such axis",
    -34: "a stop task is running",
    -35: "all motors need to be control on",
    -36: "all motors need to be control off",
    -37: "emergency stop pressed",
    -38: "a motion task is running",
    -39: "a home task is running",
    -40: "requested move not feasible",
    -41: "power supply of the limit switches off",
    -42: "power supply of the encoders off",
    -43: "fatal error: controller restart needed",
    -44: "an error is present: error reset required",
    -45: "home not completed",
    -46: "software option not available",
    -75: "NaN or infinite value",
    -76: "coordinate system transformations not initialized",
    -77: "kinematic error",
}
#: return codes meaning "this pose cannot be reached" (a refusal, nothing moved)
REFUSAL_CODES = frozenset({-40})


def describe_general_state(word: int) -> str:
    """The bits set in ``s_hexa``, in words."""
    return ", ".join(text for bit, text in enumerate(GENERAL_STATE) if word >> bit & 1)


def describe_return(code: int) -> str:
    """A return code in words, with the code."""
    return f"{RETURN_CODES.get(code, 'undocumented error')} ({code})"


def format_command(name: str, params: list[float], cfg: int | None = None) -> str:
    """The line of a command: parameters, ``c_cfg`` if given, ``c_cmd=C_NAME``."""
    parts = [f"c_cfg={cfg}"] if cfg is not None else []
    parts += [
        f"c_par({i})={v}" if isinstance(v, int) else f"c_par({i})={v:.12f}"
        for i, v in enumerate(params)
    ]
    return " ".join([*parts, f"c_cmd=C_{name}"])


class SymetriePmacController(SocketController):
    """A Symétrie controller over the Power PMAC's gpascii (see the module docstring).

    Parameters are those of :class:`~hexatherm.devices.controller.SocketController`;
    :attr:`user` and :attr:`password` are the telnet login.

    Examples
    --------
    >>> SymetriePmacController("192.168.1.10").url
    'symetrie-pmac://192.168.1.10:23'
    """

    dialect = "Symetrie gpascii (Power PMAC)"
    scheme = "symetrie-pmac"
    default_port = 23
    native_convention: Convention = "symetrie"
    terminator = b"\r\n"
    user, password = "root", "deltatau"
    #: interval between two reads of ``c_cmd``, s (on the injected clock)
    command_poll_s = 0.01
    _telnet_partial = b""

    # ----------------------------------------------------------------- telnet
    def _received(self, data: bytes) -> bytes:
        """Strip telnet commands, refusing every option asked."""
        data = self._telnet_partial + data
        self._telnet_partial = b""
        out, replies = bytearray(), bytearray()
        i = 0
        while i < len(data):
            if data[i] != IAC:
                out.append(data[i])
                i += 1
                continue
            if i + 1 >= len(data) or (data[i + 1] in (WILL, WONT, DO, DONT) and i + 2 >= len(data)):
                self._telnet_partial = data[i:]
                break
            op = data[i + 1]
            if op == IAC:
                out.append(IAC)
                i += 2
            elif op in (WILL, WONT, DO, DONT):
                if op in (DO, WILL):
                    replies += bytes([IAC, WONT if op == DO else DONT, data[i + 2]])
                i += 3
            elif op == SB:
                end = data.find(bytes([IAC, SE]), i + 2)
                if end < 0:
                    self._telnet_partial = data[i:]
                    break
                i = end + 2
            else:
                i += 2
        if replies and self._conn is not None:
            try:
                self._conn.sock.sendall(bytes(replies))
            except OSError as exc:
                self._drop()
                raise ControllerConnectionError(
                    f"connection to the {self.dialect} controller at {self.url} lost: {exc}"
                ) from exc
        return bytes(out)

    def _read_until(self, markers: tuple[bytes, ...], waiting_for: str) -> bytes:
        """Received bytes up to and including the first of ``markers`` (telnet stripped)."""
        conn = self._require()
        pending = conn.buffer.pending
        conn.buffer.reset()
        while not any(m in pending for m in markers):
            if len(pending) > 65536:
                raise ControllerError(
                    f"the controller at {self.url} sent no {waiting_for!r} prompt: is it a "
                    "Symetrie Power PMAC controller (telnet, port 23)?"
                )
            pending += self._received(self._recv(waiting_for))
        end = min(pending.find(m) + len(m) for m in markers if m in pending)
        if self.log is not None:
            self.log("rx", pending[:end].decode("latin-1"))
        conn.buffer.pending = pending[end:]
        return pending[:end]

    def _handshake(self) -> None:
        self._telnet_partial = b""
        self._read_until((b"login: ",), "login: ")
        self._send(self.user)
        self._read_until((b"Password: ",), "Password: ")
        try:  # the password is never logged
            self._require().sock.sendall(self.password.encode("ascii") + self.terminator)
        except OSError as exc:
            self._drop()
            raise ControllerConnectionError(
                f"connection to the controller at {self.url} lost at its login: {exc}"
            ) from exc
        seen = self._read_until((b"# ", b"incorrect"), "the shell prompt")
        if b"incorrect" in seen:
            raise ControllerConnectionError(
                f"the controller at {self.url} refused the login {self.user!r}"
            )
        # gpascii's start may or may not end with an acknowledge: read up to echo7's
        self._send("gpascii -2")
        self._send("echo7")
        seen_echo = False
        while not ((text := self._readline("echo7")) == "\x06" and seen_echo):
            seen_echo = seen_echo or text.strip() == "echo7"
        version = self._get("VERSION", 12)
        self.info["software_version"] = ".".join(f"{v:g}" for v in version[1:5])
        self.info["api_version"] = ".".join(f"{v:g}" for v in version[5:9])
        frames = self._get("CFG_CS", 12, cfg=0)
        self.info["user_frame_in_machine"] = format_pose(frames[:6])
        self.info["object_frame_in_platform"] = format_pose(frames[6:])
        self.info["frames_mm_deg"] = format_frames(frames)
        self.frames_mm_deg = np.asarray(frames, dtype=float).ravel()

    # ---------------------------------------------------------------- gpascii
    def _query(self, line: str) -> list[str]:
        """Send one gpascii line; its answer lines (echo and acknowledge removed)."""
        self._send(line)
        while self._readline(line).strip() != line:  # a stale answer before the echo
            pass
        answer: list[str] = []
        while (text := self._readline(line)) != "\x06":
            answer.append(text)
        for text in answer:
            if "error #" in text:
                match = re.search(r"error #(\d+)", text)
                raise ControllerReplyError(
                    f"the controller at {self.url} refused {line!r}: {text.strip()}",
                    code=-int(match[1]) if match else -1,
                    command=line,
                )
        return [t.strip() for t in answer if t.strip()]

    def _values(self, line: str, count: int) -> FloatArray:
        answer = self._query(line)
        try:
            values = np.array([float(t.rpartition("=")[2]) for t in answer], dtype=float)
        except ValueError as exc:
            raise ControllerError(f"malformed answer to {line!r}: {answer!r}") from exc
        if values.size != count or not np.isfinite(values).all():
            raise ControllerError(
                f"malformed answer to {line!r}: expected {count} finite numbers, got {answer!r}"
            )
        return values

    def _command(self, name: str, params: list[float], cfg: int | None = None) -> int:
        """Run a command; its return code (0), or raise on a negative one."""
        self._query(format_command(name, params, cfg))
        deadline = self.clock() + max(self.reply_timeout_s, 1.0)
        while True:
            code = int(self._values("c_cmd", 1)[0])
            if code <= 0:
                break
            if self.clock() >= deadline:
                raise ControllerTimeoutError(
                    f"the controller at {self.url} did not finish C_{name} (c_cmd still {code})"
                )
            self.sleep(self.command_poll_s)
        if code < 0:
            raise ControllerReplyError(
                f"the Symetrie controller at {self.url} refused C_{name}: {describe_return(code)}",
                code=code,
                command=f"C_{name}",
            )
        return code

    def _get(self, name: str, count: int, cfg: int | None = None) -> FloatArray:
        self._command(name, [], cfg)
        return self._values(f"c_par(0),{count},1", count)

    def _general_state(self) -> int:
        value = self._values("s_hexa", 1)[0]
        if value != int(value) or value < 0:
            raise ControllerError(f"malformed s_hexa: {value!r}")
        return int(value)

    # ---------------------------------------------------------------- dialect
    def _check_ready(self) -> None:
        word = self._general_state()
        problems = []
        if word >> BIT_ERROR & 1 or word >> BIT_EMERGENCY_STOP & 1:
            problems.append("it is in error or its emergency stop is pressed (clear it first)")
        if not word >> BIT_HOME_COMPLETE & 1:
            problems.append("homing is not complete")
        if not word >> BIT_CONTROL_ON & 1:
            problems.append("the control loop is off")
        if word >> BIT_MOVING & 1:
            problems.append("a motion task is running")
        if problems:
            raise ControllerError(
                f"the Symetrie controller at {self.url} is not ready to move: "
                + "; ".join(problems)
                + f" (s_hexa {word}: {describe_general_state(word)})"
            )

    def _validate_wire(self, native: FloatArray, pose: FloatArray) -> None:
        self._check_ready()
        self._command("VALID_PTP", [1, 0, *native.tolist()])
        bits = self._values("c_par(0)", 1)[0]
        if bits != int(bits):
            raise ControllerError(f"malformed validation result: {bits!r}")
        if bits < 0:
            raise ControllerReplyError(
                f"the Symetrie controller at {self.url} could not validate "
                f"{format_pose(pose)}: {describe_return(int(bits))}",
                code=int(bits),
                command="C_VALID_PTP",
            )
        if bits:
            broken = [t for b, t in enumerate(VALIDATION_LIMITS) if int(bits) >> b & 1]
            raise PoseRefusedError(
                f"the Symetrie controller refuses pose {format_pose(pose)}: "
                + (", ".join(broken) or f"validation bits {int(bits)}")
            )

    def _move_wire(self, native: FloatArray, pose: FloatArray) -> None:
        try:
            self._command("MOVE_PTP", [0, *native.tolist()])
        except ControllerReplyError as exc:
            if exc.code in REFUSAL_CODES:
                raise PoseRefusedError(
                    f"the Symetrie controller refuses the move to {format_pose(pose)}: "
                    f"{describe_return(exc.code)}"
                ) from exc
            raise

    def _state(self) -> ControllerState:
        word = self._general_state()
        error = bool(word >> BIT_ERROR & 1 or word >> BIT_EMERGENCY_STOP & 1)
        ready = all(word >> b & 1 for b in (BIT_INITIALIZED, BIT_CONTROL_ON, BIT_HOME_COMPLETE))
        return ControllerState(
            in_position=bool(word >> BIT_IN_POSITION & 1),
            moving=bool(word >> BIT_MOVING & 1),
            error=error,
            ready=ready,
            message=describe_general_state(word),
        )

    def _read_pose_wire(self) -> FloatArray:
        return self._values("s_uto_tx,6,1", 6)

    def _read_actuators_mm(self) -> FloatArray:
        return self._values("s_pos_ax_1,6,1", 6)

    def _read_temperatures_C(self) -> FloatArray:
        return np.empty(0)

    def _stop_wire(self) -> None:
        self._command("STOP", [])
