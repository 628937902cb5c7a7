"""The twin with a true geometry that differs from the nominal hexapod file (issue 15,
item 6): its measured poses relative to O are the calibration model's predictions (a
second, independent implementation of the same measurement model), and a twin given
the nominal geometry as its truth is the twin without one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.calibration import CalibrationModel, join_parameters, nominal_parameters
from hexatherm.core.effects import ThermocoupleLog
from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.core.twin import predict
from hexatherm.io.config import read_balls, read_hexapod

ROOT = Path(__file__).resolve().parents[2]
SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])


@pytest.fixture(scope="module")
def setup():
    hexapod = read_hexapod(ROOT / "configs" / "symetrie-like.yaml")
    balls = read_balls(ROOT / "configs" / "balls-3.yaml")
    rng = np.random.default_rng(4)
    targets = rng.uniform(-1, 1, (12, 6)) * SPAN
    reference_pose = [0, 0, -10, 0, 0, 0]
    steps = [("O", "origin", np.zeros(6)), ("R0", "reference", reference_pose)]
    for i, pose in enumerate(targets):
        steps += [(f"S{i + 1}", "target", pose), (f"R{i + 1}", "reference", reference_pose)]
    plan = Plan.from_steps(steps)
    t = np.arange(len(plan.labels)) * 60.0
    reference = hexapod.legs.reference_temperature_C  # no heat: no growth
    log = ThermocoupleLog(t, np.full((t.size, 6), reference))
    truth = join_parameters(
        hexapod.base_joints_mm + rng.normal(0, 0.05, (6, 3)),
        hexapod.platform_joints_mm + rng.normal(0, 0.05, (6, 3)),
        rng.normal(0, 0.03, 6),
        rng.normal(0, 2e-4, 6),
    )
    origin2cmm = transform_from_pose([450, 320, 210, 0, 0, 15], hexapod.convention)
    return hexapod, balls, plan, t, log, truth, origin2cmm


def test_measured_poses_are_the_calibration_models_predictions(setup) -> None:
    hexapod, balls, plan, t, log, truth, origin2cmm = setup
    steps = predict(hexapod, plan, t, log, balls.centres_mm, origin2cmm, true_parameters=truth)
    model = CalibrationModel(hexapod, "joints+gains")
    expected, _ = model.predict(truth, plan.poses)
    np.testing.assert_allclose(steps.pose, expected, atol=1e-9, rtol=0)
    # and the errors are there to see: microns to a tenth of a millimetre
    error_um = np.abs(steps.pose - plan.poses)[:, :3].max() * 1e3
    assert 5.0 < error_um < 500.0


def test_the_nominal_geometry_as_truth_is_no_truth(setup) -> None:
    hexapod, balls, plan, t, log, _, origin2cmm = setup
    plain = predict(hexapod, plan, t, log, balls.centres_mm, origin2cmm)
    same = predict(
        hexapod,
        plan,
        t,
        log,
        balls.centres_mm,
        origin2cmm,
        true_parameters=nominal_parameters(hexapod),
    )
    np.testing.assert_allclose(same.pose, plain.pose, atol=1e-12, rtol=0)
    np.testing.assert_allclose(same.centres_cmm_mm, plain.centres_cmm_mm, atol=1e-12, rtol=0)
    np.testing.assert_allclose(plain.pose, plan.poses, atol=1e-9, rtol=0)
