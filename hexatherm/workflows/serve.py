"""``hexatherm serve-twin``: a simulated CMM and hexapod controller backed by the twin.

The rehearsal of an unattended campaign (``hexatherm run``): an I++ DME server
(:class:`~hexatherm.devices.sim.ipp.IppSimServer`), a controller server
(:class:`~hexatherm.devices.sim.symetrie.SymetrieSimulator` or
:class:`~hexatherm.devices.sim.pi.PISimulator`) and a thermocouple logger
(:class:`~hexatherm.devices.sim.thermocouples.ThermocoupleSimulator`, for ``run
--temperature-port socket://127.0.0.1:PORT``) on 127.0.0.1, all backed by one
:class:`TwinWorld`:

- the hexapod (:class:`~hexatherm.devices.sim.symetrie.SimulatedHexapod`): moves in a
  straight line in pose space at finite speeds, raises its in-position flag a settle time
  after the motion, reads back with noise, reports the IGM's actuator lengths and the
  heating model's leg temperatures (6 channels, deg C);
- the CMM's balls: where the twin (:func:`hexatherm.core.twin.predict`) puts them for the
  commanded pose the platform is at, with the legs grown by the heating model's
  temperatures at that time (and the effects: the hexapod file's thermal model plus a
  scenario's hidden ones), placed on the CMM by ``origin_on_cmm``;
- the thermocouples: the heating model's six leg temperatures and the air's (a seventh
  channel), one line per sampling period, as a logger sends them;
- time: one clock for everything, in seconds; :class:`AcceleratedClock` runs the thermal
  history ``time_scale`` times faster than the wall clock (a night in minutes), a
  :class:`~hexatherm.devices.sim.symetrie.ManualClock` moves only when the run's waits
  sleep (tests). Every CMM motion (each ``GoTo``, and the approach and touch of a
  ``PtMeas``) takes ``cmm_move_s`` of it.

Faults (:func:`parse_fault`): I++ errors of any severity, ``E0000`` events, a dropped
connection mid-transaction, lines split across reads (:class:`~hexatherm.devices.sim.ipp.
Fault`); a late in-position flag, a connection dropped mid-move, split replies, an error
code, a refused pose (:class:`~hexatherm.devices.sim.symetrie.Faults`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hexatherm.core.effects import Effect, ThermocoupleLog
from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.heating import HeatingModel, Mat, MatHeating
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.twin import PreparedPlan, TwinSteps, predict
from hexatherm.devices.sim.ipp import Fault, IppSimServer
from hexatherm.devices.sim.pi import PISimulator, PIStart
from hexatherm.devices.sim.symetrie import (
    Faults,
    SimulatedController,
    SimulatedHexapod,
    SymetrieSimulator,
)
from hexatherm.devices.sim.symetriepmac import SymetriePmacSimulator
from hexatherm.devices.sim.thermocouples import ThermocoupleSimulator
from hexatherm.errors import HexathermError, InputError
from hexatherm.session import Balls
from hexatherm.typing import FloatArray

__all__ = [
    "AcceleratedClock",
    "ServeFaults",
    "TwinMachines",
    "TwinWorld",
    "default_heating",
    "parse_fault",
]

AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


class AcceleratedClock:
    """POSIX seconds that run ``scale`` times faster than the wall clock.

    ``clock()`` starts at ``start_s`` (default: now); ``sleep(s)`` waits ``s / scale``
    wall-clock seconds, i.e. ``s`` of this clock.

    >>> clock = AcceleratedClock(60.0, start_s=0.0)
    >>> 0.0 <= clock() < 60.0
    True
    """

    def __init__(self, scale: float = 1.0, start_s: float | None = None) -> None:
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"the time scale must be positive, got {scale!r}")
        self.scale = float(scale)
        self._origin = time.time() if start_s is None else float(start_s)
        self._wall = time.monotonic()

    def __call__(self) -> float:
        return self._origin + self.scale * (time.monotonic() - self._wall)

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of this clock."""
        if seconds > 0:
            time.sleep(seconds / self.scale)


