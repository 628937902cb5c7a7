"""The unattended campaign: drive the hexapod controller and the CMM through a plan.

For every step of the plan, in order (O, R0, then the targets with their references):

1. the probe goes up to the travel height (above every ball of every step of the plan);
2. the hexapod is commanded to the step's pose (every pose was validated before the first
   move: the stroke by the hexapod model, then the controller's own check) and waited for
   in position (flag, settle, a stable read-back; :class:`InPositionCriteria`); the step's
   record (commanded pose, read-back poses, actuator lengths, the controller's
   temperatures) goes to ``steps.csv``;
3. each ball's upper cap is probed around its **predicted** centre: the placement of frame
   O on the CMM (measured, once O's balls are; before that the nominal ``origin_on_cmm``)
   times the commanded pose, shifted by the mean offset of the balls of the same step
   already measured; each ball is fitted at once (free-radius sphere) and checked (fit,
   radius, form, RMS, distance from the prediction): a bad ball is probed once more,
   around its fitted centre when there is one; the second probing is kept, with a warning
   if it is still bad (``process``'s quality checks see it);
4. before a target, when its reference right before it was measured longer than
   ``max_gap_s`` ago (a late in-position flag, a reconnection, a resume), that reference
   is measured again first (its new points replace the old ones in ``points.csv``; the old
   ones stay in the transcript).

A dropped connection to either machine is reopened (``reconnects`` times per ball or
move) and the ball probed, or the move commanded, again from its start. Errors that need
the operator (I++ severity 3, a refused pose, no in-position flag) stop the run; so do
Ctrl-C and a machine that stays away. On every stop that is not the end of the plan the
hexapod gets ``stop()``, and :class:`~hexatherm.errors.IncompleteSession` says how to go
on: ``--resume`` rebuilds the state from the transcript (:mod:`.resume`) and continues
at the first step with a ball not accepted (the hexapod is commanded to that step's pose
again). At the end ``session.yaml`` makes the folder a session for ``hexatherm process``.

Clock and sleep are injectable (POSIX seconds): with the simulators' manual clock a whole
campaign runs without waiting.
"""

from __future__ import annotations

import collections
import contextlib
import math
import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.core.geometry import apply_transform, invert_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.registration import register
from hexatherm.core.spherefit import fit_spheres, probe_radius_mm
from hexatherm.devices.controller import InPositionCriteria, SocketController, format_pose
from hexatherm.devices.ipp import (
    TRANSCRIPT_MAGIC,
    IppClient,
    IppEvent,
    ProbedPoint,
    cap_touch_plan,
    parse_ipp_url,
    probe_cap,
)
from hexatherm.devices.serialport import PortReader, PortSettings
from hexatherm.devices.urls import controller_from_url
from hexatherm.errors import (
    AcquisitionError,
    ControllerConnectionError,
    ControllerError,
    FitError,
    HexathermError,
    IncompleteSession,
    IppConnectionLost,
    IppDmeError,
    IppTimeout,
    PoseError,
    PoseRefusedError,
)
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.seriallog import (
    LOG_NAME,
    POINTS_HEADER,
    TEMPERATURE,
    TEMPERATURES_NAME,
    FileSink,
    LogEntry,
    MemorySink,
    SerialLog,
    entry,
    parse_log,
)
from hexatherm.session import Balls
from hexatherm.typing import FloatArray
from hexatherm.workflows.acquire.files import (
    SessionFiles,
    check_same_files,
    finish_session,
    write_copies,
)
from hexatherm.workflows.acquire.recorder import Recorder as StreamRecorder
from hexatherm.workflows.run.files import (
    CONTROLLER_LOG_MAGIC,
    CONTROLLER_LOG_NAME,
    POINTS_NAME,
    STEPS_NAME,
    TRANSCRIPT_NAME,
    AcceptedBall,
    LineLog,
    iso_stamp,
    point_line,
    points_lines,
    step_header,
    step_row,
    transcript_is_new,
    write_lines,
)
from hexatherm.workflows.run.resume import (
    ProbeSettings,
    RunSettings,
    RunState,
    read_run_settings,
    rebuild_state,
    write_run_settings,
)

Notify = Callable[[str, str], None]

__all__ = [
    "BallChecks",
    "BallResult",
    "ProbeSettings",
    "RunOptions",
    "RunResult",
    "dry_run",
    "run_campaign",
]


