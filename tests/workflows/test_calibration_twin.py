"""A simulated calibration campaign with a true geometry (``geometry_errors:``), end to
end: ``simulate`` writes it and its ``truth/geometry.csv``, ``process`` measures the
poses, and the calibration fit recovers the truth (issue 15: noise-free twin campaign,
42 parameters to 1e-6 mm, held-out predictions exact)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.calibration import fit_calibration, gauge_fixed, pose_covariance_from_sigma
from hexatherm.core.calibration.model import PARAMETER_NAMES
from hexatherm.io.config import read_hexapod
from hexatherm.workflows.process.pipeline import process_session
from tests.sessions import calibration_scenario

ROOT = Path(__file__).resolve().parents[2]
SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])
POSE = ["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]
UNITS = ["mm"] * 3 + ["deg"] * 3


def scenario(targets: np.ndarray) -> str:
    return calibration_scenario(targets.round(4), geometry_seed=11, name="geometry")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("calibration")
    targets = np.random.default_rng(8).uniform(-1, 1, (30, 6)) * SPAN
    (root / "scenario.yaml").write_text(scenario(targets))
    runner = CliRunner()
    made = runner.invoke(main, ["simulate", str(root / "scenario.yaml"), "-o", str(root / "s")])
    assert made.exit_code == 0, made.output
    done = runner.invoke(main, ["process", str(root / "s")])
    assert done.exit_code == 0, done.output
    return root / "s"


def test_the_truth_file_holds_the_drawn_geometry(campaign: Path) -> None:
    truth = pd.read_csv(campaign / "truth" / "geometry.csv")
    assert list(truth["parameter"]) == list(PARAMETER_NAMES)
    joints = truth["error_um"].to_numpy()[:36]
    assert 20.0 < np.std(joints) < 80.0  # a 50 um draw
    np.testing.assert_allclose(truth["error_ppm"].to_numpy()[42:], 0.0)


def test_the_fit_recovers_the_true_geometry_from_processed_poses(campaign: Path) -> None:
    nominal = read_hexapod(campaign / "hexapod.yaml")
    # the processed poses in memory: poses.csv holds them at 1e-7 mm and 1e-7 deg, which
    # the 42-parameter fit amplifies past the 1e-6 mm this noise-free campaign recovers
    processed = process_session(campaign)
    commanded = processed.session.plan.poses[processed.correction.target_index]
    measured = processed.correction.conventional
    written = pd.read_csv(campaign / "results" / "poses.csv")
    columns = [f"{a}_conv_{u}" for a, u in zip(POSE, UNITS, strict=True)]
    np.testing.assert_allclose(written[columns].to_numpy(), measured, atol=0.5e-7 * 1.001)
    fit = fit_calibration(
        nominal, commanded, measured, pose_covariance_from_sigma(len(measured), 1.0, 5.0)
    )
    truth = pd.read_csv(campaign / "truth" / "geometry.csv")["true"].to_numpy()
    expected = gauge_fixed(truth, nominal.base_joints_mm)
    assert fit.observability.full_rank
    np.testing.assert_allclose(fit.parameters[:42], expected[:42], atol=1e-6, rtol=0)
    # held-out poses: the calibrated model predicts the truth, the nominal model does not
    held = np.random.default_rng(9).uniform(-1, 1, (50, 6)) * SPAN
    from hexatherm.core.calibration import CalibrationModel

    true_poses, _ = CalibrationModel(nominal, "joints+gains").predict(truth, held)
    np.testing.assert_allclose(fit.predict(held), true_poses, atol=1e-9, rtol=0)
    assert np.abs(true_poses - held)[:, :3].max() * 1e3 > 5.0
