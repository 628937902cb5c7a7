"""Live acquisition of a session: serial probe stream in, session folder out.

The acquisition walks the plan step by step and ball by ball (plan order, then
balls-file order) and gives every point the probe sends to a step and ball: once O
is measured, the ball whose surface at its commanded pose the point lies on (the
current ball or the next; others are rejected), before that by count and distance
(see :mod:`hexatherm.workflows.acquire.recorder`). These files make it crash-safe:

``serial.log``
    Every byte received, with the time it arrived, and every event that changes
    how the bytes are assigned (a port lost or reopened, a resume, an operator's
    ``next``/``redo``, the mode and the unit). One line per entry,
    ``<time> <kind> <source> "<payload>"``, the payload's bytes escaped
    (``\\r``, ``\\n``, ``\\t``, ``\\\\``, ``\\"``, ``\\xNN``) so the file is
    ASCII text. It is written, flushed and fsync'd *before* the entry is acted
    on: it is the primary record.
``points.csv``
    Every accepted point (points CSV contract, ``label,ball,x,y,z,time``, ISO
    8601 UTC times), appended, flushed and fsync'd as it arrives. A point's time
    is the time the bytes that completed its line arrived (as logged).
``temperatures.csv``
    The lines of a thermocouple logger on a second port, when there is one.
``rejected.csv``
    The points not assigned (``label,ball,x,y,z,time,status,reason``): ``rejected``
    (on no expected ball, an extra point, a ball out of turn) or ``set-aside`` (the
    interrupted ball's points on ``--resume``); written only when there is one.

:class:`Recorder` is the state machine that turns log entries into points: the
live loop and the replay of a log feed it the same entries, so a replay gives
the same ``points.csv`` byte for byte. ``--resume`` replays the session's own log
to rebuild the state (nothing lost, nothing doubled, even if the process died
between logging bytes and writing their points), sets the interrupted ball's points
aside (a ``note`` entry in the log says which), tells the operator what to probe and
continues at the first incomplete ball.
"""

from __future__ import annotations

import contextlib
import os
import queue
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hexatherm.devices import PointSource
from hexatherm.devices.serialport import PortReader, PortSettings
from hexatherm.errors import (
    AcquisitionError,
    IncompleteSession,
    InputError,
)
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.recording import check_new_recording, check_resume, recording_manifest
from hexatherm.io.seriallog import (
    LOG_NAME,
    POINTS_HEADER,
    POINTS_NAME,
    PROBE,
    REJECTED_NAME,
    TEMPERATURE,
    TEMPERATURES_NAME,
    FileSink,
    LogEntry,
    MemorySink,
    SerialLog,
    entry,
    now_iso,
    parse_log,
)
from hexatherm.workflows.acquire.files import (
    SessionFiles,
    check_same_files,
    finish_session,
    load_files,
    session_lock,
    write_copies,
)
from hexatherm.workflows.acquire.recorder import BallFit, FitChecks, Notify, Recorder, quiet

#: every file acquire writes in its session folder (its manifest lists only these)
ACQUIRE_FILES = (
    "plan.yaml",
    "hexapod.yaml",
    "balls.yaml",
    LOG_NAME,
    POINTS_NAME,
    TEMPERATURES_NAME,
    REJECTED_NAME,
    "session.yaml",
    ".acquire.lock",
)


class InputReader(threading.Thread):
    """Reads the operator's commands, one per line, into the queue (interactive mode)."""

    def __init__(self, lines: Iterable[str], out: queue.Queue[Any]) -> None:
        super().__init__(name="hexatherm-input", daemon=True)
        self.lines = lines
        self.out = out

    def run(self) -> None:
        for line in self.lines:
            self.out.put(("input", now_iso(), line))
        self.out.put(("input-eof", now_iso(), ""))


def operator_command(line: str) -> str | None:
    """The event an operator's line means (None: not a command).

    >>> [operator_command(x) for x in ["", "n", "redo", " Q ", "hello"]]
    ['next', 'next', 'redo', 'quit', None]
    """
    word = line.strip().lower()
    table = {
        "": "next",
        "n": "next",
        "next": "next",
        "r": "redo",
        "redo": "redo",
        "q": "quit",
        "quit": "quit",
    }
    return table.get(word)


