"""A simulated PI hexapod controller (C-887, GCS 2.0) as PI's own software sees one.

What :class:`PISimulator` answers is what a C-887 answers to the commands a PI user sends
first (checked with PI's own Python library, ``pipython``, in the tests):

* ``*IDN?``: ``manufacturer, model, serial, firmware`` (commas, as pipython's ``devname``
  needs); here ``hexatherm twin, C-887, 0, <hexatherm version>``: the model is the
  real controller's, the rest says what it is.
* Axis arguments are honoured: ``POS? Z`` answers ``Z=...`` only, in the order asked;
  an axis that is not one of ``X Y Z U V W`` sets error 15 and nothing is answered.
* Numbers are fixed decimals, 6 of them (1 nm, 1 udeg), not Python's ``repr``.
* Multi-line answers end every line but the last with a blank before the LF.
* Commands do not answer; a failure sets an error code that ``ERR?`` reads and clears
  (the first one is kept until read): 1 parameter syntax, 2 unknown command, 5 move
  without reference or with the servo off, 7 position out of limits, 10 stopped by
  command, 15 invalid axis identifier, 24 wrong number of parameters, 25 invalid number,
  530 coordinate system does not exist, 546 coordinate system write protected, 554
  coordinate system type does not exist.
* One-byte commands are taken from the byte stream wherever they come (PI's software
  sends them without a line end, the next command right behind): ``#5`` (motion
  status: a hex bit mask of the moving axes, ``0`` or ``3F``), ``#7`` (ready: the byte
  ``0xB1``, busy: ``0xB0``), ``#24`` (stop all: error 10).
* ``SVO``/``SVO?`` (*choice*: a hexapod's axes are coupled, so switching one axis
  switches all six), ``FRF``/``FRF?`` (a reference move to the zero pose; the
  controller is busy, ``#7`` answers ``0xB0`` and ``FRF?`` 0, until it ends), ``MOV``/``MOV?``,
  ``ONT?``, ``VMO?``, ``HLT`` and ``STP`` (stop, error 10), ``VLS``/``VLS?`` (the system
  velocity, mm/s; the angular speed keeps its ratio), ``VEL?``, ``TMN?``/``TMX?`` (the
  single-axis travel from the zero pose that the struts' stroke allows, computed once
  from the hexapod model), ``SAI?`` (``SAI? ALL``), ``CSV?`` (``2.0``), ``HLP?``.
* Coordinate systems: ``ZERO`` (type ``ZERO``) is the default; ``KSD NAME X x ... W w``
  defines a user system of type ``KSD`` by its offset pose, ``KEN NAME`` enables it
  (``KEN ZERO`` returns to the default), ``KEN?`` answers ``NAME=TYPE`` of the enabled
  system, ``KET?`` answers ``TYPE=NAME``. While a user system is enabled, every pose on
  the wire (``MOV``, ``MOV?``, ``POS?``, ``VMO?``) is in it (*choice*: the offset pose
  ``D`` composes as ``T(zero) = T(D) T(user)``, the pi convention): a client that
  ignores it commands the platform somewhere else.
* ``MVR`` (relative to the current target, the same checks as ``MOV``), ``NLM``/``PLM``
  and ``NLM?``/``PLM?`` (soft limits per axis, the travel until set; a limit beyond the
  travel or past the other one: error 17; ``MOV``/``MVR`` beyond them: error 7, ``VMO?``
  0), ``CCL``/``CCL?`` (command level 0, or 1 with PI's password ``advanced``, *choice*:
  nothing here needs level 1), ``VER?`` (the versions, multi-line), ``ECO?`` (echo).
  A reference move ends with the motion, whatever is asked meanwhile (not only when
  ``FRF?`` or ``#7`` polls it). A command or query this controller does not know sets
  error 2 and answers nothing, as a C-887 does (a client waiting for an answer times
  out).
* ``SPI R r S s T t`` / ``SPI?``: the pivot point (mm) about which U V W rotate: a pose
  on the wire ``T`` moves the platform by ``Tr(p) T Tr(-p)``, so that the platform's
  point ``p`` stays where the translation alone takes it (before a user system's offset).
* ``STR?`` (strut lengths) and ``TEM?`` (temperatures): hexatherm's, as
  :mod:`hexatherm.devices.pi` describes.

:class:`PIStart` gives the state the controller starts in: servo off, not referenced,
busy, a user coordinate system enabled, or a pivot point off zero (the twin's ``--fault
pi-...``).
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

import numpy as np

from hexatherm import __version__
from hexatherm.core.geometry import pose_from_transform, transform_from_pose
from hexatherm.devices.controller import LineBuffer, convert_pose
from hexatherm.devices.pi import AXES, PIVOT_AXES
from hexatherm.devices.sim.symetrie import (
    SimulatedController,
    SimulatedHexapod,
    _Drop,
)
from hexatherm.devices.sim.travel import single_axis_travel
from hexatherm.typing import FloatArray

#: the identification, ``manufacturer, model, serial, firmware``
IDENTIFICATION = f"hexatherm twin, C-887, 0, {__version__}"
#: the byte answers of ``#7``
READY, BUSY = "\xb1", "\xb0"
#: one-byte commands, by their byte
SINGLE_BYTE = {5: "#5", 7: "#7", 24: "#24"}
#: what HLP? lists: the commands this controller knows
HELP = (
    ("#5", "Request Motion Status"),
    ("#7", "Request Controller Ready Status"),
    ("#24", "Stop All Axes"),
    ("*IDN?", "Get Device Identification"),
    ("CCL", "Set Command Level"),
    ("CCL?", "Get Command Level"),
    ("CSV?", "Get Current Syntax Version"),
    ("ECO?", "Echo A String"),
    ("ERR?", "Get Error Number"),
    ("FRF", "Fast Reference Move To Reference Switch"),
    ("FRF?", "Get Referencing Result"),
    ("HLP?", "Get List Of Available Commands"),
    ("HLT", "Halt Motion Smoothly"),
    ("KEN", "Enable Coordinate System"),
    ("KEN?", "Get Enabled Coordinate Systems"),
    ("KET?", "Get Enabled Coordinate Systems By Type"),
    ("KSD", "Set KSD Coordinate System"),
    ("MOV", "Set Target Position"),
    ("MOV?", "Get Target Position"),
    ("MVR", "Set Target Relative To Current Position"),
    ("NLM", "Set Low Position Soft Limit"),
    ("NLM?", "Get Low Position Soft Limit"),
    ("PLM", "Set High Position Soft Limit"),
    ("PLM?", "Get High Position Soft Limit"),
    ("ONT?", "Get On Target State"),
    ("POS?", "Get Real Position"),
    ("SAI?", "Get List Of Current Axis Identifiers"),
    ("SPI", "Set Pivot Point"),
    ("SPI?", "Get Pivot Point"),
    ("STP", "Stop All Axes"),
    ("STR?", "Get Strut Lengths (hexatherm)"),
    ("SVO", "Set Servo Mode"),
    ("SVO?", "Get Servo Mode"),
    ("TEM?", "Get Temperatures (hexatherm)"),
    ("TMN?", "Get Minimum Commandable Position"),
    ("TMX?", "Get Maximum Commandable Position"),
    ("VER?", "Get Versions Of Firmware And Drivers"),
    ("VEL?", "Get Closed-Loop Velocity"),
    ("VLS", "Set System Velocity"),
    ("VLS?", "Get System Velocity"),
    ("VMO?", "Virtual Move"),
)


@dataclass
class PIStart:
    """The state a simulated PI controller starts in (what a lab may find).

    Attributes
    ----------
    servo_on : bool
        The servo of the six axes.
    referenced : bool
        Whether the axes were referenced (``FRF``) since power-on.
    busy : bool
        ``#7`` answers "busy" (until a reference move ends, if one is made).
    coordinate_system : str
        The enabled coordinate system: ``ZERO`` (the default), or the name of a user
        system of type ``KSD`` defined with :attr:`offset`.
    offset : tuple of 6 floats
        The user system's offset pose (X Y Z mm, U V W deg).
    pivot : tuple of 3 floats
        The pivot point ``R S T`` (``SPI``, mm) about which U V W rotate.
    """

    servo_on: bool = True
    referenced: bool = True
    busy: bool = False
    coordinate_system: str = "ZERO"
    offset: tuple[float, ...] = (0.0, 0.0, 10.0, 0.0, 0.0, 1.0)
    pivot: tuple[float, float, float] = (0.0, 0.0, 0.0)


def fixed(value: float) -> str:
    """A number as the controller writes it: 6 fixed decimals.

    >>> fixed(1.0), fixed(-2.5e-7), fixed(1 / 3)
    ('1.000000', '-0.000000', '0.333333')
    """
    return f"{value:.6f}"


class _GcsError(Exception):
    """A command refused with a GCS error code."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


