"""The analytic derivatives the uncertainty's chain rule uses (issue 37: they replaced
central differences), each against central differences of the function it derives."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.carry import shifted_poses
from hexatherm.core.geometry import angle_rates, angles_from_rotation, rotation_from_angles
from hexatherm.core.propagation import shifted_pose_derivative


def skew(omega):
    x, y, z = omega
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_angle_rates_are_the_angles_change_under_a_small_rotation(rng, convention):
    angles = np.column_stack(
        [rng.uniform(-170, 170, 30), rng.uniform(-80, 80, 30), rng.uniform(-170, 170, 30)]
    )
    rates = angle_rates(angles, convention)
    h = 1e-6
    for i in range(30):
        rot = rotation_from_angles(angles[i], convention)
        for axis in range(3):
            omega = np.eye(3)[axis] * h
            plus = angles_from_rotation(_expm(skew(omega)) @ rot, convention)
            minus = angles_from_rotation(_expm(skew(-omega)) @ rot, convention)
            numeric = (plus - minus) / (2 * h)
            np.testing.assert_allclose(rates[i, :, axis], numeric, rtol=0, atol=1e-6 * 57.3)


def _expm(s):
    """Rotation matrix of a skew matrix (Rodrigues)."""
    omega = np.array([s[2, 1], s[0, 2], s[1, 0]])
    angle = np.linalg.norm(omega)
    if angle == 0:
        return np.eye(3)
    k = s / angle
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_shifted_pose_derivative_equals_central_differences(rng, convention):
    """The corrected poses expressed in O carried to R0's state: their derivative by the
    poses against central differences (step 1e-4 mm or deg: truncation ~1e-9)."""
    from hexatherm.core.geometry import transform_from_pose

    shift = transform_from_pose([0.03, -0.02, 0.01, 0.004, -0.003, 0.002], convention)
    poses = np.column_stack([rng.normal(0, 50, (25, 3)), rng.uniform(-20, 20, (25, 3))])
    analytic = shifted_pose_derivative(shift, poses, convention)
    h = 1e-4
    numeric = np.zeros_like(analytic)
    for j in range(6):
        step = np.eye(6)[j] * h
        numeric[:, :, j] = (
            shifted_poses(shift, poses + step, convention)
            - shifted_poses(shift, poses - step, convention)
        ) / (2 * h)
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-7)
    assert np.abs(analytic - np.eye(6)).max() > 1e-5  # the shift does turn the angles


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_shift_derivative_equals_central_differences(rng, convention):
    """The same poses' derivative by the shift's own pose (O's carry to R0's state): the
    analytic one against central differences of the shift's pose, over shifts from
    micrometres to a few mm and degrees (truncation ~1e-9)."""
    from hexatherm.core.carry import shift_derivative
    from hexatherm.core.geometry import pose_from_transform, transform_from_pose

    poses = np.column_stack([rng.normal(0, 50, (25, 3)), rng.uniform(-20, 20, (25, 3))])
    for scale in (1e-3, 1.0, 300.0):
        d = rng.normal(0, 0.01, 6) * scale
        shift = transform_from_pose(d, convention)
        analytic = shift_derivative(shift, poses, convention)
        h = 1e-4
        numeric = np.zeros_like(analytic)
        base = pose_from_transform(shift, convention)
        for j in range(6):
            step = np.eye(6)[j] * h
            numeric[:, :, j] = (
                shifted_poses(transform_from_pose(base + step, convention), poses, convention)
                - shifted_poses(transform_from_pose(base - step, convention), poses, convention)
            ) / (2 * h)
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-7)
        assert np.abs(analytic[:, :3, 3:]).max() > 0.1  # the lever arm of a turn