def default_heating() -> MatHeating:
    """The rehearsal's heating without a scenario: mats on the legs from 10 min, 2 to 7 K
    plateaus with a 40 min time constant, the air at 20 degC (seconds from the start)."""
    gains = (3.0, 5.0, 2.0, 4.0, 7.0, 2.5)
    return MatHeating(tuple(Mat(g, 2400.0, ((600.0, float("inf")),)) for g in gains))


class TwinWorld:
    """The twin behind the simulated machines: a :class:`~hexatherm.devices.sim.ipp.CmmBackend`.

    Parameters
    ----------
    hexapod : Hexapod
        With its leg model (``legs``) and stroke.
    balls : Balls
        The balls on the platform.
    heating : HeatingModel
        Leg and air temperatures, seconds from ``start_s``.
    origin_on_cmm : sequence of 6 floats
        Frame O on the CMM (the hexapod's convention, mm and deg): the truth, which the
        run only knows nominally.
    effects : sequence of Effect
        Applied to the truth (the hexapod file's thermal model and hidden effects).
    clock, sleep : callable
        The world's time (s) and a wait on it.
    start_s : float
        Clock time of the start of the heating history (default: the clock now).
    cmm_move_s : float
        Clock time each CMM motion takes, s.
    sample_period_s : float
        Period of the thermocouple history the effects see (a lag needs it), s.
    speed_mm_s, speed_deg_s, settle_s, noise_um, noise_urad, seed, faults
        Of the :class:`~hexatherm.devices.sim.symetrie.SimulatedHexapod`.
    true_parameters : array_like, shape (48,), optional
        The true geometry, if not ``hexapod``'s (:func:`hexatherm.core.twin.predict`).
    """

    def __init__(
        self,
        hexapod: Hexapod,
        balls: Balls,
        *,
        heating: HeatingModel,
        origin_on_cmm: Sequence[float],
        effects: Sequence[Effect] = (),
        clock: Callable[[], float] = time.time,
        sleep: Callable[[float], None] = time.sleep,
        start_s: float | None = None,
        cmm_move_s: float = 1.0,
        sample_period_s: float = 30.0,
        speed_mm_s: float = 2.0,
        speed_deg_s: float = 1.0,
        settle_s: float = 2.0,
        noise_um: float = 0.05,
        noise_urad: float = 0.2,
        seed: int = 0,
        faults: Faults | None = None,
        true_parameters: npt.ArrayLike | None = None,
    ) -> None:
        if hexapod.legs is None:
            raise InputError("the twin needs the hexapod's leg model (legs:)")
        if not (cmm_move_s >= 0 and sample_period_s > 0):
            raise ValueError("cmm_move_s must be >= 0 and sample_period_s > 0")
        self.hexapod, self.balls, self.heating = hexapod, balls, heating
        self.effects = tuple(effects)
        self.true_parameters = true_parameters
        self.origin2cmm = transform_from_pose(origin_on_cmm, hexapod.convention)
        self.clock, self.sleep = clock, sleep
        self.start_s = clock() if start_s is None else float(start_s)
        self.cmm_move_s = float(cmm_move_s)
        self.sample_period_s = float(sample_period_s)
        self.model = SimulatedHexapod(
            hexapod,
            clock=clock,
            speed_mm_s=speed_mm_s,
            speed_deg_s=speed_deg_s,
            settle_s=settle_s,
            noise_um=noise_um,
            noise_urad=noise_urad,
            seed=seed,
            temperatures_C=self.leg_temperatures_C,
            faults=faults,
        )
        self._lock = threading.Lock()
        self._cache: tuple[float, bytes, FloatArray] | None = None
        self._plans: dict[bytes, PreparedPlan] = {}  # one-pose plans, prepared (many motions)
        self._states: dict[bytes, FloatArray] = {}  # centres by pose and legs, no effects

    def leg_temperatures_C(self, t_s: float) -> list[float]:
        """The legs' temperatures (6 channels) at clock time ``t_s``, deg C."""
        return [float(v) for v in self.heating.legs(np.array([t_s - self.start_s]))[0]]

    def thermocouples_C(self, t_s: float) -> list[float]:
        """What the thermocouple logger reads at clock time ``t_s``: the six legs, then the
        air, deg C."""
        rel = np.array([t_s - self.start_s])
        legs = self.heating.legs(rel)[0]
        return [float(v) for v in legs] + [float(self.heating.air(rel)[0])]

    def log(self, t_s: float) -> ThermocoupleLog:
        """The thermocouple history from the start to ``t_s`` (seconds from the start)."""
        rel = max(float(t_s) - self.start_s, 0.0)
        times = np.union1d(np.arange(0.0, rel, self.sample_period_s), [rel])
        return ThermocoupleLog(times, self.heating.legs(times), self.heating.air(times))

    def centres_at(self, pose_mm_deg: npt.ArrayLike, t_s: float) -> FloatArray:
        """The balls' centres on the CMM (k, 3) with the platform commanded to a pose at
        clock time ``t_s``: the twin's truth, CMM effects included, mm."""
        pose = [float(v) for v in np.asarray(pose_mm_deg, dtype=float).reshape(6)]
        key = np.array(pose).tobytes()
        prepared = self._plans.get(key)  # two threads may prepare a pose twice: the same
        if prepared is None:
            if len(self._plans) >= 256:  # more poses than a campaign's steps: anew
                self._plans.clear()
            plan = Plan.from_steps([("O", "origin", pose)])
            prepared = self._plans[key] = PreparedPlan.of(self.hexapod, plan, self.true_parameters)
        log = self.log(t_s)
        # without effects, which alone read the log's history, the centres are a function
        # of the pose and the legs' temperatures at the log's start and at t_s: a still
        # world's legs (or legs back where they were) are predicted once per pose
        state = key + log.legs_at([log.t0_s, log.times_s[-1]]).tobytes()
        if not self.effects and state in self._states:
            return self._states[state].copy()
        steps = self._predict(prepared.plan, [log.times_s[-1]], log, prepared)
        centres = np.asarray(steps.measured_centres_cmm_mm[0], dtype=float)
        if not self.effects:
            if len(self._states) >= 4096:  # legs that keep changing: anew
                self._states.clear()
            self._states[state] = centres.copy()
        return centres

    def truth(self, plan: Plan, times_s: npt.ArrayLike) -> TwinSteps:
        """The twin's truth for a plan measured at clock times ``times_s`` (N,): the true
        poses relative to the measured origin step (``pose``) and in the first reference's
        thermal state (``corrected_pose``), what ``process`` should find."""
        t = np.asarray(times_s, dtype=float).reshape(-1)
        log = self.log(float(t.max()))
        return self._predict(plan, t - self.start_s, log)

    def _predict(
        self, plan: Plan, t_s: npt.ArrayLike, log: ThermocoupleLog, prep: PreparedPlan | None = None
    ) -> TwinSteps:
        """:func:`~hexatherm.core.twin.predict` with the twin's model, balls, placement,
        effects and true geometry; with a prepared one-pose plan, no reference state."""
        args = (self.balls.centres_mm, self.origin2cmm, self.effects, self.true_parameters)
        at = {"reference_state": prep is None, "true_parameters": args[3], "prepared": prep}
        return predict(self.hexapod, plan, t_s, log, *args[:3], **at)  # type: ignore[arg-type]

    # CmmBackend
    def ball_centres_mm(self, t_s: float) -> FloatArray:
        """Where the balls are now (the platform at its current pose), mm."""
        pose = self.model.true_pose()
        key = pose.tobytes()
        with self._lock:
            if self._cache is not None and self._cache[0] == t_s and self._cache[1] == key:
                return self._cache[2].copy()
        centres = self.centres_at(pose, t_s)
        with self._lock:
            self._cache = (t_s, key, centres)
        return centres.copy()

    def ball_radii_mm(self, t_s: float) -> FloatArray:
        """The balls' radii, mm."""
        return 0.5 * np.asarray(self.balls.diameters_mm, dtype=float)

    def cmm_time_s(self) -> float:
        """The CMM's clock: every motion takes ``cmm_move_s``."""
        if self.cmm_move_s > 0:
            self.sleep(self.cmm_move_s)
        return self.clock()


