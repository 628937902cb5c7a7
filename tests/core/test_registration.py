"""Kabsch registration: exact recovery, no reflections, weights, preconditions."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core import registration
from hexatherm.core.geometry import apply_transform, transform_from_pose
from hexatherm.core.registration import check_ball_layout, register
from hexatherm.errors import RegistrationError
from tests.conftest import BALLS


def random_transforms(rng, n):
    poses = np.column_stack(
        [
            rng.uniform(-800, 800, (n, 3)),
            rng.uniform(-180, 180, (n, 1)),
            rng.uniform(-89, 89, (n, 1)),
            rng.uniform(-180, 180, (n, 1)),
        ]
    )
    return transform_from_pose(poses)


def test_recovers_random_transforms_exactly(rng):
    truth = random_transforms(rng, 500)
    centres = apply_transform(truth, BALLS)
    fit = register(centres, BALLS)
    np.testing.assert_allclose(fit.platform2cmm, truth, atol=1e-11)
    assert fit.rms_um.max() < 1e-8


def test_never_returns_a_reflection(rng):
    # mirrored measurements: the best proper rotation, not the reflection
    truth = random_transforms(rng, 50)
    centres = apply_transform(truth, BALLS * [1, 1, -1])
    fit = register(centres, BALLS)
    np.testing.assert_allclose(np.linalg.det(fit.platform2cmm[:, :3, :3]), 1.0, atol=1e-12)


def test_least_squares_optimum_with_noise(rng):
    # the residuals of a least-squares rigid fit sum to zero and are orthogonal
    # to the rotation generators: no small rigid move lowers the cost
    truth = random_transforms(rng, 1)
    centres = apply_transform(truth, BALLS) + rng.normal(scale=1e-3, size=(1, 3, 3))
    fit = register(centres, BALLS)
    res = fit.residuals_mm[0]
    np.testing.assert_allclose(res.sum(axis=0), 0.0, atol=1e-12)
    moved = apply_transform(fit.platform2cmm[0], BALLS)
    np.testing.assert_allclose(np.cross(moved - moved.mean(0), res).sum(axis=0), 0.0, atol=1e-10)


def test_weights_ignore_a_zero_weight_ball(rng):
    balls = np.vstack([BALLS, [[0.0, 0.0, 60.0]]])
    truth = random_transforms(rng, 1)
    centres = apply_transform(truth, balls)
    centres[0, 3] += [0.5, -0.3, 0.2]  # a bad fourth ball
    fit = register(centres, balls, weights=[1, 1, 1, 0])
    np.testing.assert_allclose(fit.platform2cmm[0], truth[0], atol=1e-11)


def test_preconditions_have_messages():
    with pytest.raises(RegistrationError, match="at least 3 balls"):
        check_ball_layout(BALLS[:2])
    with pytest.raises(RegistrationError, match="collinear"):
        check_ball_layout([[0, 0, 0], [10, 10, 10], [20.0, 20.0, 20.0 + 1e-12]])
    with pytest.raises(RegistrationError, match=r"shape \(N, 3, 3\)"):
        register(np.zeros((2, 4, 3)), BALLS)
    with pytest.raises(RegistrationError, match="step index 1 have a non-finite"):
        register(np.stack([BALLS, BALLS * np.nan]), BALLS)


#: how far one row's transform registered alone may lie from the same row registered
#: among many: rounding, not method. numpy's matmul and einsum choose their kernels, and
#: with them the order in which a sum over the balls is added, by the arrays' shapes and
#: by the CPU's SIMD (an AVX-512 CPU adds a 40-row batch otherwise than one row), so the
#: last bits may differ. Horn's eigenvector amplifies a relative rounding of 1e-16 by at
#: most 1/_SEPARATION = 20; the bounds keep a factor of 50 over that: 1e-13 on the
#: rotation's entries (rad), 1e-10 mm on the translation (coordinates up to 1400 mm,
#: whose own spacing is 2e-13 mm), a million times below a CMM's 0.1 um resolution
ROW_ROTATION_TOL = 1e-13
ROW_TRANSLATION_TOL_MM = 1e-10


def test_many_rows_register_as_each_row_alone(rng):
    """Horn's minors are gathered into one array for a few rows and taken in place for
    many (registration._minors): the same products, so a row's transform does not
    depend on how many rows come with it (to rounding: :data:`ROW_ROTATION_TOL`); and
    both are Kabsch's SVD solution."""
    truth = random_transforms(rng, 40)
    centres = apply_transform(truth, BALLS) + rng.normal(scale=1e-2, size=(40, 3, 3))
    together = register(centres, BALLS).platform2cmm
    assert len(together) > registration._GATHER_UP_TO
    alone = np.stack([register(centres[k], BALLS).platform2cmm[0] for k in range(40)])
    np.testing.assert_allclose(alone[:, :3, :3], together[:, :3, :3], rtol=0, atol=ROW_ROTATION_TOL)
    np.testing.assert_allclose(
        alone[:, :3, 3], together[:, :3, 3], rtol=0, atol=ROW_TRANSLATION_TOL_MM
    )
    entries = rng.normal(size=(4, 4, 40))
    gathered = registration._minors(entries[..., :5], registration._UPPER_ENTRIES)
    in_place = registration._minors(entries, registration._UPPER_ENTRIES)[:, :5]
    # elementwise products and differences, no sum: each is correctly rounded (IEEE 754)
    # whatever the SIMD width, so these agree to the bit on every CPU
    assert np.array_equal(gathered, in_place)
    b = BALLS - BALLS.mean(axis=0)
    c = centres - centres.mean(axis=1, keepdims=True)
    kabsch = registration._kabsch(np.swapaxes(c, 1, 2) @ b / 3)
    np.testing.assert_allclose(together[:, :3, :3], kabsch, atol=1e-12)


