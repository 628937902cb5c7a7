"""What ``hexatherm run`` says as it goes: each step's clock time and the campaign's ETA,
checked on the manual clock against the times the session recorded."""

from __future__ import annotations

import math
import re
from datetime import datetime
from pathlib import Path

import pandas as pd
import pytest

from hexatherm.core.planning import DEFAULT_SECONDS_PER_MOVE, DEFAULT_SECONDS_PER_POINT
from hexatherm.errors import IncompleteSession
from hexatherm.io.records import iso_to_seconds
from hexatherm.workflows.run.campaign import STOPPED_NOTE, run_campaign
from hexatherm.workflows.run.pace import Pace, clock_text, duration_text
from hexatherm.workflows.serve import default_heating
from hexatherm.workflows.serve_twin import time_scale_warning
from tests.workflows.test_run import make_bench

STEP_LINE = re.compile(
    r"^step (\d+)/(\d+) (\S+) \((\w+)\) in position at (\S+): \[.*\] deg; "
    r"ETA (\S+) \((.+) left\)$"
)


def test_pace_corrects_the_plan_timing_by_the_measured_pace() -> None:
    # the model: plan's defaults, a move of M s, 6 points a ball of B s; the run goes at
    # its own pace
    move, ball = DEFAULT_SECONDS_PER_MOVE, 6 * DEFAULT_SECONDS_PER_POINT
    assert (move, ball) == (20.0, pytest.approx(14.4))  # plan --help's defaults
    pace = Pace(6)
    assert pace.eta_s(900.0, moves_left=4, balls_left=12) == pytest.approx(
        900.0 + 4 * move + 12 * ball
    )
    pace.move_started(1000.0)  # the setup before (100 s here) is not counted
    pace.moved()  # no ball yet: the model's pace
    assert pace.eta_s(1045.0, moves_left=3, balls_left=12) == pytest.approx(
        1045.0 + 3 * move + 12 * ball
    )
    for _ in range(3):
        pace.probed()
    now = 1000.0 + 1.5 * (move + 3 * ball)  # the model's seconds done, 1.5 times slower
    assert pace.eta_s(now, moves_left=3, balls_left=9) == pytest.approx(
        now + (3 * move + 9 * ball) * 1.5
    )
    pace.move_started(now)  # only the first move starts the pace's clock
    pace.moved()
    now = 1000.0 + 1.5 * (2 * move + 3 * ball)  # 1.5 again
    assert pace.eta_s(now, moves_left=2, balls_left=9) == pytest.approx(
        now + (2 * move + 9 * ball) * 1.5
    )
    assert duration_text(7530.4) == "2 h 05 min" and duration_text(59.6) == "1 min 00 s"


def test_clock_text_is_the_local_time_with_its_offset() -> None:
    text = clock_text(1_700_000_000.9)
    stamp = datetime.fromisoformat(text)
    assert stamp.utcoffset() is not None and stamp.timestamp() == 1_700_000_000.0


