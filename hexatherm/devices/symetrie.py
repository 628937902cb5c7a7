"""Symétrie hexapod controllers over their TCP API v2 (port 61559), plain sockets.

The dialect as hexatherm speaks it (from public drivers of the API; where they are
silent, hexatherm's choice is marked *choice* and the simulator speaks exactly this):

* On connection the controller greets with lines such as ``SYMETRIE controller``,
  ``API version: 2.x``, ``Project: ...``, ending with ``Waiting for commands...``;
  hexatherm keeps ``API version`` and ``Project`` in :attr:`~SymetrieController.info`.
* A command is its name followed directly by its comma-separated arguments, e.g.
  ``MOVE#ABS0.001,0,-0.0005,0,0,0.0174532925``; lines sent end with CR LF (*choice*;
  replies may end with LF or CR LF).
* Replies are ``NAME:CODE`` or ``NAME:CODE,DATA`` with ``NAME`` the command's name
  without ``?``: ``1`` the command was accepted and runs, ``2`` it is done (with the
  data of a query), a negative code an error (decoded by :func:`describe_error`). A
  query may answer with ``2`` at once. A reply to another command than the one waited
  for (e.g. a late ``MOVE#ABS:2``) is skipped; a late negative code is kept and
  reported by the next :meth:`~SymetrieController.state`.
* ``MOVE#ABS`` takes the pose of the object in the user frame in **m and rad**,
  ``symetrie`` convention (fixed axes, ``R = Rz Ry Rx``). ``move_absolute`` returns on
  ``MOVE#ABS:1`` (or ``:2``): whether a controller sends ``:2`` when the trajectory is
  launched or when it ends, the wait is ``wait_in_position``'s.
* ``STA#HEXAPOD?``: ``status,`` then the object pose in the user frame (6 values, m and
  rad: what ``MOVE#ABS`` commands and :meth:`~SymetrieController.read_pose` returns),
  then the platform pose in the machine frame (6). ``status`` is an integer bit field
  (:data:`STATUS_BITS`): bit 0 error, 4 in position, 5 moving, ...; ``858.0`` is
  refused, as BLISS's ``int()`` refuses it.
* ``STA#AXES?``: ``n,`` then ``n`` actuator status words, then ``n`` actuator lengths in
  m.
* ``CFG#CS?3``: ``3,`` (the coordinate system asked, as ESRF's BLISS asks and parses
  it) then the user frame in the machine frame and the object frame in the platform
  frame (6 + 6 values, m and rad), read once on connection into ``info``.
* ``VALID#PTP?`` + the 6 values of a pose (*choice*: the controller's check of a
  point-to-point move without moving): ``VALID#PTP:2,BITS``, 0 when the pose can be
  reached, else the limits it breaks (:data:`VALIDATION_BITS`). A controller that
  does not know the command (unknown-command codes) leaves only hexatherm's stroke
  check, which then requires the hexapod geometry.
* ``STA#TEMP?`` (*choice*, optional, not a command of the public API): ``k,`` then
  ``k`` temperatures in deg C; a real controller answers ``STA#TEMP:-23`` (unknown
  status query), and then, as for any unknown-command code, the controller has no
  temperatures (an empty reading) and the run goes on.
* ``STOP``: ``STOP:1``, ``STOP:2``.

>>> pose_to_wire([1.0, 0, 0, 180.0, 0, 0]).round(8).tolist()
[0.001, 0.0, 0.0, 3.14159265, 0.0, 0.0]
>>> parse_reply("STA#AXES:2,6,0,0,0,0,0,0,0.26,0.26,0.26,0.26,0.26,0.26")[:2]
('STA#AXES', 2)
>>> describe_error(-126)
'actuator command out of its limits (-126)'
"""

from __future__ import annotations

import re

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import Convention
from hexatherm.devices.controller import (
    ControllerState,
    SocketController,
    format_pose,
    parse_numbers,
)
from hexatherm.errors import (
    ControllerError,
    ControllerReplyError,
    PoseRefusedError,
)
from hexatherm.typing import FloatArray