# ---------------------------------------------------------------------- live run
@dataclass(frozen=True)
class AcquireOptions:
    """Options of a live acquisition (see ``hexatherm acquire --help``)."""

    session: Path
    probe: PortSettings
    temperature_port: PortSettings | None = None
    temperatures_file: Path | None = None
    auto: bool = False
    resume: bool = False
    unit: str = "mm"
    idle_timeout_s: float | None = None
    reopen_interval_s: float = 1.0
    checks: FitChecks = field(default_factory=FitChecks)
    max_gap_s: float = 600.0


@dataclass(frozen=True)
class AcquireResult:
    """What an acquisition (or a replay) produced."""

    session: Path
    complete: bool
    n_points: int
    fits: tuple[BallFit, ...]
    session_file: Path | None


def _reconcile(sink_path: Path, lines: list[str], notify: Notify, what: str) -> None:
    """Make ``sink_path`` hold exactly ``lines`` (rebuilt from the log)."""
    expected = "".join(line + "\n" for line in lines)
    current = sink_path.read_text(encoding="utf-8") if sink_path.is_file() else ""
    if current == expected:
        return
    if expected.startswith(current):
        missing = expected.count("\n") - current.count("\n")
        notify(
            "info",
            f"{what}: {missing} line(s) received before the interruption restored from serial.log",
        )
        with open(sink_path, "a", encoding="utf-8", newline="") as handle:
            handle.write(expected[len(current) :])
            handle.flush()
            os.fsync(handle.fileno())
        return
    if not lines:
        return
    notify(
        "warn",
        f"{sink_path} did not match serial.log (edited, or a redo was "
        "interrupted); rewritten from serial.log",
    )
    atomic_write_text(sink_path, expected)


def acquire(
    files: SessionFiles,
    options: AcquireOptions,
    notify: Notify,
    operator_lines: Iterable[str] | None = None,
) -> AcquireResult:
    """Run a live acquisition into ``options.session`` (see the module docstring).

    Parameters
    ----------
    files : SessionFiles
        Plan, hexapod and balls.
    options : AcquireOptions
    notify : callable
        ``notify(level, message)`` for the operator.
    operator_lines : iterable of str, optional
        The operator's commands (standard input) in interactive mode.

    Returns
    -------
    AcquireResult

    Raises
    ------
    IncompleteSession
        When the acquisition stops before the end of the plan (idle timeout,
        the operator's ``quit``, end of the operator's input).
    AcquisitionError
        When a port does not open or the session folder is in the way.
    """
    folder = options.session
    log_path = folder / LOG_NAME
    if options.resume:
        if not log_path.is_file():
            raise AcquisitionError(f"nothing to resume: {log_path} does not exist")
        check_resume(folder, command="acquire")
    elif log_path.exists():
        raise AcquisitionError(
            f"{folder} already holds a recording ({LOG_NAME}); continue it "
            "with --resume, or choose another --session"
        )
    else:
        inputs = [*files.paths, *([options.temperatures_file] if options.temperatures_file else [])]
        check_new_recording(folder, command="acquire", inputs=inputs)
    if options.temperature_port is not None and options.temperatures_file is not None:
        raise AcquisitionError("give --temperatures or --temperature-port, not both")

    probe_port = options.probe.open()
    temperature_port = None
    try:
        if options.temperature_port is not None:
            temperature_port = options.temperature_port.open()
        folder.mkdir(parents=True, exist_ok=True)
        with session_lock(folder), recording_manifest(folder, "acquire", ACQUIRE_FILES):
            return _run(files, options, notify, operator_lines, probe_port, temperature_port)
    finally:
        for port in (probe_port, temperature_port):
            if port is not None:
                with contextlib.suppress(Exception):
                    port.close()


