"""The acquisition's state machine: log entries in, points assigned to steps and balls out.

The live loop and the replay of a log feed :class:`Recorder` the same entries, so a
replay gives the same ``points.csv`` (and ``rejected.csv``) byte for byte.

How a point is assigned
-----------------------
The plan is walked slot by slot: step by step in plan order, ball by ball in the
balls file's order. The *current* ball is the first one not complete; a ball is
complete with the plan's points per ball (``--auto``) or on the operator's ``next``.

**By geometry, once O is measured.** When the three (or more) balls of O are fitted
and registered to the balls file (``origin2cmm``), the expected centre of ball ``b`` at
step ``s`` is ``origin2cmm @ inv(T(pose_O)) @ T(pose_s)`` applied to the ball's centre
in the platform frame: the commanded pose relative to O's, placed where O was measured.
A point lies on a ball when its distance to that expected centre is the expected
radius (ball radius, plus the tip's for uncompensated points) within
``FitChecks.surface_tol_mm`` (0.5 mm by default). That tolerance has to hold what
parts the ball from its commanded place: the hexapod's positioning error (tens of um
uncalibrated), the thermal deflection the method measures (tens of um, 0.1 mm for a
20 K heated leg), O's registration error (um) and the probe's noise (um); it is far
below the gap between two balls' surfaces (more than 100 mm for the shipped balls; a
balls file whose shells come closer than two tolerances is refused). Then:

* a point on the current ball is assigned to it;
* a point on the *next* ball closes the current one (a warning when it is short of
  points: a line was lost) and is the next ball's first point;
* any other point is rejected, never assigned: it is written to ``rejected.csv`` with
  the ball it lies on (an extra point on a complete ball, a ball probed out of turn)
  or its distance to the nearest expected surface, and the operator is told.

Steps that command the same pose (the references) have the same expected balls: the
walk's order tells them apart, geometry only decides current, next or neither.

**Before O is complete** there is no expected geometry: the points of O are assigned
by count, protected by the balls' own shape. A point further than the ball's diameter
(plus the tolerance) from a point already on the current ball is not on it: it starts
the next ball (a lost line no longer shifts every later point); a point on the sphere
just fitted to the previous ball is an extra point and is rejected. When O is complete,
its fits are registered to the balls file; geometry takes over only if every ball was
fitted and no fitted centre is further than half the tolerance from the registered
one. Otherwise (a ball of O mis-probed) a warning says so, and the rest of the session
is assigned by count and the same distance rule: O has to be measured again.

Resume
------
On ``--resume`` (a ``resume`` entry in the log) the points of the interrupted ball (it
has some, but not all of its points) are *set aside*: they stay in ``serial.log``,
are written to ``rejected.csv`` as ``set-aside`` and are not fitted, and the operator is
told to probe that ball again, whole or its remaining points. The first new point
decides which: if it re-touches the first set-aside point (within 1 mm and half the
distance between set-aside touches, as a DMIS program or any repeated touch pattern
does), the ball is being probed again whole and the set-aside points stay aside;
otherwise the ball is being continued and the set-aside points are taken back, before
the new ones. Both give the ball the plan's points, all on it.

Whether the interrupted ball's last points reached ``serial.log`` before the kill must not
matter, and it does not: points the probe sent before the kill that the killed process
never read stay in the port's buffer and arrive *after* the resume, where they look like a
continuation (a new touch). So, for the ball interrupted by the resume (with points set
aside or none logged at all), a point that re-touches the ball's first point (the same
rule) restarts the ball as a whole: every point it has (taken back, or read after the
resume) is set aside and the ball is the re-probe's alone. The set-aside points of a ball
probed again whole say so (``rejected.csv``: ``set-aside``, "probed before an
interruption; the ball was probed again from its first touch point"), however the kill
fell. A touch pattern that continues a ball never re-touches its first point.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from hexatherm.core.geometry import apply_transform, invert_transform, transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.core.planning import reference_gaps
from hexatherm.devices.probestream import (
    UNITS_MM,
    LineSplitter,
    decode_line,
    format_number,
    parse_numbers,
    parse_record,
)
from hexatherm.errors import FitError, InputError, RegistrationError
from hexatherm.io.records import iso_to_seconds, seconds_to_iso
from hexatherm.io.seriallog import (
    POINTS_HEADER,
    PROBE,
    REJECTED_HEADER,
    TEMPERATURE,
    LogEntry,
    MemorySink,
    Sink,
)
from hexatherm.session import DISTANCE_REFUSAL_UM, Balls, QualityLimits
from hexatherm.text import format_pose

OPERATOR_EVENTS = ("next", "redo", "quit")

#: a new point within this distance of the first set-aside point (and within half the
#: distance between set-aside touches) re-touches it: the ball is probed again whole, mm
RETOUCH_MM = 1.0

#: why the points of an interrupted ball probed again whole are set aside (rejected.csv)
REPROBED = "probed before an interruption; the ball was probed again from its first touch point"


Level = Literal["info", "warn", "progress"]


Notify = Callable[[Level, str], None]


Mode = Literal["auto", "interactive"]


def quiet(level: Level, message: str) -> None:
    """A notifier that says nothing (used while a log is replayed to resume)."""


# ---------------------------------------------------------------------- recorder
@dataclass(frozen=True)
class FitChecks:
    """Limits of the live sphere fit after each ball, and of the assignment of points.

    Attributes
    ----------
    radius_tol_mm : float
        Warn when the fitted radius is further than this from the nominal one (half
        the quality limit ``diameter_dev_um``: the one table of limits,
        :class:`~hexatherm.session.QualityLimits`).
    form_tol_um : float
        Warn when the form error (max - min residual) is larger (``form_um``).
    min_points : int
        Warn when a ball has fewer points (4 fit a sphere, more check it).
    centre_distance_tol_mm : float
        Warn when the distance between two balls' fitted centres in one step is
        further than this from the balls file's (``distance_dev_um``: what ``process``
        would flag; beyond :data:`~hexatherm.session.DISTANCE_REFUSAL_UM` it refuses
        the step, and the wrong ball was probed).
    surface_tol_mm : float
        A point lies on a ball when its distance to the ball's expected centre is
        the expected radius within this (see the module docstring).
    """

    radius_tol_mm: float = QualityLimits.diameter_dev_um / 2 * 1e-3
    form_tol_um: float = QualityLimits.form_um
    min_points: int = 5
    centre_distance_tol_mm: float = QualityLimits.distance_dev_um * 1e-3
    surface_tol_mm: float = 0.5


@dataclass(frozen=True)
class BallFit:
    """The live fit of one ball of one step."""

    label: str
    ball: str
    n: int
    centre_mm: tuple[float, float, float] | None
    radius_mm: float
    form_um: float
    warnings: tuple[str, ...]


@dataclass
class _Point:
    xyz: tuple[float, float, float]
    time: str
    line: str = ""


@dataclass
class _Reject:
    slot: int | None
    point: _Point
    status: Literal["rejected", "set-aside"]
    reason: str


@dataclass
class _TemperatureTable:
    columns: int = 0
    lines: list[str] = field(default_factory=list)


Verdict = Literal["current", "next", "reject"]


class Recorder:
    """Assigns the points of a probe stream to the steps and balls of a plan.

    Feed it log entries with :meth:`apply`; it parses the bytes, assigns each point
    to a ball (see the module docstring: by geometry once O is measured), writes the
    points CSV lines to ``points`` and the points it does not assign to ``rejected``,
    fits each completed ball and reports through ``notify``. In ``auto`` mode a ball
    is complete with the plan's points per ball; in ``interactive`` mode the
    operator's ``next`` completes it (extra points go to the same ball) and ``redo``
    drops the current ball's points to probe it again.

    Parameters
    ----------
    plan : Plan
    balls : Balls
    points : Sink
        Receives the lines of ``points.csv`` (the header is written by the caller).
    temperatures : Sink
        Receives the lines of ``temperatures.csv`` (header first).
    notify : callable
        ``notify(level, message)``.
    checks : FitChecks
    max_gap_s : float
        Warn when a target and an adjacent reference are further apart.
    rejected : Sink, optional
        Receives the lines of ``rejected.csv`` (header first, written with the first
        point not assigned; rewritten when set-aside points are taken back).
    convention : {"symetrie", "pi"}
        Rotation convention of the plan's poses (the hexapod file's).

    Raises
    ------
    InputError
        When the tolerance is not positive, or two balls' shells widened by it
        overlap (a point could lie on both).
    """

    def __init__(
        self,
        plan: Plan,
        balls: Balls,
        *,
        points: Sink,
        temperatures: Sink,
        notify: Notify = quiet,
        checks: FitChecks | None = None,
        max_gap_s: float = 600.0,
        rejected: Sink | None = None,
        convention: str = "symetrie",
    ) -> None:
        self.plan = plan
        self.balls = balls
        self.points_sink = points
        self.temperature_sink = temperatures
        self.rejected_sink: Sink = rejected if rejected is not None else MemorySink()
        self.notify = notify
        self.checks = checks or FitChecks()
        self.max_gap_s = max_gap_s
        self.convention = convention
        self.mode: Mode = "auto"
        self.unit = "mm"
        self.slots = [(i, j) for i in range(len(plan.labels)) for j in range(len(balls.names))]
        self.cursor = 0
        self.points: dict[int, list[_Point]] = {k: [] for k in range(len(self.slots))}
        self.fits: dict[int, BallFit] = {}
        self.step_times = np.full(len(plan.labels), np.nan)
        self.temperatures = _TemperatureTable()
        self.stopped = False
        self.skipped_lines = 0
        #: expected ball centres (steps, balls, 3), CMM frame, mm; None before O
        self.expected_mm: np.ndarray | None = None
        #: points of an interrupted ball set aside on resume, per slot
        self.set_aside: dict[int, list[_Point]] = {}
        #: the points not assigned (rejected or set aside), in order
        self.rejects: list[_Reject] = []
        #: what the last resume set aside (for the log's note), or ""
        self.last_set_aside = ""
        self._decision: dict[int, Literal["again", "continue"]] = {}
        #: the ball that was being probed when the last resume came (None: none was)
        self._resumed: int | None = None
        self._rejects_written = False
        self._splitters = {PROBE: LineSplitter(), TEMPERATURE: LineSplitter()}
        self._pending: list[str] = []
        self._radius = np.array([_expected_radius(balls, j) for j in range(len(balls.names))])
        self._last_time_s: dict[str, float] = {}
        self._time_shift_s: dict[str, float] = {}
        self._burst_told = False
        self._check_tolerance()

    def _check_tolerance(self) -> None:
        tol = self.checks.surface_tol_mm
        if not (math.isfinite(tol) and 0 < tol < float(self._radius.min())):
            raise InputError(
                f"the surface tolerance must be positive and below the smallest probed "
                f"radius ({float(self._radius.min()):g} mm), got {tol:g} mm"
            )
        centres, names = self.balls.centres_mm, self.balls.names
        for a in range(len(names)):
            for b in range(a + 1, len(names)):
                gap = float(np.linalg.norm(centres[a] - centres[b]))
                if gap <= self._radius[a] + self._radius[b] + 2 * tol:
                    raise InputError(
                        f"balls {names[a]} and {names[b]} are {gap:.3f} mm apart: their "
                        f"surfaces widened by the {tol:g} mm tolerance overlap, a point "
                        "could lie on both"
                    )

    # ----------------------------------------------------------------- state
    @property
    def done(self) -> bool:
        """Every ball of every step has been measured."""
        return self.cursor >= len(self.slots)

    @property
    def point_lines(self) -> list[str]:
        """The lines of ``points.csv`` (header first), as they stand."""
        return [POINTS_HEADER] + [p.line for k in range(len(self.slots)) for p in self.points[k]]

    @property
    def rejected_lines(self) -> list[str]:
        """The lines of ``rejected.csv`` (header first; empty before the first reject)."""
        if not self.rejects and not self._rejects_written:
            return []
        return [REJECTED_HEADER] + [self._reject_line(r) for r in self.rejects]

    @property
    def n_points(self) -> int:
        """Number of points recorded."""
        return sum(len(v) for v in self.points.values())

    def _name(self, slot: int) -> str:
        i, j = self.slots[slot]
        return f"{self.balls.names[j]} of {self.plan.labels[i]}"

    def where(self) -> str:
        """Where the acquisition stands, for messages."""
        if self.done:
            return "the end of the plan"
        i, j = self.slots[self.cursor]
        have = len(self.points[self.cursor])
        aside = len(self.set_aside.get(self.cursor, []))
        return (
            f"step {self.plan.labels[i]} ball {self.balls.names[j]} "
            f"({have}/{self.plan.points_per_ball} points"
            + (f", {aside} set aside" if aside else "")
            + ")"
        )

    def announce(self) -> None:
        """Tell the operator what to do now (pose to command, ball to probe)."""
        if self.done:
            self.notify("info", "all steps measured")
            return
        i, j = self.slots[self.cursor]
        have = len(self.points[self.cursor])
        aside = self.set_aside.get(self.cursor, [])
        if j == 0 and have == 0 and not aside:
            label, kind, pose = self.plan.labels[i], self.plan.kinds[i], self.plan.poses[i]
            self.notify(
                "info",
                f"step {i + 1}/{len(self.plan.labels)} {label} ({kind}): "
                f"command the hexapod to pose {format_pose(pose)}, then probe "
                f"{', '.join(self.balls.names)}",
            )
        n = self.plan.points_per_ball
        remaining = n - have
        if aside and have == 0:
            left = n - len(aside)
            self.notify(
                "info",
                f"probe ball {self.balls.names[j]} of {self.plan.labels[i]}: the whole ball "
                f"again from its first touch point ({n} points), or its {left} remaining "
                f"point{'s' if left != 1 else ''}",
            )
        elif remaining > 0:
            self.notify(
                "info",
                f"probe ball {self.balls.names[j]} of {self.plan.labels[i]}: "
                f"{remaining} point{'s' if remaining != 1 else ''} to go",
            )

    # ----------------------------------------------------------------- entries
    def apply(self, item: LogEntry) -> None:
        """Act on one log entry."""
        kind = item.kind
        if kind == "rx":
            splitter = self._splitters.get(item.source)
            if splitter is None:
                return
            lines = splitter.feed(item.payload)
            if not lines:
                return
            when = self._stamp(item)
            for line in lines:
                if item.source == PROBE:
                    self._probe_line(line, when)
                else:
                    self._temperature_line(line, when)
        elif kind == "skip":  # lines left out by the writer (a flood): the partial one too
            splitter = self._splitters.get(item.source)
            if splitter is not None:
                splitter.reset()
        elif kind in ("lost", "open", "reopen"):
            splitter = self._splitters.get(item.source)
            dropped = splitter.reset() if splitter is not None else b""
            if dropped:
                self.notify(
                    "warn",
                    f"{item.source}: partial line {decode_line(dropped)!r} "
                    f"dropped ({'port lost' if kind == 'lost' else kind})",
                )
            if kind == "lost":
                self.notify("warn", f"{item.source} port lost ({item.text}); reopening it")
            elif kind == "reopen":
                self.notify("info", f"{item.source} port reopened")
        elif kind == "resume":
            for splitter in self._splitters.values():
                dropped = splitter.reset()
                if dropped:
                    self.notify(
                        "warn",
                        f"partial line {decode_line(dropped)!r} of the interrupted run dropped",
                    )
            self._set_aside_partial()
        elif kind == "mode":
            mode = item.text
            if mode not in ("auto", "interactive"):
                raise InputError(f"unknown mode {mode!r}", line=item.line or None)
            self.mode = mode  # type: ignore[assignment]
            if self.mode == "auto" and not self.done and self._ball_full():
                self._advance()
        elif kind == "config":
            for setting in item.text.split():
                key, _, value = setting.partition("=")
                if key == "units":
                    if value not in UNITS_MM:
                        raise InputError(f"unknown unit {value!r}", line=item.line or None)
                    self.unit = value
        elif kind == "event":
            self._event(item.text)
        self._flush()

    def _stamp(self, item: LogEntry) -> str:
        """The time of the lines an entry completes: never before the source's last one.

        The log keeps every entry's own time. Should a source's times go back (the wall
        clock set back between an interrupted run and its resume), the later entries are
        shifted by the step, so that time distances are kept and references never come
        out in reverse order.
        """
        seconds = iso_to_seconds(item.time)
        shift = self._time_shift_s.get(item.source, 0.0)
        last = self._last_time_s.get(item.source, -math.inf)
        if seconds + shift < last:
            step = last - (seconds + shift)
            shift += step
            self._time_shift_s[item.source] = shift
            self.notify(
                "warn",
                f"{item.source}: the clock went back by {step:.6f} s"
                + (f" (log line {item.line})" if item.line else "")
                + "; later times are shifted by that much",
            )
        self._last_time_s[item.source] = seconds + shift
        return item.time if shift == 0.0 else seconds_to_iso(seconds + shift)

    def _flush(self) -> None:
        if self._pending:
            self.points_sink.append(self._pending)
            self._pending = []

    def _event(self, name: str) -> None:
        if name == "quit":
            self.stopped = True
        elif self.done:
            self.notify("info", "all steps are measured already")
        elif name == "next":
            if self._ball_full():
                self._advance()
            else:
                need = self.plan.points_per_ball - len(self.points[self.cursor])
                self.notify("warn", f"{self.where()}: {need} more point(s) before moving on")
        elif name == "redo":
            slot = self.cursor
            dropped = self.points[slot]
            self.points[slot] = []
            self.fits.pop(slot, None)
            if self._decision.pop(slot, None) == "continue":
                self.set_aside.pop(slot, None)  # taken back into the dropped points
            for point in dropped:
                self.rejects.append(_Reject(slot, point, "rejected", "dropped by redo"))
            self._pending = []
            self.points_sink.rewrite(self.point_lines)
            if dropped:
                self._rewrite_rejects()
            self.notify("info", f"{len(dropped)} point(s) dropped; probe the ball again")
            self.announce()

    def _ball_full(self) -> bool:
        return len(self.points[self.cursor]) >= self.plan.points_per_ball

    # ----------------------------------------------------------------- probe
    def _probe_line(self, line: bytes, when: str) -> None:
        record = parse_record(line, self.unit)
        if record.kind == "blank":
            return
        if record.kind != "point":
            self.skipped_lines += 1
            level: Level = "progress" if record.kind == "text" else "warn"
            self.notify(level, f"skipped {record.kind} line {record.text[:60]!r}: {record.reason}")
            return
        assert record.xyz_mm is not None
        point = _Point(record.xyz_mm, when)
        if self.done:
            self._reject(None, point, "after the end of the plan")
            return
        xyz = np.array(record.xyz_mm)
        verdict, slot, reason = self._classify(xyz, allow_next=True)
        if verdict == "next":
            self._close("a point on the next ball came")
            self._advance()
            verdict, slot, reason = self._classify(xyz, allow_next=False)
        if verdict != "current":
            self._reject(slot, point, reason)
            return
        self._accept(point)

    def _surface_dev_mm(self, xyz: np.ndarray, slot: int) -> float:
        """Distance of a point from the expected surface of a slot's ball (geometry on)."""
        assert self.expected_mm is not None
        i, j = self.slots[slot]
        return abs(float(np.linalg.norm(xyz - self.expected_mm[i, j])) - float(self._radius[j]))

    def _classify(self, xyz: np.ndarray, *, allow_next: bool) -> tuple[Verdict, int | None, str]:
        """Where a point goes: the current ball, the next one, or nowhere (with why)."""
        tol = self.checks.surface_tol_mm
        cur = self.cursor
        nxt = cur + 1 if allow_next and cur + 1 < len(self.slots) else None
        if self.expected_mm is not None:
            if self._surface_dev_mm(xyz, cur) <= tol:
                return "current", cur, ""
            if nxt is not None and self._surface_dev_mm(xyz, nxt) <= tol:
                return "next", nxt, ""
            return self._why_not(xyz)
        # before O (or with an O that did not register): distances to the ball's points
        j = self.slots[cur][1]
        mine = [p.xyz for p in self.points[cur] + self.set_aside.get(cur, [])]
        reach = 2 * float(self._radius[j]) + tol
        if mine:
            far = float(np.linalg.norm(np.asarray(mine) - xyz, axis=1).max())
            if far <= reach:
                return "current", cur, ""
        previous = self.fits.get(cur - 1) if cur > 0 else None
        if previous is not None and previous.centre_mm is not None:
            pj = self.slots[cur - 1][1]
            dev = abs(float(np.linalg.norm(xyz - np.array(previous.centre_mm))) - self._radius[pj])
            if dev <= tol:
                return (
                    "reject",
                    cur - 1,
                    f"on {self._name(cur - 1)}, which is complete (an extra point)",
                )
        if not mine:
            return "current", cur, ""
        if nxt is not None:
            return "next", nxt, ""
        return (
            "reject",
            None,
            f"{far:.3f} mm from a point of {self._name(cur)}, more than its diameter "
            f"and the tolerance ({reach:.3f} mm)",
        )

    def _why_not(self, xyz: np.ndarray) -> tuple[Verdict, int | None, str]:
        assert self.expected_mm is not None
        tol = self.checks.surface_tol_mm
        cur = self.cursor
        centres = self.expected_mm.reshape(-1, 3)
        radii = np.tile(self._radius, len(self.plan.labels))
        dev = np.abs(np.linalg.norm(centres - xyz, axis=1) - radii)
        on = np.flatnonzero(dev <= tol)
        being = f"not on {self._name(cur)} (being probed)"
        if cur + 1 < len(self.slots):
            being += f" or {self._name(cur + 1)} (next)"
        if on.size:
            slot = int(on[np.argmin(np.abs(on - cur))])
            if slot < cur:
                return "reject", slot, f"on {self._name(slot)}, which is complete (an extra point)"
            return "reject", slot, f"on {self._name(slot)}, {being}"
        # steps of one commanded pose (the references) share their balls: name the one
        # nearest in the walk
        slot = int(np.lexsort((np.abs(np.arange(dev.size) - cur), np.round(dev, 9)))[0])
        return (
            "reject",
            None,
            f"on no expected ball: {float(dev[slot]):.3f} mm off the surface of the nearest, "
            f"{self._name(slot)} (tolerance {tol:g} mm); {being}",
        )

    def _accept(self, point: _Point) -> None:
        slot = self.cursor
        i, j = self.slots[slot]
        aside = self.set_aside.get(slot)
        if aside and slot not in self._decision and not self.points[slot]:
            if _retouches(np.array(point.xyz), aside):
                self._decision[slot] = "again"
                self._mark_reprobed(slot)
                self._rewrite_rejects()
                self.notify(
                    "info",
                    f"{self._name(slot)} is probed again whole (the first point re-touches "
                    f"the first set-aside one): the {len(aside)} set-aside point(s) stay aside",
                )
            else:
                self._decision[slot] = "continue"
                self.points[slot] = list(aside)
                self._pending.extend(p.line for p in aside)
                del self.set_aside[slot]
                self.rejects = [
                    r for r in self.rejects if not (r.slot == slot and r.status == "set-aside")
                ]
                self._rewrite_rejects()
                self.notify(
                    "info",
                    f"{self._name(slot)} is continued (the first point is a new touch): the "
                    f"{len(aside)} set-aside point(s) are taken back",
                )
        elif (
            slot == self._resumed
            and self.points[slot]
            and _retouches(np.array(point.xyz), self.points[slot])
        ):
            self._restart(slot)
        x, y, z = (format_number(v) for v in point.xyz)
        point.line = f"{self.plan.labels[i]},{self.balls.names[j]},{x},{y},{z},{point.time}"
        self.points[slot].append(point)
        self._pending.append(point.line)
        have = len(self.points[slot])
        self.notify(
            "progress",
            f"{self.plan.labels[i]} {self.balls.names[j]} point {have}/"
            f"{self.plan.points_per_ball}: {x}, {y}, {z}",
        )
        if have >= self.plan.points_per_ball:
            self._fit(slot)
            if self.mode == "auto":
                self._advance()
            elif have == self.plan.points_per_ball:
                self.notify(
                    "info",
                    "Enter (or 'next'): next ball; 'redo': probe this ball "
                    "again; 'quit': stop (continue later with --resume)",
                )

    def _restart(self, slot: int) -> None:
        """The interrupted ball is probed again from its first touch point: every point it
        has since the resume (taken back from the set-aside ones, or sent before the kill
        and read only after it) is set aside as a whole (see the module docstring)."""
        old = self.points[slot]
        self.points[slot] = []
        self.fits.pop(slot, None)
        self.set_aside.setdefault(slot, []).extend(old)
        for point in old:
            self.rejects.append(_Reject(slot, point, "set-aside", REPROBED))
        self._decision[slot] = "again"
        self._mark_reprobed(slot)
        self._pending = []
        self.points_sink.rewrite(self.point_lines)
        self._rewrite_rejects()
        self.notify(
            "warn",
            f"{self._name(slot)} is probed again from its first touch point (a point "
            f"re-touches its first one): its {len(old)} earlier point(s) are set aside (kept "
            "in serial.log and rejected.csv, not fitted)",
        )

    def _mark_reprobed(self, slot: int) -> None:
        """The set-aside points of a ball probed again whole say so in ``rejected.csv``."""
        for reject in self.rejects:
            if reject.slot == slot and reject.status == "set-aside":
                reject.reason = REPROBED

    def _close(self, why: str) -> None:
        """Close the current ball before it is full (or before the operator's ``next``)."""
        slot = self.cursor
        have = len(self.points[slot])
        if have < self.plan.points_per_ball:
            self.notify(
                "warn",
                f"{self._name(slot)} closed with {have} of {self.plan.points_per_ball} "
                f"points ({why}: a line lost, or the ball left early?)",
            )
        fit = self.fits.get(slot)
        if fit is None or fit.n != have:
            self._fit(slot)

    def _reject(self, slot: int | None, point: _Point, reason: str) -> None:
        x, y, z = (format_number(v) for v in point.xyz)
        self.rejects.append(_Reject(slot, point, "rejected", reason))
        self._append_reject(self.rejects[-1])
        self.notify("warn", f"point {x}, {y}, {z} rejected, not assigned: {reason}")

    def _reject_line(self, reject: _Reject) -> str:
        label = ball = ""
        if reject.slot is not None:
            i, j = self.slots[reject.slot]
            label, ball = self.plan.labels[i], self.balls.names[j]
        out = io.StringIO()
        csv.writer(out, lineterminator="").writerow(
            [
                label,
                ball,
                *(format_number(v) for v in reject.point.xyz),
                reject.point.time,
                reject.status,
                reject.reason,
            ]
        )
        return out.getvalue()

    def _append_reject(self, reject: _Reject) -> None:
        lines = [self._reject_line(reject)]
        if not self._rejects_written:
            lines.insert(0, REJECTED_HEADER)
            self._rejects_written = True
        self.rejected_sink.append(lines)

    def _rewrite_rejects(self) -> None:
        self._rejects_written = self._rejects_written or bool(self.rejects)
        if self._rejects_written:
            self.rejected_sink.rewrite(self.rejected_lines)

    def _set_aside_partial(self) -> None:
        """On resume: set the interrupted ball's points aside (see the module docstring)."""
        self.last_set_aside = ""
        self._resumed = None
        if self.done:
            return
        slot = self.cursor
        partial = self.points[slot]
        n = self.plan.points_per_ball
        if len(partial) < n:  # begun (or about to be): its re-probe replaces it as a whole
            self._resumed = slot
        if not partial or len(partial) >= n:
            return  # nothing probed yet, or complete and waiting for the operator's next
        decision = self._decision.pop(slot, None)
        old = self.set_aside.pop(slot, [])
        self.rejects = [r for r in self.rejects if not (r.slot == slot and r.status == "set-aside")]
        if decision == "again" and old:
            for point in old:
                self.rejects.append(
                    _Reject(
                        slot,
                        point,
                        "rejected",
                        "set aside, then superseded by a re-probe (itself interrupted)",
                    )
                )
        aside = list(partial)  # with "continue", the old set-aside points are in it already
        self.set_aside[slot] = aside
        for point in aside:
            self.rejects.append(
                _Reject(slot, point, "set-aside", "probed before an interruption (resume)")
            )
        self.points[slot] = []
        self.fits.pop(slot, None)
        self._pending = []
        self.points_sink.rewrite(self.point_lines)
        self._rewrite_rejects()
        self.last_set_aside = (
            f"{self._name(slot)}: {len(aside)} point(s) of the interrupted ball set aside"
        )
        self.notify(
            "warn",
            f"{self.last_set_aside} (kept in serial.log and rejected.csv, not fitted); probe "
            f"{self._name(slot)} again: the whole ball from its first touch point ({n} points), "
            f"or its {n - len(aside)} remaining point(s)",
        )

    def _fit(self, slot: int) -> BallFit:
        from hexatherm.core.spherefit import fit_spheres

        i, j = self.slots[slot]
        label, ball = self.plan.labels[i], self.balls.names[j]
        pts = np.array([p.xyz for p in self.points[slot]]).reshape(-1, 3)
        warnings: list[str] = []
        nominal = float(self._radius[j])
        centre: tuple[float, float, float] | None = None
        radius, form = math.nan, math.nan
        if len(pts) < self.checks.min_points:
            warnings.append(
                f"too few points: {len(pts)} (at least {self.checks.min_points} "
                "to fit and check a sphere)"
            )
        if len(pts) >= 4:
            try:
                fit = fit_spheres(pts)
            except FitError as exc:
                warnings.append(f"sphere fit failed: {exc}")
            else:
                c = fit.centre_mm[0]
                centre = (float(c[0]), float(c[1]), float(c[2]))
                radius, form = float(fit.radius_mm[0]), float(fit.form_um[0])
                if abs(radius - nominal) > self.checks.radius_tol_mm:
                    warnings.append(
                        f"radius {radius:.4f} mm is {1e3 * (radius - nominal):+.1f} "
                        f"um off the nominal {nominal:.4f} mm"
                    )
                if form > self.checks.form_tol_um:
                    warnings.append(f"form error {form:.1f} um > {self.checks.form_tol_um:g} um")
                warnings += self._distance_warnings(slot, np.array(centre))
        result = BallFit(
            label,
            ball,
            len(pts),
            centre,
            radius,
            form,
            tuple(warnings),
        )
        self.fits[slot] = result
        summary = f"{label} {ball}: {len(pts)} points"
        if centre is not None:
            summary += (
                f", centre {', '.join(f'{v:.4f}' for v in centre)} mm, radius "
                f"{radius:.4f} mm (nominal {nominal:.4f}), form {form:.1f} um"
            )
        self.notify("info", summary)
        for warning in warnings:
            self.notify(
                "warn",
                f"{label} {ball}: {warning}"
                + ("; 'redo' to probe it again" if self.mode == "interactive" else ""),
            )
        return result

    def _distance_warnings(self, slot: int, centre: np.ndarray) -> list[str]:
        i, j = self.slots[slot]
        out = []
        for other in range(len(self.slots)):
            oi, oj = self.slots[other]
            fit = self.fits.get(other)
            if oi != i or oj == j or fit is None or fit.centre_mm is None:
                continue
            measured = float(np.linalg.norm(centre - np.array(fit.centre_mm)))
            nominal = float(np.linalg.norm(self.balls.centres_mm[j] - self.balls.centres_mm[oj]))
            off_um = abs(measured - nominal) * 1e3
            if off_um > self.checks.centre_distance_tol_mm * 1e3:
                out.append(
                    f"{measured:.4f} mm from {self.balls.names[oj]}, the balls file says "
                    f"{nominal:.4f} mm ({off_um:.1f} um off, limit "
                    f"{self.checks.centre_distance_tol_mm * 1e3:g} um"
                    + (
                        f"; process refuses the step beyond {DISTANCE_REFUSAL_UM:g} um): "
                        "was the right ball probed?"
                        if off_um > DISTANCE_REFUSAL_UM
                        else ": process flags it)"
                    )
                )
        return out

    def _advance(self) -> None:
        i, _ = self.slots[self.cursor]
        self.cursor += 1
        if self.done or self.slots[self.cursor][0] != i:
            self._step_complete(i)
        self.announce()

    def _step_complete(self, i: int) -> None:
        times = [
            iso_to_seconds(p.time)
            for k, (si, _) in enumerate(self.slots)
            if si == i
            for p in self.points[k]
        ]
        self.step_times[i] = float(np.mean(times)) if times else np.nan
        if i == 0:
            self._locate_origin()
        elif self.step_times[i] == self.step_times[i - 1] and not self._burst_told:
            self._burst_told = True
            self.notify(
                "info",
                f"{self.plan.labels[i - 1]} and {self.plan.labels[i]} came in one read (the "
                "same arrival time): their times say nothing of when they were probed; "
                "process weighs references of equal times by the plan's order",
            )
        for gap in reference_gaps(self.plan, self.step_times):
            if self.plan.labels[i] in (gap.target, gap.reference) and gap.gap_s > self.max_gap_s:
                self.notify(
                    "warn",
                    f"{gap.target} and its reference {gap.reference} are "
                    f"{gap.gap_s / 60:.1f} min apart (allowed "
                    f"{self.max_gap_s / 60:.1f} min): the thermal state may "
                    "have changed in between",
                )

    def _locate_origin(self) -> None:
        """Register O's fitted balls; from them, the expected ball of every step."""
        from hexatherm.core.registration import register

        n_balls = len(self.balls.names)
        fits = [self.fits.get(slot) for slot in range(n_balls)]
        centres = [f.centre_mm if f is not None else None for f in fits]
        fallback = (
            "points are assigned by count and by distance to the ball's points, not by "
            "the commanded poses; measure O again"
        )
        if any(c is None for c in centres):
            missing = [self.balls.names[k] for k, c in enumerate(centres) if c is None]
            self.notify("warn", f"O: no fit for {', '.join(missing)}: {fallback}")
            return
        try:
            reg = register(np.array(centres), self.balls.centres_mm)
        except RegistrationError as exc:
            self.notify("warn", f"O does not register to the balls file ({exc}): {fallback}")
            return
        worst = float(np.linalg.norm(reg.residuals_mm[0], axis=1).max())
        limit = self.checks.surface_tol_mm / 2
        if worst > limit:
            self.notify(
                "warn",
                f"O does not match the balls file: a fitted centre is {worst:.3f} mm off "
                f"after registration (more than {limit:g} mm): {fallback}",
            )
            return
        poses = transform_from_pose(self.plan.poses, self.convention)
        platform2cmm = reg.platform2cmm[0] @ invert_transform(poses[0]) @ poses
        self.expected_mm = apply_transform(platform2cmm, self.balls.centres_mm)
        self.notify(
            "info",
            f"O registered to the balls file ({reg.rms_um[0]:.1f} um RMS): from now on a "
            "point goes to the ball whose commanded surface it lies on (within "
            f"{self.checks.surface_tol_mm:g} mm)",
        )

    # ----------------------------------------------------------- temperatures
    def _temperature_line(self, line: bytes, when: str) -> None:
        values = parse_numbers(line, 6)
        table = self.temperatures
        if values is None:
            self.notify(
                "warn",
                f"temperature line skipped (not six or more numbers): {decode_line(line)[:60]!r}",
            )
            return
        if table.columns == 0:
            table.columns = len(values)
            header = ["time"] + [f"leg{k}" for k in range(1, 7)]
            header += [f"ch{k}" for k in range(7, len(values) + 1)]
            table.lines.append(",".join(header))
            self.temperature_sink.append([table.lines[0]])
        if len(values) != table.columns:
            self.notify(
                "warn",
                f"temperature line with {len(values)} numbers skipped (the "
                f"first had {table.columns})",
            )
            return
        text = ",".join([when] + [format_number(v) for v in values])
        table.lines.append(text)
        self.temperature_sink.append([text])


def _expected_radius(balls: Balls, j: int) -> float:
    from hexatherm.core.spherefit import probe_radius_mm

    return probe_radius_mm(
        float(balls.diameters_mm[j]), balls.tip_diameter_mm, balls.probe_compensated
    )


def _retouches(xyz: np.ndarray, aside: list[_Point]) -> bool:
    """Whether a new first point re-touches the first set-aside point (a re-probe).

    Within :data:`RETOUCH_MM` of it, and within half the distance from it to the
    nearest other set-aside touch (when there is one).

    >>> aside = [_Point((0.0, 0.0, 12.7), "t"), _Point((4.0, 0.0, 12.0), "t")]
    >>> _retouches(np.array([0.05, 0.0, 12.7]), aside), _retouches(np.array([-4.0, 0, 12]), aside)
    (True, False)
    """
    first = np.array(aside[0].xyz)
    limit = RETOUCH_MM
    if len(aside) > 1:
        others = np.array([p.xyz for p in aside[1:]])
        limit = min(limit, 0.5 * float(np.linalg.norm(others - first, axis=1).min()))
    return float(np.linalg.norm(xyz - first)) < limit
