"""The acquisition's state machine: log entries in, points assigned to steps and balls out.

The live loop and the replay of a log feed :class:`Recorder` the same entries, so a
replay gives the same ``points.csv`` byte for byte.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from hexatherm.core.plan import Plan
from hexatherm.core.planning import format_pose, reference_gaps
from hexatherm.devices.probestream import (
    UNITS_MM,
    LineSplitter,
    decode_line,
    format_number,
    parse_numbers,
    parse_record,
)
from hexatherm.errors import FitError, InputError
from hexatherm.io.records import iso_to_seconds
from hexatherm.io.seriallog import POINTS_HEADER, PROBE, TEMPERATURE, LogEntry, Sink
from hexatherm.session import Balls

OPERATOR_EVENTS = ("next", "redo", "quit")


Level = Literal["info", "warn", "progress"]


Notify = Callable[[Level, str], None]


Mode = Literal["auto", "interactive"]


def quiet(level: Level, message: str) -> None:
    """A notifier that says nothing (used while a log is replayed to resume)."""


# ---------------------------------------------------------------------- recorder
@dataclass(frozen=True)
class FitChecks:
    """Limits of the live sphere fit after each ball.

    Attributes
    ----------
    radius_tol_mm : float
        Warn when the fitted radius is further than this from the nominal one.
    form_tol_um : float
        Warn when the form error (max - min residual) is larger.
    min_points : int
        Warn when a ball has fewer points (4 fit a sphere, more check it).
    centre_distance_tol_mm : float
        Warn when the distance between two balls' fitted centres in one step is
        further than this from the balls file's (the wrong ball was probed).
    """

    radius_tol_mm: float = 0.02
    form_tol_um: float = 15.0
    min_points: int = 5
    centre_distance_tol_mm: float = 0.5


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
    line: str


@dataclass
class _TemperatureTable:
    columns: int = 0
    lines: list[str] = field(default_factory=list)


class Recorder:
    """Assigns the points of a probe stream to the steps and balls of a plan.

    Feed it log entries with :meth:`apply`; it parses the bytes, assigns each
    point to the current ball, writes the points CSV lines to ``points``, fits
    each completed ball and reports through ``notify``. In ``auto`` mode it moves
    on when a ball has the plan's points per ball; in ``interactive`` mode the
    operator's ``next`` does (extra points go to the same ball) and ``redo``
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
    ) -> None:
        self.plan = plan
        self.balls = balls
        self.points_sink = points
        self.temperature_sink = temperatures
        self.notify = notify
        self.checks = checks or FitChecks()
        self.max_gap_s = max_gap_s
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
        self._splitters = {PROBE: LineSplitter(), TEMPERATURE: LineSplitter()}
        self._pending: list[str] = []
        self._radius = np.array([_expected_radius(balls, j) for j in range(len(balls.names))])

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
    def n_points(self) -> int:
        """Number of points recorded."""
        return sum(len(v) for v in self.points.values())

    def where(self) -> str:
        """Where the acquisition stands, for messages."""
        if self.done:
            return "the end of the plan"
        i, j = self.slots[self.cursor]
        have = len(self.points[self.cursor])
        return (
            f"step {self.plan.labels[i]} ball {self.balls.names[j]} "
            f"({have}/{self.plan.points_per_ball} points)"
        )

    def announce(self) -> None:
        """Tell the operator what to do now (pose to command, ball to probe)."""
        if self.done:
            self.notify("info", "all steps measured")
            return
        i, j = self.slots[self.cursor]
        have = len(self.points[self.cursor])
        if j == 0 and have == 0:
            label, kind, pose = self.plan.labels[i], self.plan.kinds[i], self.plan.poses[i]
            self.notify(
                "info",
                f"step {i + 1}/{len(self.plan.labels)} {label} ({kind}): "
                f"command the hexapod to pose {format_pose(pose)}, then probe "
                f"{', '.join(self.balls.names)}",
            )
        remaining = self.plan.points_per_ball - have
        if remaining > 0:
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
            for line in splitter.feed(item.payload):
                if item.source == PROBE:
                    self._probe_line(line, item.time)
                else:
                    self._temperature_line(line, item.time)
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
            dropped = len(self.points[self.cursor])
            self.points[self.cursor] = []
            self.fits.pop(self.cursor, None)
            self._pending = []
            self.points_sink.rewrite(self.point_lines)
            self.notify("info", f"{dropped} point(s) dropped; probe the ball again")
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
        if self.done:
            self.notify("warn", f"point {record.text!r} after the end of the plan: not recorded")
            return
        i, j = self.slots[self.cursor]
        x, y, z = (format_number(v) for v in record.xyz_mm)
        text = f"{self.plan.labels[i]},{self.balls.names[j]},{x},{y},{z},{when}"
        self.points[self.cursor].append(_Point(record.xyz_mm, when, text))
        self._pending.append(text)
        have = len(self.points[self.cursor])
        self.notify(
            "progress",
            f"{self.plan.labels[i]} {self.balls.names[j]} point {have}/"
            f"{self.plan.points_per_ball}: {x}, {y}, {z}",
        )
        if have >= self.plan.points_per_ball:
            self._fit(self.cursor)
            if self.mode == "auto":
                self._advance()
            elif have == self.plan.points_per_ball:
                self.notify(
                    "info",
                    "Enter (or 'next'): next ball; 'redo': probe this ball "
                    "again; 'quit': stop (continue later with --resume)",
                )

    def _fit(self, slot: int) -> BallFit:
        from hexatherm.core.spherefit import fit_spheres

        i, j = self.slots[slot]
        label, ball = self.plan.labels[i], self.balls.names[j]
        pts = np.array([p.xyz for p in self.points[slot]])
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
            if abs(measured - nominal) > self.checks.centre_distance_tol_mm:
                out.append(
                    f"{measured:.3f} mm from {self.balls.names[oj]}, the balls file says "
                    f"{nominal:.3f} mm: was the right ball probed?"
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
        for gap in reference_gaps(self.plan, self.step_times):
            if self.plan.labels[i] in (gap.target, gap.reference) and gap.gap_s > self.max_gap_s:
                self.notify(
                    "warn",
                    f"{gap.target} and its reference {gap.reference} are "
                    f"{gap.gap_s / 60:.1f} min apart (allowed "
                    f"{self.max_gap_s / 60:.1f} min): the thermal state may "
                    "have changed in between",
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