def _run(
    files: SessionFiles,
    options: AcquireOptions,
    notify: Notify,
    operator_lines: Iterable[str] | None,
    probe_port: Any,
    temperature_port: Any,
) -> AcquireResult:
    folder = options.session
    log_path = folder / LOG_NAME
    points_sink, temperature_sink, rejected_sink = (
        FileSink(folder / POINTS_NAME),
        FileSink(folder / TEMPERATURES_NAME),
        FileSink(folder / REJECTED_NAME),
    )
    recorder = Recorder(
        files.plan,
        files.balls,
        points=MemorySink(),
        temperatures=MemorySink(),
        rejected=MemorySink(),
        notify=quiet,
        checks=options.checks,
        max_gap_s=options.max_gap_s,
        convention=files.convention,
    )
    if options.resume:
        check_same_files(files, folder)
        raw = log_path.read_bytes()
        entries, complete = parse_log(raw, os.fspath(log_path))
        if complete < len(raw):
            notify(
                "warn",
                f"{LOG_NAME}: an unfinished last line ({len(raw) - complete} bytes) "
                "of the interrupted run dropped",
            )
            os.truncate(log_path, complete)
        for item in entries:
            recorder.apply(item)
        _reconcile(folder / POINTS_NAME, recorder.point_lines, notify, POINTS_NAME)
        _reconcile(
            folder / TEMPERATURES_NAME, recorder.temperatures.lines, notify, TEMPERATURES_NAME
        )
        _reconcile(folder / REJECTED_NAME, recorder.rejected_lines, notify, REJECTED_NAME)
        notify("info", f"resuming: {recorder.n_points} points recorded, at {recorder.where()}")
        log = SerialLog(log_path, create=False)
    else:
        write_copies(folder, files)
        log = SerialLog(log_path, create=True)
        points_sink.rewrite([POINTS_HEADER])
    recorder.points_sink, recorder.temperature_sink = points_sink, temperature_sink
    recorder.rejected_sink = rejected_sink
    recorder.stopped = False

    def record(item: LogEntry) -> None:
        log.append(item)
        recorder.apply(item)

    stop = threading.Event()
    items: queue.Queue[Any] = queue.Queue()
    readers: list[PointSource] = [
        PortReader(PROBE, options.probe, probe_port, items, stop, options.reopen_interval_s)
    ]
    if temperature_port is not None:
        assert options.temperature_port is not None
        readers.append(
            PortReader(
                TEMPERATURE,
                options.temperature_port,
                temperature_port,
                items,
                stop,
                options.reopen_interval_s,
            )
        )
    outcome = "complete"
    recorder.notify = notify
    try:
        if options.resume:
            record(entry("resume"))
            if recorder.last_set_aside:  # marked in the log for its readers
                log.append(entry("note", "-", recorder.last_set_aside))
        record(entry("config", "-", f"units={options.unit}"))
        record(entry("mode", "-", "auto" if options.auto else "interactive"))
        record(entry("open", PROBE, options.probe.describe()))
        if options.temperature_port is not None:
            record(entry("open", TEMPERATURE, options.temperature_port.describe()))
        recorder.announce()
        for reader in readers:
            reader.start()
        if not options.auto and operator_lines is not None:
            InputReader(operator_lines, items).start()
        outcome = _loop(recorder, record, items, options, notify)
    finally:
        stop.set()
        for reader in readers:
            reader.join(timeout=5.0)
        with contextlib.suppress(Exception):
            log.append(
                entry(
                    "end", "-", outcome if recorder.done or outcome != "complete" else "interrupted"
                )
            )
        log.close()
        points_sink.close()
        temperature_sink.close()
        rejected_sink.close()
    fits = tuple(recorder.fits[k] for k in sorted(recorder.fits))
    if not recorder.done:
        raise IncompleteSession(
            f"acquisition stopped ({outcome}) at {recorder.where()}: "
            f"{recorder.n_points} points recorded in {folder}; continue "
            "with --resume"
        )
    session_file = finish_session(folder, notify, options.temperatures_file)
    return AcquireResult(folder, True, recorder.n_points, fits, session_file)


def _loop(
    recorder: Recorder,
    record: Callable[[LogEntry], None],
    items: queue.Queue[Any],
    options: AcquireOptions,
    notify: Notify,
) -> str:
    """Log and apply the queue's items until the plan is done or the run stops."""
    last_data = time.monotonic()
    while not recorder.done:
        if recorder.stopped:
            return "quit"
        try:
            item = items.get(timeout=0.1)
        except queue.Empty:
            if (
                options.idle_timeout_s is not None
                and time.monotonic() - last_data > options.idle_timeout_s
            ):
                notify("warn", f"no data from the probe for {options.idle_timeout_s:g} s")
                return "idle"
            continue
        kind = item[0]
        if kind == "rx":
            _, source, when, data = item
            if source == PROBE:
                last_data = time.monotonic()
            record(LogEntry(when, "rx", source, data))
        elif kind in ("lost", "reopen"):
            _, source, when, text = item
            last_data = time.monotonic()
            record(LogEntry(when, kind, source, text.encode("utf-8", "replace")))
        elif kind == "input":
            _, when, line = item
            event = operator_command(line)
            if event is None:
                notify("warn", f"unknown command {line.strip()!r}: Enter or 'next', 'redo', 'quit'")
                continue
            record(LogEntry(when, "event", "operator", event.encode()))
        elif kind == "input-eof":
            notify("warn", "end of the operator's input")
            return "input closed"
    return "complete"


