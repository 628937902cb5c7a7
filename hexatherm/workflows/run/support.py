"""The run's helpers: predicted balls, touch plans, the dry run, the thermocouples."""

from __future__ import annotations

import contextlib
import math
import queue
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.core.frames import hexapod_in_origin
from hexatherm.core.geometry import apply_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import SocketController
from hexatherm.devices.ipp import (
    IppClient,
    ProbedPoint,
    cap_touch_plan,
    parse_ipp_url,
)
from hexatherm.devices.probestream import LineSplitter, format_number, parse_numbers
from hexatherm.devices.serialport import PortReader, PortSettings
from hexatherm.devices.urls import controller_from_url
from hexatherm.errors import (
    AcquisitionError,
    HexathermError,
    IppProtocolError,
    PoseError,
    PoseRefusedError,
)
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.records import seconds_to_iso
from hexatherm.io.seriallog import (
    LOG_NAME,
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
)
from hexatherm.workflows.acquire.recorder import Recorder as StreamRecorder
from hexatherm.workflows.run.cmmfacts import check_tool
from hexatherm.workflows.run.options import Notify, RunOptions
from hexatherm.workflows.run.resume import (
    ProbeSettings,
)

# ----------------------------------------------------------------------- helpers
#: the largest coordinate a CMM can answer, mm (100 m: no CMM's travel comes near it)
LARGEST_CMM_MM = 1e5


def check_cmm_coordinates(what: str, xyz_mm: tuple[float, ...] | FloatArray) -> None:
    """Refuse a CMM's answer whose coordinates are not finite or beyond :data:`LARGEST_CMM_MM`.

    ``what`` names the command and its tag (``PtMeas 00012``). Such numbers are no
    measurement (``X(1e308)`` would overflow the sphere fit): one line naming the command
    and the answer, never a fit of them.

    >>> check_cmm_coordinates("Get 00003", (1.5, 2.0, 3.0))
    >>> check_cmm_coordinates("PtMeas 00012", (1e308, 2.0, 3.0))
    Traceback (most recent call last):
    hexatherm.errors.IppProtocolError: the CMM answered PtMeas 00012 with X(1e+308), Y(2.0), \
Z(3.0): not a finite coordinate within 100000 mm (no CMM reaches it)
    """
    values = [float(v) for v in xyz_mm]
    if all(math.isfinite(v) and abs(v) <= LARGEST_CMM_MM for v in values):
        return
    answer = ", ".join(f"{a}({format_number(v)})" for a, v in zip("XYZ", values, strict=False))
    raise IppProtocolError(
        f"the CMM answered {what} with {answer}: not a finite coordinate within "
        f"{LARGEST_CMM_MM:g} mm (no CMM reaches it)"
    )


