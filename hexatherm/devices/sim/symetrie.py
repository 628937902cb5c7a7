"""Simulated hexapod controllers: TCP servers speaking the Symétrie and PI dialects
(the PI one: :mod:`hexatherm.devices.sim.pi`).

Both servers run on 127.0.0.1 (port 0: a free port, see ``.port`` and ``.url``), one
thread per connection, and speak exactly what :mod:`hexatherm.devices.symetrie` and
:mod:`hexatherm.devices.pi` expect. They are backed by one kinematic model,
:class:`SimulatedHexapod`, built on :class:`~hexatherm.core.hexapod.Hexapod`:

* a move runs in a straight line in pose space at ``speed_mm_s`` / ``speed_deg_s``
  (the slower governs), on the injected clock; the in-position flag rises
  ``settle_s`` after the motion ends;
* validation: every leg (the IGM) within the hexapod's stroke at 21 points along the
  path, plus an optional extra rule (``Faults.refuse``, a "user limit");
* read-back: the true pose plus optional Gaussian noise (seeded); actuator lengths: the
  IGM of the true pose; temperatures: a callable of the clock's time (none if not
  given: the query is then unknown to the controller);
* faults (:class:`Faults`, changeable while running): a late in-position flag, a
  dropped connection at the first status query during a move, replies written in
  chunks of 1 to 3 bytes, injected error codes for the next command of a name, and the
  extra refusal rule.

A :class:`ManualClock` shared with a driver's ``clock`` and ``sleep`` makes the whole
exchange run on simulated time: a test waits for nothing.

>>> clock = ManualClock()
>>> clock.sleep(1.5); clock()
1.5
"""

from __future__ import annotations

import re
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import Convention
from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import LineBuffer, convert_pose, stroke_violations
from hexatherm.devices.sim.tcpservice import TcpService
from hexatherm.devices.sim.travel import single_axis_travel
from hexatherm.devices.sim.userframes import UserObjectFrames
from hexatherm.devices.symetrie import pose_from_wire, pose_to_wire
from hexatherm.typing import FloatArray

#: points along a move's path where the stroke is checked
PATH_SAMPLES = 21


class ManualClock:
    """A clock that moves only when told: ``clock()`` reads it, ``sleep`` advances it.

    Thread-safe, so a driver (sleeping) and a simulator (reading) can share it.
    """

    def __init__(self, start_s: float = 0.0) -> None:
        self._t = float(start_s)
        self._lock = threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            return self._t

    def sleep(self, seconds: float) -> None:
        """Advance the clock by ``seconds`` (>= 0)."""
        if not seconds >= 0:
            raise ValueError(f"cannot sleep {seconds!r} s")
        with self._lock:
            self._t += float(seconds)

    advance = sleep


@dataclass
class Faults:
    """Faults a simulated controller injects (change them at any time).

    Attributes
    ----------
    late_in_position_s : float
        Extra delay of the in-position flag after the settle, s.
    drop_mid_move : bool
        Close the connection at the next status query while a move runs (once; the
        flag clears itself).
    split_writes : bool
        Write replies in chunks of 1 to 3 bytes.
    refuse : callable, optional
        ``refuse(pose)`` true for poses (mm, deg, the hexapod's convention) the
        controller refuses besides the stroke (a user limit).
    errors : dict of str to list of int
        Error codes to answer to the next commands of a name (``"MOVE#ABS"``, ``"MOV"``),
        one code per command, consumed in order; the command is not executed.
    """

    late_in_position_s: float = 0.0
    drop_mid_move: bool = False
    split_writes: bool = False
    refuse: Callable[[FloatArray], bool] | None = None
    errors: dict[str, list[int]] = field(default_factory=dict)

    def take_error(self, name: str) -> int | None:
        """The next injected code for command ``name`` (None if none)."""
        codes = self.errors.get(name)
        if codes:
            return codes.pop(0)
        return None


