"""PI hexapod controllers (C-887 and alike) over GCS on TCP (port 50000), plain sockets.

The dialect as hexatherm speaks it (GCS as documented publicly; where hexatherm had to
choose, it says *choice*, and the simulator speaks exactly this):

* Lines end with LF. Axes ``X Y Z`` (mm) and ``U V W`` (deg), the ``pi`` convention
  (mobile axes, ``R = Rx Ry Rz``).
* An answer may span lines: every line but the last ends with a blank before the LF
  (``X=1.000 \\n`` ... ``W=0.000\\n``).
* Commands (``MOV``, ``STP``) do not answer; the controller keeps the error of the last
  failed command, and ``ERR?`` answers it (an integer, 0 for none) and clears it, so
  hexatherm follows every command by ``ERR?``. Codes are decoded by
  :func:`describe_error`.
* An unknown query does not answer either (it sets error 2), so queries are sent
  together with ``ERR?``: the answer lines ``KEY=VALUE`` come first, then the bare
  integer of ``ERR?``.
* ``*IDN?``: the identification, read on connection into ``info``
  (``manufacturer, model, serial, firmware`` when it has the four fields).
* Before moving (and in a dry run), :meth:`PIController.check_ready` asks ``SVO?`` (servo
  on, all six axes), ``FRF?`` (referenced, all six), ``#7`` (the byte 0x07; ready is the
  answer byte 0xB1, busy 0xB0) and ``KEN?`` (the enabled coordinate system must be
  ``ZERO``, the default: a pose commanded in a user system lands elsewhere), each with
  ``ERR?``. A controller that does not know ``#7`` or ``KEN?`` (error 2) has no such
  state: recorded as unknown, not refused. Then ``SPI?``: the pivot point ``R S T`` (mm)
  about which ``MOV`` U V W rotate; hexatherm's poses rotate about the origin of the
  convention, so a pivot other than ``0 0 0`` (within 1 nm) is refused with the command
  that sets it back (``SPI R 0 S 0 T 0``; a controller without ``SPI?``: unknown).
* ``VMO? X x Y y Z z U u V v W w``: ``1`` when the move is allowed, ``0`` when not (the
  controller's check; nothing moves). A controller that does not know it leaves
  hexatherm's stroke check, which then requires the hexapod geometry.
* ``MOV X x ...``: starts the move (error 7, position out of limits, when refused).
* ``POS?``: ``X=..`` to ``W=..``; ``ONT?``: ``X=1`` ... (1 = on target). GCS has no
  separate "moving" flag in this subset: not on target counts as moving.
* ``STR?`` (*choice*): the six actuator (strut) lengths ``1=..`` to ``6=..`` in mm;
  ``TEM?`` (*choice*): temperature channels ``1=..`` ... in deg C. A controller that does
  not know them (error 2) has no such reading (NaN lengths, no temperatures).
* Stop: ``#24`` (the byte 0x18, PI's StopAll, acted on even mid-line), then ``STP``
  (the command), then ``ERR?`` (error 10, stopped by command, expected).

>>> parse_answer(["X=1.5 ", "Y=-2 ", "W=0.25"])
{'X': '1.5', 'Y': '-2', 'W': '0.25'}
>>> describe_error(7)
'position out of limits (7)'
"""

from __future__ import annotations

import numpy as np

from hexatherm.core.geometry import Convention
from hexatherm.devices.controller import (
    ControllerState,
    SocketController,
    format_pose,
)
from hexatherm.errors import (
    ControllerConnectionError,
    ControllerError,
    ControllerReplyError,
    PoseRefusedError,
)
from hexatherm.typing import FloatArray

AXES = ("X", "Y", "Z", "U", "V", "W")
#: GCS error codes and their meaning, in words
ERROR_CODES: dict[int, str] = {
    0: "no error",
    1: "parameter syntax error",
    2: "unknown command",
    3: "command too long",
    5: "move attempted on an unreferenced axis, or with the servo off",
    7: "position out of limits",
    8: "velocity out of limits",
    10: "controller was stopped by command",
    15: "invalid axis identifier",
    17: "parameter out of range",
    23: "invalid axis",
    24: "incorrect number of parameters",
    25: "invalid floating point number",
    26: "parameter missing",
    -1024: "motion error: position error too large, servo switched off",
}
UNKNOWN_COMMAND = 2
POSITION_OUT_OF_LIMITS = 7
STOPPED_BY_COMMAND = 10
#: the answer bytes of ``#7`` (ready, busy) and the one-byte commands hexatherm sends
READY_BYTE, BUSY_BYTE = "\xb1", "\xb0"
REQUEST_READY, STOP_ALL = 7, 24
#: the default coordinate system of a C-887
ZERO_SYSTEM = "ZERO"
#: the pivot point's axes (``SPI``/``SPI?``, mm) and the largest one taken as zero, mm
PIVOT_AXES = ("R", "S", "T")
PIVOT_TOLERANCE_MM = 1e-6