def check_probed(points: list[ProbedPoint] | tuple[ProbedPoint, ...]) -> None:
    """:func:`check_cmm_coordinates` for every point of a ball's ``PtMeas`` answers."""
    for p in points:
        check_cmm_coordinates(f"PtMeas {p.tag}", p.point_mm)


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

    def use_frames(self, values_mm_deg: FloatArray | None) -> None:
        """Predict with the controller's frames (12 values, mm and deg, Symétrie
        convention; None: none): the platform at each step relative to frame O is then
        ``O0 X O0^-1`` for the commanded ``X`` (:func:`~hexatherm.core.frames.
        hexapod_in_origin`), not ``X``."""
        values = np.zeros(12) if values_mm_deg is None else values_mm_deg
        poses = hexapod_in_origin(self.hexapod, values, self.poses)[1]
        self.step2origin = transform_from_pose(poses, self.hexapod.convention)

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
    transcript: Callable[[str], None] | None = None,
) -> int:
    """Check the whole plan against both machines' limits without moving either.

    Every pose goes through the controller's validation (the hexapod model's stroke, then
    the controller's own check), every probe position of every step (touch points,
    clearance and travel positions around the nominal prediction) through the CMM's travel
    box when one is given; the CMM is asked whether it knows the tool; the controller's
    state is checked as before a move (PI: servo, referencing, ready, coordinate system).
    Nothing moves, and nothing is written into the session folder; ``transcript`` gets
    every line of the I++ conversation (the caller keeps it where the user asked).

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
        controller.check_ready()
        geometry.use_frames(controller.frames_mm_deg)
        if controller.readiness:
            notify(
                "info",
                "controller: "
                + ", ".join(f"{key} {value}" for key, value in controller.readiness.items()),
            )
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
    # a dry run leaves nothing in the session folder: its transcript goes to the caller
    with IppClient(
        host,
        port,
        timeout_s=options.ipp_timeout_s,
        transcript=transcript,
        on_warning=lambda r, w: notify("warn", f"CMM warning on {r.tag} {r.command}: {w}"),
    ) as cmm:
        if cmm.start_session():
            notify("warn", "the CMM still had a session open (a connection gone): ended it")
        try:
            check_tool(cmm, options.probe.tool)
        finally:
            with contextlib.suppress(HexathermError):
                cmm.end_session()
    if options.cmm_limits_mm is None:
        notify("warn", "no --cmm-limits: the probe positions were not checked against the CMM")
    notify("info", f"dry run: {len(files.plan.labels)} steps can be measured; nothing moved")
    return len(files.plan.labels)


# ------------------------------------------------------------------- temperatures
#: items (reads of the port) the queue between the port's reader and the log holds at most:
#: a full queue makes the reader wait (the port's own buffer holds the rest)
QUEUE_ITEMS = 1000
#: a batch of reads completing more lines than this is a flood: only its newest row is kept.
#: A batch is what arrived while the log was busy or its threads were not scheduled (a
#: loaded machine): lines of a logger at its pace (a 10 Hz one held up for 100 s, a serial
#: line at 9600 baud streaming for a minute) stay under it and are all logged; a logger
#: streaming as fast as a socket goes exceeds it in one read (64 KiB: over 1000 lines)
FLOOD_LINES = 1000
#: reads taken from the queue at once
BATCH_ITEMS = 256


def _newest_row(lines: list[bytes]) -> bytes:
    """The newest line that is a temperature row (six or more numbers), else the newest."""
    return next((x for x in reversed(lines) if parse_numbers(x, 6) is not None), lines[-1])


class _Thermocouples:
    """A thermocouple logger on a serial port: ``serial.log`` and ``temperatures.csv``.

    The lines are parsed by ``acquire``'s recorder (the same format); an existing log (a
    resume) is replayed to rebuild ``temperatures.csv`` and continued. Every entry is
    stamped with ``clock`` (the run's clock, which also stamps the transcript, hence the
    points: one time line). A lost port is reopened every ``reopen_interval_s`` (at least
    0.05 s) until it opens.

    A logger that sends faster than the log can be written (a flood, a logger misconfigured
    to stream) must not leave the log behind the run: the queue between the reader and the
    log is bounded (:data:`QUEUE_ITEMS`), the reads waiting are taken together, and a batch
    that completes more than :data:`FLOOD_LINES` lines keeps only its newest row: a ``skip``
    entry (how many lines were left out) then the newest line, in ``serial.log``, so that a
    replay rebuilds the same ``temperatures.csv``; said once (``notify``). So is a logger
    that sends rows with NaN (an open thermocouple), at its first such row.
    """

    def __init__(
        self,
        folder: Path,
        settings: PortSettings,
        files: SessionFiles,
        clock: Callable[[], float] = time.time,
        reopen_interval_s: float = 1.0,
        notify: Notify | None = None,
    ):
        self.folder, self.settings = folder, settings
        self.notify: Notify = notify if notify is not None else (lambda level, message: None)
        #: lines left out in floods; rows of NaN seen
        self.skipped_lines = 0
        self._said: set[str] = set()

        def stamp() -> str:
            return seconds_to_iso(clock())

        self.stamp = stamp
        self.items: queue.Queue[Any] = queue.Queue(maxsize=QUEUE_ITEMS)
        self.stop_event = threading.Event()
        log_path = folder / LOG_NAME
        self.sink = FileSink(folder / TEMPERATURES_NAME)
        self.recorder = StreamRecorder(
            files.plan,
            files.balls,
            points=MemorySink(),
            temperatures=MemorySink(),
            notify=self._recorder_said,
        )
        # a log there already (a resume, or a new run in a folder where an attempt stopped
        # before its first I++ command) is continued, never replaced: what it recorded stays
        if log_path.is_file():
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
            self._record(entry("resume", when=stamp()))
        else:
            self.log = SerialLog(log_path, create=True)
        self.recorder.temperature_sink = self.sink
        #: set once a temperature row of this connection is recorded (see :meth:`wait_first_row`)
        self.first_row = threading.Event()
        self._rows_before = len(self.recorder.temperatures.lines)
        self._record(entry("open", TEMPERATURE, settings.describe(), when=stamp()))
        try:
            port = settings.open()
        except AcquisitionError:
            self.log.append(entry("end", payload="interrupted", when=stamp()))
            self.log.close()
            self.sink.close()
            raise
        self.reader = PortReader(
            TEMPERATURE,
            settings,
            port,
            self.items,
            self.stop_event,
            reopen_interval_s=max(reopen_interval_s, 0.05),
            stamp=stamp,
        )
        self.reader.start()
        self.thread = threading.Thread(target=self._drain, name="hexatherm-thermo", daemon=True)
        self.thread.start()

    def _record(self, item: LogEntry) -> None:
        self.log.append(item)
        self.recorder.apply(item)

    def _recorder_said(self, level: str, message: str) -> None:
        """The recorder's words about the logger's lines: a row of NaN said at once (the
        first), the other skipped lines once."""
        if "temperature line skipped" in message and "nan" in message.lower():
            self._say_once("nan", f"the thermocouple logger sends NaN ({message})")
        elif "skipped" in message:
            self._say_once("skipped", message + " (said once)")

    def _say_once(self, key: str, message: str) -> None:
        if key not in self._said:
            self._said.add(key)
            self.notify("warn", message)

    def _drain(self) -> None:
        while not (self.stop_event.is_set() and self.items.empty()):
            try:
                batch = [self.items.get(timeout=0.1)]
            except queue.Empty:
                continue
            with contextlib.suppress(queue.Empty):
                while len(batch) < BATCH_ITEMS:
                    batch.append(self.items.get_nowait())
            start = 0
            for k in range(len(batch) + 1):  # runs of reads, each thinned, between the others
                if k == len(batch) or batch[k][0] != "rx":
                    self._record_reads(batch[start:k])
                    if k < len(batch):
                        kind, source, when, data = batch[k]
                        text = str(data).encode("utf-8", "replace")
                        self._record(LogEntry(when, kind, source, text))
                    start = k + 1
            if len(self.recorder.temperatures.lines) > self._rows_before:
                self.first_row.set()

    def _record_reads(self, reads: list[Any]) -> None:
        """Log and apply a run of reads; a flood's only by its newest row."""
        if not reads:
            return
        data = b"".join(item[3] for item in reads)
        splitter = LineSplitter()
        lines = splitter.feed(data)
        if len(lines) <= FLOOD_LINES:
            for kind, source, when, payload in reads:
                self._record(LogEntry(when, kind, source, payload))
            return
        when, source = reads[-1][2], reads[-1][1]
        self.skipped_lines += len(lines) - 1
        self._say_once(
            "flood",
            f"the thermocouple logger at {self.settings.url} sends faster than the log can be "
            f"written ({len(lines)} lines waiting): only the newest row of each read is kept "
            "(serial.log says how many lines each time)",
        )
        why = f"{len(lines) - 1} lines left out: the logger sends faster than they are logged"
        self._record(LogEntry(when, "skip", source, why.encode("ascii")))
        self._record(LogEntry(when, "rx", source, _newest_row(lines) + b"\n" + splitter.pending))

    def wait_first_row(self, timeout_s: float) -> bool:
        """Wait until the logger's first temperature row of this run is recorded (a data
        row, not the header), at most ``timeout_s`` seconds of real time. False when none
        came."""
        return self.first_row.wait(timeout_s)

    def close(self, outcome: str = "interrupted") -> None:
        """Stop reading, log what arrived until now and ``end`` with ``outcome``."""
        self.stop_event.set()
        self.reader.join(timeout=5.0)
        self.thread.join(timeout=5.0)
        try:
            self.log.append(entry("end", payload=outcome, when=self.stamp()))
        finally:
            self.log.close()
            self.sink.close()


def check_processable(folder: Path) -> None:
    """Read the recorded session as ``process`` reads it (its session file, every ball's
    points fitted, the thermocouple log and its span over the steps); a run never calls a
    session complete that ``process`` would refuse.

    Raises
    ------
    AcquisitionError
        Naming what ``process`` would say (everything recorded is kept).
    """
    from hexatherm.io.config import read_session
    from hexatherm.workflows.process.measured import read_measured

    try:
        read_measured(read_session(folder))
    except HexathermError as exc:
        raise AcquisitionError(
            f"every step was measured, but process would refuse {folder}: {exc}"
        ) from exc
