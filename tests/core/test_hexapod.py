"""IGM/FGM round trips, the analytic Jacobian, and FGM failure modes."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import ConvergenceError, SingularityError
from tests.conftest import make_hexapod, random_poses


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_igm_fgm_round_trip(convention, rng):
    hexapod = make_hexapod(convention)
    poses = random_poses(rng, 2000)
    q = hexapod.igm(poses)
    back = hexapod.fgm(q)
    np.testing.assert_allclose(hexapod.igm(back), q, atol=1e-10, rtol=0)
    np.testing.assert_allclose(back[:, :3], poses[:, :3], atol=1e-9, rtol=0)
    np.testing.assert_allclose(back[:, 3:], poses[:, 3:], atol=1e-9, rtol=0)


def test_igm_by_hand():
    hexapod = make_hexapod()
    pose = np.array([1.0, -2.0, 3.0, 0.5, -0.4, 0.3])
    rot = (
        __import__("scipy")
        .spatial.transform.Rotation.from_euler("xyz", pose[3:], degrees=True)
        .as_matrix()
    )
    expected = [
        np.linalg.norm(pose[:3] + rot @ p - b)
        for p, b in zip(hexapod.platform_joints_mm, hexapod.base_joints_mm, strict=True)
    ]
    np.testing.assert_allclose(hexapod.igm(pose)[0], expected, atol=1e-12)


def test_zero_pose_has_equal_legs(hexapod):
    q0 = hexapod.zero_pose_leg_length_mm()
    assert np.ptp(q0) < 1e-12
    assert 200 < q0[0] < 300


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_jacobian_matches_finite_differences(convention, rng):
    hexapod = make_hexapod(convention)
    poses = random_poses(rng, 20)
    jac = hexapod.jacobian(poses)
    h = 1e-4
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        numeric = (hexapod.igm(poses + step) - hexapod.igm(poses - step)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-8)


def test_fgm_reports_non_convergence(hexapod):
    q = hexapod.igm(np.zeros(6))
    q[0, 0] += 1e3  # no pose has one leg a metre longer than the others
    with pytest.raises(ConvergenceError, match=r"pose index 0, leg length residual"):
        hexapod.fgm(q, max_iter=5)


def test_fgm_names_the_failing_pose(hexapod, rng):
    q = hexapod.igm(random_poses(rng, 5))
    q[3] += [400.0, -150.0, 0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ConvergenceError, match=r"pose index 3"):
        hexapod.fgm(q)


def test_fgm_detects_singular_jacobian():
    # all joints on one radius and no twist between base and platform: at the
    # pose where the legs are parallel, the rotation about Z is unconstrained
    base = np.array([[np.cos(a), np.sin(a), -1.0] for a in np.deg2rad(np.arange(6) * 60.0)]) * 100
    base[:, 2] = -200.0
    plat = base.copy()
    plat[:, 2] = 0.0
    hexapod = Hexapod(
        name="degenerate", convention="symetrie", base_joints_mm=base, platform_joints_mm=plat
    )
    q = hexapod.igm(np.zeros(6))
    with pytest.raises(SingularityError, match="singular Jacobian at pose index 0"):
        hexapod.fgm(q, initial_poses=np.zeros(6))


def test_stroke_check():
    hexapod = Hexapod.symmetric(
        base_radius_mm=150,
        platform_radius_mm=100,
        base_half_angle_deg=10,
        platform_half_angle_deg=10,
        height_mm=220,
        stroke_mm=(230.0, 250.0),
    )
    q = hexapod.igm([[0, 0, 0, 0, 0, 0], [0, 0, 30, 0, 0, 0]])
    mask = hexapod.check_stroke(q)
    assert not mask[0].any() and mask[1].all()


def test_bad_geometry_rejected():
    with pytest.raises(ValueError, match="base_joints_mm must be six finite"):
        Hexapod(
            name="x",
            convention="symetrie",
            base_joints_mm=np.zeros((5, 3)),
            platform_joints_mm=np.zeros((6, 3)),
        )