def test_platform_frames_are_the_registrations_transforms(rng, monkeypatch):
    """The uncertainty's central differences take the transforms alone: the same fit
    (same checks, same arithmetic row by row, in blocks of rows), against register's own
    of all rows at once, with weights, and the same refusal of a non-finite centre."""
    truth = random_transforms(rng, 300)
    centres = apply_transform(truth, BALLS) + rng.normal(0, 1e-3, (300, len(BALLS), 3))
    weights = rng.uniform(0.5, 2.0, (300, len(BALLS)))
    for block in (registration.FRAME_BLOCK, 7, 64):  # in blocks, as whole
        monkeypatch.setattr(registration, "FRAME_BLOCK", block)
        for w in (None, weights):
            frames = registration.platform_frames(centres, BALLS, w)
            # each row its own arithmetic: equal but for what a kernel may order otherwise
            expected = register(centres, BALLS, w).platform2cmm
            np.testing.assert_allclose(frames, expected, rtol=1e-15, atol=1e-12)
    centres[207, 1, 2] = np.nan
    with pytest.raises(RegistrationError, match="step index 207"):
        registration.platform_frames(centres, BALLS)


def central_frame_derivatives(centres, balls, weights, h=1e-4):
    """The derivatives of :func:`platform_frames` by central differences: ``omega`` (the
    rotation's change ``dR R^T``, a skew matrix) and ``dt`` per centre coordinate."""
    frames = registration.platform_frames(centres, balls, weights)
    d_rot = np.zeros(centres.shape[:1] + (3,) + centres.shape[1:])
    d_trans = np.zeros_like(d_rot)
    for ball in range(centres.shape[1]):
        for axis in range(3):
            plus, minus = centres.copy(), centres.copy()
            plus[:, ball, axis] += h
            minus[:, ball, axis] -= h
            up = registration.platform_frames(plus, balls, weights)
            down = registration.platform_frames(minus, balls, weights)
            skew = (
                (up[:, :3, :3] - down[:, :3, :3]) / (2 * h) @ np.swapaxes(frames[:, :3, :3], 1, 2)
            )
            d_rot[:, :, ball, axis] = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], -1)
            d_trans[:, :, ball, axis] = (up[:, :3, 3] - down[:, :3, 3]) / (2 * h)
    return d_rot, d_trans


@pytest.mark.parametrize("n_balls", [3, 5])
def test_frame_derivatives_equal_central_differences(rng, n_balls):
    """The analytic derivative of the registration (implicit function theorem on Horn's
    optimum) against central differences of the fit itself, with and without weights,
    three and five balls (the fifth nearly on a plane with two others), noisy centres."""
    balls = np.vstack([BALLS, [[30.0, -40.0, 55.0], [-20.0, 10.0, -35.0]]])[:n_balls]
    truth = random_transforms(rng, 40)
    centres = apply_transform(truth, balls) + rng.normal(0, 5e-3, (40, n_balls, 3))
    for weights in (None, rng.uniform(0.2, 3.0, (40, n_balls))):
        frames, d_rot, d_trans = registration.frame_derivatives(centres, balls, weights)
        assert np.array_equal(frames, registration.platform_frames(centres, balls, weights))
        num_rot, num_trans = central_frame_derivatives(centres, balls, weights)
        # the differences' truncation (h^2 over the balls' spread squared) and rounding
        # are about 1e-10 of the derivatives; a wrong sign or factor is of their size
        np.testing.assert_allclose(d_rot, num_rot, rtol=0, atol=1e-6 * np.abs(num_rot).max())
        np.testing.assert_allclose(d_trans, num_trans, rtol=0, atol=1e-6 * np.abs(num_trans).max())
    # a translation of every centre moves the frame's translation alone, one for one
    moved = d_trans.sum(axis=2)
    np.testing.assert_allclose(moved, np.broadcast_to(np.eye(3), moved.shape), atol=1e-9)
    np.testing.assert_allclose(d_rot.sum(axis=2), 0.0, atol=1e-12)
