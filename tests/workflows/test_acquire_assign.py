"""How acquire assigns probed points to steps and balls (issue 12, items 15 and 16).

A simulated probe (:class:`Probe`) knows the truth: the platform at every step stands at
its commanded pose plus a positioning/thermal error (tens of um, 100 urad), frame O is on
the CMM at a known pose, and each ball is touched at a fixed pattern of points (as a DMIS
program does) with 0.5 um noise. The recorder is fed log entries directly (no port), and
what it recorded is compared with the truth, point by point.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.geometry import (
    apply_transform,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.planning import build_plan
from hexatherm.core.registration import register
from hexatherm.errors import InputError
from hexatherm.io.config import read_balls
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.seriallog import LOG_MAGIC, POINTS_HEADER, MemorySink, entry
from hexatherm.session import Balls
from hexatherm.workflows.acquire.files import load_files
from hexatherm.workflows.acquire.recorder import FitChecks, Recorder
from hexatherm.workflows.acquire.run import session_from_log

ROOT = Path(__file__).resolve().parents[2]
HEXAPOD_FILE = ROOT / "configs" / "symetrie-like.yaml"
BALLS_FILE = ROOT / "configs" / "balls-3.yaml"
BALLS = read_balls(BALLS_FILE)
ORIGIN_ON_CMM = [450.0, 320.0, 210.0, 0.2, -0.1, 15.0]
N = 6
PLAN = build_plan(
    [[4.0, -3.0, 2.0, 0.3, -0.2, 1.5], [-6.0, 5.0, -3.0, -0.4, 0.25, -2.0]], points_per_ball=N
)
NUMBER = re.compile(rb"[+-]\d+\.\d+")
T0 = "2024-05-01T10:00:00.000000"


# ------------------------------------------------------------------ the probe
@dataclass(frozen=True)
class Touch:
    """One point the probe sends: its line, its values, and the ball it is on (truth)."""

    line: bytes
    xyz: tuple[float, float, float]
    label: str | None
    ball: str | None


class Probe:
    """Where every ball of every step truly is, and the touches a probe sends on it.

    Parameters
    ----------
    plan : Plan
    seed : int
    error_um, error_urad : float
        Standard deviation of the platform's error from its commanded pose, per axis
        (positioning and thermal deflection together).
    convention : str
        Rotation convention of the plan's poses.
    balls : Balls
    """

    def __init__(
        self,
        plan=PLAN,
        seed: int = 1,
        error_um: float = 30.0,
        error_urad: float = 100.0,
        convention: str = "symetrie",
        balls: Balls = BALLS,
    ) -> None:
        self.plan, self.balls, self.rng = plan, balls, np.random.default_rng(seed)
        error = np.c_[
            self.rng.normal(0, error_um * 1e-3, (len(plan.labels), 3)),
            np.degrees(self.rng.normal(0, error_urad * 1e-6, (len(plan.labels), 3))),
        ]
        self.true_poses = plan.poses + error
        base2cmm = transform_from_pose(ORIGIN_ON_CMM) @ invert_transform(
            transform_from_pose(plan.poses[0], convention)
        )
        self.platform2cmm = base2cmm @ transform_from_pose(self.true_poses, convention)
        self.centres = apply_transform(self.platform2cmm, balls.centres_mm)  # (steps, balls, 3)
        self.radius = balls.diameters_mm / 2 + (0 if balls.probe_compensated else 1.0)
        # the touch pattern of every ball: N directions over the upper cap (CMM +Z)
        k = np.arange(plan.points_per_ball)
        theta = np.radians(15 + 50 * (k % 3) / 2)
        phi = 2.39996 * k
        self.pattern = np.c_[
            np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)
        ]

    def touch(self, label: str, ball: str, k: int, noise_um: float = 0.5) -> Touch:
        """The k-th touch of the pattern on a ball (new noise every call)."""
        i, j = self.plan.labels.index(label), self.balls.names.index(ball)
        r = self.radius[j] + self.rng.normal(0, noise_um * 1e-3)
        return self._line(self.centres[i, j] + r * self.pattern[k], label, ball)

    def off(self, label: str, ball: str, k: int, by_mm: float) -> Touch:
        """A touch ``by_mm`` off the ball's surface (on the stand, the platform): no ball."""
        i, j = self.plan.labels.index(label), self.balls.names.index(ball)
        return self._line(self.centres[i, j] + (self.radius[j] + by_mm) * self.pattern[k])

    def ball(self, label: str, ball: str, ks=None) -> list[Touch]:
        ks = range(self.plan.points_per_ball) if ks is None else ks
        return [self.touch(label, ball, k) for k in ks]

    def session(self) -> list[Touch]:
        """Every ball of every step in plan order."""
        return [t for lab in self.plan.labels for b in self.balls.names for t in self.ball(lab, b)]

    @staticmethod
    def _line(xyz, label=None, ball=None) -> Touch:
        line = "X{:+010.4f} Y{:+010.4f} Z{:+010.4f}".format(*xyz).encode()
        values = tuple(float(v) for v in NUMBER.findall(line))
        return Touch(line, values, label, ball)  # type: ignore[arg-type]