@dataclass(frozen=True)
class BallChecks:
    """When a ball's live fit calls for probing it again.

    Attributes
    ----------
    radius_tol_um : float
        Largest deviation of the fitted radius from the nominal (ball radius, plus the tip
        radius when the probe is not compensated), um.
    form_um : float
        Largest form error (max - min residual), um.
    rms_um : float
        Largest RMS of the residuals, um.
    centre_tol_mm : float
        Largest distance of the fitted centre from the predicted one, mm (a larger one means
        the prediction, hence the touch points, were off: probed again around the fit).
    """

    radius_tol_um: float = 20.0
    form_um: float = 10.0
    rms_um: float = 3.0
    centre_tol_mm: float = 0.5


@dataclass(frozen=True)
class RunOptions:
    """Options of ``hexatherm run`` (see its ``--help``).

    Attributes
    ----------
    session : Path
        The session folder.
    cmm_url, controller_url : str
        ``ipp://HOST[:PORT]``; ``symetrie://HOST[:PORT]`` or ``pi://HOST[:PORT]``.
    origin_on_cmm : tuple of 6 floats, optional
        Nominal placement of frame O on the CMM (hexapod's convention, mm and deg);
        required for a new run, taken from ``run.yaml`` on a resume.
    resume : bool
    probe : ProbeSettings
    checks : BallChecks
    criteria : InPositionCriteria
    max_gap_s : float
        Largest time between a target and the reference right before it, s.
    cmm_limits_mm : pair of 3 floats, optional
        Lower and upper corners of the CMM's travel, mm: every probe position is checked.
    temperature_port : PortSettings, optional
        A thermocouple logger on a serial port (as ``acquire --temperature-port``).
    durable : bool
        fsync every log line (the default); flushing alone survives a killed process.
    reconnects : int
        Reopenings of a dropped connection per ball or per move.
    reconnect_wait_s : float
        Wait before reopening, s.
    ipp_timeout_s : float
        Longest I++ transaction, s.
    reply_timeout_s : float
        Longest wait for a controller's reply, s.
    """

    session: Path
    cmm_url: str
    controller_url: str
    origin_on_cmm: tuple[float, ...] | None = None
    resume: bool = False
    probe: ProbeSettings = field(default_factory=ProbeSettings)
    checks: BallChecks = field(default_factory=BallChecks)
    criteria: InPositionCriteria = field(default_factory=InPositionCriteria)
    max_gap_s: float = 600.0
    cmm_limits_mm: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    temperature_port: PortSettings | None = None
    durable: bool = True
    reconnects: int = 3
    reconnect_wait_s: float = 1.0
    ipp_timeout_s: float = 120.0
    reply_timeout_s: float = 5.0


@dataclass(frozen=True)
class BallResult:
    """The live fit of one accepted ball.

    Attributes
    ----------
    label, ball : str
    n : int
    centre_mm : ndarray, shape (3,)
        Fitted centre (NaN when the fit failed).
    radius_mm, form_um, rms_um : float
    predicted_mm : ndarray, shape (3,)
        The centre the touch points were planned around.
    attempts : int
        Probings of this ball in this visit (2: probed again).
    problems : tuple of str
        Checks the kept probing still fails.
    """

    label: str
    ball: str
    n: int
    centre_mm: FloatArray
    radius_mm: float
    form_um: float
    rms_um: float
    predicted_mm: FloatArray
    attempts: int
    problems: tuple[str, ...]


@dataclass(frozen=True)
class RunResult:
    """What a run produced."""

    session: Path
    n_points: int
    balls: tuple[BallResult, ...]
    remeasured: tuple[str, ...]
    session_file: Path


# ----------------------------------------------------------------------- helpers
def _pose_problems(controller: SocketController, poses: FloatArray) -> list[tuple[int, str]]:
    """``(step index, why)`` for every pose the hexapod model or the controller refuses."""
    problems = []
    for i, pose in enumerate(poses):
        try:
            controller.validate(pose)
        except PoseRefusedError as exc:
            problems.append((i, str(exc)))
    return problems


def _cmm_problems(
    positions_mm: FloatArray,
    limits: tuple[tuple[float, float, float], tuple[float, float, float]] | None,
) -> str | None:
    if limits is None:
        return None
    low, high = np.asarray(limits[0], dtype=float), np.asarray(limits[1], dtype=float)
    out = (positions_mm < low) | (positions_mm > high)
    if not out.any():
        return None
    worst = positions_mm[np.flatnonzero(out.any(axis=-1))[0]]
    return (
        f"probe position {', '.join(f'{v:.3f}' for v in worst)} mm is outside the CMM's "
        f"travel [{', '.join(f'{v:g}' for v in low)}] .. [{', '.join(f'{v:g}' for v in high)}]"
    )


