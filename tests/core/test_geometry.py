"""Pose conventions and transforms, checked against scipy's Rotation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hexatherm.core import geometry as g


@pytest.mark.parametrize(("convention", "seq"), [("symetrie", "xyz"), ("pi", "XYZ")])
def test_rotation_matches_scipy(convention, seq, rng):
    angles = rng.uniform(-170, 170, size=(200, 3))
    angles[:, 1] = rng.uniform(-85, 85, size=200)
    ours = g.rotation_from_angles(angles, convention)
    theirs = Rotation.from_euler(seq, angles, degrees=True).as_matrix()
    np.testing.assert_allclose(ours, theirs, atol=1e-14)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_pose_round_trip(convention, rng):
    poses = np.column_stack(
        [
            rng.uniform(-500, 500, (300, 3)),
            rng.uniform(-179, 179, 300),
            rng.uniform(-89, 89, 300),
            rng.uniform(-179, 179, 300),
        ]
    )
    back = g.pose_from_transform(g.transform_from_pose(poses, convention), convention)
    np.testing.assert_allclose(back, poses, atol=1e-9)


def test_conventions_differ_and_are_each_others_reverse(rng):
    angles = rng.uniform(-30, 30, size=3)
    sym = g.rotation_from_angles(angles, "symetrie")
    pi = g.rotation_from_angles(angles, "pi")
    assert np.abs(sym - pi).max() > 1e-3
    # R_pi(a) = Rx Ry Rz = (Rz(-c) Ry(-b) Rx(-a))^T = R_sym(-a)^T
    np.testing.assert_allclose(pi, g.rotation_from_angles(-angles, "symetrie").T, atol=1e-15)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_rotation_derivatives_match_finite_differences(convention, rng):
    angles = rng.uniform(-20, 20, size=3)
    analytic = g.rotation_derivatives(angles, convention)
    h = 1e-6
    for k in range(3):
        step = np.zeros(3)
        step[k] = h
        numeric = (
            g.rotation_from_angles(angles + step, convention)
            - g.rotation_from_angles(angles - step, convention)
        ) / (2 * h)
        np.testing.assert_allclose(analytic[k], numeric, atol=1e-9)


def test_compose_and_invert(rng):
    a2b = g.transform_from_pose(rng.uniform(-10, 10, 6))
    b2c = g.transform_from_pose(rng.uniform(-10, 10, 6))
    a2c = b2c @ a2b
    np.testing.assert_allclose(g.relative_transform(b2c @ np.eye(4), a2c), a2b, atol=1e-12)
    np.testing.assert_allclose(g.invert_transform(a2c) @ a2c, np.eye(4), atol=1e-12)
    pts = rng.normal(size=(5, 3))
    np.testing.assert_allclose(
        g.apply_transform(a2c, pts),
        g.apply_transform(b2c, g.apply_transform(a2b, pts)),
        atol=1e-12,
    )


def test_checks_have_precise_messages():
    with pytest.raises(ValueError, match=r"shape \(6,\) or \(N, 6\), got \(5,\)"):
        g.check_poses([0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="non-finite value \\(row 0, component 2\\)"):
        g.check_poses([0, 0, np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match="unknown rotation convention 'zyx'"):
        g.rotation_from_angles([0, 0, 0], "zyx")
    bad = np.eye(4)
    bad[0, 0] = -1
    with pytest.raises(ValueError, match="not a proper rotation"):
        g.check_transforms(bad)


def _angle_rates_before(angles, convention):
    """``angle_rates`` as it was (issue 37 replaced it by its closed form): the inverse of
    the matrix whose column k is ``vee(dR/dangle_k R^T)``, from the derivatives."""
    a = np.asarray(angles, dtype=float)
    rot = g.rotation_from_angles(a, convention)
    skew = g.rotation_derivatives(a, convention) @ np.swapaxes(rot, -1, -2)[..., None, :, :]
    columns = np.stack([skew[..., 2, 1], skew[..., 0, 2], skew[..., 1, 0]], axis=-1)
    velocities = np.swapaxes(columns, -1, -2)
    return velocities, np.linalg.inv(velocities)


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_closed_form_angle_rates_equal_the_former_inverse(convention, rng):
    # random angles, zero, +-180 and near the gimbal lock (Ry -> +-90: cond ~ 1/cos Ry)
    angles = np.vstack(
        [
            np.column_stack(
                [
                    rng.uniform(-180, 180, 500),
                    rng.uniform(-89, 89, 500),
                    rng.uniform(-180, 180, 500),
                ]
            ),
            [[0.0, 0.0, 0.0], [180.0, 0.0, -180.0], [30.0, 89.9, -40.0], [-5.0, -89.99, 170.0]],
        ]
    )
    velocities, rates = _angle_rates_before(angles, convention)
    ours = g.angle_rates(angles, convention)
    # relative to each matrix's size: the former inverse loses ~cond * eps near the lock
    size = np.abs(rates).max(axis=(1, 2))[:, None, None]
    assert np.all(np.abs(ours - rates) <= 1e-12 * size)
    np.testing.assert_allclose(g.angle_velocities(angles, convention), velocities, atol=1e-15)
    # and each is the other's inverse (the identity to rounding)
    np.testing.assert_allclose(
        g.angle_velocities(angles, convention) @ ours,
        np.broadcast_to(np.eye(3), ours.shape),
        atol=1e-9,
    )
    # one pose (no leading axis) as many
    assert g.angle_rates(angles[3], convention).shape == (3, 3)