def stream(touches: list[Touch]) -> bytes:
    return b"".join(t.line + b"\r\n" for t in touches)


def truth_rows(touches: list[Touch]) -> list[tuple]:
    return [(t.label, t.ball, *t.xyz) for t in touches]


def rows(lines: list[str]) -> list[tuple]:
    assert lines[0] == POINTS_HEADER
    out = []
    for line in lines[1:]:
        label, ball, x, y, z, _ = line.split(",")
        out.append((label, ball, float(x), float(y), float(z)))
    return out


class Collect:
    def __init__(self):
        self.messages: list[tuple[str, str]] = []

    def __call__(self, level, message):
        self.messages.append((level, message))

    def warnings(self):
        return [m for level, m in self.messages if level == "warn"]

    def text(self):
        return "\n".join(m for _, m in self.messages)


def recorder(plan=PLAN, **kwargs):
    notes = Collect()
    rec = Recorder(
        plan,
        kwargs.pop("balls", BALLS),
        points=MemorySink(),
        temperatures=MemorySink(),
        rejected=MemorySink(),
        notify=notes,
        **kwargs,
    )
    return rec, notes


def feed(rec: Recorder, touches: list[Touch], when: str = T0) -> None:
    for t in touches:
        rec.apply(entry("rx", "probe", t.line + b"\r\n", when))


def rejected_rows(rec: Recorder) -> list[tuple]:
    """(label, ball, x, y, z, status) of rejected.csv."""
    import csv

    lines = rec.rejected_sink.lines  # type: ignore[attr-defined]
    table = list(csv.reader(lines))
    assert table[0] == ["label", "ball", "x", "y", "z", "time", "status", "reason"]
    return [(r[0], r[1], float(r[2]), float(r[3]), float(r[4]), r[6]) for r in table[1:]]