class _Geometry:
    """Predicted ball centres and probe positions of every step (CMM frame, mm)."""

    def __init__(self, hexapod: Hexapod, balls: Balls, poses: FloatArray, probe: ProbeSettings):
        self.hexapod, self.balls, self.poses, self.probe = hexapod, balls, poses, probe
        self.step2origin = transform_from_pose(poses, hexapod.convention)

    def centres(self, origin2cmm: FloatArray, index: int | slice = slice(None)) -> FloatArray:
        """Predicted centres (k, 3) of step ``index`` (or (N, k, 3) of all)."""
        frames = origin2cmm @ self.step2origin[index]
        return apply_transform(frames, self.balls.centres_mm)

    def top_z(self, centres_mm: FloatArray) -> float:
        """Highest tip-centre height touching any ball top, mm."""
        r = 0.5 * self.balls.diameters_mm + 0.5 * self.balls.tip_diameter_mm
        return float(np.max(centres_mm[..., 2] + r))

    def touch_positions(self, centres_mm: FloatArray, n_points: int) -> FloatArray:
        """Every probe position of the touch plans of these centres (.., 3)."""
        out = []
        tip = self.balls.tip_diameter_mm or 1e-3
        for j, d in enumerate(self.balls.diameters_mm):
            plan = cap_touch_plan(
                centres_mm[..., j, :],
                float(d),
                tip,
                n_points,
                self.probe.cap_angle_deg,
                approach_mm=self.probe.approach_mm,
                clearance_mm=self.probe.clearance_mm,
            )
            out += [plan.approach_mm.reshape(-1, 3), plan.above_mm.reshape(-1, 3)]
            out.append(plan.safe_mm.reshape(-1, 3))
        return np.concatenate(out)


def _validate_plan(
    files: SessionFiles,
    hexapod: Hexapod,
    controller: SocketController,
    geometry: _Geometry,
    origin2cmm: FloatArray,
    options: RunOptions,
    travel_z: float,
) -> None:
    """Raise :class:`PoseError` naming every step the machines cannot do; moves nothing."""
    plan = files.plan
    problems = _pose_problems(controller, plan.poses)
    centres = geometry.centres(origin2cmm)
    for i in range(len(plan.labels)):
        positions = geometry.touch_positions(centres[i], plan.points_per_ball)
        travel = positions.copy()
        travel[:, 2] = travel_z
        cmm = _cmm_problems(np.concatenate([positions, travel]), options.cmm_limits_mm)
        if cmm is not None:
            problems.append((i, cmm))
    if problems:
        problems.sort(key=lambda p: p[0])
        first, why = problems[0]
        others = "; ".join(f"step {plan.labels[i]} ({plan.kinds[i]}): {w}" for i, w in problems[1:])
        raise PoseError(
            why + (f". Also: {others}" if others else "") + ". Nothing was moved",
            step=plan.labels[first],
            pose=plan.poses[first],
        )


def _travel_z(geometry: _Geometry, origin2cmm: FloatArray) -> float:
    probe = geometry.probe
    return geometry.top_z(geometry.centres(origin2cmm)) + probe.clearance_mm + probe.travel_mm


# ----------------------------------------------------------------------- dry run
def dry_run(
    files: SessionFiles,
    hexapod: Hexapod,
    options: RunOptions,
    notify: Notify,
    *,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
) -> int:
    """Check the whole plan against both machines' limits without moving either.

    Every pose goes through the controller's validation (the hexapod model's stroke, then
    the controller's own check), every probe position of every step (touch points,
    clearance and travel positions around the nominal prediction) through the CMM's travel
    box when one is given; the CMM is asked whether it knows the tool. Nothing moves.

    Returns
    -------
    int
        The number of steps checked.

    Raises
    ------
    PoseError
        Naming the first step refused (and the others in the message).
    """
    if options.origin_on_cmm is None:
        raise AcquisitionError("a dry run needs --origin-on-cmm (nominal placement of O)")
    geometry = _Geometry(hexapod, files.balls, files.plan.poses, options.probe)
    origin2cmm = transform_from_pose(options.origin_on_cmm, hexapod.convention)
    controller = controller_from_url(
        options.controller_url,
        hexapod=hexapod,
        reply_timeout_s=options.reply_timeout_s,
        clock=clock,
        sleep=sleep,
    )
    controller.connect()
    try:
        _validate_plan(
            files,
            hexapod,
            controller,
            geometry,
            origin2cmm,
            options,
            _travel_z(geometry, origin2cmm),
        )
    finally:
        controller.close()
    host, port = parse_ipp_url(options.cmm_url)
    with IppClient(host, port, timeout_s=options.ipp_timeout_s) as cmm:
        cmm.start_session()
        cmm.find_tool(options.probe.tool)
        cmm.end_session()
    if options.cmm_limits_mm is None:
        notify("warn", "no --cmm-limits: the probe positions were not checked against the CMM")
    notify("info", f"dry run: {len(files.plan.labels)} steps can be measured; nothing moved")
    return len(files.plan.labels)