@dataclass
class ServeFaults:
    """Faults of both simulated machines (see :func:`parse_fault`)."""

    ipp: list[Fault] = field(default_factory=list)
    controller: Faults = field(default_factory=Faults)
    pi: PIStart = field(default_factory=PIStart)


_FAULT_KEYS = {
    "ipp-error": {"severity", "method", "nth", "number"},
    "ipp-event": {"method", "nth"},
    "ipp-drop": {"method", "nth", "after"},
    "ipp-split": {"method", "nth", "chunk"},
    "late-in-position": {"seconds"},
    "controller-drop": set(),
    "controller-split": set(),
    "controller-error": {"command", "code"},
    "refuse": {"axis", "min", "max"},
    "pi-servo-off": set(),
    "pi-unreferenced": set(),
    "pi-busy": set(),
    "pi-coordinate-system": {"name"},
    "pi-pivot": {"r", "s", "t"},
}


def parse_fault(text: str, into: ServeFaults | None = None) -> ServeFaults:
    """Add one fault, ``KIND[:key=value,...]``, to ``into`` (a new one by default).

    Kinds and keys:

    - ``ipp-error:severity=2,method=PtMeas,nth=3[,number=1006]``: the nth command (of that
      method, else of all) fails with an I++ error of that severity;
    - ``ipp-event:method=PtMeas,nth=2``: ``E0000`` events interleaved with its response;
    - ``ipp-drop:method=PtMeas,nth=5[,after=2]``: the connection closed after ``after``
      lines of the response (1: after the ``&``);
    - ``ipp-split:method=PtMeas,nth=1[,chunk=3]``: its response written in chunks of bytes;
    - ``late-in-position:seconds=30``: the in-position flag that much after the settle
      (every move);
    - ``controller-drop``: the connection closed at the first status query during a move;
    - ``controller-split``: replies written in chunks of 1 to 3 bytes;
    - ``controller-error:command=MOVE#ABS,code=-104``: the next such command answered with
      that error code (PI: ``command=MOV,code=7``);
    - ``refuse:axis=Tz[,min=-5][,max=5]``: poses with that component outside [min, max]
      (mm, deg) refused by the controller (a user limit);
    - ``pi-servo-off``, ``pi-unreferenced``, ``pi-busy``: the PI controller starts with the
      servo off, not referenced, or busy (``#7``);
    - ``pi-pivot[:r=0,s=0,t=100]``: the PI controller starts with its pivot point (``SPI``,
      mm) there;
    - ``pi-coordinate-system[:name=SAMPLE]``: the PI controller starts with a user
      coordinate system (type KSD, offset Z 10 mm, W 1 deg) enabled.

    >>> f = parse_fault("ipp-error:severity=3,method=GoTo,nth=4")
    >>> f.ipp[0].severity, f.ipp[0].method, f.ipp[0].nth
    (3, 'GoTo', 4)
    >>> f = parse_fault("refuse:axis=Tz,max=5", f)
    >>> f.controller.refuse([0, 0, 6.0, 0, 0, 0]), f.controller.refuse([0, 0, 4.0, 0, 0, 0])
    (True, False)
    """
    out = ServeFaults() if into is None else into
    kind, _, rest = text.strip().partition(":")
    if kind not in _FAULT_KEYS:
        raise InputError(f"unknown fault {kind!r}; known: {', '.join(sorted(_FAULT_KEYS))}")
    values: dict[str, str] = {}
    for item in filter(None, (x.strip() for x in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or key not in _FAULT_KEYS[kind]:
            raise InputError(
                f"fault {kind}: bad setting {item!r} (keys: "
                f"{', '.join(sorted(_FAULT_KEYS[kind])) or 'none'})"
            )
        values[key] = value.strip()

    def number(key: str, default: float | None = None) -> float:
        if key not in values:
            if default is None:
                raise InputError(f"fault {kind} needs {key}=...")
            return default
        try:
            value = float(values[key])
        except ValueError:
            raise InputError(f"fault {kind}: {key} must be a number, got {values[key]!r}") from None
        if not np.isfinite(value):
            raise InputError(f"fault {kind}: {key} must be a finite number, got {values[key]!r}")
        return value

    def whole(key: str, default: int | None = None) -> int:
        value = number(key, None if default is None else float(default))
        if value != int(value):
            raise InputError(f"fault {kind}: {key} must be a whole number")
        return int(value)

    try:
        if kind == "ipp-error":
            number_ = values.get("number")
            out.ipp.append(
                Fault(
                    "error",
                    whole("nth", 1),
                    values.get("method"),
                    severity=whole("severity", 2),
                    number=None if number_ is None else whole("number"),
                )
            )
        elif kind == "ipp-event":
            out.ipp.append(Fault("event", whole("nth", 1), values.get("method")))
        elif kind == "ipp-drop":
            out.ipp.append(
                Fault("drop", whole("nth", 1), values.get("method"), after_lines=whole("after", 1))
            )
        elif kind == "ipp-split":
            out.ipp.append(
                Fault("split", whole("nth", 1), values.get("method"), chunk_bytes=whole("chunk", 3))
            )
        elif kind == "late-in-position":
            seconds = number("seconds")
            if seconds < 0:
                raise InputError(f"fault {kind}: seconds must be >= 0, got {values['seconds']!r}")
            out.controller.late_in_position_s = seconds
        elif kind == "controller-drop":
            out.controller.drop_mid_move = True
        elif kind == "controller-split":
            out.controller.split_writes = True
        elif kind == "pi-servo-off":
            out.pi.servo_on = False
        elif kind == "pi-unreferenced":
            out.pi.referenced = False
        elif kind == "pi-busy":
            out.pi.busy = True
        elif kind == "pi-coordinate-system":
            name = values.get("name", "SAMPLE").upper()
            if not name.isalnum() or name == "ZERO":
                raise InputError(f"fault {kind}: name must be letters and digits, not ZERO")
            out.pi.coordinate_system = name
        elif kind == "pi-pivot":
            out.pi.pivot = (number("r", 0.0), number("s", 0.0), number("t", 100.0))
        elif kind == "controller-error":
            command = values.get("command")
            if not command:
                raise InputError("fault controller-error needs command=...")
            out.controller.errors.setdefault(command, []).append(whole("code"))
        else:
            axis = values.get("axis", "")
            if axis not in AXES:
                raise InputError(f"fault refuse: axis must be one of {', '.join(AXES)}")
            k = AXES.index(axis)
            low, high = number("min", -np.inf), number("max", np.inf)
            if low > high:
                raise InputError(
                    f"fault refuse: min={values['min']} is above max={values['max']}: an empty "
                    "interval, every pose would be refused"
                )
            previous = out.controller.refuse

            def refuse(pose: FloatArray) -> bool:
                outside = not (low <= float(np.asarray(pose)[k]) <= high)
                return outside or (previous is not None and previous(pose))

            out.controller.refuse = refuse
    except HexathermError:
        raise
    except ValueError as exc:  # the device classes' own checks
        raise InputError(f"fault {kind}: {exc}") from None
    return out


class TwinMachines:
    """The simulated machines (CMM, controller, thermocouple logger) around one
    :class:`TwinWorld` (a context manager).

    Parameters
    ----------
    world : TwinWorld
    dialect : {"symetrie", "pi", "symetrie-pmac"}
    tool : str
        Name of the CMM's tool (tip diameter: the balls file's).
    point_noise_um : float
        Probing noise along the normal, um.
    seed : int
        Seed of the probing noise.
    ipp_faults : sequence of Fault
    cmm_port, controller_port, thermocouple_port : int
        Ports on 127.0.0.1 (0: free ones).
    thermocouple_period_s : float
        Sampling period of the thermocouple logger, on the world's clock, s.
    cmm_limits_mm : pair of 3 floats
        The CMM's travel box.
    pi_start : PIStart, optional
        The state the PI controller starts in (``dialect="pi"``).
    cmm_dialect : {"dme-1.4.3", "dme-1.4"}
        How the simulated CMM speaks (``dme-1.4``: a plain DME 1.4 server, see
        :data:`~hexatherm.devices.sim.ipp.CMM_DIALECTS`).

    Attributes
    ----------
    cmm : IppSimServer
    controller : SimulatedController
    thermocouples : ThermocoupleSimulator
    """

    def __init__(
        self,
        world: TwinWorld,
        *,
        dialect: str = "symetrie",
        tool: str = "Probe1",
        point_noise_um: float = 0.0,
        seed: int = 0,
        ipp_faults: Sequence[Fault] = (),
        cmm_port: int = 0,
        controller_port: int = 0,
        thermocouple_port: int = 0,
        thermocouple_period_s: float = 10.0,
        cmm_limits_mm: tuple[Sequence[float], Sequence[float]] = (
            (-2000.0, -2000.0, -2000.0),
            (2000.0, 2000.0, 2000.0),
        ),
        pi_start: PIStart | None = None,
        cmm_dialect: str = "dme-1.4.3",
    ) -> None:
        if dialect not in ("symetrie", "pi", "symetrie-pmac"):
            raise InputError(f"dialect must be symetrie, pi or symetrie-pmac, got {dialect!r}")
        balls = world.balls
        tip = balls.tip_diameter_mm if balls.tip_diameter_mm > 0 else 2.0
        home = world.ball_centres_mm(world.clock()).max(axis=0) + [0.0, 0.0, 150.0]
        self.world = world
        self.cmm = IppSimServer(
            world,
            port=cmm_port,
            tools={tool: tip},
            noise_um=point_noise_um,
            seed=seed,
            faults=ipp_faults,
            compensated=balls.probe_compensated,
            time_s=world.cmm_time_s,
            home_mm=tuple(float(v) for v in home),
            limits_mm=cmm_limits_mm,
            dialect=cmm_dialect,
        )
        try:
            self.controller: SimulatedController = (
                SymetrieSimulator(world.model, port=controller_port)
                if dialect == "symetrie"
                # Symetrie's Power PMAC gpascii over telnet
                else SymetriePmacSimulator(world.model, port=controller_port)
                if dialect == "symetrie-pmac"
                else PISimulator(world.model, port=controller_port, start=pi_start)
            )
        except BaseException:
            self.cmm.close()
            raise
        try:
            self.thermocouples = ThermocoupleSimulator(
                world.thermocouples_C,
                clock=world.clock,
                period_s=thermocouple_period_s,
                port=thermocouple_port,
            )
        except BaseException:
            self.controller.close()
            self.cmm.close()
            raise

    @property
    def cmm_url(self) -> str:
        """``ipp://127.0.0.1:PORT``."""
        return self.cmm.url

    @property
    def controller_url(self) -> str:
        """``symetrie://127.0.0.1:PORT`` or ``pi://127.0.0.1:PORT``."""
        return self.controller.url

    @property
    def thermocouples_url(self) -> str:
        """``socket://127.0.0.1:PORT``: the thermocouple logger, for ``--temperature-port``."""
        return self.thermocouples.url

    def close(self) -> None:
        """Stop the servers (their connections drop, as machines that go away)."""
        try:
            self.thermocouples.close()
        finally:
            try:
                self.controller.close()
            finally:
                self.cmm.close()

    def __enter__(self) -> TwinMachines:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