# ---------------------------------------------------------------- by geometry
def test_lost_extra_wrong_and_stray_points_each_land_where_they_belong():
    probe = Probe(seed=2)
    sent: list[Touch] = []
    expected: list[Touch] = []
    wrong: list[Touch] = []
    for label in PLAN.labels:
        for ball in BALLS.names:
            touches = probe.ball(label, ball)
            if (label, ball) == ("S1", "B2"):
                touches = touches[:3] + touches[4:]  # a line lost: 5 points, then B3
            sent += touches
            expected += touches
            if (label, ball) == ("R1", "B1"):
                extra = probe.touch("R1", "B1", 2)  # one more line after the ball is complete
                sent.append(extra)
                wrong.append(extra)
    # while S2 B1 is probed: a touch on B3 (the ball after next), and one on B1's stand
    at = next(k for k, t in enumerate(sent) if (t.label, t.ball) == ("S2", "B1")) + 2
    out_of_turn = probe.touch("S2", "B3", 0)
    stray = probe.off("S2", "B1", 4, by_mm=3.0)
    sent[at:at] = [out_of_turn, stray]
    wrong += [out_of_turn, stray]
    after_end = probe.touch("R2", "B3", 1)
    sent.append(after_end)
    wrong.append(after_end)

    rec, notes = recorder()
    feed(rec, sent)
    assert rec.done
    assert rows(rec.point_lines) == truth_rows(expected)  # nothing shifted, nothing lost
    assert rec.fits[PLAN.labels.index("S1") * 3 + 1].n == 5
    assert "B2 of S1 closed with 5 of 6 points" in notes.text()
    got = rejected_rows(rec)
    assert [r[2:5] for r in got] == [t.xyz for t in wrong]
    assert all(r[5] == "rejected" for r in got)
    assert [r[:2] for r in got] == [("R1", "B1"), ("S2", "B3"), ("", ""), ("", "")]
    warnings = [w for w in notes.warnings() if "rejected" in w]
    assert warnings[0].endswith("on B1 of R1, which is complete (an extra point)")
    assert warnings[1].endswith("on B3 of S2, not on B1 of S2 (being probed) or B2 of S2 (next)")
    assert re.search(
        r"on no expected ball: 3\.0\d\d mm off the surface of the nearest, B1 of S2", warnings[2]
    )
    assert warnings[3].endswith("after the end of the plan")
    # every ball fitted from its own points: the registered poses are the true ones
    centres = np.array([rec.fits[k].centre_mm for k in range(len(rec.slots))]).reshape(-1, 3, 3)
    measured = register(centres, BALLS.centres_mm).platform2cmm
    relative = pose_from_transform(invert_transform(measured[0]) @ measured)
    truth = pose_from_transform(invert_transform(probe.platform2cmm[0]) @ probe.platform2cmm)
    # (6 points on a cap, 0.5 um noise: a free-radius fit's centre moves um along the axis)
    np.testing.assert_allclose(relative[:, :3], truth[:, :3], atol=6e-3)


