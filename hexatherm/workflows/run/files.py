"""The files of an unattended run, and ``points.csv`` rebuilt from the I++ transcript.

A run's session folder holds, besides the copies of the plan, hexapod and balls files:

``ipp.transcript``
    Every line sent to and received from the CMM, with its time (the transcript format of
    :mod:`hexatherm.devices.ipp`), written and flushed (fsync'd by default) before the
    client acts on it. The run adds its own notes (direction ``*``, first word ``run``),
    which the I++ recorder ignores and which say which ball the points that follow belong
    to::

        ... * "run begin S1 B2 attempt 1"
        ... (GoTo / PtMeas transactions)
        ... * "run accept S1 B2"            # or "run reject S1 B2 <why>"

    A ball's points are the points of the successful ``PtMeas`` transactions between its
    ``begin`` and its ``accept``; a later ``accept`` of the same step and ball (the ball
    probed again, a reference measured again) replaces the earlier one. A ``begin``
    without its ``accept`` (a crash, a lost connection, a rejected ball) gives nothing.
    That is all :func:`points_csv_from_transcript` needs: the transcript alone gives
    ``points.csv``, byte for byte.
``points.csv``
    The points CSV contract as ``hexatherm acquire`` writes it (``label,ball,x,y,z,time``,
    shortest round-trip numbers, ISO 8601 UTC times: the time each point's data line
    arrived), in plan order (step, then ball), each ball appended when it is accepted.
``controller.log``
    Every line sent to (``>``) and received from (``<``) the hexapod controller, and the
    run's notes (``*``), with their time, in the transcript's line format.
``steps.csv``
    One row per time the hexapod was brought in position for a step (a resumed or
    re-measured step has several): commanded pose, the controller's read-back pose (mean of
    the stable readings) and its deviation, actuator lengths, the controller's temperatures.
``run.yaml``
    The run's settings that a resume needs (the nominal placement of O on the CMM, the
    probing settings).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexatherm.core.plan import Plan
from hexatherm.devices.controller import StepRecord
from hexatherm.devices.ipp import (
    ProbedPoint,
    Recorder,
    TranscriptEntry,
    parse_transcript,
)
from hexatherm.devices.probestream import format_number
from hexatherm.io.records import iso_to_seconds, seconds_to_iso
from hexatherm.io.seriallog import POINTS_HEADER, POINTS_NAME
from hexatherm.session import Balls

TRANSCRIPT_NAME = "ipp.transcript"
CONTROLLER_LOG_NAME = "controller.log"
STEPS_NAME = "steps.csv"
RUN_NAME = "run.yaml"
CONTROLLER_LOG_MAGIC = "# hexatherm controller log 1"
#: first word of the run's notes in the transcript and the controller log
MARK = "run"

__all__ = [
    "CONTROLLER_LOG_MAGIC",
    "CONTROLLER_LOG_NAME",
    "MARK",
    "POINTS_NAME",
    "RUN_NAME",
    "STEPS_NAME",
    "TRANSCRIPT_NAME",
    "AcceptedBall",
    "LineLog",
    "accepted_balls",
    "iso_stamp",
    "point_line",
    "points_csv_from_transcript",
    "points_lines",
    "step_header",
    "step_row",
    "truncate_partial_line",
]


def iso_stamp(seconds: float) -> str:
    """POSIX seconds as the run stamps its logs: ISO 8601, UTC offset written.

    >>> iso_stamp(1577836810.25)
    '2020-01-01T00:00:10.250000+00:00'
    """
    return seconds_to_iso(seconds) + "+00:00"


class LineLog:
    """An append-only text log shared by threads: every line flushed, and fsync'd if durable.

    A callable :data:`~hexatherm.devices.ipp.TranscriptSink` (it takes whole formatted lines)
    that also writes entries of its own (:meth:`note`, :meth:`entry`) under the same lock, so
    that the client's lines and the run's notes never interleave within a line.

    Parameters
    ----------
    path : path
        The file; created with ``magic`` as its first line when missing or empty.
    magic : str
        The first line.
    clock : callable
        POSIX seconds, for the entries' times.
    durable : bool
        fsync every line (a power loss loses nothing acted on); flushing alone survives a
        killed process.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        magic: str,
        clock: Callable[[], float],
        *,
        durable: bool = True,
    ) -> None:
        self.path = Path(path)
        self.clock = clock
        self.durable = durable
        self._lock = threading.Lock()
        new = not self.path.exists() or self.path.stat().st_size == 0
        self._handle = open(self.path, "a", encoding="ascii", newline="\n")  # noqa: SIM115
        if new:
            self(magic + "\n")

    def __call__(self, line: str) -> None:
        """Write one formatted line (with its LF)."""
        with self._lock:
            self._handle.write(line)
            self._handle.flush()
            if self.durable:
                os.fsync(self._handle.fileno())

    def entry(self, direction: str, text: str) -> str:
        """Write an entry stamped now; returns the stamp."""
        stamp = iso_stamp(self.clock())
        self(TranscriptEntry(stamp, direction, text).format())  # type: ignore[arg-type]
        return stamp

    def note(self, text: str) -> str:
        """A note of the run (``* "run ..."``); returns its stamp."""
        return self.entry("*", f"{MARK} {text}")

    def close(self) -> None:
        """Close the file."""
        with self._lock:
            self._handle.close()