#: bits of the STA#HEXAPOD? status word and what they mean
STATUS_BITS: dict[int, str] = {
    0: "error",
    1: "system ready",
    2: "emergency stop pressed",
    3: "safety enabled",
    4: "in position",
    5: "moving",
    6: "control on",
    7: "brake on",
    8: "phasing done",
    9: "homing done",
    10: "homing running",
    11: "virtual homing",
    12: "motion restrained",
    13: "software limit reached",
    14: "following error",
    15: "hardware limit reached",
    16: "drive fault",
    17: "encoder error",
    18: "system error",
    19: "fatal error",
}
BIT_ERROR, BIT_READY, BIT_IN_POSITION, BIT_MOVING = 0, 1, 4, 5
#: status bits that mean the controller is in error
ERROR_BITS = (0, 2, 14, 15, 16, 17, 18, 19)

#: bits of the VALID#PTP? answer (a choice of hexatherm, see the module docstring)
VALIDATION_BITS: dict[int, str] = {
    0: "outside the machine workspace limits",
    1: "outside the user workspace limits",
    2: "an actuator outside its stroke",
    3: "a joint outside its angular range",
}

#: error codes and their meaning, in words
ERROR_CODES: dict[int, str] = {
    -1: "command ignored",
    -2: "rejected: a priority command was received",
    -6: "unknown command",
    -7: "command string too long",
    -9: "wrong number of arguments",
    -10: "wrong group or axis number",
    -12: "the command is already running",
    -23: "unknown status query",
    -47: "user level restriction",
    -48: "wrong argument value",
    -49: "wrong number of parameters",
    -58: "busy state machine timed out",
    -67: "not allowed in the current state",
    -68: "command aborted",
    -70: "not allowed while warnings are set",
    -73: "not allowed while moving",
    -74: "an error prevents power-on",
    -76: "an error is present: reset needed",
    -81: "in-position timeout",
    -103: "wrong start position",
    -104: "object pose outside the workspace (user frame)",
    -105: "pose outside the workspace (intermediate frame)",
    -106: "platform pose outside the workspace (machine frame)",
    -108: "homing not done",
    -111: "inverse kinematics failed",
    -112: "forward kinematics failed",
    -118: "actuator homing not done",
    -126: "actuator command out of its limits",
    -273: "inverse kinematics: actuator length out of range",
    -274: "inverse kinematics: pose out of the volume",
    -288: "joints out of their volume",
    -289: "axis out of its limits",
    -310: "no command matching",
    -311: "command not implemented",
    -312: "command not allowed",
    -313: "no command matching",
}
#: codes meaning "this controller does not know the command" (-23: an unknown STA# query)
UNSUPPORTED_CODES = frozenset({-6, -23, -310, -311, -313})
#: the coordinate system asked of ``CFG#CS?`` (as BLISS asks: user and object frames)
CS_USER_OBJECT = 3
#: codes meaning "this pose cannot be reached" (a refusal, nothing moved)
REFUSAL_CODES = frozenset({-103, -104, -105, -106, -126, -273, -274, -288, -289})

_REPLY = re.compile(r"^(?P<name>[^:,]+):(?P<code>[+-]?\d+)(?:,(?P<data>.*))?$")


def describe_error(code: int) -> str:
    """An error code of the controller in words, with the code."""
    return f"{ERROR_CODES.get(code, 'undocumented error')} ({code})"


def describe_status(status: int) -> str:
    """The bits set in a STA#HEXAPOD? status word, in words.

    >>> describe_status(0b110010)
    'system ready, in position, moving'
    """
    return ", ".join(text for bit, text in STATUS_BITS.items() if status >> bit & 1)


def parse_reply(line: str) -> tuple[str, int, str | None]:
    """``(name, code, data)`` of a reply line ``NAME:CODE[,DATA]``.

    >>> parse_reply("MOVE#ABS:-126")
    ('MOVE#ABS', -126, None)
    >>> parse_reply("hello")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hexatherm.errors.ControllerError: malformed reply ... 'hello'
    """
    match = _REPLY.match(line.strip())
    if match is None:
        raise ControllerError(f"malformed reply from the Symetrie controller: {line!r}")
    return match["name"], int(match["code"]), match["data"]


def pose_to_wire(pose_mm_deg: npt.ArrayLike) -> FloatArray:
    """A pose in mm and deg as the controller takes it: m and rad."""
    p = np.array(pose_mm_deg, dtype=float)
    p[..., :3] *= 1e-3
    p[..., 3:] = np.deg2rad(p[..., 3:])
    return p


