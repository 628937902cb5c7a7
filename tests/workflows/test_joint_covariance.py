"""The joint covariance of all targets' poses (what calibrate weighs with) agrees with the
two other products of the same Jacobian: each target's 12 x 12 block, and each output's
covariance between targets."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.propagation import target_jacobian
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import (
    centre_covariance,
    joint_pose_covariance,
    pose_chain,
)
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("corrected", [True, False])
def test_joint_covariance_matches_the_blocks_and_the_between_target_terms(corrected) -> None:
    result = process_session(SHIPPED / "paper-zero-pose")
    joint = joint_pose_covariance(result, corrected=corrected)
    centres = centre_covariance(result)
    jacobian = target_jacobian(pose_chain(result), result.centres.centres_mm)
    blocks = jacobian.covariance(centres.cov_mm2)  # (M, 12, 12)
    between = jacobian.between_targets(centres.cov_mm2)  # (12, M, M)
    m = blocks.shape[0]
    out = slice(6, 12) if corrected else slice(0, 6)
    scale = np.abs(joint).max()
    for a in range(m):
        np.testing.assert_allclose(
            joint[6 * a : 6 * a + 6, 6 * a : 6 * a + 6], blocks[a, out, out], atol=1e-12 * scale
        )
    for y in range(6):
        np.testing.assert_allclose(joint[y::6, y::6], between[out][y], atol=1e-12 * scale, rtol=0)
    np.testing.assert_allclose(joint, joint.T, atol=0)
    assert np.linalg.eigvalsh(joint).min() > -1e-12 * scale
    # the shared frame O correlates the targets: the terms between them are not zero
    assert np.abs(joint[0:6, 6:12]).max() > 0.1 * np.abs(joint[0:6, 0:6]).max()