def truncate_partial_line(path: str | os.PathLike[str]) -> int:
    """Cut an unfinished last line (a writer killed mid-line); returns the bytes cut.

    Nothing was acted on from such a line: every line is complete before it is used.
    """
    p = Path(path)
    if not p.is_file():
        return 0
    raw = p.read_bytes()
    end = raw.rfind(b"\n") + 1
    if end < len(raw):
        os.truncate(p, end)
    return len(raw) - end


# ------------------------------------------------------------------------ points
def point_line(label: str, ball: str, point: ProbedPoint) -> str:
    """One line of ``points.csv``: ``label,ball,x,y,z,time`` (time in UTC, as acquire writes).

    >>> p = ProbedPoint("00007", "2024-05-01T10:00:00.500000+02:00", (0.0, 0.0, 0.0), None,
    ...                 (1.5, -2.0, 3.25), None, None)
    >>> point_line("S1", "B2", p)
    'S1,B2,1.5,-2.0,3.25,2024-05-01T08:00:00.500000'
    """
    x, y, z = (format_number(v) for v in point.point_mm)
    return f"{label},{ball},{x},{y},{z},{seconds_to_iso(iso_to_seconds(point.time))}"


@dataclass(frozen=True)
class AcceptedBall:
    """A ball of a step as the transcript accepted it (the last accept of that step and ball).

    Attributes
    ----------
    label, ball : str
    points : tuple of ProbedPoint
    accepted_at : str
        Stamp of the ``accept`` note.
    """

    label: str
    ball: str
    points: tuple[ProbedPoint, ...]
    accepted_at: str

    @property
    def xyz_mm(self) -> np.ndarray:
        """The points (n, 3), mm."""
        return np.array([p.point_mm for p in self.points], dtype=float).reshape(-1, 3)

    @property
    def time_s(self) -> float:
        """Mean time of the points, POSIX seconds (the ball's time, as ``process`` takes it)."""
        return float(np.mean([iso_to_seconds(p.time) for p in self.points]))

    @property
    def last_time_s(self) -> float:
        """Time of the last point, POSIX seconds."""
        return max(iso_to_seconds(p.time) for p in self.points)


