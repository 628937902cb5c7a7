"""Every fault the simulated machines inject, handled by ``hexatherm run`` as specified."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.sim.ipp import Fault
from hexatherm.devices.sim.symetrie import Faults
from hexatherm.errors import ControllerError, IncompleteSession, PoseError
from hexatherm.io.records import iso_to_seconds
from hexatherm.workflows.serve import parse_fault
from tests.workflows.test_run import START, Bench, check_complete, make_bench


@pytest.fixture
def tmp(tmp_path: Path) -> Path:
    return tmp_path


#: O, R0, S1, R1 with 6 points per ball: every fault has its chance, the tests stay short
SHORT = {"targets": [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]], "points_per_ball": 6}


def bench_with(tmp: Path, **kwargs: object) -> Bench:
    return make_bench(tmp, **{**SHORT, **kwargs})  # type: ignore[arg-type]


def transcript(b: Bench) -> str:
    return (b.session / "ipp.transcript").read_text()


def test_severity_2_error_is_cleared_and_the_command_retried(tmp: Path) -> None:
    b = bench_with(tmp, ipp_faults=[Fault("error", 5, "PtMeas", severity=2)])
    try:
        b.run()
        text = transcript(b)
        assert "Error(2, 1011" in text and "ClearAllErrors()" in text
        check_complete(b)
    finally:
        b.machines.close()


def test_severity_3_error_stops_the_hexapod_and_resume_finishes(tmp: Path) -> None:
    b = bench_with(tmp, ipp_faults=[Fault("error", 20, "PtMeas", severity=3)])
    try:
        with pytest.raises(IncompleteSession, match="continue with --resume") as stopped:
            b.run()
        assert "STOP" in b.machines.controller.received
        # said once, in the error: no warning before it saying it again
        assert ". The hexapod was sent STOP; " in str(stopped.value)
        assert not any("STOP" in m for _, m in b.messages)
        before = pd.read_csv(b.session / "points.csv")
        b.run(resume=True)
        after = check_complete(b)
        # what was accepted before the error is kept as it was, nothing doubled
        pd.testing.assert_frame_equal(after.iloc[: len(before)], before)
    finally:
        b.machines.close()


def test_events_are_routed_apart_and_reported(tmp: Path) -> None:
    b = bench_with(tmp, ipp_faults=[Fault("event", 3, "PtMeas"), Fault("event", 9, "GoTo")])
    try:
        b.run()
        assert 'E0000 # KeyPress(\\"F1\\")' in transcript(b)
        events = [m for level, m in b.messages if m.startswith("CMM event")]
        assert len(events) == 4
        check_complete(b)
    finally:
        b.machines.close()


def test_a_connection_dropped_mid_transaction_is_reopened_and_the_ball_probed_again(
    tmp: Path,
) -> None:
    # the connection closes after the data line of the 12th PtMeas, before its '%'
    b = bench_with(tmp, ipp_faults=[Fault("drop", 12, "PtMeas", after_lines=2)])
    try:
        b.run()
        text = transcript(b)
        assert "lost connection closed by the server" in text
        assert "run abandon" in text and text.count("connect 127.0.0.1") == 2
        check_complete(b)  # the ball probed again: its points once, the lost point nowhere
    finally:
        b.machines.close()


def test_lines_split_across_reads_make_the_same_points(tmp: Path) -> None:
    faults = [Fault("split", n, "PtMeas", chunk_bytes=2) for n in range(1, 7)]
    b = bench_with(tmp, ipp_faults=faults)
    try:
        b.run()
        check_complete(b)
    finally:
        b.machines.close()


def test_a_late_in_position_flag_is_waited_for(tmp: Path) -> None:
    b = bench_with(tmp, faults=Faults(late_in_position_s=45.0))
    try:
        b.run()
        steps = pd.read_csv(b.session / "steps.csv")
        assert (steps["flag_after_s"] >= 45.0).all()
        check_complete(b)
    finally:
        b.machines.close()


def test_a_delay_that_breaks_the_gap_has_the_reference_measured_again(tmp: Path) -> None:
    b = bench_with(tmp)
    jumped: list[float] = []

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if " S1 (target) in position" in message and not jumped:
            jumped.append(b.clock())
            b.clock.advance(900.0)  # the night shift opened a door: 15 min lost

    b.notify = notify  # type: ignore[method-assign]
    try:
        result = b.run(max_gap_s=600.0)
        assert result.remeasured == ("R0",)
        assert "run remeasure R0 for S1" in transcript(b)
        points = check_complete(b)
        t = points.groupby("label")["time"].min().map(iso_to_seconds)
        # R0's points are the new ones, between the delay and S1
        assert jumped[0] + 900.0 < t["R0"] < t["S1"]
        steps = pd.read_csv(b.session / "steps.csv")
        assert list(steps["label"]) == ["O", "R0", "S1", "R0", "S1", "R1"]
    finally:
        b.machines.close()


def test_a_controller_connection_dropped_mid_move_is_reopened(tmp: Path) -> None:
    b = bench_with(tmp, faults=Faults(drop_mid_move=True))
    try:
        b.run()
        assert b.machines.controller.connections == 2
        assert "run reconnect" in (b.session / "controller.log").read_text()
        check_complete(b)
    finally:
        b.machines.close()


def test_controller_replies_split_across_reads(tmp: Path) -> None:
    b = bench_with(tmp, faults=Faults(split_writes=True))
    try:
        b.run(criteria=InPositionCriteria(settle_s=2.0, poll_s=5.0, timeout_s=900.0))
        check_complete(b)
    finally:
        b.machines.close()


def test_a_pose_the_controller_refuses_stops_before_anything_moves(tmp: Path) -> None:
    faults = parse_fault("refuse:axis=Tz,max=3").controller
    b = bench_with(tmp, faults=faults)
    try:
        with pytest.raises(PoseError, match=r"step S1: .*the Symetrie controller refuses"):
            b.run()
        assert b.world.model.moves == 0 and b.machines.cmm.touches == 0
    finally:
        b.machines.close()


def test_a_bad_ball_is_probed_once_more(tmp: Path) -> None:
    b = bench_with(tmp)
    radii = b.world.ball_radii_mm
    state = {"until": -1}

    def bumped(t_s: float) -> np.ndarray:
        r = radii(t_s)
        if b.machines.cmm.touches < state["until"]:
            r[1] += 0.04  # B2 looks 40 um too large for one probing
        return r

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if message.startswith("S1 B1:"):
            state["until"] = b.machines.cmm.touches + 6

    b.world.ball_radii_mm = bumped  # type: ignore[method-assign]
    b.notify = notify  # type: ignore[method-assign]
    try:
        result = b.run()
        reject = [x for x in transcript(b).splitlines() if "run reject S1" in x]
        assert len(reject) == 1 and "run reject S1 B2 radius +" in reject[0]
        assert abs(float(reject[0].split("radius ")[1].split(" um")[0]) - 40.0) < 1.0
        s1b2 = [r for r in result.balls if (r.label, r.ball) == ("S1", "B2")]
        assert len(s1b2) == 1 and s1b2[0].attempts == 2 and not s1b2[0].problems
        assert abs(s1b2[0].radius_mm - 12.7) < 1e-3
        check_complete(b)
    finally:
        b.machines.close()


def _gaps_s(b: Bench) -> dict[str, float]:
    """Time from each step's last point to the next step's first point, by the next step."""
    points = check_complete(b)
    points["t"] = points["time"].map(iso_to_seconds)
    span = points.groupby("label")["t"].agg(["min", "max"]).loc[list(b.files.plan.labels)]
    return {
        later: float(span.loc[later, "min"] - span.loc[earlier, "max"])
        for earlier, later in zip(span.index[:-1], span.index[1:], strict=True)
    }


def test_a_delay_after_a_target_has_it_measured_again_between_fresh_references(
    tmp: Path,
) -> None:
    """The after-reference would come too late (a delay once the target is measured): the
    target is measured again, with its reference before it, then the after-reference."""
    b = bench_with(tmp)
    jumped: list[float] = []

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if message.startswith("S1 B3:") and not jumped:  # S1's last ball accepted
            jumped.append(b.clock())
            b.clock.advance(900.0)

    b.notify = notify  # type: ignore[method-assign]
    try:
        result = b.run(max_gap_s=600.0)
        assert result.remeasured == ("S1", "R0")
        text = transcript(b)
        assert "run remeasure S1 for R1 gap 90" in text  # 900 s and the time it took
        assert "run remeasure R0 for S1 gap 10" in text
        # the delay was seen before moving: no move to R1 before S1 and R0 were measured again
        steps = pd.read_csv(b.session / "steps.csv")
        assert list(steps["label"]) == ["O", "R0", "S1", "R0", "S1", "R1"]
        gaps = _gaps_s(b)
        assert max(gaps["S1"], gaps["R1"]) < 600.0  # the target between fresh references
        points = pd.read_csv(b.session / "points.csv")
        first = points.groupby("label")["time"].min().map(iso_to_seconds)
        assert jumped[0] + 900.0 < first["R0"] < first["S1"] < first["R1"]
    finally:
        b.machines.close()


def test_a_resume_the_next_morning_measures_the_open_targets_references_again(tmp: Path) -> None:
    """Stopped once R1 is in position (an emergency stop), resumed 2 h later: S1 is measured
    again between a new R0 and R1, and process finds their time gaps within the limit."""
    b = bench_with(tmp)

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if " R1 (reference) in position" in message and b.clock() < START + 3600:
            raise ControllerError("emergency stop pressed")

    b.notify = notify  # type: ignore[method-assign]
    try:
        with pytest.raises(IncompleteSession, match=r"step R1 \(reference\), ball B1"):
            b.run(max_gap_s=600.0)
        b.clock.advance(7200.0)
        stopped = b.clock()
        result = b.run(resume=True, max_gap_s=600.0)
        assert result.remeasured == ("S1", "R0")
        steps = pd.read_csv(b.session / "steps.csv")
        assert list(steps["label"]) == ["O", "R0", "S1", "R1", "R0", "S1", "R1"]
        gaps = _gaps_s(b)
        assert gaps["R0"] > 7200.0  # O was not measured again: only R0's thermal state counts
        assert max(gaps["S1"], gaps["R1"]) < 600.0
        points = pd.read_csv(b.session / "points.csv")
        first = points.groupby("label")["time"].min().map(iso_to_seconds)
        assert stopped < first["R0"] < first["S1"] < first["R1"]
        result = CliRunner().invoke(main, ["process", str(b.session)])
        assert result.exit_code == 0, result.output
        quality = pd.read_csv(b.session / "results" / "quality.csv").set_index("label")
        assert quality.loc["S1", "time_gap_s"] < 600.0 and quality.loc["S1", "ok_time_gap"]
    finally:
        b.machines.close()


def test_a_controller_error_code_on_a_move_stops_the_run_and_resume_finishes(tmp: Path) -> None:
    """controller-error: the controller answers MOVE#ABS with an error code (here once R0 is
    measured): nothing is retried blindly, the hexapod gets STOP, the code is named, and
    --resume finishes."""
    b = bench_with(tmp)

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if message.startswith("R0 B3:"):
            injected = parse_fault("controller-error:command=MOVE#ABS,code=-104").controller
            b.machines.controller.faults.errors.update(injected.errors)

    b.notify = notify  # type: ignore[method-assign]
    try:
        with pytest.raises(IncompleteSession, match=r"-104") as stopped:
            b.run()
        assert "step S1 (target), ball B1" in str(stopped.value)
        assert b.machines.controller.received[-1] == "STOP"
        before = pd.read_csv(b.session / "points.csv")
        assert set(before["label"]) == {"O", "R0"}
        b.notify = lambda level, message: b.messages.append((level, message))  # type: ignore[method-assign]
        b.run(resume=True)
        after = check_complete(b)
        pd.testing.assert_frame_equal(after.iloc[: len(before)], before)
    finally:
        b.machines.close()


def test_no_in_position_flag_stops_the_run_and_resume_finishes(tmp: Path) -> None:
    """The flag does not come within the in-position timeout (a late flag beyond it): the
    run stops with the hexapod sent STOP; once the controller is well, --resume finishes."""
    b = bench_with(tmp, faults=Faults(late_in_position_s=600.0))
    criteria = InPositionCriteria(settle_s=2.0, poll_s=1.0, timeout_s=300.0)
    try:
        with pytest.raises(IncompleteSession, match=r"step O \(origin\)"):
            b.run(criteria=criteria)
        assert "STOP" in b.machines.controller.received
        assert not (b.session / "points.csv").read_text().strip().count("\n")
        b.machines.controller.faults.late_in_position_s = 0.0
        b.run(resume=True, criteria=criteria)
        check_complete(b)
    finally:
        b.machines.close()


def test_ctrl_c_stops_the_hexapod_and_resume_finishes(tmp: Path) -> None:
    b = bench_with(tmp)

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if message.startswith("S1 B2:"):
            raise KeyboardInterrupt

    b.notify = notify  # type: ignore[method-assign]
    try:
        with pytest.raises(KeyboardInterrupt):
            b.run()
        assert b.machines.controller.received[-1] == "STOP"
        assert "run stopped interrupted (Ctrl-C)" in transcript(b)
        before = pd.read_csv(b.session / "points.csv")
        assert len(before) == (2 * 3 + 2) * 6  # O, R0 and S1's first two balls
        b.notify = lambda level, message: b.messages.append((level, message))  # type: ignore[method-assign]
        b.run(resume=True)
        after = check_complete(b)
        pd.testing.assert_frame_equal(after.iloc[: len(before)], before)
    finally:
        b.machines.close()


def test_the_pi_dialect_end_to_end(tmp: Path) -> None:
    """The same campaign through a PI GCS controller (U, V, W axes, the pi convention on the
    wire): every ball on its own step, the controller's log in GCS."""
    b = bench_with(tmp)
    b.restart(dialect="pi")
    try:
        b.run()
        check_complete(b)
        log = (b.session / "controller.log").read_text()
        assert ' > "MOV ' in log and ' > "POS?' in log and "MOVE#ABS" not in log
        steps = pd.read_csv(b.session / "steps.csv")
        q = b.world.hexapod.igm(b.files.plan.poses)
        np.testing.assert_allclose(steps[[f"q_leg{i}_mm" for i in range(1, 7)]], q, atol=1e-4)
    finally:
        b.machines.close()
