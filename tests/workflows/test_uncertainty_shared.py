"""Parts of u common to all targets and of their own, and the covariance between targets.

The chain-rule Jacobian's between-target covariance and common parts against the brute
force (every centre coordinate moved one at a time through the whole chain); the files
``process`` writes against the uncertainty they come from. The replicas check the same
numbers against the scatter of new noise (``test_uncertainty_replicas.py``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.core import propagation
from hexatherm.core.propagation import TargetJacobian, output_difference, target_jacobian
from hexatherm.workflows.process import errorterms
from hexatherm.workflows.process.outputs import (
    covariance_frame,
    deviation_columns,
    poses_frame,
    write_results,
)
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.uncertainty import centre_covariance, pose_chain, pose_uncertainty
from tests.workflows.test_uncertainty import points_session

URAD_PER_DEG = np.pi / 180 * 1e6


def brute_force_full(chain, centres, cov, step_mm=1e-3):
    """Covariance (M*12, M*12) of all outputs, the Jacobian one coordinate at a time."""
    n, k = centres.shape[:2]
    pert = np.broadcast_to(centres, (n, k, 3, 2, n, k, 3)).copy()
    for s in range(n):
        for b in range(k):
            for a in range(3):
                pert[s, b, a, 0, s, b, a] += step_mm
                pert[s, b, a, 1, s, b, a] -= step_mm
    out = chain(pert)
    jac = output_difference(out[:, :, :, 0], out[:, :, :, 1]) / (2 * step_mm)  # (n,k,3,M,12)
    jac = jac.reshape(n * k * 3, -1).T
    big = np.zeros((n * k * 3, n * k * 3))
    for i in range(n * k):
        big[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = cov.reshape(-1, 3, 3)[i]
    return jac @ big @ jac.T


@pytest.fixture(scope="module")
def one_sided(tmp_path_factory: pytest.TempPathFactory) -> ProcessResult:
    # R0 S1 S2 R2 S3 S4 R4: R0 is also a reference, some targets use one neighbour
    session = points_session(tmp_path_factory.mktemp("shared") / "s", n_targets=4)
    plan_text = (session / "plan.yaml").read_text()
    (session / "plan.yaml").write_text(re.sub(r"  - \{label: R[13],.*\n", "", plan_text))
    (session / "points.csv").write_text(
        "".join(
            ln
            for ln in (session / "points.csv").read_text().splitlines(keepends=True)
            if not ln.startswith(("R1,", "R3,"))
        )
    )
    return process_session(session)


@pytest.mark.parametrize("dense_limit", [propagation.DENSE_BETWEEN_LIMIT, 0])
def test_between_target_covariance_equals_the_brute_force_one(
    one_sided: ProcessResult, dense_limit: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(propagation, "DENSE_BETWEEN_LIMIT", dense_limit)  # 0: sparse
    chain = pose_chain(one_sided)
    centres = one_sided.centres.centres_mm
    cov = centre_covariance(one_sided).cov_mm2
    full = brute_force_full(chain, centres, cov)  # (M*12, M*12)
    m = full.shape[0] // 12
    slow = full.reshape(m, 12, m, 12).transpose(1, 3, 0, 2)[np.arange(12), np.arange(12)]
    fast = target_jacobian(chain, centres).between_targets(cov)  # (12, M, M)
    scale = np.sqrt(np.diagonal(slow, axis1=1, axis2=2)).max(axis=1)  # per output
    assert np.all(np.abs(fast - slow).max(axis=(1, 2)) <= 1e-6 * scale**2)
    # the common part: only O's and R0's centres uncertain
    common_only = np.zeros_like(cov)
    plan = one_sided.session.plan
    for step in (plan.origin_index, plan.reference_indices[0]):
        common_only[step] = cov[step]
    slow_common = np.einsum(
        "myy->my",
        brute_force_full(chain, centres, common_only).reshape(m, 12, m, 12)[
            np.arange(m), :, np.arange(m)
        ],
    )
    fast_common = np.einsum(
        "myy->my", target_jacobian(chain, centres).covariance(cov, TargetJacobian.COMMON_PARTS)
    )
    np.testing.assert_allclose(fast_common, slow_common, rtol=1e-6, atol=1e-9 * slow_common.max())


def test_poses_and_covariance_files_carry_the_parts(
    one_sided: ProcessResult, tmp_path: Path
) -> None:
    u = pose_uncertainty(one_sided)
    write_results(one_sided, tmp_path / "out", uncertainty=u)
    written = pd.read_csv(tmp_path / "out" / "poses.csv")
    assert (
        len(pd.read_csv(tmp_path / "out" / "covariance.csv"))
        == len(written) * (len(written) + 1) // 2
    )
    # the identities in memory, to 1e-12 (the files hold the same at their resolution,
    # tests/workflows/test_resolution.py)
    poses, cov = poses_frame(one_sided, u), covariance_frame(one_sided, u)
    assert list(poses.columns) == list(written.columns)
    m = len(poses)
    assert len(cov) == m * (m + 1) // 2
    names = [*deviation_columns("conv"), *deviation_columns("corr")]
    columns = list(poses.columns)
    for name in names:
        # beside u: u, its common part, its own part
        at = columns.index(f"u_{name}")
        assert columns[at + 1 : at + 3] == [f"u_common_{name}", f"u_own_{name}"]
        total = poses[f"u_{name}"] ** 2
        parts = poses[f"u_common_{name}"] ** 2 + poses[f"u_own_{name}"] ** 2
        np.testing.assert_allclose(parts, total, rtol=1e-12)
        assert (poses[f"u_common_{name}"] > 0).all() and (poses[f"u_own_{name}"] > 0).all()
    labels = list(poses["label"])
    diagonal = cov[cov["label_a"] == cov["label_b"]].set_index("label_a").loc[labels]
    for name in names:
        np.testing.assert_allclose(diagonal[f"cov_{name}2"], poses[f"u_{name}"] ** 2, rtol=1e-12)
    # an entry off the diagonal, from the covariance in mm and deg
    assert u.between_covariance is not None
    row = cov[(cov["label_a"] == labels[0]) & (cov["label_b"] == labels[3])].iloc[0]
    assert row["cov_dTz_corr_um2"] == pytest.approx(u.between_covariance[8, 0, 3] * 1e6)
    assert row["cov_dRx_conv_urad2"] == pytest.approx(
        u.between_covariance[3, 0, 3] * URAD_PER_DEG**2
    )
    # every pair shares O and R0: positively correlated, but for the corrected poses of
    # two targets between the same two references (S1, S2 and S3, S4), whose errors of
    # the growth there are of opposite signs (the first takes the reference before it, the
    # second the one after)
    assert (cov.filter(like="conv_") > 0).all().all()
    interval = {"S1": 0, "S2": 0, "S3": 1, "S4": 1}
    apart = cov["label_a"].map(interval) != cov["label_b"].map(interval)
    apart |= cov["label_a"] == cov["label_b"]
    assert (cov[apart].filter(like="corr_") > 0).all().all()
    assert (cov[~apart].filter(like="cov_dTz_corr") < 0).all().all()


def test_monte_carlo_keeps_the_linear_shares(
    one_sided: ProcessResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    linear = pose_uncertainty(one_sided)
    mc = pose_uncertainty(one_sided, mc=200, seed=1)
    assert mc.common_u is not None and mc.own_u is not None and mc.between_covariance is not None
    assert linear.common_u is not None and linear.between_covariance is not None
    u = np.concatenate([mc.conventional_u, mc.corrected_u], 1)
    np.testing.assert_allclose(mc.common_u**2 + mc.own_u**2, u**2, rtol=1e-12)
    lin_u = np.concatenate([linear.conventional_u, linear.corrected_u], 1)
    # the targets with one neighbour get the interpolation's own error, an own part
    # added after the propagation (linear or Monte Carlo): the shares are the propagated
    # part's
    monkeypatch.setattr(errorterms, "curvature_excess", lambda *args: None)
    bare = pose_uncertainty(one_sided)
    added = lin_u**2 - np.concatenate([bare.conventional_u, bare.corrected_u], 1) ** 2
    assert added[:, :6].max() == 0 and added[:, 6:].max() > 0
    np.testing.assert_allclose(
        mc.common_u / np.sqrt(u**2 - added),
        linear.common_u / np.sqrt(lin_u**2 - added),
        rtol=1e-9,
    )
    np.testing.assert_allclose(
        np.diagonal(mc.between_covariance, axis1=1, axis2=2).T, u**2, rtol=1e-12
    )