def test_the_count_alone_would_have_shifted_every_later_point():
    """The same lost line without geometry (the old rule) puts B3's first point on B2."""
    probe = Probe(seed=3)
    touches = probe.session()
    lost = next(k for k, t in enumerate(touches) if (t.label, t.ball) == ("S1", "B2")) + 1
    sent = touches[:lost] + touches[lost + 1 :]
    rec, _ = recorder()
    feed(rec, sent)
    assert rows(rec.point_lines) == truth_rows(sent)
    by_count = [(PLAN.labels[k // (3 * N)], BALLS.names[(k // N) % 3]) for k in range(len(sent))]
    # one point of every later ball (10 of them) on the ball before it
    assert sum(a != (t.label, t.ball) for a, t in zip(by_count, sent, strict=True)) == 10


def test_geometry_takes_over_when_o_registers_and_follows_the_convention():
    for convention in ("symetrie", "pi"):
        plan = build_plan([[5.0, -4.0, 3.0, 8.0, -6.0, 10.0]], points_per_ball=N)
        probe = Probe(plan, seed=4, error_um=0.0, error_urad=0.0, convention=convention)
        rec, notes = recorder(plan, convention=convention)
        feed(rec, probe.ball("O", "B1") + probe.ball("O", "B2") + probe.ball("O", "B3"))
        assert rec.expected_mm is not None
        assert "O registered to the balls file" in notes.text()
        np.testing.assert_allclose(rec.expected_mm, probe.centres, atol=1e-2)
        feed(rec, [t for lab in plan.labels[1:] for b in BALLS.names for t in probe.ball(lab, b)])
        assert rec.done and not rec.rejects
    # the other convention puts the balls of the rotated target millimetres away
    rec, _ = recorder(plan, convention="symetrie")
    feed(rec, probe.session())
    assert rec.rejects and not rec.done


def test_before_o_a_lost_line_and_an_extra_line_are_caught_by_distance():
    probe = Probe(seed=5)
    b1, b2, b3 = (probe.ball("O", b) for b in BALLS.names)
    rec, notes = recorder()
    feed(rec, b1[:4] + b2)  # B1 lost two lines: B2's first point starts B2
    assert rows(rec.point_lines) == truth_rows(b1[:4] + b2)
    assert "B1 of O closed with 4 of 6 points" in notes.text()
    extra = probe.touch("O", "B2", 3)
    feed(rec, [extra] + b3)  # one line too many on B2: rejected, B3 unharmed
    assert rows(rec.point_lines)[-N:] == truth_rows(b3)
    assert rejected_rows(rec)[0][:5] == ("O", "B2", *extra.xyz)
    assert rec.expected_mm is not None


def test_an_o_that_does_not_match_the_balls_file_is_said_and_not_trusted():
    probe = Probe(seed=6)
    moved = Probe(seed=6)
    moved.centres = moved.centres.copy()
    moved.centres[0, 1] += [1.0, 0.0, 0.0]  # B2 of O 1 mm off: the wrong ball, or loose
    rec, notes = recorder()
    feed(rec, probe.ball("O", "B1") + moved.ball("O", "B2") + probe.ball("O", "B3"))
    assert rec.expected_mm is None
    assert any(
        w.startswith("O does not match the balls file: a fitted centre is 0.")
        for w in notes.warnings()
    )
    # the session goes on by count and distance
    feed(rec, probe.ball("R0", "B1"))
    assert rec.cursor == 4


def test_non_finite_points_are_refused_and_said():
    rec, notes = recorder()
    rec.apply(entry("rx", "probe", b"X=1e400 Y=0 Z=0\r\n1,2,1e999\r\n", T0))
    assert rec.n_points == 0 and not rec.rejects
    assert notes.warnings() == [
        "skipped garbage line 'X=1e400 Y=0 Z=0': a number overflows (not finite)",
        "skipped garbage line '1,2,1e999': a number overflows (not finite)",
    ]


def test_tolerances_that_cannot_tell_balls_apart_are_refused():
    with pytest.raises(InputError, match="below the smallest probed radius"):
        recorder(checks=FitChecks(surface_tol_mm=13.0))
    with pytest.raises(InputError, match="surface tolerance must be positive"):
        recorder(checks=FitChecks(surface_tol_mm=float("nan")))
    close = Balls(
        ("A", "B", "C"), np.array([[0, 0, 0], [26.0, 0, 0], [0, 60, 0]]), np.full(3, 25.4)
    )
    with pytest.raises(InputError, match="balls A and B are 26.000 mm apart"):
        recorder(balls=close)


# -------------------------------------------------------------------- resume
@pytest.mark.parametrize("protocol", ["again", "continue"])
def test_resume_sets_the_interrupted_ball_aside_and_both_protocols_are_right(protocol):
    probe = Probe(seed=7)
    before = [t for lab in ("O", "R0") for b in BALLS.names for t in probe.ball(lab, b)]
    partial = probe.ball("S1", "B1", range(4))
    rec, notes = recorder()
    feed(rec, before + partial)
    rec.apply(entry("resume", when=T0))
    assert rows(rec.point_lines) == truth_rows(before)
    assert [r[:5] for r in rejected_rows(rec)] == truth_rows(partial)
    assert {r[5] for r in rejected_rows(rec)} == {"set-aside"}
    told = notes.warnings()[-1]
    assert told == (
        "B1 of S1: 4 point(s) of the interrupted ball set aside (kept in serial.log and "
        "rejected.csv, not fitted); probe B1 of S1 again: the whole ball from its first touch "
        "point (6 points), or its 2 remaining point(s)"
    )
    if protocol == "again":
        redo = probe.ball("S1", "B1")
        ball = redo
    else:
        redo = probe.ball("S1", "B1", range(4, N))
        ball = partial + redo
    rest = [t for lab in PLAN.labels[2:] for b in BALLS.names for t in probe.ball(lab, b)][N:]
    feed(rec, redo + rest)
    assert rec.done
    assert rows(rec.point_lines) == truth_rows(before + ball + rest)
    aside = rejected_rows(rec)
    assert [r[:5] for r in aside] == (truth_rows(partial) if protocol == "again" else [])
    assert ("probed again whole" if protocol == "again" else "is continued") in notes.text()


def test_a_second_interruption_in_the_same_ball():
    probe = Probe(seed=8)
    o = [t for b in BALLS.names for t in probe.ball("O", b)]
    first = probe.ball("R0", "B1", range(3))
    again = probe.ball("R0", "B1", range(2))  # re-probe whole, interrupted again
    rec, _ = recorder()
    feed(rec, o + first)
    rec.apply(entry("resume", when=T0))
    feed(rec, again)
    rec.apply(entry("resume", when=T0))
    got = rejected_rows(rec)
    assert [(r[:5], r[5]) for r in got] == [(row, "rejected") for row in truth_rows(first)] + [
        (row, "set-aside") for row in truth_rows(again)
    ]
    cont = probe.ball("R0", "B1", range(2, N))  # then continued
    feed(rec, cont)
    assert rows(rec.point_lines)[-N:] == truth_rows(again + cont)


def test_a_ball_full_in_interactive_mode_is_kept_on_resume():
    probe = Probe(seed=9)
    rec, notes = recorder()
    rec.apply(entry("mode", "-", "interactive", T0))
    feed(rec, probe.ball("O", "B1"))
    rec.apply(entry("resume", when=T0))
    assert len(rec.points[0]) == N and not rec.rejects
    rec.apply(entry("event", "operator", "next", T0))
    assert rec.cursor == 1


# -------------------------------------------------------------------- times
def test_a_clock_set_back_between_runs_shifts_later_times():
    probe = Probe(seed=10)
    rec, notes = recorder()
    feed(rec, probe.ball("O", "B1"), "2024-05-01T10:00:05.000000")
    feed(rec, probe.ball("O", "B2")[:1], "2024-05-01T10:00:02.000000")  # 3 s back
    feed(rec, probe.ball("O", "B2")[1:2], "2024-05-01T10:00:03.500000")
    times = [line.rsplit(",", 1)[1] for line in rec.point_lines[1:]]
    assert times[-2:] == ["2024-05-01T10:00:05.000000", "2024-05-01T10:00:06.500000"]
    assert "probe: the clock went back by 3.000000 s" in notes.warnings()[0]


def test_a_burst_gives_a_session_that_processes(tmp_path):
    """The whole stream in one read: every step has the same time, and process still runs."""
    from hexatherm.workflows.process.pipeline import process_session

    (tmp_path / "plan.yaml").write_text(_plan_yaml())
    files = load_files(tmp_path / "plan.yaml", HEXAPOD_FILE, BALLS_FILE)
    probe = Probe(seed=11, error_um=0.0, error_urad=0.0)
    log = tmp_path / "burst.log"
    log.write_text(
        LOG_MAGIC
        + "\n"
        + entry("mode", "-", "auto", T0).format()
        + entry("rx", "probe", stream(probe.session()), T0).format()
    )
    notes = Collect()
    result = session_from_log(files, log, tmp_path / "s", notes)
    assert result.complete
    assert "O and R0 came in one read" in notes.text()
    points = read_measurement_csv(tmp_path / "s" / "points.csv")
    assert set(points.time_s) == {points.time_s[0]}
    processed = process_session(tmp_path / "s")
    assert any("same time" in w for w in processed.warnings)
    corr = processed.correction
    both = (corr.before_index >= 0) & (corr.after_index >= 0)
    np.testing.assert_array_equal(corr.weight_after[both], 0.5)
    # the conventional poses are the true ones (no thermal error simulated here)
    truth = pose_from_transform(invert_transform(probe.platform2cmm[0]) @ probe.platform2cmm)
    np.testing.assert_allclose(corr.conventional, truth[corr.target_index], atol=2e-3)
    # and, with no thermal growth between references, the corrected ones too
    np.testing.assert_allclose(corr.corrected, truth[corr.target_index], atol=2e-3)


def _plan_yaml() -> str:
    from hexatherm.io.config import plan_to_yaml

    return plan_to_yaml(PLAN)