# ------------------------------------------------------------------- temperatures
class _Thermocouples:
    """A thermocouple logger on a serial port: ``serial.log`` and ``temperatures.csv``.

    The lines are parsed by ``acquire``'s recorder (the same format); on a resume the log is
    replayed to rebuild ``temperatures.csv``.
    """

    def __init__(self, folder: Path, settings: PortSettings, files: SessionFiles, resume: bool):
        self.folder, self.settings = folder, settings
        self.items: queue.Queue[Any] = queue.Queue()
        self.stop_event = threading.Event()
        log_path = folder / LOG_NAME
        self.sink = FileSink(folder / TEMPERATURES_NAME)
        self.recorder = StreamRecorder(
            files.plan, files.balls, points=MemorySink(), temperatures=MemorySink()
        )
        if resume and log_path.is_file():
            raw = log_path.read_bytes()
            entries, complete = parse_log(raw, str(log_path))
            if complete < len(raw):
                with open(log_path, "r+b") as handle:
                    handle.truncate(complete)
            for item in entries:
                self.recorder.apply(item)
            lines = self.recorder.temperatures.lines
            atomic_write_text(folder / TEMPERATURES_NAME, "".join(x + "\n" for x in lines))
            self.log = SerialLog(log_path, create=False)
            self._record(entry("resume"))
        else:
            self.log = SerialLog(log_path, create=True)
        self.recorder.temperature_sink = self.sink
        self._record(entry("open", TEMPERATURE, settings.describe()))
        port = settings.open()
        self.reader = PortReader(TEMPERATURE, settings, port, self.items, self.stop_event)
        self.reader.start()
        self.thread = threading.Thread(target=self._drain, name="hexatherm-thermo", daemon=True)
        self.thread.start()

    def _record(self, item: LogEntry) -> None:
        self.log.append(item)
        self.recorder.apply(item)

    def _drain(self) -> None:
        while not (self.stop_event.is_set() and self.items.empty()):
            try:
                item = self.items.get(timeout=0.1)
            except queue.Empty:
                continue
            kind, source, when, data = item
            payload = data if isinstance(data, bytes) else str(data).encode("utf-8", "replace")
            self._record(LogEntry(when, kind, source, payload))

    def close(self) -> None:
        self.stop_event.set()
        self.reader.join(timeout=5.0)
        self.thread.join(timeout=5.0)
        self.log.close()
        self.sink.close()