def describe_error(code: int) -> str:
    """A GCS error code in words, with the code."""
    return f"{ERROR_CODES.get(code, 'undocumented error')} ({code})"


def parse_answer(lines: list[str]) -> dict[str, str]:
    """``{KEY: VALUE}`` of the lines ``KEY=VALUE`` of an answer.

    >>> parse_answer(["1=20.5 ", "2=21"])
    {'1': '20.5', '2': '21'}
    >>> parse_answer(["X 1.5"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hexatherm.errors.ControllerError: malformed GCS answer line 'X 1.5' ...
    """
    out: dict[str, str] = {}
    for line in lines:
        key, sep, value = line.strip().partition("=")
        if not sep or not key:
            raise ControllerError(f"malformed GCS answer line {line!r} (expected KEY=VALUE)")
        out[key.strip()] = value.strip()
    return out


def parse_error(lines: list[str]) -> int:
    """The integer of an ``ERR?`` answer.

    >>> parse_error(["10"])
    10
    """
    text = " ".join(line.strip() for line in lines)
    try:
        return int(text)
    except ValueError as exc:
        raise ControllerError(f"malformed ERR? answer {text!r}") from exc


def keyed_floats(answer: dict[str, str], keys: tuple[str, ...], what: str) -> FloatArray:
    """The values of ``keys`` in an answer, as finite floats.

    >>> keyed_floats({"1": "2.5", "2": "-1e-3"}, ("1", "2"), "STR?").tolist()
    [2.5, -0.001]
    """
    missing = [k for k in keys if k not in answer]
    if missing:
        raise ControllerError(f"answer to {what} lacks {', '.join(missing)}: {answer}")
    try:
        values = np.array([float(answer[k]) for k in keys])
    except ValueError as exc:
        raise ControllerError(f"malformed number in the answer to {what}: {answer}") from exc
    if not np.all(np.isfinite(values)):
        raise ControllerError(f"non-finite number in the answer to {what}: {answer}")
    return values


def format_axes(pose_mm_deg: FloatArray) -> str:
    """``X x Y y Z z U u V v W w``, 9 decimals (1 pm, 1 ndeg).

    >>> format_axes(np.array([1.0, 0, 0, 0, 0, -0.5]))
    'X 1.000000000 Y 0.000000000 Z 0.000000000 U 0.000000000 V 0.000000000 W -0.500000000'
    """
    return " ".join(f"{a} {v:.9f}" for a, v in zip(AXES, pose_mm_deg, strict=True))


def _is_integer(lines: list[str]) -> bool:
    return len(lines) == 1 and lines[0].strip().lstrip("+-").isdigit()


