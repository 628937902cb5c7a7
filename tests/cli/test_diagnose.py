"""``hexatherm diagnose``: the files, the story, refusals, and the model it writes."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.effects import effects_from_dicts, make_effect
from hexatherm.io.config import read_hexapod
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session

LAG = make_effect("leg_thermal_lag", NOMINAL_HIDDEN["leg_thermal_lag"])


@pytest.fixture(scope="module")
def lagging(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("cli") / "lagging"
    write_twin_session(diagnosis_campaign((LAG,), 12, n_targets=6), folder)
    return folder


@pytest.fixture(scope="module")
def diagnosed(lagging: Path, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("out") / "diag"
    result = CliRunner().invoke(main, ["diagnose", str(lagging), "-o", str(out)])
    return result, out


def test_diagnose_writes_the_files_and_tells_the_story(diagnosed) -> None:
    result, out = diagnosed
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == [
        ".hexatherm-manifest.json",  # what hexatherm wrote there, for --overwrite
        "diagnosis.json",
        "hexapod.yaml",
        "provenance.json",  # command, options, inputs with SHA-256, times
        "report.html",  # the story as one page, figures embedded
        "report.md",
        "residuals_legs_time.png",
        "residuals_steps.png",
        "residuals_temperature.png",
        "residuals_time.png",
    ]
    doc = json.loads((out / "diagnosis.json").read_text())
    assert [a["effect"] for a in doc["added"]] == ["leg_thermal_lag"]
    tau = doc["added"][0]["parameters"]["tau_s"]
    assert tau == pytest.approx(1500.0, rel=0.25)
    assert doc["final_rms_um"] < 0.5 * doc["baseline_rms_um"]
    story = result.stdout
    assert "-> added leg_thermal_lag" in story
    assert f"tau_s = {tau:.4g}" in story
    assert f"{doc['baseline_rms_um']:.3f} -> {doc['final_rms_um']:.3f} um" in story
    assert "wrote" not in story and "wrote" in result.stderr  # data out, logs err
    # a progress bar per round (its label, off a terminal), on standard error
    assert "round 1: candidates" in result.stderr and "round 2: candidates" in result.stderr


def test_the_written_model_is_a_hexapod_file_with_the_effect(diagnosed, lagging: Path) -> None:
    _, out = diagnosed
    model = read_hexapod(out / "hexapod.yaml")
    session_model = read_hexapod(lagging / "hexapod.yaml")
    assert (model.base_joints_mm == session_model.base_joints_mm).all()
    (effect,) = effects_from_dicts(model.effects)
    assert effect.name == "leg_thermal_lag"


def test_diagnosing_again_with_the_written_model_adds_nothing(
    diagnosed, lagging: Path, tmp_path: Path
) -> None:
    _, out = diagnosed
    again = tmp_path / "again"
    result = CliRunner().invoke(
        main, ["diagnose", str(lagging), "-o", str(again), "--hexapod", str(out / "hexapod.yaml")]
    )
    assert result.exit_code == 0, result.output
    doc = json.loads((again / "diagnosis.json").read_text())
    assert doc["added"] == []
    assert doc["model"][0]["name"] == "leg_thermal_lag"
    assert "nothing passes" in result.stdout


def test_diagnose_refuses_to_overwrite(diagnosed, lagging: Path) -> None:
    _, out = diagnosed
    before = (out / "diagnosis.json").read_text()
    result = CliRunner().invoke(main, ["diagnose", str(lagging), "-o", str(out)])
    assert result.exit_code == 1
    assert "--overwrite" in result.stderr
    assert (out / "diagnosis.json").read_text() == before


def test_diagnose_without_thermocouples_says_so(lagging: Path, tmp_path: Path) -> None:
    folder = tmp_path / "notemps"
    shutil.copytree(lagging, folder)
    session = folder / "session.yaml"
    session.write_text(
        "".join(
            line
            for line in session.read_text().splitlines(keepends=True)
            if not line.startswith("temperatures")
        )
    )
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["diagnose", str(folder), "-o", str(out)])
    assert result.exit_code == 1
    assert "thermocouple log" in result.stderr and "session.yaml" in result.stderr
    assert "Traceback" not in result.output
    assert not out.exists()