def pose_from_wire(pose_m_rad: npt.ArrayLike) -> FloatArray:
    """A pose in m and rad as the controller gives it: mm and deg."""
    p = np.array(pose_m_rad, dtype=float)
    p[..., :3] *= 1e3
    p[..., 3:] = np.rad2deg(p[..., 3:])
    return p


def format_frames(values_mm_deg: npt.ArrayLike) -> str:
    """The user frame in the machine frame then the object frame in the platform frame,
    12 numbers (mm, deg, Symétrie convention) to 15 significant digits: ``run.yaml``'s
    record of them, which ``calibrate`` reads (``user_frame_in_machine`` and
    ``object_frame_in_platform`` are rounded, for the eye).

    >>> format_frames([0.5, 0, 0, 0, 0, 1 / 3] + [0] * 6)
    '0.5 0 0 0 0 0.333333333333333 0 0 0 0 0 0'
    """
    return " ".join(f"{v:.15g}" for v in np.asarray(values_mm_deg, dtype=float).ravel())


def format_wire(values: npt.ArrayLike) -> str:
    """Comma-separated numbers in fixed notation (12 decimals: 1 pm, 1 prad).

    >>> format_wire([0.001, -0.5])
    '0.001000000000,-0.500000000000'
    """
    return ",".join(f"{v:.12f}" for v in np.asarray(values, dtype=float).ravel())


