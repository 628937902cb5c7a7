"""A noise-free session the twin explains exactly, with constant air: an air-driven effect
moves no prediction there. Its fit used to feed NaN steps to the trust region and end
in a traceback; now it keeps its start and nothing is added, and the story says that
these data do not see it (not that it sits at a bound of its range)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.diagnosis import bound_flags
from hexatherm.core.effects import make_effect

ROOT = Path(__file__).resolve().parents[2]
MAT = "{gain_C: 3.0, tau_s: 2400, power: [[300, null]]}"
SCENARIO = f"""format: hexatherm-scenario/1
hexapod: {ROOT / "configs" / "symetrie-like.yaml"}
balls: {ROOT / "configs" / "balls-3.yaml"}
plan: {{targets: [[5, 0, 0, 0, 0, 0], [0, 5, 0, 1, 0, 0], [0, 0, 5, 0, 1, 0]],
        reference_pose: [0, 0, -40, 0, 0, 0], cycles: 3}}
heating: {{mats: [{", ".join([MAT] * 6)}]}}
"""


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory: pytest.TempPathFactory):
    tmp_path = tmp_path_factory.mktemp("constant-air")
    (tmp_path / "scenario.yaml").write_text(SCENARIO)
    made = CliRunner().invoke(
        main, ["simulate", str(tmp_path / "scenario.yaml"), "-o", str(tmp_path / "s")]
    )
    assert made.exit_code == 0, made.output
    result = CliRunner().invoke(main, ["diagnose", str(tmp_path / "s"), "-o", str(tmp_path / "d")])
    return tmp_path, result


def test_a_noise_free_session_with_constant_air_is_diagnosed_without_error(diagnosed) -> None:
    _, result = diagnosed
    assert result.exit_code == 0, result.output
    assert "nothing passes: the model is kept as it is" in result.stdout


def test_an_effect_the_data_do_not_see_is_said_so_not_at_a_bound(diagnosed) -> None:
    tmp_path, result = diagnosed
    air = (tmp_path / "s" / "temperatures.csv").read_text().splitlines()
    assert len({line.split(",")[-1] for line in air[1:]}) == 1  # the air is constant
    rounds = json.loads((tmp_path / "d" / "diagnosis.json").read_text())["rounds"][0]
    notes = {c["effect"]: c for c in rounds}
    for name in ("base_expansion", "ball_plate_expansion"):  # the air-driven effects
        note = notes[name]["note"]
        assert note == (
            "alpha_per_K has no effect on these data (not identifiable: kept at its start value 0)"
        )
        assert notes[name]["std_errors"] == {"alpha_per_K": None}  # no uncertainty to give
        assert f"{name} " in result.stdout and note in result.stdout
    assert "alpha_per_K at the bound" not in result.stdout
    # a parameter the data see and that the fit pushes to its bound keeps the bound note
    lag = notes["leg_thermal_lag"]
    assert lag["note"] == "tau_s at the bound of its range [1, 86400]"
    assert math.isfinite(lag["std_errors"]["tau_s"])


def test_bound_flags_flag_bounds_but_not_what_the_data_do_not_see() -> None:
    pinned = make_effect("base_expansion", {"alpha_per_K": 0.0})  # at its lower bound
    assert bound_flags(pinned) == ("alpha_per_K at the bound of its range [0, 3e-05]",)
    assert bound_flags(pinned, unseen=("alpha_per_K",)) == ()
    inside = make_effect("leg_thermal_lag", {"tau_s": 1800.0})
    assert bound_flags(inside) == ()
    outside = make_effect("leg_thermal_lag", {"tau_s": 1e6})
    assert len(bound_flags(outside)) == 2  # outside the range, and at (beyond) its bound