class PISimulator(SimulatedController):
    """A simulated PI C-887 hexapod controller (see the module docstring).

    Examples
    --------
    >>> from hexatherm.core.hexapod import Hexapod
    >>> hexapod = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
    ...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200,
    ...     stroke_mm=(150, 300), convention="pi")
    >>> with PISimulator(SimulatedHexapod(hexapod)) as sim:
    ...     sim.respond("*IDN?")[0].split(",")[:2], sim.respond("POS? Z X")
    (['hexatherm twin', ' C-887'], ['Z=0.000000 ', 'X=0.000000'])
    """

    scheme = "pi"
    native_convention = "pi"
    line_end = "\n"

    def __init__(
        self,
        model: SimulatedHexapod,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        start: PIStart | None = None,
    ) -> None:
        start = PIStart() if start is None else start
        self.error_code = 0
        self.servo_on = start.servo_on
        self.referenced = start.referenced
        self.busy = start.busy
        self.referencing = False
        self.systems: dict[str, tuple[str, FloatArray]] = {"ZERO": ("ZERO", np.zeros(6))}
        self.enabled = "ZERO"
        if start.coordinate_system.upper() != "ZERO":
            name = start.coordinate_system.upper()
            self.systems[name] = ("KSD", np.asarray(start.offset, dtype=float))
            self.enabled = name
        self.pivot = np.asarray(start.pivot, dtype=float)
        self.travel = single_axis_travel(model)
        #: the soft limits (NLM, PLM) per axis, wire; the travel until set
        self.soft = (self.travel[0].copy(), self.travel[1].copy())
        self.command_level = 0
        super().__init__(model, host, port)

    # ------------------------------------------------------------ the stream
    def _serve(self, sock: socket.socket) -> None:
        self._accepted(sock)
        buffer = LineBuffer()
        try:
            while True:
                data = sock.recv(4096)
                if not data:
                    return
                text = bytearray()
                for byte in data:
                    if byte < 32 and byte not in (10, 13):  # a one-byte command
                        lines = buffer.feed(bytes(text))
                        text.clear()
                        self._handle(sock, lines)
                        self._handle(sock, [SINGLE_BYTE.get(byte, f"#{byte}")])
                    else:
                        text.append(byte)
                self._handle(sock, buffer.feed(bytes(text)))
        except (_Drop, OSError):
            return
        finally:
            self._finished(sock)

    # ------------------------------------------------------------ answers
    @staticmethod
    def _answer(pairs: list[tuple[str, str]]) -> list[str]:
        lines = [f"{k}={v}" for k, v in pairs]
        return [line + " " for line in lines[:-1]] + lines[-1:]

    def _set_error(self, code: int) -> list[str]:
        if self.error_code == 0:  # GCS keeps the first error until ERR? reads it
            self.error_code = code
        return []

    @staticmethod
    def _axes(args: list[str]) -> list[str]:
        """The axes of a query (all six when none), in the order asked."""
        if not args:
            return list(AXES)
        axes = [a.upper() for a in args]
        if any(a not in AXES for a in axes):
            raise _GcsError(15)
        return axes

    @staticmethod
    def _pairs(args: list[str], axes: tuple[str, ...] = AXES) -> dict[str, float]:
        """``AXIS value`` pairs of a command."""
        if not args or len(args) % 2:
            raise _GcsError(24)
        out: dict[str, float] = {}
        for axis, value in zip(args[::2], args[1::2], strict=True):
            if axis.upper() not in axes:
                raise _GcsError(15)
            try:
                number = float(value)
            except ValueError:
                raise _GcsError(25) from None
            if not np.isfinite(number):
                raise _GcsError(25)
            out[axis.upper()] = number
        return out

    def _per_axis(self, args: list[str], values: FloatArray | list[str]) -> list[str]:
        texts = [fixed(float(v)) if not isinstance(v, str) else v for v in values]
        return self._answer([(a, texts[AXES.index(a)]) for a in self._axes(args)])

    # ------------------------------------------------ coordinate systems
    def _offset(self) -> FloatArray | None:
        if self.enabled == "ZERO":
            return None
        return self.systems[self.enabled][1]

    def _shift(self, sign: float) -> FloatArray:
        shift = np.eye(4)
        shift[:3, 3] = sign * self.pivot
        return shift

    def _to_zero(self, native: FloatArray) -> FloatArray:
        """A pose of the wire as a pose of the platform (the pi convention): U V W rotate
        about the pivot point ``p`` (``T = Tr(p) T(wire) Tr(-p)``: the platform's point
        ``p`` goes where the translation alone takes it), in the enabled system (its offset
        pose ``D``: ``T(zero) = T(D) T``)."""
        if self._offset() is None and not self.pivot.any():
            return native
        frame = self._shift(1.0) @ transform_from_pose(native, "pi") @ self._shift(-1.0)
        offset = self._offset()
        if offset is not None:
            frame = transform_from_pose(offset, "pi") @ frame
        return np.asarray(pose_from_transform(frame, "pi"), dtype=float)

    def _from_zero(self, native: FloatArray) -> FloatArray:
        if self._offset() is None and not self.pivot.any():
            return native
        frame = transform_from_pose(native, "pi")
        offset = self._offset()
        if offset is not None:
            frame = np.linalg.inv(transform_from_pose(offset, "pi")) @ frame
        frame = self._shift(-1.0) @ frame @ self._shift(1.0)
        return np.asarray(pose_from_transform(frame, "pi"), dtype=float)

    def _wire(self, model_pose: FloatArray) -> FloatArray:
        """A pose of the model as the wire gives it (pi convention, enabled system)."""
        return self._from_zero(convert_pose(model_pose, self.model.convention, "pi"))

    def _model(self, wire: FloatArray) -> FloatArray:
        return convert_pose(self._to_zero(wire), "pi", self.model.convention)

    def _relative(self, args: list[str]) -> FloatArray:
        """The pose of ``AXIS step`` pairs added to the current target (``MVR``), wire."""
        native = self._wire(self.model.target)
        for axis, value in self._pairs(args).items():
            native[AXES.index(axis)] += value
        return native

    def _target(self, args: list[str]) -> FloatArray:
        """The pose of ``AXIS value`` pairs (missing axes: the current target), wire."""
        native = self._wire(self.model.target)
        for axis, value in self._pairs(args).items():
            native[AXES.index(axis)] = value
        return native

    # ------------------------------------------------------------ commands
    def is_busy(self) -> bool:
        """``#7`` answers busy: the start state, or a reference move under way."""
        if self.referencing and not self.model.moving():
            self.referencing = self.busy = False
            self.referenced = True
        return self.busy

    def respond(self, line: str) -> list[str]:
        tokens = line.split()
        cmd, args = tokens[0].upper(), tokens[1:]
        if cmd == "ERR?":
            code, self.error_code = self.error_code, 0
            return [str(code)]
        self.is_busy()  # a reference move ends with the motion, whoever asks
        injected = self.faults.take_error(cmd)
        if injected is not None:
            return self._set_error(injected)
        try:
            return self._respond(cmd, args)
        except _GcsError as exc:
            return self._set_error(exc.code)

    def _respond(self, cmd: str, args: list[str]) -> list[str]:
        m = self.model
        if cmd == "#5":
            return ["3F" if m.moving() else "0"]
        if cmd == "#7":
            return [BUSY if self.is_busy() else READY]
        if cmd in ("#24", "STP", "HLT"):
            if cmd == "HLT":
                self._axes(args)
            m.stop()
            if self.referencing:  # a reference move cut short: still not referenced
                self.referencing = self.busy = False
            raise _GcsError(10)
        if cmd == "*IDN?":
            return [IDENTIFICATION]
        if cmd == "CSV?":
            return ["2.0"]
        if cmd == "HLP?":
            lines = ["The following commands are valid:"]
            lines += [f"{name} {what}" for name, what in HELP]
            lines.append("end of help")
            return [line + " " for line in lines[:-1]] + lines[-1:]
        if cmd == "SAI?":
            if args and [a.upper() for a in args] != ["ALL"]:
                raise _GcsError(1)
            return [a + " " for a in AXES[:-1]] + [AXES[-1]]
        if cmd == "POS?":
            self._axes(args)
            return self._per_axis(args, self._wire(m.read_pose()))
        if cmd == "MOV?":
            self._axes(args)
            return self._per_axis(args, self._wire(m.target))
        if cmd == "ONT?":
            self._drop_if_moving()
            self._axes(args)
            flag = "1" if m.in_position() else "0"
            return self._per_axis(args, [flag] * 6)
        if cmd in ("SVO?", "FRF?"):
            self._axes(args)
            self.is_busy()  # a reference move may have ended
            on = self.servo_on if cmd == "SVO?" else self.referenced
            return self._per_axis(args, ["1" if on else "0"] * 6)
        if cmd in ("TMN?", "TMX?"):
            self._axes(args)
            return self._per_axis(args, self.travel[0 if cmd == "TMN?" else 1])
        if cmd == "VEL?":
            self._axes(args)
            return self._per_axis(args, np.array([m.speed_mm_s] * 3 + [m.speed_deg_s] * 3))
        if cmd == "VLS?":
            return [fixed(m.speed_mm_s)]
        if cmd == "VLS":
            if len(args) != 1:
                raise _GcsError(24)
            value = _number(args[0])
            if not value > 0:
                raise _GcsError(17)
            m.speed_deg_s *= value / m.speed_mm_s
            m.speed_mm_s = value
            return []
        if cmd == "SVO":
            states = set(self._pairs(args).values())
            if not states <= {0.0, 1.0} or len(states) != 1:
                raise _GcsError(17)
            self.servo_on = states == {1.0}
            if not self.servo_on:
                m.stop()
            return []
        if cmd == "FRF":
            self._axes(args)
            if not self.servo_on:
                raise _GcsError(5)
            m.start_move(convert_pose(np.zeros(6), "pi", m.convention))
            self.referenced, self.referencing, self.busy = False, True, True
            return []
        if cmd in ("MOV", "VMO?", "MVR"):
            wire = self._target(args) if cmd != "MVR" else self._relative(args)
            stroke_ok, rule_ok = m.check(self._model(wire))
            soft_ok = bool(np.all((wire >= self.soft[0]) & (wire <= self.soft[1])))
            if cmd == "VMO?":
                return ["1" if stroke_ok and rule_ok and soft_ok else "0"]
            if not (self.servo_on and self.referenced) or self.is_busy():
                raise _GcsError(5)
            if not (stroke_ok and rule_ok and soft_ok):
                raise _GcsError(7)
            m.start_move(self._model(wire))
            return []
        if cmd in ("NLM?", "PLM?"):
            self._axes(args)
            return self._per_axis(args, self.soft[0 if cmd == "NLM?" else 1])
        if cmd in ("NLM", "PLM"):
            side = 0 if cmd == "NLM" else 1
            values = self._pairs(args)
            for axis, value in values.items():
                k = AXES.index(axis)
                low, high = self.travel[0][k], self.travel[1][k]
                other = self.soft[1 - side][k]
                if not low <= value <= high or (value > other if side == 0 else value < other):
                    raise _GcsError(17)  # beyond the travel, or crossing the other limit
            for axis, value in values.items():
                self.soft[side][AXES.index(axis)] = value
            return []
        if cmd == "CCL?":
            return [str(self.command_level)]
        if cmd == "CCL":
            if len(args) not in (1, 2) or args[0] not in ("0", "1"):
                raise _GcsError(17)
            if args[0] == "1" and args[1:] != ["advanced"]:
                raise _GcsError(17)  # *choice*: level 1 needs PI's documented password
            self.command_level = int(args[0])
            return []
        if cmd == "VER?":
            lines = [f"{IDENTIFICATION.split(', ')[1]}: hexatherm twin {__version__}"]
            lines.append(f"hexatherm: {__version__}")
            return [line + " " for line in lines[:-1]] + lines[-1:]
        if cmd == "ECO?":
            return [" ".join(args)]
        if cmd == "STR?":
            if not m.report_actuators:
                raise _GcsError(2)
            q = m.actuators_mm()
            return self._answer([(str(i + 1), fixed(float(v))) for i, v in enumerate(q)])
        if cmd == "SPI?":
            axes = [a.upper() for a in args] or list(PIVOT_AXES)
            if any(a not in PIVOT_AXES for a in axes):
                raise _GcsError(15)
            return self._answer([(a, fixed(self.pivot[PIVOT_AXES.index(a)])) for a in axes])
        if cmd == "SPI":
            values = self._pairs(args, PIVOT_AXES)
            for axis, value in values.items():
                self.pivot[PIVOT_AXES.index(axis)] = value
            return []
        if cmd == "TEM?":
            temps = m.temperatures()
            if temps is None:
                raise _GcsError(2)
            return self._answer([(str(i + 1), fixed(float(v))) for i, v in enumerate(temps)])
        return self._coordinate_systems(cmd, args)

    def _coordinate_systems(self, cmd: str, args: list[str]) -> list[str]:
        names = [a.upper() for a in args]
        if cmd == "KEN?":
            if any(n not in self.systems for n in names):
                raise _GcsError(530)
            if names and self.enabled not in names:
                return self._answer([(n, "0") for n in names])
            return self._answer([(self.enabled, self.systems[self.enabled][0])])
        if cmd == "KET?":
            kind = self.systems[self.enabled][0]
            if any(n not in ("ZERO", "KSD") for n in names):
                raise _GcsError(554)
            return self._answer([(kind, self.enabled)])
        if cmd == "KEN":
            if len(names) != 1:
                raise _GcsError(24)
            if names[0] not in self.systems:
                raise _GcsError(530)
            self.enabled = names[0]
            return []
        if cmd == "KSD":
            if not names:
                raise _GcsError(24)
            if names[0] == "ZERO":
                raise _GcsError(546)
            old = self.systems.get(names[0], ("KSD", np.zeros(6)))[1].copy()
            for axis, value in self._pairs(args[1:]).items():
                old[AXES.index(axis)] = value
            self.systems[names[0]] = ("KSD", old)
            return []
        raise _GcsError(2)


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _GcsError(25) from None
    if not np.isfinite(value):
        raise _GcsError(25)
    return value
