"""``hexatherm calibrate --poses twin --twin-model FILE`` (issue 15, item 2).

A heated campaign (heating mats, tens of um of leg growth) whose legs lag their
thermocouples (a hidden ``leg_thermal_lag``) and whose true geometry differs from its
hexapod file, and the same campaign drift-free (same seed: the same centre noise). The
twin's model is the hexapod file with the effects of ``truth/effects.yaml`` as its
``thermal_model``: the scenario's true thermal model. Calibrated from its twin-corrected
poses, the geometry lands on the truth as the drift-free calibration does; from the
conventional poses it does not, nor with a twin that misses the lag.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.calibration import gauge_fixed
from hexatherm.io.config import read_hexapod
from hexatherm.workflows.calibrate.outputs import calibrated_hexapod_yaml, parameters_frame
from hexatherm.workflows.calibrate.run import (
    Campaign,
    calibrate,
    read_campaign,
    simulated_twin_campaign,
)
from tests.sessions import calibration_scenario, calibration_targets

ROOT = Path(__file__).resolve().parents[2]
SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])
MATS = ", ".join(
    f"{{gain_C: {g}, tau_s: 2400, power: [[300, null]]}}" for g in (8, 10, 12, 9, 11, 10)
)
HOT = (
    f"heating: {{mats: [{MATS}]}}\n"
    "hidden_effects: [{name: leg_thermal_lag, parameters: {tau_s: 1800}}]\n"
)


def scenario(heating: str) -> str:
    return calibration_scenario(
        calibration_targets(3, decimals=3),
        geometry_seed=5,
        seed=3,
        points_per_ball=8,
        cmm={"point_noise_um": 0.3},
        thermocouples={"period_s": 30, "noise_C": 0.02},
        timing={"seconds_per_point": 2.0, "seconds_per_move": 20},
        extra=heating,
    )


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def model_file(session: Path, path: Path, effects: list[dict] | None = None) -> Path:
    """The session's hexapod file with ``effects`` (default: the truth's) as its
    thermal model."""
    doc = yaml.safe_load((session / "hexapod.yaml").read_text())
    if effects is None:
        effects = yaml.safe_load((session / "truth" / "effects.yaml").read_text())["effects"]
    doc["thermal_model"] = {"effects": effects}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("twin")
    folders = {}
    for name, heating in (("free", ""), ("hot", HOT)):
        (root / f"{name}.yaml").write_text(scenario(heating))
        made = run("simulate", root / f"{name}.yaml", "-o", root / name)
        assert made.exit_code == 0, made.output
        folders[name] = root / name
    effects = yaml.safe_load((folders["hot"] / "truth" / "effects.yaml").read_text())["effects"]
    assert [e["name"] for e in effects] == ["leg_thermal_lag"]  # the model has something to do
    model = model_file(folders["hot"], root / "twin.yaml")
    done = run(
        "calibrate",
        folders["hot"],
        "-o",
        root / "cal",
        "--level",
        "joints",
        "--poses",
        "twin",
        "--twin-model",
        model,
    )
    assert done.exit_code == 0, done.output
    folders["cal-twin"] = root / "cal"
    folders["model"] = model
    return folders


def z_scores(session: Path, out: Path | Campaign) -> pd.Series:
    """(calibrated - true) / u of every parameter, the truth in the fit's gauge, from
    the output folder ``out`` of calibrate or a campaign calibrated here (joints)."""
    if isinstance(out, Campaign):
        params = parameters_frame(calibrate(out, "joints")).set_index("parameter")
    else:
        params = pd.read_csv(out / "parameters.csv").set_index("parameter")
    truth = pd.read_csv(session / "truth" / "geometry.csv")
    nominal = read_hexapod(session / "hexapod.yaml")
    expected = pd.Series(
        gauge_fixed(truth["true"].to_numpy(), nominal.base_joints_mm), index=truth["parameter"]
    )
    return (params["calibrated"] - expected[params.index]) / params["u"]


def test_twin_poses_recover_the_truth_as_drift_free_poses_do(campaign) -> None:
    hot = campaign["hot"]
    twin = z_scores(hot, campaign["cal-twin"])
    free = z_scores(campaign["free"], read_campaign([campaign["free"]], "conventional"))
    conventional = z_scores(hot, read_campaign([hot], "conventional"))
    # every parameter within its predicted uncertainty of the truth, the uncertainty honest
    assert np.abs(twin).max() < 4.5
    assert 0.4 < np.sqrt(np.mean(twin**2)) < 1.6
    # as close as the drift-free calibration (same noise), far closer than conventional
    assert np.sqrt(np.mean(twin**2)) < 1.3 * np.sqrt(np.mean(free**2))
    assert np.sqrt(np.mean(conventional**2)) > 8.0 * np.sqrt(np.mean(twin**2))
    doc = json.loads((campaign["cal-twin"] / "calibration.json").read_text())
    assert doc["poses"] == "twin" and 0.5 < doc["chi_square_per_dof"] < 1.6


def test_twin_poses_are_the_drift_free_poses_and_weighted_as_measured(campaign) -> None:
    """The twin's truth: with the true thermal model, the hot campaign's twin-corrected
    poses are the drift-free campaign's measured ones (same centre noise) but for the
    thermocouples' noise; they carry the conventional poses' covariance."""
    twin = simulated_twin_campaign(campaign["hot"])
    free = read_campaign([campaign["free"]], "conventional")
    hot = read_campaign([campaign["hot"]], "conventional")
    sigma = np.sqrt(np.diag(free.covariance)).reshape(-1, 6)
    gap = np.abs(twin.measured - free.measured)
    assert np.all(gap < 0.3 * sigma)  # 0.02 degC of thermocouple noise: 0.19 sigma here
    assert np.abs(hot.measured - free.measured)[:, :3].max() > 50 * sigma[:, :3].max()
    np.testing.assert_array_equal(twin.covariance, hot.covariance)
    assert twin.poses == "twin" and twin.twin is not None
    assert twin.twin.path.endswith("effects.yaml")


def test_a_twin_missing_the_lag_calibrates_worse(campaign, tmp_path: Path) -> None:
    plain = model_file(campaign["hot"], tmp_path / "plain.yaml", effects=[])
    args = ("--level", "joints", "--poses", "twin", "--twin-model", plain)
    done = run("calibrate", campaign["hot"], "-o", tmp_path / "cal", *args)
    assert done.exit_code == 0, done.output
    z = z_scores(campaign["hot"], tmp_path / "cal")
    truth = z_scores(campaign["hot"], campaign["cal-twin"])
    assert np.sqrt(np.mean(z**2)) > 4.0 * np.sqrt(np.mean(truth**2))


def test_the_record_names_the_poses_and_the_twin_model(campaign) -> None:
    out, model = campaign["cal-twin"], campaign["model"]
    record = yaml.safe_load((out / "hexapod.yaml").read_text())["calibration"]
    assert record["poses"] == "twin"
    assert record["twin_model"] == str(model)
    assert record["twin_model_sha256"] == hashlib.sha256(model.read_bytes()).hexdigest()
    read_hexapod(out / "hexapod.yaml")  # the record's keys are checked
    inputs = json.loads((out / "provenance.json").read_text())["inputs"]
    assert str(model) in [entry["path"] for entry in inputs]
    conventional = calibrated_hexapod_yaml(
        calibrate(read_campaign([campaign["hot"]], "conventional"), "offsets")
    )
    assert "poses: conventional" in conventional and "twin_model" not in conventional


def test_twin_model_goes_with_twin_poses_only(campaign, tmp_path: Path) -> None:
    hot, model = campaign["hot"], campaign["model"]
    missing = run("calibrate", hot, "-o", tmp_path / "a", "--poses", "twin")
    assert missing.exit_code == 2 and "--twin-model" in missing.output
    stray = run("calibrate", hot, "-o", tmp_path / "b", "--twin-model", model)
    assert stray.exit_code == 2 and "--poses corrected" in stray.output
    other = run(
        "calibrate", hot, "-o", tmp_path / "c", "--poses", "conventional", "--twin-model", model
    )
    assert other.exit_code == 2 and "--poses conventional" in other.output
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="twin model"):
        read_campaign([hot], "twin")


def test_iterate_gives_the_twin_the_calibrated_joints_and_converges(campaign, tmp_path) -> None:
    args = ("--level", "joints", "--poses", "twin", "--twin-model", campaign["model"])
    done = run("calibrate", campaign["hot"], "-o", tmp_path / "cal", "--iterate", *args)
    assert done.exit_code == 0, done.output
    rounds = [line for line in done.stderr.splitlines() if line.startswith("round ")]
    assert 1 <= len(rounds) <= 3 and float(rounds[-1].split()[-2]) <= 0.01
    # the twin's deflection with the calibrated joints differs from the nominal one's
    # at second order: the parameters move by a fraction of their uncertainty and stay
    # on the truth
    z = z_scores(campaign["hot"], tmp_path / "cal")
    first = z_scores(campaign["hot"], campaign["cal-twin"])
    assert 0.0 < np.abs(z - first).max() < 0.5
    assert np.abs(z).max() < 4.5 and 0.4 < np.sqrt(np.mean(z**2)) < 1.6
