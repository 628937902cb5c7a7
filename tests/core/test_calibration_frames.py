"""The calibration's rigid part as controller frames (issue 33 item 7): against a true
geometry whose joints' error is a known rigid motion (base by ``A``, platform by ``C``),
where the frames that serve are known by hand: ``G = H = C^-1`` once the base is put in
frame O (the platform frame at the zero command, ``Y0 = A C^-1``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from hexatherm.core.calibration.frames import (
    command,
    corrected_frames,
    fit_frames,
    frame_correction,
    frames_covariance,
)
from hexatherm.core.frames import campaign_transforms, machine_in_origin, poses_from_origin
from hexatherm.core.geometry import (
    apply_transform,
    invert_transform,
    pose_from_transform,
    to_um_urad,
    transform_from_pose,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError

A = transform_from_pose([0.21, -0.13, 0.08, 0.03, -0.02, 0.05])
C = transform_from_pose([-0.05, 0.11, -0.04, -0.04, 0.025, -0.03])
RNG = np.random.default_rng(7)
POSES = np.concatenate([np.zeros((1, 6)), RNG.uniform(-1, 1, (24, 6)) * [8, 8, 5, 2, 2, 3]])


def rigidly_wrong(nominal: Hexapod) -> Hexapod:
    """The true hexapod: the nominal joints moved by ``A`` (base) and ``C`` (platform),
    the base put in frame O, the true platform at the zero command ``Y0 = A C^-1``."""
    y0 = A @ invert_transform(C)
    base_o = apply_transform(invert_transform(y0), apply_transform(A, nominal.base_joints_mm))
    return replace(
        nominal,
        base_joints_mm=base_o,
        platform_joints_mm=apply_transform(C, nominal.platform_joints_mm),
    )


def hexapods() -> tuple[Hexapod, Hexapod]:
    """The nominal hexapod and the true one."""
    nominal = Hexapod.symmetric(
        base_radius_mm=150,
        platform_radius_mm=100,
        base_half_angle_deg=10,
        platform_half_angle_deg=10,
        height_mm=200,
    )
    return nominal, rigidly_wrong(nominal)


def test_a_rigid_joint_error_is_taken_exactly_by_the_frames_known_by_hand():
    nominal, true = hexapods()

    def predict(given: np.ndarray) -> np.ndarray:  # the controller's IGM, the truth's FGM
        return true.fgm(nominal.igm(given), initial_poses=given)

    # without frames the poses are off by tens of um (the test can fail)
    assert np.abs(to_um_urad(predict(POSES) - POSES)).max() > 20.0
    rigid = frame_correction(
        nominal.base_joints_mm,
        nominal.platform_joints_mm,
        true.base_joints_mm,
        true.platform_joints_mm,
    )
    want = pose_from_transform(invert_transform(np.stack([C, C])), "symetrie").ravel()
    np.testing.assert_allclose(rigid.values("symetrie"), want, atol=1e-12)
    assert np.abs(rigid.base_rest_mm).max() < 1e-12 and np.abs(rigid.platform_rest_mm).max() < 1e-12
    # the least-squares frames from zero find the same, and the poses are reached
    frames = fit_frames(predict, POSES, "symetrie")
    np.testing.assert_allclose(frames.values, want, atol=1e-9)
    assert np.abs(frames.residuals_um_urad).max() < 1e-5
    reached = predict(command(frames.values, POSES, "symetrie"))
    assert np.abs(to_um_urad(reached - POSES)).max() < 1e-5


def test_a_non_rigid_error_the_frames_never_make_worse_and_their_u_by_hand():
    nominal, true = hexapods()
    bent = true.base_joints_mm.copy()
    bent[2] += [0.05, -0.03, 0.02]  # one joint off the rigid motion: no frame takes it
    true = replace(true, base_joints_mm=bent)

    def predict(given: np.ndarray) -> np.ndarray:
        return true.fgm(nominal.igm(given), initial_poses=given)

    before = np.sum(to_um_urad(predict(POSES) - POSES) ** 2)
    frames = fit_frames(predict, POSES, "symetrie")
    assert np.sum(frames.residuals_um_urad**2) < before
    # the values' covariance from a parameter that shifts every Tx residual by 1 mm per
    # unit: G's translation adds to every pose's, so G's Tx undoes it (-1 mm per unit,
    # to the model's slope, 1e-3): variance 4 mm^2 for a variance 4 of the parameter
    by_tx = np.zeros((POSES.size, 1))
    by_tx[0::6, 0] = 1e3  # um per unit
    cov = frames.covariance(by_tx, np.eye(1) * 4.0)
    assert abs(cov[0, 0] - 4.0) < 4e-3 * 4.0
    assert np.abs(np.diag(cov)[1:]).max() < 1e-3


def test_frames_set_during_the_campaign_map_the_poses_and_compose_with_the_fitted_ones():
    """A campaign measured with frames ``U0``, ``O0`` set on a controller (its IGM the
    nominal one of ``M = U0 X O0^-1``) whose hexapod is rigidly wrong: relative to frame
    O (where the origin step put the platform) it is a campaign without frames of the
    nominal hexapod with its base moved by ``O0 U0^-1``, commanded ``O0 X O0^-1`` (the
    same legs); the frames fitted there, composed with ``U0``, ``O0``, make the true
    platform reach ``O0 X O0^-1`` relative to frame O (the object frame at ``X`` from
    where it stood at the origin step) within 1 nm and 1 nrad."""
    nominal, true = hexapods()
    during = np.array([0.8, -1.5, 2.0, 0.4, -0.3, 1.2, 2.0, 1.0, 30.0, -0.5, 0.7, 20.0])
    user, obj = campaign_transforms(during)

    def controller(frames: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """Where the true platform stands (machine frame) for poses commanded with frames:
        the controller's nominal IGM of ``U X O^-1``, the truth's FGM."""
        u, o = campaign_transforms(frames)
        m = pose_from_transform(u @ transform_from_pose(poses) @ invert_transform(o))
        return true.fgm(nominal.igm(m), initial_poses=m)

    origin = transform_from_pose(controller(during, np.zeros((1, 6)))[0])  # frame O

    def measured(frames: np.ndarray, poses: np.ndarray) -> np.ndarray:
        placed = transform_from_pose(controller(frames, poses), "symetrie")
        return pose_from_transform(invert_transform(origin) @ placed, "symetrie")

    # the same legs through the campaign's frames and through frame O's nominal
    shifted = replace(
        nominal,
        base_joints_mm=apply_transform(machine_in_origin(user, obj), nominal.base_joints_mm),
    )
    y = poses_from_origin(POSES, obj, "symetrie")
    machine = pose_from_transform(
        user @ transform_from_pose(POSES) @ invert_transform(obj), "symetrie"
    )
    np.testing.assert_allclose(shifted.igm(y), nominal.igm(machine), atol=1e-10)
    t_o = transform_from_pose(
        true.fgm(shifted.igm(np.zeros((1, 6))), initial_poses=np.zeros((1, 6)))[0]
    )

    def predict(given: np.ndarray) -> np.ndarray:  # frame O's world: no frames
        placed = transform_from_pose(true.fgm(shifted.igm(given), initial_poses=given))
        return pose_from_transform(invert_transform(t_o) @ placed, "symetrie")

    np.testing.assert_allclose(predict(y), measured(during, POSES), atol=1e-9)
    # without composing (the fitted frames alone), or with none, the poses are missed
    frames = fit_frames(predict, y, "symetrie")
    written = corrected_frames(frames.values, "symetrie", during)
    for wrong in (frames.values, during):
        assert np.abs(to_um_urad(measured(wrong, POSES) - y)).max() > 20.0
    error = to_um_urad(measured(written, POSES) - y)
    assert np.abs(error).max() < 1e-3, error
    # with no frames during the campaign, the fitted frames as they are
    np.testing.assert_allclose(corrected_frames(frames.values, "pi"), frames.values, atol=1e-12)


def test_the_composed_frames_covariance_is_the_spread_of_composed_samples():
    """frames_covariance against a second method: the covariance of the composed frames
    of 4000 samples of the fitted ones (small: the composition is smooth there)."""
    rng = np.random.default_rng(3)
    values = np.array([0.1, -0.2, 0.3, 0.01, -0.02, 0.03, -0.05, 0.04, 0.02, 0.0, 0.01, -0.01])
    during = np.array([0.8, -1.5, 2.0, 0.4, -0.3, 1.2, 2.0, 1.0, 30.0, -0.5, 0.7, 20.0])
    root = rng.normal(size=(12, 12)) * 1e-3
    cov = root @ root.T
    got = frames_covariance(values, cov, "symetrie", during)
    samples = rng.multivariate_normal(values, cov, 4000)
    composed = np.array([corrected_frames(v, "symetrie", during) for v in samples])
    spread = np.cov(composed.T)
    scale = np.sqrt(np.outer(np.diag(spread), np.diag(spread)))
    assert np.abs(got - spread).max() / scale.max() < 0.1
    assert np.abs(np.diag(got) / np.diag(spread) - 1).max() < 0.1
    # the composition moves it: not the fitted values' covariance
    assert np.abs(got - cov).max() > 0.2 * np.abs(cov).max()
    # with no frames during the campaign, the same covariance
    np.testing.assert_allclose(frames_covariance(values, cov, "symetrie"), cov, atol=1e-12)


def test_the_frames_need_two_poses():
    with pytest.raises(CalibrationError, match="at least 2 commanded poses"):
        fit_frames(lambda given: given, POSES[:1], "symetrie")
