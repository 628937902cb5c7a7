"""Geometric calibration: model, Jacobians, gauge, exact recovery, rank and bad input.

The truth is an independent simulation written here with the hexapod's IGM/FGM and the
geometry module's transforms (not the calibration module): commanded legs from the
nominal IGM, offsets and gains on them, the true hexapod's FGM from the commanded pose,
and the pose relative to the frame the true hexapod reaches for the zero command.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from hexatherm.core.calibration import (
    LEVELS,
    CalibrationModel,
    PoseWeights,
    commanded_leg_lengths,
    compose_pose,
    fit_calibration,
    gauge_directions,
    gauge_fixed,
    join_parameters,
    nominal_parameters,
    pose_covariance_from_sigma,
    relative_pose,
    true_leg_lengths,
)
from hexatherm.core.geometry import pose_from_transform, relative_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError, HexathermError, RankDeficientError

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "symetrie-like.yaml"
#: the issue's box: +-20/+-20/+-15 mm, +-4/+-4/+-8 deg
SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])


def symetrie_like(convention: str = "symetrie") -> Hexapod:
    data = yaml.safe_load(CONFIG.read_text())
    return Hexapod(
        name=data["name"],
        convention=convention,  # type: ignore[arg-type]
        base_joints_mm=data["base_joints"],
        platform_joints_mm=data["platform_joints"],
        stroke_mm=data["stroke"],
    )


def true_geometry(nominal, rng, joint_sigma_mm=0.05, offset_sigma_mm=0.03, gain_sigma=0.0):
    base = nominal.base_joints_mm + rng.normal(0, joint_sigma_mm, (6, 3))
    plat = nominal.platform_joints_mm + rng.normal(0, joint_sigma_mm, (6, 3))
    return base, plat, rng.normal(0, offset_sigma_mm, 6), rng.normal(0, gain_sigma, 6)


def simulate(nominal, base, plat, offsets, gains, commanded):
    """Poses relative to O of a true hexapod for commanded poses (independent of the module)."""
    truth = Hexapod(
        name="truth", convention=nominal.convention, base_joints_mm=base, platform_joints_mm=plat
    )
    home = nominal.igm(np.zeros(6))[0]
    q_cmd = nominal.igm(commanded)
    q_true = q_cmd + offsets + gains * (q_cmd - home)
    stand = truth.fgm(q_true, commanded, tol_mm=1e-12)
    origin = truth.fgm((home + offsets)[None], np.zeros((1, 6)), tol_mm=1e-12)
    cv = nominal.convention
    rel = relative_transform(transform_from_pose(origin, cv), transform_from_pose(stand, cv))
    return pose_from_transform(rel, cv)


def kabsch_onto(points, reference):
    """``points`` moved rigidly onto ``reference`` in least squares (scipy's align_vectors)."""
    pc, rc = points.mean(axis=0), reference.mean(axis=0)
    rot, _ = Rotation.align_vectors(reference - rc, points - pc)
    return rot.apply(points - pc) + rc


@pytest.fixture(scope="module")
def nominal():
    return symetrie_like()


@pytest.fixture(scope="module")
def campaign(nominal):
    rng = np.random.default_rng(15)
    base, plat, offsets, gains = true_geometry(nominal, rng)
    commanded = rng.uniform(-1, 1, (30, 6)) * SPAN
    held = rng.uniform(-1, 1, (200, 6)) * SPAN
    return {
        "truth": (base, plat, offsets, gains),
        "theta": join_parameters(base, plat, offsets, gains),
        "commanded": commanded,
        "measured": simulate(nominal, base, plat, offsets, gains, commanded),
        "held": held,
        "held_true": simulate(nominal, base, plat, offsets, gains, held),
        "cov": pose_covariance_from_sigma(30, 1.0, 5.0),
    }


# ---------------------------------------------------------------------- model
def test_prediction_matches_independent_simulation(nominal, campaign):
    model = CalibrationModel(nominal, "joints+gains")
    base, plat, offsets, _ = campaign["truth"]
    gains = np.array([1e-4, -2e-4, 3e-4, 0.0, -1e-4, 2e-4])
    theta = join_parameters(base, plat, offsets, gains)
    expected = simulate(nominal, base, plat, offsets, gains, campaign["commanded"])
    predicted, _ = model.predict(theta, campaign["commanded"])
    np.testing.assert_allclose(predicted, expected, atol=1e-11, rtol=0)
    # the nominal model predicts the commanded poses themselves
    exact, _ = model.predict(nominal_parameters(nominal), campaign["commanded"])
    np.testing.assert_allclose(exact, campaign["commanded"], atol=1e-11, rtol=0)


def test_true_and_commanded_leg_lengths_invert_each_other():
    rng = np.random.default_rng(0)
    q = 268.0 + rng.uniform(-30, 30, (50, 6))
    home, offsets, gains = np.full(6, 268.0), rng.normal(0, 0.03, 6), rng.normal(0, 1e-4, 6)
    true = true_leg_lengths(q, home, offsets, gains)
    np.testing.assert_allclose(true - q, offsets + gains * (q - home), atol=1e-12)
    np.testing.assert_allclose(commanded_leg_lengths(true, home, offsets, gains), q, atol=1e-12)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_relative_and_composed_poses_with_their_derivatives(convention):
    rng = np.random.default_rng(1)
    a = rng.uniform(-1, 1, (8, 6)) * [30, 30, 30, 20, 20, 40]
    b = rng.uniform(-1, 1, (8, 6)) * [30, 30, 30, 20, 20, 40]
    ta, tb = transform_from_pose(a, convention), transform_from_pose(b, convention)
    for func, expected in (
        (relative_pose, pose_from_transform(relative_transform(ta, tb), convention)),
        (compose_pose, pose_from_transform(ta @ tb, convention)),
    ):
        pose, d_a, d_b = func(a, b, convention)
        np.testing.assert_allclose(pose, expected, atol=1e-12)
        h = 1e-6
        for k in range(6):
            step = np.zeros(6)
            step[k] = h
            num_a = (func(a + step, b, convention)[0] - func(a - step, b, convention)[0]) / (2 * h)
            num_b = (func(a, b + step, convention)[0] - func(a, b - step, convention)[0]) / (2 * h)
            np.testing.assert_allclose(d_a[:, :, k], num_a, atol=1e-7)
            np.testing.assert_allclose(d_b[:, :, k], num_b, atol=1e-7)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_analytic_jacobians_match_central_differences(convention):
    nominal = symetrie_like(convention)
    rng = np.random.default_rng(2)
    base, plat, offsets, _ = true_geometry(nominal, rng)
    theta = join_parameters(base, plat, offsets, rng.normal(0, 1e-4, 6))
    commanded = rng.uniform(-1, 1, (6, 6)) * SPAN
    model = CalibrationModel(nominal, "joints+gains")
    measured = model.predict(theta, commanded)[0] + rng.normal(0, 1e-3, (6, 6))
    _, jac = model.predict(theta, commanded)
    _, leg_jac, by_meas = model.leg_residuals(theta, commanded, measured)
    h = 1e-5
    for k in range(48):
        step = np.zeros(48)
        step[k] = h
        num = model.predict(theta + step, commanded)[0] - model.predict(theta - step, commanded)[0]
        np.testing.assert_allclose(jac[..., k], num / (2 * h), atol=2e-7 * np.abs(jac).max())
        num_leg = (
            model.leg_residuals(theta + step, commanded, measured)[0]
            - model.leg_residuals(theta - step, commanded, measured)[0]
        )
        np.testing.assert_allclose(
            leg_jac[..., k], num_leg / (2 * h), atol=2e-7 * np.abs(leg_jac).max()
        )
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        num = (
            model.leg_residuals(theta, commanded, measured + step)[0]
            - model.leg_residuals(theta, commanded, measured - step)[0]
        )
        np.testing.assert_allclose(by_meas[..., k], num / (2 * h), atol=1e-7)


# ---------------------------------------------------------------------- gauge
def test_moving_the_base_rigidly_changes_no_prediction(nominal, campaign):
    model = CalibrationModel(nominal, "joints")
    theta = campaign["theta"]
    before, jac = model.predict(theta, campaign["held"][:50])
    rot = Rotation.from_euler("xyz", [3.0, -2.0, 5.0], degrees=True)
    moved = theta.copy()
    moved[:18] = (rot.apply(theta[:18].reshape(6, 3)) + [4.0, -7.0, 2.5]).ravel()
    after, _ = model.predict(moved, campaign["held"][:50])
    np.testing.assert_allclose(after, before, atol=1e-10, rtol=0)
    # the six gauge directions are exactly the Jacobian's null space over the 42
    gauge = gauge_directions(theta[:18])
    assert np.abs(jac.reshape(-1, 48) @ gauge).max() < 1e-9 * np.abs(jac).max()
    values = np.linalg.svd(jac.reshape(-1, 48)[:, :42], compute_uv=False)
    assert np.sum(values > 1e-8 * values[0]) == 36
    # the gauge's representative: the base Kabsch-aligned onto the nominal base
    fixed = gauge_fixed(moved, nominal.base_joints_mm)
    np.testing.assert_allclose(
        fixed[:18].reshape(6, 3),
        kabsch_onto(moved[:18].reshape(6, 3), nominal.base_joints_mm),
        atol=1e-12,
    )
    change = (fixed - nominal_parameters(nominal))[:18].reshape(6, 3)
    np.testing.assert_allclose(change.sum(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(np.cross(nominal.base_joints_mm, change).sum(axis=0), 0, atol=1e-9)


def test_the_fit_is_unique_after_the_gauge(nominal, campaign):
    args = (nominal, campaign["commanded"], campaign["measured"], campaign["cov"])
    from_nominal = fit_calibration(*args, level="joints")
    rot = Rotation.from_euler("xyz", [1.0, 2.0, -1.5], degrees=True)
    start = campaign["theta"].copy()
    start[:18] = (rot.apply(start[:18].reshape(6, 3)) + [1.0, 2.0, -3.0]).ravel()
    start[:42] += np.random.default_rng(3).normal(0, 0.02, 42)
    from_elsewhere = fit_calibration(*args, level="joints", start=start)
    np.testing.assert_allclose(from_elsewhere.parameters, from_nominal.parameters, atol=1e-9)


# ---------------------------------------------------------------------- exact recovery
def test_noise_free_campaign_recovers_the_42_parameters(nominal, campaign):
    fit = fit_calibration(
        nominal, campaign["commanded"], campaign["measured"], campaign["cov"], level="joints"
    )
    base, plat, offsets, _ = campaign["truth"]
    assert fit.observability.rank == 42 and fit.observability.full_rank
    assert fit.dof == 180 - 36 and fit.chi_square < 1e-12
    np.testing.assert_allclose(
        fit.parameters[:18].reshape(6, 3), kabsch_onto(base, nominal.base_joints_mm), atol=1e-6
    )
    np.testing.assert_allclose(fit.parameters[18:36].reshape(6, 3), plat, atol=1e-6)
    np.testing.assert_allclose(fit.leg_offsets_mm, offsets, atol=1e-6)
    np.testing.assert_array_equal(fit.leg_gains, 0.0)
    # held-out predictions exact to 1e-6 um, the nominal model off by microns
    predicted = fit.predict(campaign["held"])
    np.testing.assert_allclose(predicted, campaign["held_true"], atol=1e-9, rtol=0)
    nominal_error_um = 1e3 * (campaign["held_true"] - campaign["held"])[:, :3]
    assert np.sqrt(np.mean(nominal_error_um**2)) > 5.0


def test_calibrated_hexapod_reproduces_the_truth_from_frame_o(nominal, campaign):
    fit = fit_calibration(
        nominal, campaign["commanded"], campaign["measured"], campaign["cov"], level="joints"
    )
    calibrated = fit.hexapod()
    base, plat, offsets, _ = campaign["truth"]
    home = nominal.zero_pose_leg_length_mm()
    np.testing.assert_allclose(calibrated.igm(np.zeros(6))[0], home + offsets, atol=1e-9)
    q_true = true_leg_lengths(nominal.igm(campaign["held"]), home, fit.leg_offsets_mm, 0.0)
    poses = calibrated.fgm(q_true, campaign["held"])
    np.testing.assert_allclose(poses, campaign["held_true"], atol=1e-9, rtol=0)
    np.testing.assert_allclose(calibrated.platform_joints_mm, plat, atol=1e-6)
    assert calibrated.stroke_mm is not None and calibrated.name == nominal.name
    # the base in O is the truth's base in the frame it reaches at the zero command
    truth = Hexapod(name="t", convention="symetrie", base_joints_mm=base, platform_joints_mm=plat)
    origin = truth.fgm((home + offsets)[None], np.zeros((1, 6)), tol_mm=1e-12)[0]
    rot = Rotation.from_euler("xyz", origin[3:], degrees=True)
    np.testing.assert_allclose(
        calibrated.base_joints_mm, rot.inv().apply(base - origin[:3]), atol=1e-6
    )
    # its covariance: the O-frame parameters predict the same, so their uncertainty is
    # that of the gauge-fixed ones carried over (same predicted-pose covariance)
    theta_o, cov_o = fit.origin_parameters()
    np.testing.assert_allclose(theta_o[:18].reshape(6, 3), calibrated.base_joints_mm, atol=1e-12)
    model = fit.model
    _, jac = model.predict(theta_o, campaign["held"][:5])
    pred_cov = jac @ cov_o @ np.swapaxes(jac, 1, 2)
    np.testing.assert_allclose(
        pred_cov, fit.predicted_covariance(campaign["held"][:5]), rtol=1e-6, atol=1e-18
    )


@pytest.mark.parametrize("level", ["offsets", "joints+gains"])
def test_other_levels_recover_their_parameters(nominal, level):
    rng = np.random.default_rng(4)
    commanded = rng.uniform(-1, 1, (30, 6)) * SPAN
    if level == "offsets":
        base, plat = nominal.base_joints_mm, nominal.platform_joints_mm
        offsets, gains = rng.normal(0, 0.03, 6), np.zeros(6)
    else:
        base, plat, offsets, gains = true_geometry(nominal, rng, gain_sigma=2e-4)
    measured = simulate(nominal, base, plat, offsets, gains, commanded)
    fit = fit_calibration(
        nominal, commanded, measured, pose_covariance_from_sigma(30, 1.0, 5.0), level=level
    )
    assert fit.observability.rank == {"offsets": 6, "joints+gains": 48}[level]
    np.testing.assert_allclose(fit.leg_offsets_mm, offsets, atol=1e-7)
    np.testing.assert_allclose(fit.leg_gains, gains, atol=1e-9)
    np.testing.assert_allclose(fit.parameters[18:36].reshape(6, 3), plat, atol=1e-7)


# ---------------------------------------------------------------------- rank and refusals
def test_translation_only_poses_are_rank_24_of_42_and_refused(nominal, campaign):
    commanded = campaign["commanded"].copy()
    commanded[:, 3:] = 0.0
    base, plat, offsets, gains = campaign["truth"]
    measured = simulate(nominal, base, plat, offsets, gains, commanded)
    with pytest.raises(RankDeficientError) as info:
        fit_calibration(nominal, commanded, measured, campaign["cov"], level="joints")
    error = info.value
    assert (error.rank, error.n_parameters) == (24, 42)
    assert error.directions.shape == (18, 48)
    assert "rank 24 of 42" in str(error) and "Rx, Ry, Rz" in str(error)
    # the unseen directions move each leg's base and platform joint together
    pairs = np.zeros((18, 48))
    pairs[np.arange(18), np.arange(18)] = pairs[np.arange(18), 18 + np.arange(18)] = 1.0
    model = CalibrationModel(nominal, "joints")
    _, jac = model.predict(model.theta0, commanded)
    assert np.abs(jac.reshape(-1, 48) @ pairs.T).max() < 1e-12
    # the offsets alone are identified from the same poses
    fit = fit_calibration(nominal, commanded, measured, campaign["cov"], level="offsets")
    assert fit.observability.rank == 6 and fit.observability.reason == ""


def test_bad_input_is_refused_with_clear_errors(nominal, campaign):
    commanded, measured, cov = campaign["commanded"], campaign["measured"], campaign["cov"]
    with pytest.raises(CalibrationError, match="unknown calibration level"):
        fit_calibration(nominal, commanded, measured, cov, level="everything")
    with pytest.raises(CalibrationError, match="29 measured poses for 30"):
        fit_calibration(nominal, commanded, measured[:29], cov)
    with pytest.raises(CalibrationError, match="at least 7 poses"):
        fit_calibration(nominal, commanded[:6], measured[:6], cov[:6])
    bad = cov.copy()
    bad[7] = 0.0
    with pytest.raises(CalibrationError, match=r"not positive definite \(pose index 7\)"):
        fit_calibration(nominal, commanded, measured, bad)
    with pytest.raises(CalibrationError, match="shape"):
        fit_calibration(nominal, commanded, measured, cov[:, :3, :3])
    with pytest.raises(CalibrationError, match="unknown residual space"):
        fit_calibration(nominal, commanded, measured, cov, residuals="joint")
    start = nominal_parameters(nominal)
    start[45] = 1e-3
    with pytest.raises(CalibrationError, match="leg4_gain"):
        fit_calibration(nominal, commanded, measured, cov, level="joints", start=start)
    assert issubclass(CalibrationError, HexathermError)
    assert LEVELS == ("offsets", "joints", "joints+gains")


def test_full_covariance_weights_equal_blocks_when_block_diagonal(campaign):
    rng = np.random.default_rng(5)
    a = rng.normal(size=(4, 6, 6))
    blocks = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(6)
    full = np.zeros((24, 24))
    for k in range(4):
        full[6 * k : 6 * k + 6, 6 * k : 6 * k + 6] = blocks[k]
    x = rng.normal(size=(4, 6))
    w_block, w_full = PoseWeights(blocks, 4), PoseWeights(full, 4)
    np.testing.assert_allclose(w_block.whiten(x), w_full.whiten(x), atol=1e-12)
    # whitening makes the covariance the identity: L^-1 C L^-T = I
    white = w_full.whiten(np.eye(24).reshape(24, 4, 6).transpose(1, 2, 0))
    np.testing.assert_allclose(white @ full @ white.T, np.eye(24), atol=1e-10)
    np.testing.assert_allclose(
        w_full.subset([1, 3]).covariance, full[np.r_[6:12, 18:24]][:, np.r_[6:12, 18:24]]
    )
