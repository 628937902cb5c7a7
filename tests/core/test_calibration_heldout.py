"""The held-out folds' refits by Gauss-Newton from the fit to all poses (issue 37)
against the former refits, Levenberg-Marquardt to convergence from the same start; the
derivatives kept factored against the 48-column solve they replace."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.calibration import (
    CalibrationModel,
    fit_calibration,
    fold_of_poses,
    pose_covariance_from_sigma,
)
from hexatherm.core.calibration import heldout as heldout_module
from hexatherm.core.calibration.heldout import heldout_residuals
from hexatherm.core.calibration.model import LEVELS
from hexatherm.core.calibration.weights import PoseWeights
from hexatherm.core.hexapod import NEAR_MM
from tests.conftest import make_hexapod
from tests.core.test_calibration_stats import SIGMA_UM, SIGMA_URAD, noisy_campaign
from tests.core.test_calibration_stats import nominal as nominal  # noqa: F401 (fixture)


def former_heldout(nominal, fit, commanded, measured, weights, folds):
    """As select_level refitted a fold before: fit_calibration from the fit to all poses,
    then the held-out poses predicted."""
    held = np.full(commanded.shape, np.nan)
    for f in np.unique(folds):
        train, test = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
        part = fit_calibration(
            nominal,
            commanded[train],
            measured[train],
            weights.subset(train),
            level=fit.model.level,
            start=fit.parameters,
        )
        held[test] = measured[test] - part.predict(commanded[test])
    return held


@pytest.mark.parametrize("level", LEVELS)
def test_gauss_newton_folds_equal_levenberg_marquardts(nominal, level):  # noqa: F811
    c = noisy_campaign(nominal, 3, n_poses=60, gain_sigma=2e-4)
    cov = pose_covariance_from_sigma(60, SIGMA_UM, SIGMA_URAD)
    weights = PoseWeights(cov, 60)
    folds = fold_of_poses(60, 5)
    fit = fit_calibration(nominal, c["commanded"], c["measured"], weights, level=level)
    held, squares, notes = heldout_residuals(
        nominal, fit, c["commanded"], c["measured"], weights, folds, "pose"
    )
    former = former_heldout(nominal, fit, c["commanded"], c["measured"], weights, folds)
    assert notes == [] and np.all(np.isfinite(held))
    # the same minimum: a tenth of the files' resolution (1e-7 mm; deg likewise)
    assert np.abs(held - former).max() <= 1e-8
    assert np.abs(held).max() > 1e-4  # residuals there are to compare (micrometres)
    white = sum(
        float(w @ w)
        for f in np.unique(folds)
        for w in [weights.subset(np.flatnonzero(folds == f)).whiten(held[folds == f])]
    )
    assert squares == pytest.approx(white, rel=1e-12)


def test_a_fold_not_converged_is_refitted_as_before(nominal, monkeypatch):  # noqa: F811
    c = noisy_campaign(nominal, 4, n_poses=40)
    weights = PoseWeights(pose_covariance_from_sigma(40, SIGMA_UM, SIGMA_URAD), 40)
    folds = fold_of_poses(40, 4)
    fit = fit_calibration(nominal, c["commanded"], c["measured"], weights, level="joints")
    monkeypatch.setattr(heldout_module, "MAX_STEPS", 0)  # never vouched for
    held, _, _ = heldout_residuals(
        nominal, fit, c["commanded"], c["measured"], weights, folds, "pose"
    )
    former = former_heldout(nominal, fit, c["commanded"], c["measured"], weights, folds)
    np.testing.assert_array_equal(held, former)


def test_factored_derivatives_equal_the_solve(nominal):  # noqa: F811
    """dY/dtheta = J^-1 (dq/dtheta - dIGM/dtheta) solved with its 48 columns, as before."""
    c = noisy_campaign(nominal, 5, n_poses=25, gain_sigma=2e-4)
    model = CalibrationModel(nominal, "joints+gains")
    theta = c["theta"]
    geometry = model.hexapod(theta)
    q_cmd = model.commanded_legs(c["commanded"])
    poses, factored = model._stand(geometry, theta, q_cmd, c["commanded"])
    q_true, dq = model._true_legs(theta, q_cmd)
    np.testing.assert_allclose(geometry.igm(poses), q_true, rtol=0, atol=1e-10)
    rhs = dq - model._igm_by_joints(geometry, poses)
    solved = np.linalg.solve(geometry.jacobian(poses), rhs)
    scale = np.abs(solved).max()
    assert np.abs(factored.times() - solved).max() <= 1e-12 * scale
    left = np.random.default_rng(6).normal(size=(25, 6, 6))
    assert np.abs(factored.times(left) - left @ solved).max() <= 1e-12 * np.abs(left @ solved).max()


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_fgm_near_from_far_keeps_the_tolerance_asked(convention):
    """A start beyond NEAR_MM goes to the certified FGM with the tolerance given (it went
    with the FGM's default, 1e-10 mm, whatever was asked)."""
    hexapod = make_hexapod(convention)
    rng = np.random.default_rng(21)
    poses = np.column_stack([rng.uniform(-20, 20, (50, 3)), rng.uniform(-5, 5, (50, 3))])
    q = hexapod.igm(poses)
    far = poses + np.array([5.0, 0, 0, 1.0, 0, 0])
    assert np.abs(hexapod.igm(far) - q).max() > NEAR_MM
    for tol in (1e-6, 1e-12):
        x, jac = hexapod.fgm_near(q, far, tol_mm=tol)
        np.testing.assert_array_equal(x, hexapod.fgm(q, initial_poses=far, tol_mm=tol))
        np.testing.assert_array_equal(jac, hexapod.jacobian(x))