def test_each_step_line_has_its_clock_time_and_the_campaigns_eta(tmp_path: Path) -> None:
    b = make_bench(tmp_path)
    try:
        b.run()
    finally:
        b.machines.close()
    plan, names = b.files.plan, b.files.balls.names
    n = len(plan.labels)
    lines = [m for _, m in b.messages if m.startswith("step ")]
    assert len(lines) == n
    steps = pd.read_csv(b.session / "steps.csv")
    points = pd.read_csv(b.session / "points.csv")
    points["t"] = [iso_to_seconds(x) for x in points["time"]]
    last_point = points.groupby(["label", "ball"])["t"].max()
    end_s = float(points["t"].max())
    # the pace's clock starts when the first move is commanded (controller.log's note)
    log = (b.session / "controller.log").read_text().splitlines()
    first_move = next(line for line in log if line.endswith(' * "run move O"'))
    start_s = iso_to_seconds(first_move.split()[0])
    ppb = plan.points_per_ball
    for k, line in enumerate(lines):
        match = STEP_LINE.match(line)
        assert match, line
        assert (int(match[1]), int(match[2]), match[3]) == (k + 1, n, plan.labels[k])
        # the clock time is the one steps.csv recorded for the step, to the second
        now_s = iso_to_seconds(steps["time"][k])
        assert datetime.fromisoformat(match[5]).timestamp() == math.floor(now_s)
        # the ETA, from what the session recorded: the plan's default model (20 s a
        # move, 2.4 s a point) for the work left, scaled by the time taken since the first move over
        # the model's time of the moves in position and the balls accepted (the model's
        # pace before the first ball)
        done_balls = int((last_point < now_s).sum())
        (move, point) = (DEFAULT_SECONDS_PER_MOVE, DEFAULT_SECONDS_PER_POINT)
        done_model_s = (k + 1) * move + done_balls * ppb * point
        left_model_s = (n - 1 - k) * move + (n - k) * len(names) * ppb * point
        ratio = (now_s - start_s) / done_model_s if done_balls else 1.0
        expected = now_s + left_model_s * ratio
        eta = datetime.fromisoformat(match[6]).timestamp()
        assert eta in {math.floor(expected - 1e-6), math.floor(expected + 1e-6)}, (line, expected)
        assert match[7] == duration_text(expected - now_s)
    # the last step's ETA is the run's end within the pace's spread on this clock
    last_eta = datetime.fromisoformat(STEP_LINE.match(lines[-1])[6]).timestamp()  # type: ignore[index]
    last_now = iso_to_seconds(steps["time"][n - 1])
    assert abs(last_eta - end_s) < 0.5 * (end_s - last_now)


def test_the_time_scale_warning_says_what_it_does_to_the_heating() -> None:
    assert time_scale_warning(1.0, default_heating()) is None
    fast = time_scale_warning(60.0, default_heating())
    assert fast is not None
    assert "legs heat 60 times faster" in fast
    assert "2400 s time constant lasts 40 s of the session's times" in fast
    slow = time_scale_warning(0.5, default_heating())
    assert slow is not None and "2 times slower" in slow and "lasts 4800 s" in slow


def test_a_stop_that_cannot_be_delivered_after_a_move_is_said_once(tmp_path: Path) -> None:
    """Both machines go away once S1 is in position: the run stops, the STOP cannot be
    delivered, and the one error says the hexapod may still be moving (no line before it
    claiming it was stopped)."""
    b = make_bench(tmp_path)

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if " S1 (target) in position" in message:
            b.machines.close()

    b.notify = notify  # type: ignore[method-assign]
    try:
        with pytest.raises(IncompleteSession) as stopped:
            b.run(reconnects=0)
    finally:
        b.machines.close()
    text = str(stopped.value)
    assert text.count("STOP") == 1 and "THE HEXAPOD MAY STILL BE MOVING; " in text, text
    assert ". Could not deliver STOP to the " in text and text.endswith("continue with --resume")
    assert not any("STOP" in m or "MAY STILL" in m for _, m in b.messages)
    assert (b.session / "points.csv").is_file()  # a machine answered: the session is kept


def test_ctrl_c_before_any_machine_answered_leaves_no_folder(tmp_path: Path) -> None:
    """Ctrl-C as the run starts (here: raised by the clock stamping the transcript's first
    note, before the controller is contacted): the note the command line prints says
    nothing was moved and nothing recorded, and the new folder is gone."""
    b = make_bench(tmp_path)
    raised: list[float] = []

    def clock() -> float:
        if not raised:
            raised.append(b.clock())
            raise KeyboardInterrupt
        return b.clock()

    session = tmp_path / "night" / "NEW"
    try:
        with pytest.raises(KeyboardInterrupt) as stopped:
            run_campaign(
                b.files,
                b.world.hexapod,
                b.options(session=session),
                b.notify,
                clock=clock,
                sleep=b.clock.sleep,
            )
    finally:
        b.machines.close()
    assert raised and getattr(stopped.value, "__notes__", None) == [
        f"{STOPPED_NOTE}nothing was moved (the hexapod controller was not contacted); "
        f"nothing was recorded ({session} was not created)"
    ]
    assert not session.parent.exists() and b.messages == []
    assert not b.machines.controller.received  # the controller was never contacted