class PIController(SocketController):
    """A PI hexapod controller over GCS (see the module docstring).

    Parameters are those of :class:`~hexatherm.devices.controller.SocketController`.

    Examples
    --------
    >>> driver = PIController("192.168.1.20")
    >>> driver.url, driver.convention
    ('pi://192.168.1.20:50000', 'pi')
    """

    dialect = "PI GCS"
    scheme = "pi"
    default_port = 50000
    native_convention: Convention = "pi"
    terminator = b"\n"

    def _handshake(self) -> None:
        self._has_validation: bool | None = None
        self._has_struts: bool | None = None
        self._has_temperatures: bool | None = None
        self._send("*IDN?")
        self.info["identification"] = " ".join(s.strip() for s in self._answer("*IDN?"))
        fields = [f.strip() for f in self.info["identification"].split(",")]
        if len(fields) == 4:
            keys = ("manufacturer", "model", "serial", "firmware")
            self.info.update(zip(keys, fields, strict=True))
        code = self._error_code()
        if code:
            self.info["error_at_connection"] = describe_error(code)

    # ---------------------------------------------------------------- answers
    def _answer(self, waiting_for: str) -> list[str]:
        """The lines of one answer (up to a line without a blank before its end)."""
        lines = []
        while True:
            line = self._readline(waiting_for)
            lines.append(line)
            if not line.endswith(" "):
                return lines

    def _error_code(self) -> int:
        self._send("ERR?")
        return parse_error(self._answer("ERR?"))

    def _raise(self, command: str, code: int) -> None:
        raise ControllerReplyError(
            f"the PI controller at {self.url} reports after {command.split()[0]}: "
            f"{describe_error(code)}",
            code=code,
            command=command,
        )

    def _send_byte(self, code: int) -> None:
        """Send a one-byte command (``#7``, ``#24``): the byte alone, no line end."""
        conn = self._require()
        if self.log is not None:
            self.log("tx", f"#{code}")
        try:
            conn.sock.sendall(bytes([code]))
        except OSError as exc:
            self._drop()
            raise ControllerConnectionError(
                f"connection to the {self.dialect} controller at {self.url} lost while "
                f"sending #{code}: {exc}"
            ) from exc

    def _command(self, command: str) -> int:
        """Send a command, then ERR?; the error code (0: none)."""
        self._send(command)
        return self._error_code()

    def _keyed(self, query: str) -> tuple[dict[str, str] | None, int]:
        """Send a KEY=VALUE query with ERR?: ``(answer or None, error code)``."""
        self._send(query)
        self._send("ERR?")
        first = self._answer(query)
        if _is_integer(first) and "=" not in first[0]:
            code = parse_error(first)  # the query did not answer: this is ERR?
            if code == 0:
                raise ControllerError(f"the PI controller did not answer {query} (no error)")
            return None, code
        return parse_answer(first), parse_error(self._answer("ERR?"))

    def _keyed_required(self, query: str) -> dict[str, str]:
        answer, code = self._keyed(query)
        if code or answer is None:
            self._raise(query, code)
        assert answer is not None
        return answer

    # ---------------------------------------------------------------- checks
    def check_ready(self) -> None:
        """Servo on, referenced, ready, the default coordinate system and the pivot point at
        zero, or refuse.

        Every state found goes in :attr:`readiness` (``servo``, ``referenced``,
        ``ready``, ``coordinate_system``, ``pivot_point``), then :class:`ControllerError`
        names every problem. Nothing moves.
        """
        with self._lock:
            found: dict[str, str] = {}
            problems: list[str] = []
            for query, key, what, fix in (
                ("SVO?", "servo", "servo off", "switch the servo on (SVO)"),
                ("FRF?", "referenced", "not referenced", "reference the hexapod (FRF)"),
            ):
                answer = self._keyed_required(query)
                off = [a for a in AXES if answer.get(a, "").strip() != "1"]
                found[key] = (
                    f"{'no' if off else 'yes'} ({query} "
                    + " ".join(f"{a}={answer.get(a, '-')}" for a in AXES)
                    + ")"
                )
                if off:
                    problems.append(f"{what} on {' '.join(off)}: {fix} first")
            found["ready"] = self._ready_state(problems)
            found["coordinate_system"] = self._coordinate_system(problems)
            found["pivot_point"] = self._pivot_point(problems)
            self.readiness = found
        if problems:
            raise ControllerError(
                f"the PI controller at {self.url} is not ready to move: "
                + "; ".join(problems)
                + ". Nothing was moved"
            )

    def _ready_state(self, problems: list[str]) -> str:
        self._send_byte(REQUEST_READY)
        self._send("ERR?")
        first = self._answer("#7")
        text = "".join(first)
        if text in (READY_BYTE, BUSY_BYTE):
            code = parse_error(self._answer("ERR?"))
            if code:
                self._raise("#7", code)
            if text == BUSY_BYTE:
                problems.append("busy (#7 answers 0xB0: referencing or another motion)")
                return "no (#7 0xB0)"
            return "yes (#7 0xB1)"
        if _is_integer(first) and parse_error(first) == UNKNOWN_COMMAND:
            return "unknown (#7 not known)"
        if _is_integer(first):
            self._raise("#7", parse_error(first))
        raise ControllerError(f"unexpected answer to #7: {text!r} (expected 0xB1 or 0xB0)")

    def _state_query(self, query: str) -> dict[str, str] | None:
        """The answer to a readiness query; None when the controller does not know it
        (error 2: no such state), another error raised."""
        answer, code = self._keyed(query)
        if answer is None and code == UNKNOWN_COMMAND:
            return None
        if code or answer is None:
            self._raise(query, code)
        return answer

    def _coordinate_system(self, problems: list[str]) -> str:
        answer = self._state_query("KEN?")
        if answer is None:
            return "unknown (KEN? not known)"
        enabled = " ".join(f"{name}={kind}" for name, kind in answer.items())
        others = [name for name in answer if name.upper() != ZERO_SYSTEM]
        if others or not answer:
            problems.append(
                f"coordinate system {', '.join(others) or '(none)'} enabled (KEN? {enabled}): "
                f"poses would be commanded in it; enable {ZERO_SYSTEM} first (KEN {ZERO_SYSTEM})"
            )
        return enabled

    def _pivot_point(self, problems: list[str]) -> str:
        answer = self._state_query("SPI?")
        if answer is None:
            return "unknown (SPI? not known)"
        pivot = keyed_floats(answer, PIVOT_AXES, "SPI?")
        text = " ".join(f"{a}={answer[a]}" for a in PIVOT_AXES)
        if np.any(np.abs(pivot) > PIVOT_TOLERANCE_MM):
            problems.append(
                f"pivot point {text} mm (SPI?): MOV U V W would rotate about it, not about "
                "the origin the poses are given in; set it to zero first (SPI R 0 S 0 T 0)"
            )
        return text

    # ---------------------------------------------------------------- dialect
    def _validate_wire(self, native: FloatArray, pose: FloatArray) -> None:
        if self._has_validation is not False:
            query = "VMO? " + format_axes(native)
            self._send(query)
            self._send("ERR?")
            first = self._answer("VMO?")
            text = " ".join(s.strip() for s in first)
            if text in ("0", "1"):  # the VMO? answer; ERR? follows
                code = parse_error(self._answer("ERR?"))
                if code:
                    self._raise(query, code)
                self._has_validation = True
                if text == "0":
                    raise PoseRefusedError(
                        f"the PI controller refuses pose {format_pose(pose)}: VMO? says the "
                        "move is not allowed (limits, workspace or struts)"
                    )
                return
            code = parse_error(first)
            if code != UNKNOWN_COMMAND:
                self._raise(query, code)
            self._has_validation = False
        if self.hexapod is None:
            raise ControllerError(
                f"the PI controller at {self.url} cannot validate poses (VMO? unknown) and "
                "no hexapod geometry was given to check the stroke: refusing to move "
                "without a check"
            )
        self.info["validation"] = "stroke of the hexapod geometry only (no VMO?)"

    def _move_wire(self, native: FloatArray, pose: FloatArray) -> None:
        command = "MOV " + format_axes(native)
        code = self._command(command)
        if code == POSITION_OUT_OF_LIMITS:
            raise PoseRefusedError(
                f"the PI controller refuses the move to {format_pose(pose)}: {describe_error(code)}"
            )
        if code:
            self._raise(command, code)

    def _state(self) -> ControllerState:
        answer, code = self._keyed("ONT?")
        if answer is None:
            self._raise("ONT?", code)
        assert answer is not None
        on = keyed_floats(answer, AXES, "ONT?")
        in_position = bool(np.all(on == 1))
        off = [a for a, v in zip(AXES, on, strict=True) if v != 1]
        message = "on target" if in_position else "not on target: " + " ".join(off)
        if code:
            message = f"{describe_error(code)}; {message}"
        return ControllerState(
            in_position=in_position,
            moving=not in_position,
            error=code != 0,
            ready=code == 0,
            message=message,
        )

    def _read_pose_wire(self) -> FloatArray:
        return keyed_floats(self._keyed_required("POS?"), AXES, "POS?")

    def _optional_keyed(self, query: str, flag: str) -> dict[str, str] | None:
        if getattr(self, flag) is False:
            return None
        answer, code = self._keyed(query)
        if answer is None and code == UNKNOWN_COMMAND:
            setattr(self, flag, False)
            return None
        if code or answer is None:
            self._raise(query, code)
        setattr(self, flag, True)
        return answer

    def _read_actuators_mm(self) -> FloatArray:
        answer = self._optional_keyed("STR?", "_has_struts")
        if answer is None:
            return np.full(6, np.nan)
        return keyed_floats(answer, tuple("123456"), "STR?")

    def _read_temperatures_C(self) -> FloatArray:
        answer = self._optional_keyed("TEM?", "_has_temperatures")
        if answer is None:
            return np.empty(0)
        keys = tuple(sorted(answer, key=lambda k: (len(k), k)))
        return keyed_floats(answer, keys, "TEM?")

    def _stop_wire(self) -> None:
        self._send_byte(STOP_ALL)
        self._send("STP")
        self._send("ERR?")
        # Answers of a transaction cut short (Ctrl-C) may still arrive before ERR?'s:
        # skip KEY=VALUE answers up to the bare integer.
        for _ in range(64):
            answer = self._answer("ERR? after STP")
            if _is_integer(answer):
                code = parse_error(answer)
                if code not in (0, STOPPED_BY_COMMAND):
                    self.info["error_at_stop"] = describe_error(code)
                return
        raise ControllerError("no ERR? answer after STP among 64 answers")
