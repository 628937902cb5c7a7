"""Repeated O and R0 (issue 14, part 2): planned, averaged, checked, and u's common part shrunk.

``plan --origin-repeats N --reference0-repeats N`` writes ``O, R0, O-2, R0-2, ...``; ``process``
averages each ball's centres over the repeats before registration. The common part of u
(O and R0) then falls as 1/sqrt(N), which new noise replicas confirm; the repeats'
scatter is checked against their claimed u.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.plan import Plan, find_repeats, without_repeats
from hexatherm.core.planning import sequence_steps
from hexatherm.io.config import read_plan
from hexatherm.workflows.process import errorterms
from hexatherm.workflows.process.outputs import write_results
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.uncertainty import PoseUncertainty, pose_uncertainty
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    TwinSessionSpec,
    simulate_session,
)
from tests.replicas import SessionReader, write_session
from tests.sessions import BALLS, LEG_GAIN_C, REFERENCE, ROOT

HEXAPOD_TEXT = (ROOT / "configs" / "symetrie-like.yaml").read_text()
GAIN = LEG_GAIN_C
CMM = "cmm: {point_noise_um: 1.0, points_per_ball: 25}\n"


def repeated_plan(n_targets: int, repeats: int) -> Plan:
    rng = np.random.default_rng(1)
    targets = rng.uniform(-1, 1, (n_targets, 6)) * [10, 10, 5, 1, 1, 2]
    steps = sequence_steps(targets, REFERENCE, origin_repeats=repeats, reference0_repeats=repeats)
    return Plan.from_steps(steps, reference_pose=REFERENCE)


def spec(
    folder: Path, seed: int, repeats: int, n_targets: int = 3, gain: tuple[float, ...] = GAIN
) -> TwinSessionSpec:
    return TwinSessionSpec(
        name="repeats",  # one session file for every replica: read once (SessionReader)
        hexapod_text=HEXAPOD_TEXT,
        balls=BALLS,
        plan=repeated_plan(n_targets, repeats),
        heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=gain),
        seed=seed,
        output="centres",
        fit_centres=True,
        point_noise_mm=1e-3,
        points_per_ball=25,
        cap_half_angle_deg=70.0,
    )


def session(
    folder: Path,
    seed: int,
    repeats: int,
    n_targets: int = 3,
    gain: tuple[float, ...] = GAIN,
    edit: Callable[[Path], None] | None = None,
) -> Path:
    twin = simulate_session(spec(folder, seed, repeats, n_targets, gain), truth_files=False)
    write_session(twin.files, folder)
    (folder / "session.yaml").write_text((folder / "session.yaml").read_text() + CMM)
    if edit is not None:
        edit(folder)
    return folder


def test_the_plan_sequence_and_its_repeats() -> None:
    steps = sequence_steps(np.zeros((2, 6)), REFERENCE, origin_repeats=3, reference0_repeats=2)
    labels = [s[0] for s in steps]
    # a repeat of O is a target: it needs a reference beside it, so R0 comes as often
    assert labels == ["O", "R0", "O-2", "R0-2", "O-3", "R0-3", "S1", "R1", "S2", "R2"]
    plan = Plan.from_steps(steps, reference_pose=REFERENCE)
    repeats = find_repeats(plan)
    assert repeats.origin == (0, 2, 4) and repeats.reference0 == (1, 3, 5)
    reduced, keep = without_repeats(plan, repeats)
    assert reduced.labels == ("O", "R0", "S1", "R1", "S2", "R2")
    assert keep.tolist() == [0, 1, 6, 7, 8, 9]
    assert reduced.adjacent_references() == [(1, 3), (3, 5)]
    # R0 alone: consecutive references
    only_r0 = [s[0] for s in sequence_steps(np.zeros((1, 6)), REFERENCE, reference0_repeats=3)]
    assert only_r0 == ["O", "R0", "R0-2", "R0-3", "S1", "R1"]
    # no repeats: the usual plan, nothing found; a target named O-2 elsewhere is a target
    plain = Plan.from_steps(sequence_steps(np.zeros((1, 6)), REFERENCE), reference_pose=REFERENCE)
    assert not find_repeats(plain).any
    odd = Plan.from_steps(
        [("O", "origin", [0] * 6), ("R0", "reference", REFERENCE), ("O-2", "target", [1] * 6)]
        + [("R1", "reference", REFERENCE)],
        reference_pose=REFERENCE,
    )
    assert find_repeats(odd).origin == (0,)


def test_plan_command_writes_the_repeats(tmp_path: Path) -> None:
    (tmp_path / "t.csv").write_text("Tx,Ty,Tz,Rx,Ry,Rz\n5,-3,2,0.5,-0.4,3\n")
    result = CliRunner().invoke(
        main,
        [
            "plan",
            "--hexapod",
            str(ROOT / "configs" / "symetrie-like.yaml"),
            "--balls",
            str(ROOT / "configs" / "balls-3.yaml"),
            "--targets",
            str(tmp_path / "t.csv"),
            "--origin-repeats",
            "2",
            "--reference0-repeats",
            "3",
            "-o",
            str(tmp_path / "plan.yaml"),
        ],
    )
    assert result.exit_code == 0, result.output
    plan = read_plan(tmp_path / "plan.yaml")  # the contract's reader takes it
    assert plan.labels == ("O", "R0", "O-2", "R0-2", "R0-3", "S1", "R1")
    assert "(1 targets x" in result.output
    assert "O measured 2 time(s), R0 3 time(s)" in result.output


def test_process_averages_the_centres_of_the_repeats(tmp_path: Path) -> None:
    """O's centres are the mean of its measurements (the conventional poses' frame); R0's
    are each carried to the last one's thermal state by the leg model and the log, then
    averaged, at the last one's time (issue 35): the twin's true centres of R0's last
    measurement, within the noise, where the plain mean is the heating's average."""
    folder = session(tmp_path / "s", seed=3, repeats=3)
    result = process_session(folder)
    centres = pd.read_csv(folder / "centres.csv")
    assert result.session.plan.labels == ("O", "R0", "S1", "R1", "S2", "R2", "S3", "R3")
    assert [g.labels for g in result.repeats] == [("O", "O-2", "O-3"), ("R0", "R0-2", "R0-3")]
    epoch = pd.Timestamp(0, tz="UTC")
    means = {}
    for step, group in ((0, ("O", "O-2", "O-3")), (1, ("R0", "R0-2", "R0-3"))):
        rows = centres[centres["label"].isin(group)]
        means[step] = rows.groupby("ball")[["x", "y", "z"]].mean().loc[list(BALLS.names)].to_numpy()
        seconds = (pd.to_datetime(rows["time"], utc=True) - epoch).dt.total_seconds().to_numpy()
        last = seconds[rows["label"].to_numpy() == group[-1]].mean()
        expected_time = seconds.mean() if step == 0 else last
        assert result.centres.times_s[step] == pytest.approx(expected_time, abs=1e-3)
        assert result.centres.measurements[step] == 3
    np.testing.assert_allclose(result.centres.centres_mm[0], means[0], rtol=0, atol=1e-12)
    truth = simulate_session(spec(tmp_path / "s", seed=3, repeats=3)).truth
    true_last = truth.centres_cmm_mm[repeated_plan(3, 3).labels.index("R0-3")]
    carried_off = np.abs(result.centres.centres_mm[1] - true_last).max()
    mean_off = np.abs(means[1] - true_last).max()
    assert carried_off < 2e-3 < mean_off, (carried_off, mean_off)
    assert result.centres.measurements[2:].tolist() == [1] * 6
    # the files: legs.csv has the averaged steps, fits.csv every measurement
    write_results(result, tmp_path / "out")
    assert pd.read_csv(tmp_path / "out" / "legs.csv")["label"].tolist()[:3] == ["O", "R0", "S1"]
    assert "O-3" in set(pd.read_csv(tmp_path / "out" / "fits.csv")["label"])