# ------------------------------------------------------------------------- replay
def session_from_log(
    files: SessionFiles,
    log_file: Path,
    session: Path,
    notify: Notify,
    temperatures_file: Path | None = None,
) -> AcquireResult:
    """Re-run the parser and the assignment on a recorded ``serial.log``.

    Writes a new session folder ``session`` with the configuration copies, a
    copy of the log's complete lines, ``points.csv`` (the same bytes as the
    recording's) and, when the recording covers the whole plan, ``session.yaml``.
    """
    log_file = Path(log_file)
    try:
        raw = log_file.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=os.fspath(log_file)) from None
    entries, complete = parse_log(raw, os.fspath(log_file))
    if session.exists() and (not session.is_dir() or any(session.iterdir())):
        raise AcquisitionError(f"{session} exists and is not empty; replay into a new folder")
    session.mkdir(parents=True, exist_ok=True)
    write_copies(session, files)
    with open(session / LOG_NAME, "xb") as handle:
        handle.write(raw[:complete])
    points_sink = FileSink(session / POINTS_NAME)
    temperature_sink = FileSink(session / TEMPERATURES_NAME)
    rejected_sink = FileSink(session / REJECTED_NAME)
    points_sink.rewrite([POINTS_HEADER])
    recorder = Recorder(
        files.plan,
        files.balls,
        points=points_sink,
        temperatures=temperature_sink,
        rejected=rejected_sink,
        notify=notify,
        convention=files.convention,
    )
    try:
        for item in entries:
            recorder.apply(item)
    finally:
        points_sink.close()
        temperature_sink.close()
        rejected_sink.close()
    fits = tuple(recorder.fits[k] for k in sorted(recorder.fits))
    session_file = None
    if recorder.done:
        session_file = finish_session(session, notify, temperatures_file)
    else:
        notify(
            "warn",
            f"the recording ends at {recorder.where()}: the session is incomplete "
            "(no session.yaml)",
        )
    return AcquireResult(session, recorder.done, recorder.n_points, fits, session_file)


# ------------------------------------------------------------------- the command
@dataclass(frozen=True)
class AcquireRequest:
    """What ``hexatherm acquire`` was asked (its options, in the workflow's types).

    ``hexapod`` and ``balls`` default to the session's copies (with ``replay_log``: the
    copies beside the log); a live run reads the ``probe`` port, a replay ``replay_log``.
    """

    plan: Path
    session: Path
    hexapod: Path | None = None
    balls: Path | None = None
    probe: PortSettings | None = None
    reopen_interval_s: float = 1.0
    unit: str = "mm"
    auto: bool = False
    resume: bool = False
    replay_log: Path | None = None
    idle_timeout_s: float | None = None
    max_gap_s: float = 600.0
    checks: FitChecks = field(default_factory=FitChecks)
    temperatures_file: Path | None = None
    temperature_port: PortSettings | None = None


def record(
    request: AcquireRequest, notify: Notify, operator_lines: Iterable[str] | None = None
) -> AcquireResult:
    """``hexatherm acquire`` from its request to its outcome: read the plan, hexapod and
    balls files, then replay ``request.replay_log`` into a new session
    (:func:`session_from_log`) or record from the probe's port (:func:`acquire`)."""
    config_dir = request.session if request.replay_log is None else request.replay_log.parent
    files = load_files(
        request.plan,
        request.hexapod or config_dir / "hexapod.yaml",
        request.balls or config_dir / "balls.yaml",
    )
    if request.replay_log is not None:
        return session_from_log(
            files, request.replay_log, request.session, notify, request.temperatures_file
        )
    if request.probe is None:
        raise ValueError("a live acquisition needs the probe's port")
    options = AcquireOptions(
        session=request.session,
        probe=request.probe,
        temperature_port=request.temperature_port,
        temperatures_file=request.temperatures_file,
        auto=request.auto,
        resume=request.resume,
        unit=request.unit,
        idle_timeout_s=request.idle_timeout_s,
        reopen_interval_s=request.reopen_interval_s,
        checks=request.checks,
        max_gap_s=request.max_gap_s,
    )
    return acquire(files, options, notify, operator_lines)