class SymetrieController(SocketController):
    """A Symétrie hexapod controller over API v2 (see the module docstring).

    Parameters are those of :class:`~hexatherm.devices.controller.SocketController`.

    Examples
    --------
    >>> driver = SymetrieController("192.168.1.10")
    >>> driver.url, driver.convention
    ('symetrie://192.168.1.10:61559', 'symetrie')
    """

    dialect = "Symetrie API v2"
    scheme = "symetrie"
    default_port = 61559
    native_convention: Convention = "symetrie"
    terminator = b"\r\n"
    #: greeting lines read at most before ``Waiting for commands``
    max_greeting_lines = 20

    def _handshake(self) -> None:
        self._late_error: str | None = None
        self._has_temperatures: bool | None = None
        self._has_validation: bool | None = None
        for _ in range(self.max_greeting_lines):
            line = self._readline("the greeting").strip()
            if line.lower().startswith("waiting for commands"):
                break
            key, sep, value = line.partition(":")
            if sep and key.strip().lower() in ("api version", "project"):
                self.info[key.strip().lower().replace(" ", "_")] = value.strip()
        else:
            raise ControllerError(
                f"the controller at {self.url} did not end its greeting with "
                f"'Waiting for commands' within {self.max_greeting_lines} lines: is it a "
                "Symetrie API v2 controller?"
            )
        data = parse_numbers(self._transact("CFG#CS?", str(CS_USER_OBJECT)), "CFG#CS?", 13)
        if data[0] != CS_USER_OBJECT:
            raise ControllerError(
                f"malformed reply to CFG#CS?{CS_USER_OBJECT}: its leading field is "
                f"{data[0]:g}, not the coordinate system asked ({CS_USER_OBJECT})"
            )
        mm_deg = pose_from_wire(data[1:].reshape(2, 6))
        self.info["user_frame_in_machine"] = format_pose(mm_deg[0])
        self.info["object_frame_in_platform"] = format_pose(mm_deg[1])
        self.info["frames_mm_deg"] = format_frames(mm_deg)
        self.frames_mm_deg = np.asarray(mm_deg, dtype=float).ravel()

    # ---------------------------------------------------------------- replies
    def _transact(self, command: str, args: str = "", *, accepted: bool = False) -> str:
        """Send ``command`` + ``args``; the DATA of its reply with code 2 ("" if none).

        With ``accepted``, code 1 is enough. A negative code raises
        :class:`ControllerReplyError`.
        """
        name = command.rstrip("?")
        self._send(command + args)
        while True:
            line = self._readline(command)
            if not line.strip():
                continue
            reply, code, data = parse_reply(line)
            if reply != name:
                if code < 0:  # a late failure of an earlier command (a move)
                    self._late_error = f"{reply} failed: {describe_error(code)}"
                continue
            if code < 0:
                raise ControllerReplyError(
                    f"the Symetrie controller at {self.url} refused {command}: "
                    f"{describe_error(code)}",
                    code=code,
                    command=command,
                )
            if code == 2 or (code == 1 and accepted):
                return data or ""
            if code != 1:
                raise ControllerError(f"unexpected reply code {code} to {command}: {line!r}")

    def _optional(self, command: str, args: str = "") -> str | None:
        """The data of a query the controller may not know (None if it does not)."""
        try:
            return self._transact(command, args)
        except ControllerReplyError as exc:
            if exc.code in UNSUPPORTED_CODES:
                return None
            raise

    # ---------------------------------------------------------------- dialect
    def _validate_wire(self, native: FloatArray, pose: FloatArray) -> None:
        if self._has_validation is not False:
            data = self._optional("VALID#PTP?", format_wire(pose_to_wire(native)))
            self._has_validation = data is not None
            if data is not None:
                try:
                    bits = int(data.split(",")[0])
                except ValueError as exc:
                    raise ControllerError(f"malformed reply to VALID#PTP?: {data!r}") from exc
                if bits:
                    broken = [t for b, t in VALIDATION_BITS.items() if bits >> b & 1]
                    raise PoseRefusedError(
                        f"the Symetrie controller refuses pose {format_pose(pose)}: "
                        + (", ".join(broken) or f"validation bits {bits}")
                    )
                return
        if self.hexapod is None:
            raise ControllerError(
                f"the Symetrie controller at {self.url} cannot validate poses (VALID#PTP? "
                "unknown) and no hexapod geometry was given to check the stroke: refusing "
                "to move without a check"
            )
        self.info["validation"] = "stroke of the hexapod geometry only (no VALID#PTP?)"

    def _move_wire(self, native: FloatArray, pose: FloatArray) -> None:
        self._late_error = None
        try:
            self._transact("MOVE#ABS", format_wire(pose_to_wire(native)), accepted=True)
        except ControllerReplyError as exc:
            if exc.code in REFUSAL_CODES:
                raise PoseRefusedError(
                    f"the Symetrie controller refuses the move to {format_pose(pose)}: "
                    f"{describe_error(exc.code)}"
                ) from exc
            raise

    def _status(self) -> tuple[int, FloatArray]:
        word, _, rest = self._transact("STA#HEXAPOD?").partition(",")
        if not re.fullmatch(r"\+?\d+", word.strip()):  # an integer, as clients int() it
            raise ControllerError(f"malformed status word in STA#HEXAPOD?: {word!r}")
        data = parse_numbers(rest, "STA#HEXAPOD?", 12)
        return int(word), pose_from_wire(data[:6])

    def _state(self) -> ControllerState:
        status, _ = self._status()
        message = describe_status(status)
        late, self._late_error = self._late_error, None
        error = any(status >> b & 1 for b in ERROR_BITS) or late is not None
        if late is not None:
            message = f"{late}; {message}" if message else late
        return ControllerState(
            in_position=bool(status >> BIT_IN_POSITION & 1),
            moving=bool(status >> BIT_MOVING & 1),
            error=error,
            ready=bool(status >> BIT_READY & 1),
            message=message,
        )

    def _read_pose_wire(self) -> FloatArray:
        return self._status()[1]

    def _read_actuators_mm(self) -> FloatArray:
        data = parse_numbers(self._transact("STA#AXES?"), "STA#AXES?")
        n = int(data[0]) if data.size else -1
        if n != 6 or data.size != 1 + 2 * n:
            raise ControllerError(
                f"malformed reply to STA#AXES?: expected 6 actuators (13 numbers), got "
                f"{data.size} numbers"
            )
        return data[1 + n :] * 1e3

    def _read_temperatures_C(self) -> FloatArray:
        if self._has_temperatures is False:
            return np.empty(0)
        data = self._optional("STA#TEMP?")
        self._has_temperatures = data is not None
        if data is None:
            return np.empty(0)
        values = parse_numbers(data, "STA#TEMP?")
        if values.size < 1 or values[0] != values.size - 1:
            raise ControllerError(f"malformed reply to STA#TEMP?: {data!r}")
        return values[1:]

    def _stop_wire(self) -> None:
        self._transact("STOP")
