"""Consistency a user trips on (issue 25, item 7): one set of planning defaults,
diagnose's +- labelled k = 1, quality.csv's booleans, a bad --quality-threshold is a
usage error, process names what it was given instead of a session. (calibrate -o's
default: tests/cli/test_calibrate_outputs.py.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.planning import (
    DEFAULT_CAP_ANGLE_DEG,
    DEFAULT_SECONDS_PER_MOVE,
    DEFAULT_SECONDS_PER_POINT,
)
from hexatherm.io.scenario import read_scenario
from hexatherm.session import CmmNoise
from hexatherm.workflows.plan import PlanRequest
from tests.sessions import calibration_scenario
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "paper-zero-pose"


def option_default(command: str, name: str) -> object:
    cmd = main.get_command(None, command)  # type: ignore[arg-type]
    return next(p.default for p in cmd.params if p.name == name)


def test_plan_and_simulate_share_their_defaults(tmp_path):
    path = tmp_path / "scenario.yaml"
    path.write_text(calibration_scenario(np.zeros((2, 6)), geometry_seed=1))  # no timing, no cmm
    scenario = read_scenario(path)
    assert (scenario.seconds_per_point, scenario.seconds_per_move) == (
        DEFAULT_SECONDS_PER_POINT,
        DEFAULT_SECONDS_PER_MOVE,
    )
    assert scenario.cap_half_angle_deg == DEFAULT_CAP_ANGLE_DEG == CmmNoise(1.0).cap_angle_deg
    assert option_default("plan", "seconds_per_point") == DEFAULT_SECONDS_PER_POINT
    assert option_default("plan", "seconds_per_move") == DEFAULT_SECONDS_PER_MOVE
    assert option_default("plan", "cap_angle") == DEFAULT_CAP_ANGLE_DEG == 70.0
    request = PlanRequest.__dataclass_fields__
    assert request["seconds_per_point"].default == DEFAULT_SECONDS_PER_POINT
    assert request["seconds_per_move"].default == DEFAULT_SECONDS_PER_MOVE
    assert request["cap_angle_deg"].default == DEFAULT_CAP_ANGLE_DEG


def test_diagnose_plus_minus_is_labelled_k_1():
    from hexatherm.workflows.diagnose.outputs import _format_effect
    from hexatherm.workflows.diagnose.report import format_value

    assert format_value(1509.358, 35.9, "s") == "1509 ± 36 s (k = 1)"
    assert _format_effect({"tau_s": 1509.0}, {"tau_s": 36.0}, ("s",)).endswith(
        "(± standard uncertainty, k = 1)"
    )


# report takes no process option (tests/cli/test_report_results.py)
@pytest.mark.parametrize("command", ["process"])
def test_a_bad_quality_threshold_is_a_usage_error(tmp_path, command):
    out = tmp_path / ("o" if command == "process" else "r.html")
    result = CliRunner().invoke(
        main, [command, str(SESSION), "-o", str(out), "--quality-threshold", "temp=2"]
    )
    assert result.exit_code == 2, result.output
    assert "unknown name 'temp'" in result.output and "temperature_change_C" in result.output
    assert not out.exists()


def test_process_says_what_it_was_given(tmp_path):
    plan = CliRunner().invoke(
        main, ["process", str(SESSION / "plan.yaml"), "-o", str(tmp_path / "a")]
    )
    assert plan.exit_code == 1
    assert "this is a plan file (hexatherm-plan/1), not a session file" in plan.output
    results = CliRunner().invoke(
        main, ["process", str(SESSION / "expected"), "-o", str(tmp_path / "b")]
    )
    assert results.exit_code == 1
    assert "a results folder (poses.csv" in results.output
    assert f"its session is {SESSION}" in results.output
    empty = tmp_path / "empty"
    empty.mkdir()
    other = CliRunner().invoke(main, ["process", str(empty), "-o", str(tmp_path / "c")])
    assert other.exit_code == 1 and "no session.yaml in it" in other.output
