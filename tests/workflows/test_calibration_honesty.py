"""The calibration's uncertainty is honest over 20 independently simulated campaigns
(issue 15, acceptance): simulate (a true geometry, probing noise, warming legs) ->
process -> calibrate the corrected poses. The parameter error's Mahalanobis distance in
the 36 free coordinates follows its chi-square (mean within 15 % of 36), and the
calibrated model's error on held-out poses is within 1.2x its predicted sigma."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from hexatherm.core.calibration import CalibrationModel
from hexatherm.io.scenario import read_scenario
from hexatherm.workflows.calibrate.run import calibrate, read_campaign
from hexatherm.workflows.simulate.run import simulate
from tests.replicas import write_session
from tests.sessions import calibration_scenario, calibration_targets

ROOT = Path(__file__).resolve().parents[2]
SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])
N_SEEDS = 20


def scenario(seed: int) -> str:
    mats = ", ".join(["{gain_C: 1.0, tau_s: 3600, power: [[0, null]]}"] * 6)
    return calibration_scenario(
        calibration_targets(seed),
        geometry_seed=seed + 500,
        seed=seed,
        points_per_ball=8,
        cmm={"point_noise_um": 0.3},
        thermocouples={"noise_C": 0.02},
        extra=f"heating: {{mats: [{mats}]}}\n",
    )


def test_parameter_errors_follow_their_covariance_over_20_campaigns() -> None:
    held = np.random.default_rng(77).uniform(-1, 1, (100, 6)) * SPAN
    distances, normalized, p_values = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(N_SEEDS):
            path = Path(tmp) / f"s{seed}.yaml"
            path.write_text(scenario(seed))
            read = read_scenario(path)
            folder = Path(tmp) / f"s{seed}"
            write_session(simulate(read).files, folder)
            run = calibrate(read_campaign([folder]), level="joints")
            fit, model = run.fit, run.fit.model
            p_values.append(fit.chi_square_p)
            assert read.true_parameters is not None
            error = model.coordinates(fit.parameters) - model.coordinates(read.true_parameters)
            distances.append(float(error @ np.linalg.solve(fit.covariance_free, error)))
            truth_model = CalibrationModel(model.nominal, "joints+gains")
            true_poses, _ = truth_model.predict(read.true_parameters, held)
            predicted_error = (fit.predict(held) - true_poses) * np.array([1e3] * 3 + [1.0] * 3)
            sigma = fit.predicted_sigma_um_urad(held)
            normalized.append(predicted_error[:, :3] / sigma[:, :3])
    mean = float(np.mean(distances))
    assert abs(mean / 36.0 - 1.0) < 0.15, (mean, distances)
    ratio = float(np.sqrt(np.mean(np.square(normalized))))
    assert ratio < 1.2, ratio
    # the chi-square test: a right model with an honest covariance passes it (p uniform:
    # two of 20 below 0.001 would happen once in 5000; not piled at either end)
    assert sum(p < 1e-3 for p in p_values) <= 1, p_values
    assert 0.2 < float(np.mean(p_values)) < 0.8, p_values
