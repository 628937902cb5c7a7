"""The unattended campaign.

Walk the plan, move, wait in position, probe, fit, re-probe, re-measure late references, resume.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import stat
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.core.geometry import invert_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.registration import register
from hexatherm.core.spherefit import fit_spheres, probe_radius_mm
from hexatherm.devices.controller import SocketController, format_pose
from hexatherm.devices.ipp import (
    TRANSCRIPT_MAGIC,
    ErrorReport,
    IppClient,
    IppEvent,
    ProbedPoint,
    TransactionResult,
    cap_touch_plan,
    parse_ipp_url,
    probe_cap,
)
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
    Terminated,
)
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.manifest import MANIFEST_NAME
from hexatherm.io.recording import check_new_recording, check_resume, recording_manifest
from hexatherm.io.runrecord import read_recorded_frames
from hexatherm.io.seriallog import (
    LOG_NAME,
    POINTS_HEADER,
    TEMPERATURES_NAME,
)
from hexatherm.typing import FloatArray
from hexatherm.workflows.acquire.files import (
    SessionFiles,
    check_same_files,
    finish_session,
    write_copies,
)
from hexatherm.workflows.run.cmmfacts import changed_tool, dme_version, tip_radius
from hexatherm.workflows.run.files import (
    CONTROLLER_LOG_MAGIC,
    CONTROLLER_LOG_NAME,
    POINTS_NAME,
    RUN_NAME,
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
from hexatherm.workflows.run.options import BallResult, Notify, RunOptions, RunResult
from hexatherm.workflows.run.pace import Pace, clock_text, duration_text
from hexatherm.workflows.run.reconnect import reopen
from hexatherm.workflows.run.resume import (
    RunSettings,
    RunState,
    read_run_settings,
    rebuild_state,
    record_cmm_facts,
    record_controller,
    write_run_settings,
)
from hexatherm.workflows.run.support import (
    _Geometry,
    _Thermocouples,
    _travel_z,
    _validate_plan,
    check_cmm_coordinates,
    check_probed,
    check_processable,
)

# ------------------------------------------------------------------------ the run
#: starts the note an interrupted run adds to its KeyboardInterrupt: what became of the
#: hexapod (the command line prints it)
STOPPED_NOTE = "hexatherm run: "
#: seconds (of the run's clock) a run waits, after opening the thermocouple port, for the
#: logger's first temperature row before it moves anything (a logger samples every few
#: seconds; the line that arrives while the port opens is discarded by the port): the log
#: then covers frame O
FIRST_TEMPERATURE_WAIT_S = 120.0
NOT_MOVED = "nothing was moved (the hexapod controller was not contacted)"
#: every file a run writes in its session folder (its manifest lists only these)
RUN_FILES = (
    "plan.yaml",
    "hexapod.yaml",
    "balls.yaml",
    RUN_NAME,
    POINTS_NAME,
    STEPS_NAME,
    TRANSCRIPT_NAME,
    CONTROLLER_LOG_NAME,
    LOG_NAME,
    TEMPERATURES_NAME,
    "session.yaml",
    ".run.lock",
)


@contextlib.contextmanager
def _session_lock(folder: Path) -> Iterator[None]:
    """An exclusive lock on the session folder (POSIX; released if the process dies)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    path = folder / ".run.lock"
    flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    try:  # never blocks: a FIFO put there is refused, not waited on
        fd = os.open(path, flags, 0o644)
    except OSError as exc:
        raise AcquisitionError(f"cannot lock {path}: {exc.strerror}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise AcquisitionError(f"cannot lock {path}: not a regular file")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise AcquisitionError(f"another hexatherm run is recording {folder}") from None
        yield
    finally:
        os.close(fd)


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
        machine away); the hexapod was sent ``stop()``; the message says once what
        became of it; ``--resume`` continues.
    PoseError
        A pose of the plan is refused (nothing moved).
    AcquisitionError
        The session folder is in the way, or there is nothing to resume; or a new run
        reached no machine (the controller and the thermocouple port did not answer):
        what it created is removed again (:func:`_remove_created`) and the message says
        so. A KeyboardInterrupt gets a note (:data:`STOPPED_NOTE`) saying what became of
        the hexapod and of the session.
    """
    folder = options.session
    transcript = folder / TRANSCRIPT_NAME
    if os.path.lexists(transcript) and not stat.S_ISREG(os.lstat(transcript).st_mode):
        raise AcquisitionError(
            f"{transcript} is not a regular file (a FIFO, a device, a folder or a link): a "
            "run records into a file of its own; remove it or choose another --session"
        )
    if options.resume:
        if not transcript.is_file():
            raise AcquisitionError(f"nothing to resume: {transcript} does not exist")
        check_resume(folder, command="run")
    elif not transcript_is_new(transcript):
        raise AcquisitionError(
            f"{folder} already holds a run ({TRANSCRIPT_NAME}); continue it with --resume, "
            "or choose another --session"
        )
    else:
        check_new_recording(folder, command="run", inputs=files.paths)
    # what a new run creates, removed again when no machine answered
    created_dirs = [p for p in (folder, *folder.parents) if not os.path.lexists(p)]
    before = set() if created_dirs else set(os.listdir(folder))
    folder.mkdir(parents=True, exist_ok=True)
    campaigns: list[_Campaign] = []
    try:
        return _record(files, hexapod, options, notify, clock, sleep, campaigns)
    except BaseException as exc:
        campaign = campaigns[0] if campaigns else None
        kept = options.resume or (campaign is not None and campaign.reached)
        left = (
            f"everything measured is in {folder}; continue with --resume"
            if kept
            else _remove_created(folder, before, created_dirs)
        )
        if isinstance(exc, KeyboardInterrupt):
            said = campaign.stopped if campaign is not None and campaign.stopped else NOT_MOVED
            exc.add_note(f"{STOPPED_NOTE}{said}; {left}")
        elif isinstance(exc, IncompleteSession) and not kept:
            cause = exc.__cause__ or exc
            said = campaign.stopped if campaign is not None and campaign.stopped else NOT_MOVED
            raise AcquisitionError(
                f"run stopped before any machine answered: {cause}. "
                f"{said[0].upper()}{said[1:]}; {left}"
            ) from cause
        raise


def _remove_created(folder: Path, before: set[str], created_dirs: list[Path]) -> str:
    """Remove what a run that reached no machine created in ``folder`` (its own files that
    were not there ``before``, the folders it made, if then empty); say what was left."""
    for name in (*RUN_FILES, MANIFEST_NAME):
        if name not in before:
            with contextlib.suppress(FileNotFoundError, IsADirectoryError):
                (folder / name).unlink()
    for path in created_dirs:
        try:
            path.rmdir()
        except OSError:
            return f"nothing was recorded ({path} holds files this run did not write: kept)"
    if created_dirs:
        return f"nothing was recorded ({folder} was not created)"
    return f"nothing was recorded ({folder} left as it was)"


def _record(
    files: SessionFiles,
    hexapod: Hexapod,
    options: RunOptions,
    notify: Notify,
    clock: Callable[[], float],
    sleep: Callable[[float], None],
    campaigns: list[_Campaign],
) -> RunResult:
    """Record the run into its (existing) folder; the campaign goes into ``campaigns``."""
    folder = options.session
    with _session_lock(folder), recording_manifest(folder, "run", RUN_FILES):
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
        campaigns.append(campaign)
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
        self.pace = Pace(self.plan.points_per_ball)
        #: a machine answered (the controller connected, the thermocouple port opened)
        self.reached = False
        #: a move was commanded in this run (a STOP that cannot be delivered matters)
        self.commanded = False
        self.controller_connected = False
        #: what became of the hexapod when the run stopped (:meth:`_stop`)
        self.stopped = ""
        #: the CMM's event that changed its tool away from the run's (:meth:`_restore_tool`)
        self.tool_event: IppEvent | None = None
        #: the controller's frames were said (once, when not zero)
        self.frames_said = False

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
                thermo = _Thermocouples(
                    folder, port, self.files, self.clock, options.reconnect_wait_s, self.notify
                )
                self.reached = True
                if not self._wait_first_temperature(thermo):
                    self.notify(
                        "warn",
                        f"no temperature row from {port.describe()} within "
                        f"{FIRST_TEMPERATURE_WAIT_S:.0f} s of opening it: the run goes on, "
                        "and temperatures.csv will start after the first points",
                    )
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
        except KeyboardInterrupt as exc:  # Ctrl-C, or a terminating signal (Terminated)
            how = exc.name if isinstance(exc, Terminated) else "Ctrl-C"
            # said once, by the command line, with what became of the hexapod (a note)
            self._stop(f"interrupted ({how})", say=False)
            raise
        except HexathermError as exc:
            stopped = self._stop(f"{type(exc).__name__}: {exc}", say=False)
            if isinstance(exc, PoseError) and not self.state.accepted and not options.resume:
                raise
            raise IncompleteSession(
                f"run stopped at {self._where()}: {exc}. {stopped[0].upper()}{stopped[1:]}; "
                f"{self._n_points()} points in {folder}; continue with --resume"
            ) from exc
        except BaseException as exc:
            self._stop(f"{type(exc).__name__}: {exc}")
            raise
        finally:
            if thermo is not None:
                thermo.close("complete" if completed else "interrupted")
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
        check_processable(folder)
        return RunResult(
            folder,
            self._n_points(),
            tuple(self.results),
            tuple(self.remeasured),
            session_file,
            self._failed(),
        )

    def _failed(self) -> tuple[BallResult, ...]:
        """The accepted balls whose kept probing fails a check, in plan order."""
        last = {(r.label, r.ball): r for r in self.results}
        out = []
        for label in self.plan.labels:
            for name in self.balls.names:
                ball = self.state.accepted.get((label, name))
                if ball is None:
                    continue
                result = last.get((label, name))
                if result is None:  # accepted before a resume: checked again around its fit
                    result = self._check(label, name, ball.xyz_mm, self.fits[(label, name)], 0)
                if result.problems:
                    out.append(result)
        return tuple(out)

    def _n_points(self) -> int:
        return sum(len(b.points) for b in self.state.accepted.values())

    def _where(self) -> str:
        i = self._next_step()
        if i is None:
            return "the end of the plan"
        label = self.plan.labels[i]
        missing = [b for b in self.balls.names if (label, b) not in self.state.accepted]
        return f"step {label} ({self.plan.kinds[i]}), ball {missing[0]}"

    def _stop(self, why: str, say: bool = True) -> str:
        """Stop the hexapod (whatever happened) and say so in the logs.

        Returns what became of the hexapod, one phrase (also a warning with ``say``): sent
        STOP; not moved by this run (the controller not reached, or no move commanded,
        when STOP could not be delivered); or STOP not delivered after a move.
        """
        with contextlib.suppress(Exception):
            if self.tlog is not None:
                self.tlog.note(f"stopped {why}")
        with contextlib.suppress(Exception):
            if self.clog is not None:
                self.clog.note(f"stopped {why}")
        controller = self.controller
        if controller is None:
            said = NOT_MOVED
        else:
            try:
                controller.stop()
                said = "the hexapod was sent STOP"
            except HexathermError as exc:
                if self.commanded:  # the controller's own words: THE HEXAPOD MAY STILL BE MOVING
                    said = str(exc)
                elif not self.controller_connected:
                    said = f"nothing was moved (the controller at {controller.url} was not reached)"
                else:  # no move was commanded: the hexapod was never set moving by this run
                    said = "nothing was moved (no move had been commanded; STOP was not delivered)"
        self.stopped = said
        if say:
            with contextlib.suppress(OSError):  # SIGHUP: the terminal may be gone
                self.notify("warn", f"{said} ({why})")
        return said

    # ------------------------------------------------------------- machines
    def _controller_log(self, direction: str, line: str) -> None:
        assert self.clog is not None
        self.clog.entry(">" if direction == "tx" else "<", line)

    def _wait_first_temperature(self, thermo: _Thermocouples) -> bool:
        """Wait for the logger's first temperature row, up to
        :data:`FIRST_TEMPERATURE_WAIT_S` of the run's clock, in steps of one second of it
        (a rehearsal's clock moves only when the run sleeps, and its logger samples on
        that clock), each after a quarter second of real time for the row to arrive."""
        waited_s = 0.0
        while not thermo.wait_first_row(0.25):
            if waited_s >= FIRST_TEMPERATURE_WAIT_S:
                return False
            self.sleep(1.0)
            waited_s += 1.0
        return True

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
        self.reached = self.controller_connected = True
        self._check_controller()

    def _reconnect_controller(self, why: str, tries: int) -> int:
        """Reopen the controller's connection (:func:`.reconnect.reopen`); the tries used."""
        controller, clog = self.controller, self.clog
        assert controller is not None and clog is not None
        self.notify("warn", f"controller connection lost ({why}); reconnecting")
        clog.note(f"reconnect after {why}")

        def connect() -> None:
            controller.connect()
            self._check_controller()

        def failed(exc: Exception, wait_s: float) -> None:
            clog.note(f"reconnect failed {exc}")
            self.notify("warn", f"controller reconnection failed ({exc}); again in {wait_s:g} s")

        return reopen(
            connect,
            (ControllerConnectionError,),
            tries=tries,
            budget=self.options.reconnects,
            first_wait_s=self.options.reconnect_wait_s,
            sleep=self.sleep,
            failed=failed,
        )

    def _check_controller(self) -> None:
        """Servo, referencing, readiness, coordinate system (PI): checked before any move
        and recorded in run.yaml, whatever the outcome."""
        controller = self.controller
        assert controller is not None
        try:
            controller.check_ready()
        finally:
            record_controller(
                self.folder,
                iso_stamp(self.clock()),
                controller.url,
                controller.info,
                controller.readiness,
            )
        # the balls predicted through the frames the session's records give (one setting
        # for the whole session: read_recorded_frames refuses records that differ)
        frames = read_recorded_frames(self.folder).values
        self.geometry.use_frames(frames)
        if frames.any() and not self.frames_said:
            self.frames_said = True
            self.notify(
                "info",
                "controller frames (user, object; mm, deg): "
                + ", ".join(f"{v:.6g}" for v in frames)
                + ": the balls are predicted, and the stroke checked, where they put the "
                "platform",
            )

    def _on_event(self, event: IppEvent) -> None:
        """An event line (on the reader thread): said; a tool change is undone before the
        next probing (:meth:`_restore_tool`); one not understood is a warning (the open
        transaction's own lines stay strict, and the line is in the transcript)."""
        if event.problem is not None:
            line = event.line.encode("ascii", "backslashreplace").decode("ascii")
            problem = event.problem.encode("ascii", "backslashreplace").decode("ascii")
            self.notify(
                "warn", f"CMM event not understood ({problem}), kept in the transcript: {line}"
            )
            return
        tool = changed_tool(event)
        if tool is not None and tool != self.settings.probe.tool:
            self.tool_event = event  # said when it is undone
            return
        self.notify("warn", f"CMM event: {event.line}")

    def _restore_tool(self) -> None:
        """Change back to the run's tool if the CMM changed it (said once, in the transcript
        too)."""
        event = self.tool_event
        if event is None or self.cmm is None:
            return
        tool = self.settings.probe.tool
        self.cmm.change_tool(tool)
        self.tool_event = None
        assert self.tlog is not None
        self.tlog.note(f"tool changed back to {tool} after {event.time}")
        self.notify(
            "warn",
            f"the CMM changed its tool ({event.line}, at {event.time}): changed back to {tool}",
        )

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
            on_warning=self._on_warning,
        )
        cmm = self.cmm
        if cmm.start_session():
            self.notify("warn", "the CMM still had a session open (a connection gone): ended it")
        facts = dme_version(cmm, self.notify)
        if not cmm.is_homed():
            self.notify("info", "homing the CMM")
            cmm.home()
        cmm.change_tool(self.settings.probe.tool)
        self.tool_event = None
        cmm.on_pt_meas_report("X", "Y", "Z", "IJK", "ER")
        tool, tip = self.settings.probe.tool, self.balls.tip_diameter_mm
        tip_radius(cmm, facts, tool, tip, self.notify)
        record_cmm_facts(self.folder, facts)

    def _on_warning(self, result: TransactionResult, warning: ErrorReport) -> None:
        self.notify("warn", f"CMM warning on {result.tag} {result.command}: {warning}")

    def _reconnect_cmm(self, why: str, tries: int) -> int:
        """Reopen the CMM's connection (:func:`.reconnect.reopen`); the tries used."""
        self.notify("warn", f"CMM connection lost ({why}); reconnecting")

        def connect() -> None:
            if self.cmm is not None:
                self.cmm.close()
                self.cmm = None
            self._connect_cmm()

        def failed(exc: Exception, wait_s: float) -> None:
            self.notify("warn", f"CMM reconnection failed ({exc}); again in {wait_s:g} s")

        return reopen(
            connect,
            (IppConnectionLost, IppTimeout),
            tries=tries,
            budget=self.options.reconnects,
            first_wait_s=self.options.reconnect_wait_s,
            sleep=self.sleep,
            failed=failed,
        )

    def _lift(self, z_mm: float) -> None:
        """Probe straight up to ``z_mm`` (if below)."""
        assert self.cmm is not None
        x, y, z = self.cmm.get_position()
        check_cmm_coordinates("Get(X(), Y(), Z())", (x, y, z))
        if z < z_mm:
            self.cmm.goto(x, y, z_mm)

    # ------------------------------------------------------------------ steps
    def _steps(self) -> None:
        while (i := self._next_step()) is not None:
            self._visit(i)

    def _last_time_s(self, i: int) -> float:
        """Time of the last point of step i (every ball accepted), s."""
        label = self.plan.labels[i]
        return max(self.state.accepted[(label, b)].last_time_s for b in self.balls.names)

    def _stale_neighbour(self, i: int) -> tuple[int, float] | None:
        """The step to measure again before step i, and the gap that calls for it, if any.

        - Step i a target: the reference right before it, measured longer than
          ``max_gap_s`` ago (a delay between them).
        - Step i a reference: the target right before it (whose after-reference step i is),
          measured longer than ``max_gap_s`` ago (a delay after the target, a resume the
          next morning): the target is measured again (its own reference before it too,
          by the rule above), then step i, so the target has fresh references both sides.
        """
        plan = self.plan
        r = i - 1
        if r < 0 or not self._done(r):
            return None
        pairs = (("target", "reference"), ("reference", "target"))
        if (plan.kinds[i], plan.kinds[r]) not in pairs:
            return None
        gap = self.clock() - self._last_time_s(r)
        return (r, gap) if gap > self.options.max_gap_s else None

    def _visit(self, i: int, again: bool = False, check: bool = True) -> None:
        """Bring the hexapod to step i and probe its balls not accepted (all if ``again``).

        With ``check``, a neighbour that a delay made stale (:meth:`_stale_neighbour`) is
        measured again first (before the move when the delay is already there, else once
        in position), and then every ball of step i. A reference measured again for a
        target checks nothing further (no cascade back through the plan).
        """
        plan = self.plan
        label = plan.labels[i]
        travel = _travel_z(self.geometry, self.origin2cmm())
        stale = self._stale_neighbour(i) if check else None
        if stale is None:
            self._cmm_call(lambda: self._lift(travel))
            self._move(i)
            stale = self._stale_neighbour(i) if check else None
        if stale is not None:
            r, gap = stale
            before, after = plan.labels[r], label
            self.notify(
                "warn",
                f"{before} was measured {gap / 60:.1f} min before {after} (allowed "
                f"{self.options.max_gap_s / 60:.1f} min): measuring {before} again",
            )
            assert self.tlog is not None
            self.tlog.note(f"remeasure {before} for {after} gap {gap:.3f} s")
            self.remeasured.append(before)
            # a target measured again checks its own reference before it; a reference
            # measured again for a target does not look further back
            self._visit(r, again=True, check=plan.kinds[r] == "target")
            travel = _travel_z(self.geometry, self.origin2cmm())
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
        self.pace.move_started(self.clock())
        self.clog.note(f"move {label}")
        tries = 0
        while True:
            try:
                self.commanded = True
                self.controller.move_absolute(pose)
                record = self.controller.wait_in_position(self.options.criteria)
                break
            except ControllerConnectionError as exc:
                tries += 1
                if tries > self.options.reconnects:
                    raise
                tries = self._reconnect_controller(str(exc), tries)
            except PoseRefusedError as exc:
                raise ControllerError(f"step {label}: {exc}") from exc
        self.state.positionings[label] += 1
        n = self.state.positionings[label]
        now = self.clock()
        row = step_row(label, self.plan.kinds[i], n, now, record)
        write_lines(self.folder / STEPS_NAME, [row], durable=self.options.durable)
        self.clog.note(f"in position {label}")
        self.pace.moved()
        labels, names = self.plan.labels, self.balls.names
        eta = self.pace.eta_s(
            now,
            moves_left=sum(not self._done(k) for k in range(i + 1, len(labels))),
            balls_left=sum(
                (labels[k], b) not in self.state.accepted
                for k in range(i, len(labels))
                for b in names
            ),
        )
        self.notify(
            "info",
            f"step {i + 1}/{len(labels)} {label} ({self.plan.kinds[i]}) in position at "
            f"{clock_text(now)}: {format_pose(record.pose_mm_deg)}; ETA {clock_text(eta)} "
            f"({duration_text(eta - now)} left)",
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
                tries = self._reconnect_cmm(str(exc), tries)

    def _measure_ball(self, i: int, j: int, travel: float) -> None:
        label, name = self.plan.labels[i], self.balls.names[j]
        assert self.tlog is not None
        predicted = self.predicted(i, j)
        centre = predicted
        attempt, losses, tool_changes = 1, 0, 0
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
                self._restore_tool()
                self._lift(travel)
                self.cmm.goto(touch.safe_mm[0], touch.safe_mm[1], travel)
                measured = probe_cap(self.cmm, touch)
            except (IppConnectionLost, IppTimeout) as exc:
                self.tlog.note(f"abandon {label} {name} {type(exc).__name__}")
                losses += 1
                if losses > self.options.reconnects:
                    raise
                losses = self._reconnect_cmm(str(exc), losses)
                continue
            except IppDmeError:
                self.tlog.note(f"abandon {label} {name} error")
                raise
            if self.tool_event is not None:  # the CMM changed its tool while probing
                self.tlog.note(f"abandon {label} {name} tool changed")
                tool_changes += 1
                if tool_changes > 1:
                    raise IppDmeError(
                        f"the CMM changed its tool again while {label} {name} was probed "
                        f"({self.tool_event.line}): the run does not probe with a tool it "
                        "did not choose"
                    )
                continue
            try:
                check_probed(measured.probed)
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
        self.pace.probed()
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