# ------------------------------------------------------------------------ the run
@contextlib.contextmanager
def _session_lock(folder: Path) -> Iterator[None]:
    """An exclusive lock on the session folder (POSIX; released if the process dies)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    with open(folder / ".run.lock", "a") as handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise AcquisitionError(f"another hexatherm run is recording {folder}") from None
        yield


def run_campaign(
    files: SessionFiles,
    hexapod: Hexapod,
    options: RunOptions,
    notify: Notify,
    *,
    clock: Callable[[], float] = time.time,
    sleep: Callable[[float], None] = time.sleep,
) -> RunResult:
    """Run (or resume) a campaign into ``options.session`` (see the module docstring).

    Parameters
    ----------
    files : SessionFiles
        Plan, balls and the files' texts (copied into the session).
    hexapod : Hexapod
        The hexapod model (stroke validation, predictions).
    options : RunOptions
    notify : callable
        ``notify(level, message)``, level ``info``, ``warn`` or ``progress``.
    clock, sleep : callable
        POSIX seconds and sleeping (the logs' times, the waits, the gap check).

    Returns
    -------
    RunResult

    Raises
    ------
    IncompleteSession
        The run stopped before the end of the plan (an error needing the operator, a
        machine away); the hexapod was sent ``stop()``; ``--resume`` continues.
    PoseError
        A pose of the plan is refused (nothing moved).
    AcquisitionError
        The session folder is in the way, or there is nothing to resume.
    """
    folder = options.session
    transcript = folder / TRANSCRIPT_NAME
    if options.resume:
        if not transcript.is_file():
            raise AcquisitionError(f"nothing to resume: {transcript} does not exist")
    elif not transcript_is_new(transcript):
        raise AcquisitionError(
            f"{folder} already holds a run ({TRANSCRIPT_NAME}); continue it with --resume, "
            "or choose another --session"
        )
    elif folder.exists() and not folder.is_dir():
        raise AcquisitionError(f"{folder} exists and is not a folder")
    folder.mkdir(parents=True, exist_ok=True)
    with _session_lock(folder):
        if options.resume:
            check_same_files(files, folder)
            settings = read_run_settings(folder)
            if options.origin_on_cmm is not None and not np.allclose(
                options.origin_on_cmm, settings.origin_on_cmm
            ):
                notify("warn", "--origin-on-cmm differs from the session's run.yaml: kept that")
            state = rebuild_state(folder, files.plan, files.balls, notify)
        else:
            if options.origin_on_cmm is None:
                raise AcquisitionError("--origin-on-cmm is needed: nominal placement of O")
            settings = RunSettings(tuple(options.origin_on_cmm), options.probe)
            write_copies(folder, files)
            write_run_settings(folder, settings)
            atomic_write_text(folder / POINTS_NAME, POINTS_HEADER + "\n")
            atomic_write_text(folder / STEPS_NAME, step_header() + "\n")
            state = RunState({}, collections.Counter())
        campaign = _Campaign(files, hexapod, options, settings, state, notify, clock, sleep)
        return campaign.run()


class _Campaign:
    """The run's state and its machines (one instance per run or resume)."""

    def __init__(
        self,
        files: SessionFiles,
        hexapod: Hexapod,
        options: RunOptions,
        settings: RunSettings,
        state: RunState,
        notify: Notify,
        clock: Callable[[], float],
        sleep: Callable[[float], None],
    ) -> None:
        self.files, self.plan, self.balls = files, files.plan, files.balls
        self.hexapod, self.options, self.settings = hexapod, options, settings
        self.state, self.notify, self.clock, self.sleep = state, notify, clock, sleep
        self.folder = options.session
        self.geometry = _Geometry(hexapod, self.balls, self.plan.poses, settings.probe)
        self.nominal_origin2cmm = transform_from_pose(settings.origin_on_cmm, hexapod.convention)
        self.radius_mm = np.array(
            [
                probe_radius_mm(float(d), self.balls.tip_diameter_mm, self.balls.probe_compensated)
                for d in self.balls.diameters_mm
            ]
        )
        self.fits: dict[tuple[str, str], FloatArray] = {}
        for key, ball in state.accepted.items():
            self.fits[key] = self._fit_centre(ball.xyz_mm)
        self.results: list[BallResult] = []
        self.remeasured: list[str] = []
        self.cmm: IppClient | None = None
        self.controller: SocketController | None = None
        self.tlog: LineLog | None = None
        self.clog: LineLog | None = None

    # ------------------------------------------------------------------ state
    def _fit_centre(self, xyz: FloatArray) -> FloatArray:
        try:
            return np.asarray(fit_spheres(xyz).centre_mm[0], dtype=float)
        except FitError:
            return np.full(3, np.nan)

    def _done(self, i: int) -> bool:
        label = self.plan.labels[i]
        return all((label, b) in self.state.accepted for b in self.balls.names)

    def _next_step(self) -> int | None:
        return next((i for i in range(len(self.plan.labels)) if not self._done(i)), None)

    def origin2cmm(self) -> FloatArray:
        """The placement of frame O on the CMM: measured when O's balls are, else nominal."""
        origin = self.plan.origin_index
        label = self.plan.labels[origin]
        centres = [self.fits.get((label, b)) for b in self.balls.names]
        if any(c is None or not np.all(np.isfinite(c)) for c in centres):
            return self.nominal_origin2cmm
        frame = register(np.array(centres), self.balls.centres_mm).platform2cmm[0]
        return np.asarray(frame @ invert_transform(self.geometry.step2origin[origin]))

    def predicted(self, i: int, j: int) -> FloatArray:
        """Predicted centre of ball j at step i, shifted by the step's measured balls."""
        centres = self.geometry.centres(self.origin2cmm(), i)
        label = self.plan.labels[i]
        offsets = [
            self.fits[(label, b)] - centres[k]
            for k, b in enumerate(self.balls.names)
            if k != j and (label, b) in self.fits and np.all(np.isfinite(self.fits[(label, b)]))
        ]
        shift = np.mean(offsets, axis=0) if offsets else np.zeros(3)
        return np.asarray(centres[j] + shift)

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:
        options = self.options
        folder = self.folder
        self.tlog = LineLog(
            folder / TRANSCRIPT_NAME, TRANSCRIPT_MAGIC, self.clock, durable=options.durable
        )
        self.clog = LineLog(
            folder / CONTROLLER_LOG_NAME, CONTROLLER_LOG_MAGIC, self.clock, durable=options.durable
        )
        thermo: _Thermocouples | None = None
        completed = False
        try:
            if options.resume:
                self.tlog.note(f"resume with {len(self.state.accepted)} balls accepted")
                self.clog.note("resume")
            else:
                self.tlog.note("start")
                self.clog.note("start")
            if options.temperature_port is not None:
                port = options.temperature_port
                thermo = _Thermocouples(folder, port, self.files, options.resume)
            self._connect_controller()
            travel = _travel_z(self.geometry, self.origin2cmm())
            assert self.controller is not None
            _validate_plan(
                self.files,
                self.hexapod,
                self.controller,
                self.geometry,
                self.nominal_origin2cmm,
                options,
                travel,
            )
            self._connect_cmm()
            self._steps()
            completed = True
            self.tlog.note("end complete")
            self.clog.note("end complete")
        except KeyboardInterrupt:
            self._stop("interrupted (Ctrl-C)")
            raise
        except HexathermError as exc:
            self._stop(f"{type(exc).__name__}: {exc}")
            if isinstance(exc, PoseError) and not self.state.accepted and not options.resume:
                raise
            raise IncompleteSession(
                f"run stopped at {self._where()}: {exc}. The hexapod was sent STOP; "
                f"{self._n_points()} points in {folder}; continue with --resume"
            ) from exc
        except BaseException as exc:
            self._stop(f"{type(exc).__name__}: {exc}")
            raise
        finally:
            if thermo is not None:
                thermo.close()
            if self.cmm is not None:
                if completed:
                    with contextlib.suppress(HexathermError):
                        self.cmm.end_session()
                self.cmm.close()
            if self.controller is not None:
                self.controller.close()
            self.tlog.close()
            self.clog.close()
        session_file = finish_session(folder, self.notify, None)
        return RunResult(
            folder,
            self._n_points(),
            tuple(self.results),
            tuple(self.remeasured),
            session_file,
        )

    def _n_points(self) -> int:
        return sum(len(b.points) for b in self.state.accepted.values())

    def _where(self) -> str:
        i = self._next_step()
        if i is None:
            return "the end of the plan"
        label = self.plan.labels[i]
        missing = [b for b in self.balls.names if (label, b) not in self.state.accepted]
        return f"step {label} ({self.plan.kinds[i]}), ball {missing[0]}"

    def _stop(self, why: str) -> None:
        """Stop the hexapod (whatever happened) and say so in the logs."""
        with contextlib.suppress(Exception):
            if self.tlog is not None:
                self.tlog.note(f"stopped {why}")
        with contextlib.suppress(Exception):
            if self.clog is not None:
                self.clog.note(f"stopped {why}")
        controller = self.controller
        if controller is None:
            return
        try:
            controller.stop()
            self.notify("warn", f"hexapod stopped ({why})")
        except HexathermError as exc:
            self.notify("warn", f"could not stop the hexapod: {exc}")

    # ------------------------------------------------------------- machines
    def _controller_log(self, direction: str, line: str) -> None:
        assert self.clog is not None
        self.clog.entry(">" if direction == "tx" else "<", line)

    def _connect_controller(self) -> None:
        options = self.options
        controller = controller_from_url(
            options.controller_url,
            hexapod=self.hexapod,
            reply_timeout_s=options.reply_timeout_s,
            clock=self.clock,
            sleep=self.sleep,
            log=self._controller_log,
        )
        self.controller = controller
        assert self.clog is not None
        self.clog.note(f"connect {controller.url}")
        controller.connect()

    def _reconnect_controller(self, why: str) -> None:
        assert self.controller is not None and self.clog is not None
        self.notify("warn", f"controller connection lost ({why}); reconnecting")
        self.clog.note(f"reconnect after {why}")
        self.sleep(self.options.reconnect_wait_s)
        self.controller.connect()

    def _on_event(self, event: IppEvent) -> None:
        self.notify("warn", f"CMM event: {event.line}")

    def _connect_cmm(self) -> None:
        options = self.options
        host, port = parse_ipp_url(options.cmm_url)
        clock = self.clock
        self.cmm = IppClient(
            host,
            port,
            timeout_s=options.ipp_timeout_s,
            transcript=self.tlog,
            on_event=self._on_event,
            clock=lambda: iso_stamp(clock()),
        )
        cmm = self.cmm
        cmm.start_session()
        if not cmm.is_homed():
            self.notify("info", "homing the CMM")
            cmm.home()
        cmm.change_tool(self.settings.probe.tool)
        cmm.on_pt_meas_report("X", "Y", "Z", "IJK", "ER")
        radius = cmm.get_prop("Tool.AvrRadius")["Tool.AvrRadius"]
        tip = 0.5 * self.balls.tip_diameter_mm
        if radius and isinstance(radius[0], float) and abs(radius[0] - tip) > 1e-3:
            self.notify(
                "warn",
                f"the CMM's tool {self.settings.probe.tool} has a tip radius of {radius[0]:g} mm, "
                f"the balls file says {tip:g} mm",
            )

    def _reconnect_cmm(self, why: str) -> None:
        self.notify("warn", f"CMM connection lost ({why}); reconnecting")
        if self.cmm is not None:
            self.cmm.close()
            self.cmm = None
        self.sleep(self.options.reconnect_wait_s)
        self._connect_cmm()

    def _lift(self, z_mm: float) -> None:
        """Probe straight up to ``z_mm`` (if below)."""
        assert self.cmm is not None
        x, y, z = self.cmm.get_position()
        if z < z_mm:
            self.cmm.goto(x, y, z_mm)

    # ------------------------------------------------------------------ steps
    def _steps(self) -> None:
        while (i := self._next_step()) is not None:
            self._visit(i)

    def _gap_broken(self, i: int) -> float | None:
        """The time since the reference right before target i, if longer than allowed."""
        plan = self.plan
        r = i - 1
        if plan.kinds[i] != "target" or r < 0 or plan.kinds[r] != "reference" or not self._done(r):
            return None
        last = max(self.state.accepted[(plan.labels[r], b)].last_time_s for b in self.balls.names)
        gap = self.clock() - last
        return gap if gap > self.options.max_gap_s else None

    def _visit(self, i: int, again: bool = False) -> None:
        """Bring the hexapod to step i and probe its balls not accepted (all if ``again``)."""
        plan = self.plan
        label = plan.labels[i]
        travel = _travel_z(self.geometry, self.origin2cmm())
        self._cmm_call(lambda: self._lift(travel))
        self._move(i)
        gap = None if again else self._gap_broken(i)
        if gap is not None:
            r = i - 1
            self.notify(
                "warn",
                f"{plan.labels[r]} was measured {gap / 60:.1f} min before {label} (allowed "
                f"{self.options.max_gap_s / 60:.1f} min): measuring {plan.labels[r]} again",
            )
            assert self.tlog is not None
            self.tlog.note(f"remeasure {plan.labels[r]} for {label} gap {gap:.3f} s")
            self.remeasured.append(plan.labels[r])
            self._visit(r, again=True)
            self._cmm_call(lambda: self._lift(travel))
            self._move(i)
            again = True
        for j, name in enumerate(self.balls.names):
            if again or (label, name) not in self.state.accepted:
                self._measure_ball(i, j, travel)

    def _move(self, i: int) -> None:
        """Command step i's pose and wait in position; record the step."""
        assert self.controller is not None and self.clog is not None
        label, pose = self.plan.labels[i], self.plan.poses[i]
        self.clog.note(f"move {label}")
        tries = 0
        while True:
            try:
                self.controller.move_absolute(pose)
                record = self.controller.wait_in_position(self.options.criteria)
                break
            except ControllerConnectionError as exc:
                tries += 1
                if tries > self.options.reconnects:
                    raise
                self._reconnect_controller(str(exc))
            except PoseRefusedError as exc:
                raise ControllerError(f"step {label}: {exc}") from exc
        self.state.positionings[label] += 1
        n = self.state.positionings[label]
        row = step_row(label, self.plan.kinds[i], n, self.clock(), record)
        write_lines(self.folder / STEPS_NAME, [row], durable=self.options.durable)
        self.clog.note(f"in position {label}")
        self.notify(
            "info",
            f"step {i + 1}/{len(self.plan.labels)} {label} ({self.plan.kinds[i]}) in position at "
            f"{format_pose(record.pose_mm_deg)}",
        )

    def _cmm_call(self, action: Callable[[], Any]) -> Any:
        tries = 0
        while True:
            try:
                return action()
            except (IppConnectionLost, IppTimeout) as exc:
                tries += 1
                if tries > self.options.reconnects:
                    raise
                self._reconnect_cmm(str(exc))

    def _measure_ball(self, i: int, j: int, travel: float) -> None:
        label, name = self.plan.labels[i], self.balls.names[j]
        assert self.tlog is not None
        predicted = self.predicted(i, j)
        centre = predicted
        attempt, losses = 1, 0
        probe = self.settings.probe
        while True:
            self.tlog.note(f"begin {label} {name} attempt {attempt}")
            touch = cap_touch_plan(
                centre,
                float(self.balls.diameters_mm[j]),
                self.balls.tip_diameter_mm or 1e-3,
                self.plan.points_per_ball,
                probe.cap_angle_deg,
                approach_mm=probe.approach_mm,
                clearance_mm=probe.clearance_mm,
            )
            try:
                assert self.cmm is not None
                self._lift(travel)
                self.cmm.goto(touch.safe_mm[0], touch.safe_mm[1], travel)
                measured = probe_cap(self.cmm, touch)
            except (IppConnectionLost, IppTimeout) as exc:
                self.tlog.note(f"abandon {label} {name} {type(exc).__name__}")
                losses += 1
                if losses > self.options.reconnects:
                    raise
                self._reconnect_cmm(str(exc))
                continue
            except IppDmeError:
                self.tlog.note(f"abandon {label} {name} error")
                raise
            result = self._check(label, name, measured.points_mm, centre, attempt)
            if result.problems and attempt == 1:
                self.tlog.note(f"reject {label} {name} {'; '.join(result.problems)}")
                self.notify(
                    "warn", f"{label} {name}: {'; '.join(result.problems)}: probing it again"
                )
                if np.all(np.isfinite(result.centre_mm)) and (
                    np.linalg.norm(result.centre_mm - centre) < 2 * probe.approach_mm
                ):
                    centre = result.centre_mm
                attempt += 1
                continue
            self._accept(i, j, measured.probed, result)
            return

    def _check(
        self, label: str, name: str, xyz: FloatArray, predicted: FloatArray, attempt: int
    ) -> BallResult:
        checks = self.options.checks
        j = self.balls.names.index(name)
        problems: list[str] = []
        centre = np.full(3, np.nan)
        radius = form = rms = math.nan
        try:
            fit = fit_spheres(xyz)
        except FitError as exc:
            problems.append(f"sphere fit failed: {exc}")
        else:
            centre = np.asarray(fit.centre_mm[0], dtype=float)
            radius, form, rms = (
                float(fit.radius_mm[0]),
                float(fit.form_um[0]),
                float(fit.rms_um[0]),
            )
            dev = 1e3 * (radius - self.radius_mm[j])
            if abs(dev) > checks.radius_tol_um:
                limit = checks.radius_tol_um
                problems.append(f"radius {dev:+.1f} um off nominal (limit {limit:g})")
            if form > checks.form_um:
                problems.append(f"form {form:.1f} um (limit {checks.form_um:g})")
            if rms > checks.rms_um:
                problems.append(f"RMS {rms:.2f} um (limit {checks.rms_um:g})")
            miss = float(np.linalg.norm(centre - predicted))
            if miss > checks.centre_tol_mm:
                problems.append(
                    f"centre {miss:.3f} mm from the prediction (limit {checks.centre_tol_mm:g})"
                )
        return BallResult(
            label, name, len(xyz), centre, radius, form, rms, predicted, attempt, tuple(problems)
        )

    def _accept(self, i: int, j: int, probed: Sequence[ProbedPoint], result: BallResult) -> None:
        assert self.tlog is not None
        label, name = result.label, result.ball
        stamp = self.tlog.note(f"accept {label} {name}")
        key = (label, name)
        replaced = key in self.state.accepted
        self.state.accepted.pop(key, None)
        self.state.accepted[key] = AcceptedBall(label, name, tuple(probed), stamp)
        self.fits[key] = result.centre_mm
        self.results.append(result)
        slot = i * len(self.balls.names) + j
        later = any(
            self.plan.labels.index(k[0]) * len(self.balls.names) + self.balls.names.index(k[1])
            > slot
            for k in self.state.accepted
        )
        path = self.folder / POINTS_NAME
        if replaced or later:
            lines = points_lines(self.plan, self.balls, self.state.accepted)
            atomic_write_text(path, "".join(x + "\n" for x in lines))
        else:
            write_lines(
                path, [point_line(label, name, p) for p in probed], durable=self.options.durable
            )
        if result.problems:
            self.notify(
                "warn",
                f"{label} {name}: kept after probing it again, still {'; '.join(result.problems)}",
            )
        self.notify(
            "progress",
            f"{label} {name}: {result.n} points, centre "
            f"{', '.join(f'{v:.4f}' for v in result.centre_mm)} mm, radius {result.radius_mm:.4f} "
            f"mm, form {result.form_um:.2f} um",
        )
