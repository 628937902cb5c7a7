"""The joint covariance of all targets' poses (what calibrate weighs with) is the one
``process`` states: each target's 12 x 12 block, each output's covariance between
targets, and ``covariance.csv`` as ``hexatherm process`` writes it (a second path: the
command's own run), with every term beyond the propagation (O's carry to R0's state, the
interpolation's own error shared by the targets of one interval)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.workflows.process.errorterms import error_terms
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import (
    centre_covariance,
    joint_pose_covariance,
    joint_pose_covariance_structured,
    pose_chain,
    pose_uncertainty,
)
from tests.shipped import SHIPPED
from tests.workflows.test_interpolation_shared import pairs_session

URAD_PER_DEG = np.pi / 180 * 1e6


@pytest.mark.parametrize("corrected", [True, False])
def test_joint_covariance_matches_the_blocks_and_the_between_target_terms(corrected) -> None:
    result = process_session(SHIPPED / "paper-zero-pose")
    joint = joint_pose_covariance(result, corrected=corrected)
    u = pose_uncertainty(result)
    assert u.between_covariance is not None
    m = u.covariance.shape[0]
    out = slice(6, 12) if corrected else slice(0, 6)
    scale = np.abs(joint).max()
    for a in range(m):
        np.testing.assert_allclose(
            joint[6 * a : 6 * a + 6, 6 * a : 6 * a + 6],
            u.covariance[a, out, out],
            atol=1e-12 * scale,
        )
    for y in range(6):
        np.testing.assert_allclose(
            joint[y::6, y::6], u.between_covariance[out][y], atol=1e-12 * scale, rtol=0
        )
    np.testing.assert_allclose(joint, joint.T, atol=0)
    assert np.linalg.eigvalsh(joint).min() > -1e-12 * scale
    # the shared frame O correlates the targets: the terms between them are not zero
    assert np.abs(joint[0:6, 6:12]).max() > 0.1 * np.abs(joint[0:6, 0:6]).max()


@pytest.fixture(scope="module")
def no_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A twin session without a thermocouple log (O carried by the references' growth),
    two targets between every two references and one past the last."""
    return pairs_session(tmp_path_factory.mktemp("joint") / "s", 0, log=False)


@pytest.fixture(scope="module")
def smooth_pairs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Twin sessions the smooth fit is used on, two targets between every two references
    and one past the last: with a log (mats on from the start) and without (mats on 600 s
    before the last reference)."""
    root = tmp_path_factory.mktemp("smooth")
    return {
        "smooth": pairs_session(root / "log", 0, on_s=0.0, pairs=4),
        "smooth-no-log": pairs_session(root / "nolog", 0, log=False, on_s=2000.0, pairs=4),
    }


@pytest.mark.parametrize(
    "session", ["paper-zero-pose", "serial-capture", "no-log", "smooth", "smooth-no-log"]
)
def test_joint_covariance_is_what_process_writes_to_covariance_csv(
    session: str, no_log: Path, smooth_pairs: dict[str, Path], tmp_path: Path
) -> None:
    """Before: the calibration's weights left out O's carry (its noise through the
    references without a log, its model error) and the straight line's own error, which
    ``covariance.csv`` holds: their u of the corrected poses was 0.93-1.0 of the file's
    on paper-zero-pose (median over the targets), 0.75-0.80 on serial-capture (no log),
    down to 0.21 (Tx at S14) on with-hidden-effect. With ``--interpolation smooth``, the
    smooth fit's own error shared by two targets of one interval (with a log) and past
    the last reference (without) is in both."""
    folder = {"no-log": no_log, **smooth_pairs}.get(session, SHIPPED / session)
    smooth = session.startswith("smooth")
    options = ["--interpolation", "smooth"] if smooth else []
    out = tmp_path / "out"
    run = CliRunner().invoke(main, ["process", str(folder), "-o", str(out), *options])
    assert run.exit_code == 0, run.output
    written = pd.read_csv(out / "covariance.csv")
    result = process_session(folder, interpolation="smooth" if smooth else "linear")
    if smooth:
        assert result.correction.smooth is not None and result.correction.smooth.used
        terms = error_terms(result, pose_chain(result), centre_covariance(result).cov_mm2)
        assert terms.excess is not None
        a, b, vectors = terms.shared()[-1]
        if session == "smooth":  # shared by the targets of one interval
            assert np.abs(np.einsum("pyk,pyk->py", vectors[a], vectors[b])).max() > 0
        else:  # the target past the last reference has it, no other
            assert np.abs(vectors[-1]).max() > 0 and not np.any(vectors[:-1])
    labels = [result.session.plan.labels[i] for i in result.correction.target_index]
    index = {label: k for k, label in enumerate(labels)}
    a = written["label_a"].map(index).to_numpy()
    b = written["label_b"].map(index).to_numpy()
    to_unit2 = np.array([1e6] * 3 + [URAD_PER_DEG**2] * 3)
    for tag, corrected in (("corr", True), ("conv", False)):
        joint = joint_pose_covariance(result, corrected=corrected)
        for y, name in enumerate(("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")):
            unit = "um2" if y < 3 else "urad2"
            stated = written[f"cov_d{name}_{tag}_{unit}"].to_numpy()
            mine = joint[6 * a + y, 6 * b + y] * to_unit2[y]
            # written at the file's resolution, 1e-6 um2 and urad2 (io/csvout.py)
            np.testing.assert_allclose(mine, stated, rtol=0, atol=0.51e-6)


def test_the_structure_the_fit_whitens_with_is_the_joint_covariance(tmp_path: Path) -> None:
    """Without a log (O's carry reads the references: more low-rank columns) and with two
    targets between the same references (their shared error in the band): the
    structured covariance is the dense one (17 targets: a band is worth it)."""
    result = process_session(pairs_session(tmp_path / "s", 0, log=False, pairs=8))
    structure = joint_pose_covariance_structured(result)
    assert structure is not None
    dense = joint_pose_covariance(result)
    np.testing.assert_allclose(structure.dense(), dense, rtol=0, atol=1e-13 * np.abs(dense).max())
    # the shared error is in the band: the two targets of the first interval share no
    # step beyond O, R0 and those O's carry reads (all in the low-rank part), Tx
    terms = error_terms(result, pose_chain(result), centre_covariance(result).cov_mm2)
    assert terms.curved is not None
    f = terms.curved[0]
    band = dense[0, 6] - structure.common[0] @ structure.common[6]
    assert band == pytest.approx(float(f[0, 0] @ f[1, 0]), rel=1e-9)
    assert abs(band) > 0.01 * dense[0, 0]