class SimulatedHexapod:
    """The kinematic model behind the simulated controllers.

    Poses are mm and deg in the hexapod's convention (``hexapod.convention``); the
    servers convert to their dialect's convention and units.

    Parameters
    ----------
    hexapod : Hexapod
        Geometry and stroke (a stroke is required: it is what validation checks).
    clock : callable
        Time source, s.
    speed_mm_s, speed_deg_s : float
        Speeds of a move (> 0).
    settle_s : float
        Delay of the in-position flag after the motion ends, s.
    noise_um, noise_urad : float
        Standard deviation of the read-back pose's noise per component.
    seed : int
        Seed of the noise.
    temperatures_C : callable, optional
        ``temperatures_C(t_s)`` -> the controller's temperature channels, deg C.
    report_actuators : bool
        Whether the controller reports actuator lengths.
    faults : Faults, optional
    """

    def __init__(
        self,
        hexapod: Hexapod,
        *,
        clock: Callable[[], float] = time.monotonic,
        speed_mm_s: float = 1.0,
        speed_deg_s: float = 1.0,
        settle_s: float = 0.5,
        noise_um: float = 0.0,
        noise_urad: float = 0.0,
        seed: int = 0,
        temperatures_C: Callable[[float], Sequence[float]] | None = None,
        report_actuators: bool = True,
        faults: Faults | None = None,
    ) -> None:
        if hexapod.stroke_mm is None:
            raise ValueError("the simulated hexapod needs a stroke (stroke_mm) to validate")
        if not (speed_mm_s > 0 and speed_deg_s > 0):
            raise ValueError("speeds must be > 0")
        if not (settle_s >= 0 and noise_um >= 0 and noise_urad >= 0):
            raise ValueError("settle_s, noise_um and noise_urad must be >= 0")
        self.hexapod = hexapod
        self.convention: Convention = hexapod.convention
        self.clock = clock
        self.speed_mm_s, self.speed_deg_s = float(speed_mm_s), float(speed_deg_s)
        self.settle_s = float(settle_s)
        self.noise_um, self.noise_urad = float(noise_um), float(noise_urad)
        self.temperatures_C = temperatures_C
        self.report_actuators = report_actuators
        self.faults = Faults() if faults is None else faults
        self.moves = 0
        self._rng = np.random.default_rng(seed)
        self._lock = threading.RLock()
        now = clock()
        self._start = np.zeros(6)
        self._target = np.zeros(6)
        self._t0 = self._t1 = now - self.settle_s  # at rest, in position
        self._late = 0.0

    # ----------------------------------------------------------------- state
    def true_pose(self) -> FloatArray:
        """The platform's pose now (no noise), mm and deg."""
        with self._lock:
            t = self.clock()
            if t >= self._t1 or self._t1 <= self._t0:
                return self._target.copy()
            f = (t - self._t0) / (self._t1 - self._t0)
            return self._start + f * (self._target - self._start)

    @property
    def target(self) -> FloatArray:
        """The pose of the last accepted move."""
        with self._lock:
            return self._target.copy()

    def moving(self) -> bool:
        """A motion is under way."""
        with self._lock:
            return self.clock() < self._t1

    def in_position(self) -> bool:
        """The in-position flag: the motion ended ``settle_s`` (+ a late delay) ago."""
        with self._lock:
            return self.clock() >= self._t1 + self.settle_s + self._late

    def read_pose(self) -> FloatArray:
        """The read-back: the true pose plus noise."""
        with self._lock:
            pose = self.true_pose()
            pose[:3] += self._rng.normal(0.0, self.noise_um * 1e-3, 3)
            pose[3:] += self._rng.normal(0.0, np.rad2deg(self.noise_urad * 1e-6), 3)
            return pose

    def actuators_mm(self) -> FloatArray:
        """Actuator lengths of the true pose (the IGM), mm."""
        return self.hexapod.igm(self.true_pose())[0]

    def temperatures(self) -> FloatArray | None:
        """The temperature channels now, or None when the controller has none."""
        if self.temperatures_C is None:
            return None
        return np.asarray(self.temperatures_C(self.clock()), dtype=float).ravel()

    # ----------------------------------------------------------------- moves
    def check(self, pose_mm_deg: npt.ArrayLike) -> tuple[bool, bool]:
        """``(stroke_ok, rule_ok)`` of a move from the current pose to ``pose_mm_deg``."""
        pose = np.asarray(pose_mm_deg, dtype=float)
        start = self.true_pose()
        path = start + np.linspace(0.0, 1.0, PATH_SAMPLES)[:, None] * (pose - start)
        stroke_ok = not self.hexapod.check_stroke(self.hexapod.igm(path)).any()
        stroke_ok = stroke_ok and not stroke_violations(self.hexapod, pose)
        refuse = self.faults.refuse
        rule_ok = refuse is None or not refuse(pose)
        return stroke_ok, rule_ok

    def start_move(self, pose_mm_deg: npt.ArrayLike) -> None:
        """Start a move (the caller has checked it)."""
        pose = np.asarray(pose_mm_deg, dtype=float)
        with self._lock:
            start = self.true_pose()
            d = np.abs(pose - start)
            duration = max(d[:3].max() / self.speed_mm_s, d[3:].max() / self.speed_deg_s)
            self._start, self._target = start, pose.copy()
            self._t0 = self.clock()
            self._t1 = self._t0 + duration
            self._late = self.faults.late_in_position_s
            self.moves += 1

    def stop(self) -> None:
        """Stop where the platform is now."""
        with self._lock:
            here = self.true_pose()
            self._start = self._target = here
            self._t0 = self._t1 = self.clock()
            self._late = 0.0