def accepted_balls(text: str) -> dict[tuple[str, str], AcceptedBall]:
    """Every accepted ball of a transcript, by ``(label, ball)``; the last accept wins.

    The transcript is fed to a new :class:`~hexatherm.devices.ipp.Recorder` entry by entry,
    as the live client fed its own, so the points are the same, bit for bit. A last line
    without its LF is left out.

    Raises
    ------
    IppDmeError
        Not a transcript, or a malformed line.
    """
    recorder = Recorder()
    out: dict[tuple[str, str], AcceptedBall] = {}
    current: tuple[str, str] | None = None
    start = 0
    for item in parse_transcript(text):
        if item.direction == ">":
            recorder.sent(item.time, item.text)
        elif item.direction == "<":
            recorder.received(item.time, item.text)
        else:
            recorder.note(item.time, item.text)
            words = item.text.split()
            if len(words) >= 4 and words[0] == MARK:
                action, key = words[1], (words[2], words[3])
                if action == "begin":
                    current, start = key, len(recorder.points)
                elif action == "accept" and current == key:
                    out.pop(key, None)  # re-insert: the dict keeps the order of acceptance
                    out[key] = AcceptedBall(
                        key[0], key[1], tuple(recorder.points[start:]), item.time
                    )
                    current = None
                elif action in ("accept", "reject", "abandon"):
                    current = None
    return out


def points_lines(
    plan: Plan, balls: Balls, accepted: dict[tuple[str, str], AcceptedBall]
) -> list[str]:
    """The lines of ``points.csv`` (header first), in plan order: step, then ball."""
    lines = [POINTS_HEADER]
    for label in plan.labels:
        for name in balls.names:
            got = accepted.get((label, name))
            if got is not None:
                lines += [point_line(label, name, p) for p in got.points]
    return lines


def points_csv_from_transcript(text: str, plan: Plan, balls: Balls) -> str:
    """``points.csv`` of a run, rebuilt from its I++ transcript alone (see the module doc)."""
    return "".join(line + "\n" for line in points_lines(plan, balls, accepted_balls(text)))


# ------------------------------------------------------------------------- steps
_POSE = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


def step_header() -> str:
    """The header of ``steps.csv``."""
    cols = ["label", "kind", "positioning", "time", "flag_after_s"]
    cols += [f"{a}_cmd_{'mm' if a[0] == 'T' else 'deg'}" for a in _POSE]
    cols += [f"{a}_ctrl_{'mm' if a[0] == 'T' else 'deg'}" for a in _POSE]
    cols += [f"d{a}_ctrl_{'um' if a[0] == 'T' else 'urad'}" for a in _POSE]
    cols += [f"q_leg{i}_mm" for i in range(1, 7)]
    cols += ["readings", "T_ctrl_C"]
    return ",".join(cols)


def step_row(label: str, kind: str, positioning: int, time_s: float, record: StepRecord) -> str:
    """One row of ``steps.csv`` (controller temperatures ``;``-separated in ``T_ctrl_C``)."""

    def numbers(values: Iterable[float]) -> list[str]:
        return [format_number(v) for v in values]

    cells = [label, kind, str(positioning), seconds_to_iso(time_s)]
    cells += numbers([record.flag_after_s])
    cells += numbers(record.commanded_pose_mm_deg)
    cells += numbers(record.pose_mm_deg)
    cells += numbers(record.deviation_um_urad)
    cells += numbers(record.actuators_mm)
    cells += [str(len(record.readings_pose_mm_deg))]
    cells += [";".join(numbers(record.temperatures_C))]
    return ",".join(cells)


def write_lines(path: Path, lines: Sequence[str], *, durable: bool = True) -> None:
    """Append lines to a CSV file, flushed (and fsync'd when durable)."""
    with open(path, "a", encoding="utf-8", newline="") as handle:
        handle.write("".join(line + "\n" for line in lines))
        handle.flush()
        if durable:
            os.fsync(handle.fileno())


def transcript_is_new(path: Path) -> bool:
    """Whether nothing was ever sent to the CMM in this transcript (missing, or notes only).

    A run refused before its first command (a pose out of the stroke) can then be started
    again in the same folder.
    """
    if not path.is_file():
        return True
    text = path.read_text(encoding="ascii", errors="replace")
    return ' > "' not in text
