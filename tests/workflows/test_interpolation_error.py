"""The straight line's own error between references in u, and the centres' z scale off
the heating's motion (issue 35's leftovers), against the twin's truth over replicas.

The twin heats the legs from 1000 s (tau 600 s, mats switched on: the growth bends and
has a kink between two references); 6 targets, 7 references, centres fitted to 25
points over 70 deg with 1 um point noise. Claimed u over the RMS error of the corrected
poses against ``truecorr``, Tx Ty Tz Rx Ry Rz, over 10 replicas x 6 targets: a ratio
over so few errors (sharing O and R0 within a session) scatters by about 0.1-0.15, the
bounds 0.8-1.3 hold that, and the failures before were far outside them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.core.heating import HeatingModel
from hexatherm.core.plan import Plan
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.summary import uncertainty_summary
from hexatherm.workflows.process.uncertainty import pose_uncertainty
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    TwinSessionSpec,
    pose_columns,
    simulate_session,
    write_files,
)
from tests.sessions import BALLS, LEG_GAIN_C, REFERENCE, ROOT, small_plan

GAIN = LEG_GAIN_C
REPLICAS = 10
CMM = "cmm: {point_noise_um: 1.0, points_per_ball: 25, cap_angle_deg: 70}\n"


def pairs_plan() -> Plan:
    """O, R0, then two targets between every two references (T T R) x 4."""
    rng = np.random.default_rng(1)
    steps = [("O", "origin", [0.0] * 6), ("R0", "reference", REFERENCE)]
    for i in range(4):
        for j in range(2):
            pose = rng.uniform(-1, 1, 6) * [10, 10, 5, 1, 1, 2]
            steps.append((f"S{i}{j}", "target", pose.tolist()))
        steps.append((f"R{i + 1}", "reference", REFERENCE))
    return Plan.from_steps(steps, reference_pose=REFERENCE)


def heated(
    folder: Path,
    seed: int,
    *,
    gap_s: float = 0.0,
    cmm: bool = True,
    plan: Plan | None = None,
    pauses: tuple[float, ...] | None = None,
    heating: HeatingModel | None = None,
) -> Path:
    """A twin session heated from 1000 s (``heating``: by that instead); ``gap_s`` pauses
    before the fourth reference (``pauses``: before every step instead); ``cmm``: the
    session states the probing (else its centres carry no u at all)."""
    plan = small_plan(6, 1) if plan is None else plan
    if pauses is None:
        pauses = tuple(gap_s if i == 7 else 0.0 for i in range(len(plan.labels)))
    spec = TwinSessionSpec(
        name=folder.name,
        hexapod_text=(ROOT / "configs" / "symetrie-like.yaml").read_text(),
        balls=BALLS,
        plan=plan,
        heating=Heating(on_s=1000.0, tau_s=600.0, gain_C=GAIN) if heating is None else heating,
        seed=seed,
        output="centres",
        fit_centres=True,
        point_noise_mm=1e-3,
        pauses_s=pauses,
    )
    write_files(simulate_session(spec).files, folder)
    if cmm:
        (folder / "session.yaml").write_text((folder / "session.yaml").read_text() + CMM)
    return folder


def claimed_over_observed(folders: list[Path], interpolation: str = "linear") -> np.ndarray:
    errors, claimed = [], []
    for folder in folders:
        result = process_session(folder, interpolation=interpolation)
        truth = pd.read_csv(folder / "truth" / "steps.csv").set_index("label")
        labels = [result.session.plan.labels[i] for i in result.correction.target_index]
        errors.append(result.correction.corrected - truth.loc[labels, pose_columns("truecorr")])
        claimed.append(pose_uncertainty(result).corrected_u)
    e, c = np.concatenate(errors), np.concatenate(claimed)
    return np.asarray(np.sqrt(np.mean(c**2, axis=0) / np.mean(e**2, axis=0)))


def test_the_straight_lines_own_error_is_in_linears_u(tmp_path: Path) -> None:
    # before: 0.52 0.97 0.76 0.97 1.04 0.90 (60 seeds; Tx and Tz the components the
    # heating's error falls on); now 1.04 1.06 0.92 0.93 1.00 0.90 (20 seeds)
    folders = [heated(tmp_path / f"r{seed}", seed) for seed in range(REPLICAS)]
    ratio = claimed_over_observed(folders)
    assert np.all((ratio > 0.8) & (ratio < 1.3)), ratio


def test_a_target_with_one_reference_has_its_first_order_error_in_u(tmp_path: Path) -> None:
    # two targets between two references: the first takes the reference before it, the
    # second the one after (the growth between them and the target in neither's u):
    # before 0.22 0.98 0.45 0.91 0.95 1.02 (linear, 20 seeds), now 1.03 1.08 1.02 1.06
    # 0.96 1.10 (12 seeds)
    plan = pairs_plan()
    folders = [heated(tmp_path / f"p{seed}", seed, plan=plan) for seed in range(REPLICAS)]
    ratio = claimed_over_observed(folders)
    assert np.all((ratio > 0.8) & (ratio < 1.3)), ratio


def test_a_long_gap_between_references_is_in_linears_u(tmp_path: Path) -> None:
    # a 30 min pause before the fourth reference: before 0.26 0.97 0.51 0.94 1.03 0.92
    folders = [heated(tmp_path / f"g{seed}", seed, gap_s=1800.0) for seed in range(REPLICAS)]
    ratio = claimed_over_observed(folders)
    assert np.all((ratio > 0.8) & (ratio < 1.3)), ratio
    lines = uncertainty_summary(pose_uncertainty(process_session(folders[0])))
    assert any("own error between references on a growth shaped as the" in x for x in lines)
    # without the log the references' curvature does not hold a heating that starts in
    # the gap (0.45 and 0.61 of Tx and Tz over 20 seeds): the screen says so
    session = folders[0] / "session.yaml"
    lines = session.read_text().splitlines(keepends=True)
    session.write_text("".join(x for x in lines if not x.startswith("temperatures:")))
    lines = uncertainty_summary(pose_uncertainty(process_session(folders[0])))
    assert any("from the curvature of the references' growth" in x for x in lines)
    assert any(x.startswith("warning: references up to 5.5x their median") for x in lines)


def test_centres_without_u_are_not_widened_by_a_bending_heating(tmp_path: Path) -> None:
    # no u and no cmm: the z part of the centres' covariance is scaled to the references'
    # ball heights; their plain second differences read the heating's bend as noise
    # (3.9x in variance): before 0.86 1.63 1.50 1.91 2.06 0.90 (linear, 60 seeds)
    folders = [heated(tmp_path / f"n{seed}", seed, cmm=False) for seed in range(REPLICAS)]
    ratio = claimed_over_observed(folders)
    assert np.all((ratio > 0.75) & (ratio < 1.25)), ratio
    result = process_session(folders[0])
    text = pose_uncertainty(result).centres.description
    assert "off the heights' common thermal motion" in text