class _Drop(Exception):
    """Raised by a dialect to close the connection (fault injection)."""


class SimulatedController(TcpService):
    """A threaded TCP server of one dialect around a :class:`SimulatedHexapod`.

    Use as a context manager, or call :meth:`close`. ``received`` lists every command
    line received, in order (from every connection).
    """

    scheme = ""
    native_convention: Convention = "symetrie"
    line_end = "\n"

    def __init__(self, model: SimulatedHexapod, host: str = "127.0.0.1", port: int = 0) -> None:
        self.model = model
        self.received: list[str] = []
        self._chunks = np.random.default_rng(12345)
        self._start(host, port)

    @property
    def faults(self) -> Faults:
        """The model's faults."""
        return self.model.faults

    @property
    def url(self) -> str:
        """``SCHEME://HOST:PORT``, for :func:`~hexatherm.devices.controller.controller_from_url`."""
        return f"{self.scheme}://{self.host}:{self.port}"

    def __enter__(self) -> SimulatedController:
        return self

    # -------------------------------------------------------------- plumbing
    def _wire_pose(self) -> FloatArray:
        """The read-back pose in the dialect's convention."""
        return convert_pose(self.model.read_pose(), self.model.convention, self.native_convention)

    def _model_pose(self, native: FloatArray) -> FloatArray:
        return convert_pose(native, self.native_convention, self.model.convention)

    def _write(self, sock: socket.socket, lines: list[str]) -> None:
        data = "".join(line + self.line_end for line in lines).encode("latin-1")
        if not self.faults.split_writes:
            sock.sendall(data)
            return
        i = 0
        while i < len(data):
            n = int(self._chunks.integers(1, 4))
            sock.sendall(data[i : i + n])
            i += n
            time.sleep(0.0002)  # pacing only, so that the chunks travel apart

    def _serve(self, sock: socket.socket) -> None:
        self._accepted(sock)
        buffer = LineBuffer()
        try:
            self._write(sock, self.greeting())
            while True:
                data = sock.recv(4096)
                if not data:
                    return
                self._handle(sock, buffer.feed(data))
        except (_Drop, OSError):
            return
        finally:
            self._finished(sock)

    def _handle(self, sock: socket.socket, lines: list[str]) -> None:
        """Answer each non-blank line received (kept in :attr:`received`)."""
        for line in lines:
            line = line.strip()
            if not line:
                continue
            with self._lock:
                self.received.append(line)
            self._reply_to(sock, line)

    def _reply_to(self, sock: socket.socket, line: str) -> None:
        """Send the answer to one line."""
        self._write(sock, self.respond(line))

    def _drop_if_moving(self) -> None:
        if self.faults.drop_mid_move and self.model.moving():
            self.faults.drop_mid_move = False
            raise _Drop

    def greeting(self) -> list[str]:  # pragma: no cover - overridden
        return []

    def respond(self, line: str) -> list[str]:  # pragma: no cover - overridden
        raise NotImplementedError


def _floats(text: str, n: int) -> FloatArray | None:
    try:
        values = np.array([float(v) for v in text.split(",")], dtype=float)
    except ValueError:
        return None
    if values.size != n or not np.all(np.isfinite(values)):
        return None
    return values