def common_and_own(folder: Path) -> tuple[np.ndarray, np.ndarray, PoseUncertainty]:
    u = pose_uncertainty(process_session(folder))
    assert u.common_u is not None and u.own_u is not None
    return u.common_u, u.own_u, u


@pytest.mark.parametrize("repeats", [2, 4])
def test_the_common_part_falls_as_one_over_sqrt_n(
    tmp_path: Path, repeats: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the propagated parts only: the interpolation's own error (an own part, another for
    # the repeats' other times) is tested against the truth in test_interpolation_error.py
    monkeypatch.setattr(errorterms, "curvature_excess", lambda *args: None)
    common_1, own_1, _ = common_and_own(session(tmp_path / "one", seed=5, repeats=1))
    common_n, own_n, u = common_and_own(session(tmp_path / "n", seed=5, repeats=repeats))
    # the error of carrying the repeats to R0's last state (issue 35) is common too
    assert u.carry is not None
    carried = np.diagonal(u.carry.covariance(), axis1=1, axis2=2)
    assert np.all(carried <= 0.25 * common_n**2)
    noise_n = np.sqrt(common_n**2 - carried)
    # targets whose references are not R0: O's and R0's noise enter whole, 1/N of it
    np.testing.assert_allclose(noise_n[1:] / common_1[1:], 1 / np.sqrt(repeats), rtol=0.01)
    np.testing.assert_allclose(own_n[1:], own_1[1:], rtol=0.01)
    # S1 uses R0 as its reference before, now at the repeats' mean time (another weight)
    assert np.all(common_n[0] < 0.85 * common_1[0])
    assert [c.n for c in u.repeats] == [repeats, repeats]


def test_a_displaced_repeat_is_told(tmp_path: Path) -> None:
    def displace(folder: Path) -> None:
        path = folder / "centres.csv"
        rows = pd.read_csv(path)
        rows.loc[rows["label"] == "O-2", "z"] += 0.010  # 10 um: a platform that moved
        rows.to_csv(path, index=False)

    _, _, u = common_and_own(session(tmp_path / "s", seed=2, repeats=3, edit=displace))
    checks = {c.label: c for c in u.repeats}
    assert not checks["O"].ok and checks["O"].ratio > 3
    assert checks["R0"].ok
    result = CliRunner().invoke(main, ["process", str(tmp_path / "s")])
    assert result.exit_code == 0, result.output
    assert "warning: the 3 measurements of O scatter more than their u allows" in result.output
    assert "R0 measured 3 times, averaged: their scatter is" in result.output
    assert "O averaged over 3 measurements" in result.output


REPLICAS = 60


@pytest.fixture(scope="module")
def replicas(
    tmp_path_factory: pytest.TempPathFactory,
) -> list[tuple[ProcessResult, PoseUncertainty]]:
    root = tmp_path_factory.mktemp("repeats")
    out = []
    reader = SessionReader()
    for seed in range(REPLICAS):
        result = reader.process(session(root / f"r{seed}", seed=seed, repeats=3))
        out.append((result, pose_uncertainty(result)))
    return out


def test_replicas_scatter_as_the_shrunk_u_claims(
    replicas: list[tuple[ProcessResult, PoseUncertainty]],
) -> None:
    poses = np.array(
        [
            np.concatenate([r.correction.conventional, r.correction.corrected], 1)
            for r, _ in replicas
        ]
    )
    claimed = np.array([np.concatenate([u.conventional_u, u.corrected_u], 1) for _, u in replicas])
    between = np.array([u.between_covariance for _, u in replicas])
    limit = 4 / np.sqrt(2 * (REPLICAS - 1))  # 4 standard errors of a standard deviation
    # every pose component
    ratio = np.sqrt((claimed**2).mean(axis=(0, 1))) / np.sqrt(
        np.var(poses, axis=0, ddof=1).mean(axis=0)
    )
    assert np.all(np.abs(ratio - 1) < limit), ratio.round(3)
    # the mean over the targets: the common part and what the own parts leave
    mean_ratio = np.std(poses.mean(axis=1), axis=0, ddof=1) / np.sqrt(between.mean(axis=(0, 2, 3)))
    assert np.all(np.abs(mean_ratio - 1) < limit), mean_ratio.round(3)
    assert abs(mean_ratio.mean() - 1) < 0.12, mean_ratio.mean()


def test_the_repeats_scatter_as_their_u_without_heating(tmp_path: Path) -> None:
    """Noise alone (mats off): chi2 / dof of the repeats, pooled over 30 replicas, is 1
    within 4 standard errors, for O and for R0 (measured 0.88 and 1.08 over 40)."""
    reader = SessionReader()
    checks = [
        pose_uncertainty(
            reader.process(session(tmp_path / f"r{seed}", seed, 3, n_targets=1, gain=(0.0,) * 6))
        ).repeats
        for seed in range(30)
    ]
    for k, label in enumerate(("O", "R0")):
        assert all(c[k].label == label for c in checks)
        chi2, dof = sum(c[k].chi2 for c in checks), sum(c[k].dof for c in checks)
        assert abs(chi2 / dof - 1) < 4 * np.sqrt(2 / dof), (label, chi2 / dof)


def test_the_repeat_check_does_not_cry_wolf_on_heating(
    replicas: list[tuple[ProcessResult, PoseUncertainty]],
) -> None:
    """Mats on from the start (tau 40 min): the straight line takes most of the drift
    between the repeats (measured chi2/dof 1.22 for O, the curvature left, 1.05 for R0);
    at most one warning in 60 sessions (p < 1e-3)."""
    for k in range(2):
        chi2 = sum(u.repeats[k].chi2 for _, u in replicas)
        dof = sum(u.repeats[k].dof for _, u in replicas)
        assert 0.8 < chi2 / dof < 1.35
    assert sum(not c.ok for _, u in replicas for c in u.repeats) <= 1


def test_monte_carlo_refits_the_repeats_and_agrees_with_linear(tmp_path: Path) -> None:
    """Probed points: every measurement of O and R0 is refitted and averaged per draw."""
    spec = TwinSessionSpec(
        name="s",
        hexapod_text=HEXAPOD_TEXT,
        balls=BALLS,
        plan=repeated_plan(3, 3),
        heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=GAIN),
        seed=6,
        output="points",
        point_noise_mm=1e-3,
        points_per_ball=25,
        cap_half_angle_deg=70.0,
    )
    write_session(simulate_session(spec, truth_files=False).files, tmp_path / "s")
    result = process_session(tmp_path / "s")
    assert [len(g.labels) for g in result.repeats] == [3, 3]
    mc = pose_uncertainty(result, mc=1500, seed=2)
    assert mc.drawn == "points"
    ratio = mc.ratio_to_linear()
    assert np.all(np.abs(ratio - 1) < 0.1), ratio.round(3)
    # the common part: O's and R0's refits averaged, not drawn whole
    assert mc.common_u is not None and mc.own_u is not None
    np.testing.assert_allclose(
        mc.common_u**2 + mc.own_u**2,
        np.concatenate([mc.conventional_u, mc.corrected_u], 1) ** 2,
        rtol=1e-12,
    )