class SymetrieSimulator(UserObjectFrames, SimulatedController):
    """A simulated Symétrie controller (API v2 as in :mod:`hexatherm.devices.symetrie`).

    Examples
    --------
    >>> hexapod = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
    ...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200,
    ...     stroke_mm=(150, 300))
    >>> with SymetrieSimulator(SimulatedHexapod(hexapod)) as sim:
    ...     sim.url.startswith("symetrie://127.0.0.1:")
    True
    """

    model: SimulatedHexapod
    scheme = "symetrie"
    native_convention: Convention = "symetrie"
    line_end = "\r\n"
    _COMMAND = re.compile(r"^(?P<name>[A-Z#]+\??)(?P<args>.*)$")
    #: wall-clock pause between a command's acceptance (``:1``) and its completion
    #: (``:2``), and the poll of a move's end: a controller's cycle, so that the two
    #: replies never travel in one packet. ESRF's BLISS 2.4 fails a command whose two
    #: replies it finds waiting together, as a client process not scheduled within the
    #: cycle does: of the runs of ``bench/peers_bliss.py`` on 2 cores, 4 of 10 failed at
    #: 5 ms (load 11 to 14), 2 of 15 at 20 ms (at load 16), none of 10 at 50 ms (load
    #: 12 to 17). ``cycle_s`` sets it per server.
    CYCLE_S = 0.02
    #: accelerations reported by ``CFG#ACC?`` (m/s2, rad/s2): *choice*, the twin's
    #: motion has no acceleration phase (it moves at its speed from the start)
    ACCELERATIONS = (0.01, 0.005)

    def __init__(
        self,
        model: SimulatedHexapod,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        cycle_s: float = CYCLE_S,
    ) -> None:
        if not cycle_s > 0:
            raise ValueError(f"the controller's cycle must be > 0 s, not {cycle_s!r}")
        self.cycle_s = float(cycle_s)
        self.frames = np.zeros(12)
        self._wire_lock = threading.Lock()
        #: per connection: a ``MOVE#ABS`` accepted whose ``:2`` waits for the motion's end
        self._moves: dict[socket.socket, bool] = {}
        self.travel = single_axis_travel(model)
        super().__init__(model, host, port)

    def _serve(self, sock: socket.socket) -> None:
        closed = threading.Event()
        self._moves[sock] = False
        watcher = threading.Thread(
            target=self._move_ends, args=(sock, closed), name="symetrie-sim-moves", daemon=True
        )
        watcher.start()
        try:
            super()._serve(sock)
        finally:
            closed.set()
            self._moves.pop(sock, None)

    def _move_ends(self, sock: socket.socket, closed: threading.Event) -> None:
        """Send ``MOVE#ABS:2`` when an accepted move has ended (polled each cycle)."""
        while not closed.wait(self.cycle_s):
            if self._moves.get(sock) and not self.model.moving():
                self._moves[sock] = False
                try:
                    self._send_replies(sock, ["MOVE#ABS:2"])
                except OSError:
                    return

    def _send_replies(self, sock: socket.socket, lines: list[str]) -> None:
        with self._wire_lock:  # a reply's bytes are never mixed with another's
            self._write(sock, lines)

    def _reply_to(self, sock: socket.socket, line: str) -> None:
        """An acknowledged command's ``:1`` at once, its ``:2`` a cycle later
        (``MOVE#ABS``: when the motion ends)."""
        replies = self.respond(line)
        if len(replies) >= 2 and replies[0].endswith(":1"):
            self._send_replies(sock, replies[:1])
            if replies[0] == "MOVE#ABS:1":
                self._moves[sock] = True
                return
            time.sleep(self.cycle_s)
            replies = replies[1:]
        self._send_replies(sock, replies)

    def _specific_position(self, short: str, args: str) -> list[str]:
        """``CFG#SPECIFICPOS?0``: ``0,BITS,LARGEST`` (the positions defined, the largest
        number); ``?i``: ``i,ENABLED,CS,`` + the pose (m, rad) + ``,"NAME"``. The twin's
        three are those of its gpascii server: 1 user zero (CS 3, object in user), 2
        retracted (the lowest Tz the struts allow) and 3 machine zero (CS 0, platform in
        machine); names *choice*. Another number: -48 (ParamsIn_WrongValue)."""
        if not re.fullmatch(r"\d+", args):
            return [f"{short}:-9"]
        index = int(args)
        if index == 0:
            return [f"{short}:1", f"{short}:2,0,{0b111},3"]
        if index > 3:
            return [f"{short}:-48"]
        pose = np.zeros(6)
        if index == 2:
            pose[2] = self.travel[0][2]
        name, cs = {1: ("USER ZERO", 3), 2: ("RETRACTED", 0), 3: ("MACHINE ZERO", 0)}[index]
        values = ",".join(repr(float(v)) for v in pose_to_wire(pose))
        return [f"{short}:1", f'{short}:2,{index},1,{cs},{values},"{name}"']

    def greeting(self) -> list[str]:
        return [
            "SYMETRIE controller",
            "API version: 2.0 (hexatherm simulator)",
            "Project: hexatherm simulated hexapod",
            "Waiting for commands...",
        ]

    def _status_word(self) -> int:
        m = self.model
        bits = {1, 3, 6, 8, 9}  # ready, safety, control on, phasing and homing done
        if m.in_position():
            bits.add(4)
        if m.moving():
            bits.add(5)
        return sum(1 << b for b in bits)

    def _axis_word(self) -> int:
        """An actuator's status word, as the hexapod's: bits 3 control, 5 phasing and 6
        homing done; 1 in position, 2 moving (BLISS's ``AXIS_STATUS_FIELDS``)."""
        bits = {3, 5, 6}
        if self.model.in_position():
            bits.add(1)
        if self.model.moving():
            bits.add(2)
        return sum(1 << b for b in bits)

    def respond(self, line: str) -> list[str]:
        match = self._COMMAND.match(line)
        if match is None:
            return [f"{line.split(':')[0][:20]}:-6"]
        name, args = match["name"], match["args"].strip()
        short = name.rstrip("?")
        code = self.faults.take_error(short)
        if code is not None:
            return [f"{short}:{code}"]
        m = self.model
        if name == "STA#HEXAPOD?":
            self._drop_if_moving()
            pose = pose_to_wire(np.stack([self._wire_pose(), self._platform_pose()]))
            values = ",".join(repr(float(v)) for v in pose.ravel())
            return [f"{short}:2,{self._status_word()},{values}"]  # an integer word
        if name == "STA#AXES?":
            if not m.report_actuators:
                return [f"{short}:-6"]
            lengths = m.actuators_mm() * 1e-3
            data = ["6"] + [str(self._axis_word())] * 6 + [repr(float(v)) for v in lengths]
            return [f"{short}:2," + ",".join(data)]
        if name == "STA#TEMP?":
            temps = m.temperatures()
            if temps is None:  # not a command of the API: Panel_UnknownStaCmd
                return [f"{short}:-23"]
            return [f"{short}:2,{temps.size}" + "".join(f",{v!r}" for v in temps.tolist())]
        if name in ("CFG#SPD?", "CFG#ACC?"):  # current then largest, m/s and rad/s (/s)
            speeds = [m.speed_mm_s * 1e-3, float(np.deg2rad(m.speed_deg_s))]
            numbers = (speeds if name == "CFG#SPD?" else list(self.ACCELERATIONS)) * 2
            return [f"{short}:1", f"{short}:2," + ",".join(repr(float(v)) for v in numbers)]
        if name in ("CFG#LIM#WS?", "CFG#LIM#ENABLE?"):  # 1 machine limits, 2 user limits
            if args not in ("1", "2"):
                return [f"{short}:-9"]
            if name == "CFG#LIM#ENABLE?":
                enabled = args == "1" or self.faults.refuse is not None
                return [f"{short}:1", f"{short}:2,{args},{int(enabled)}"]
            limits = pose_to_wire(np.array(self.travel)).ravel()
            return [f"{short}:1", f"{short}:2,{args}," + ",".join(repr(float(v)) for v in limits)]
        if name == "CFG#SPECIFICPOS?":
            return self._specific_position(short, args)
        if name == "CFG#CS?":  # CFG#CS?CS: that CS first, then user and object frames
            if not re.fullmatch(r"\d+", args):
                return [f"{short}:-9"]
            now = ",".join(repr(float(v)) for v in pose_to_wire(self.frames.reshape(2, 6)).ravel())
            return [f"{short}:1", f"{short}:2,{int(args)},{now}"]
        if name == "CFG#CS":  # *choice*: the 12 values of CFG#CS?'s answer (m, rad)
            given = _floats(args, 12)
            if given is None:
                return [f"{short}:-9"]
            self.frames = pose_from_wire(given.reshape(2, 6)).ravel()
            return [f"{short}:1", f"{short}:2"]
        if name in ("VALID#PTP?", "MOVE#ABS"):
            wire = _floats(args, 6)
            if wire is None:
                return [f"{short}:-9"]
            pose = self._model_pose(pose_from_wire(wire))
            stroke_ok, rule_ok = m.check(pose)
            if name == "VALID#PTP?":
                bits = (0 if stroke_ok else 4) | (0 if rule_ok else 2)
                return [f"{short}:1", f"{short}:2,{bits}"]
            if not stroke_ok:
                return [f"{short}:-126"]
            if not rule_ok:
                return [f"{short}:-104"]
            m.start_move(pose)
            return [f"{short}:1", f"{short}:2"]
        if name == "STOP":
            m.stop()
            return [f"{short}:1", f"{short}:2"]
        return [f"{short}:-6"]
