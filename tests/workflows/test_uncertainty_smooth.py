"""``process --interpolation smooth``: its propagated uncertainty against the brute force and
against noise replicas; what the screen and ``poses.csv`` say; the fallback on a step."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.propagation import target_jacobian
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.smootherror import smooth_excess
from hexatherm.workflows.process.uncertainty import (
    PoseUncertainty,
    centre_covariance,
    joint_pose_covariance,
    pose_chain,
    pose_uncertainty,
)
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    SimulatedSession,
    TwinSessionSpec,
    simulate_session,
)
from tests.replicas import SessionReader, write_session
from tests.sessions import BALLS, LEG_GAIN_C, ROOT, small_plan
from tests.workflows.test_uncertainty_shared import brute_force_full

HEXAPOD_TEXT = (ROOT / "configs" / "symetrie-like.yaml").read_text()
GAIN = LEG_GAIN_C
CMM = "cmm: {point_noise_um: 1.0, points_per_ball: 25}\n"
N_TARGETS = 6
STEPS = small_plan(N_TARGETS, 1).labels


def simulated(seed: int, heating: Heating | None = None) -> SimulatedSession:
    spec = TwinSessionSpec(
        name="smooth",  # one session file for every replica: read once (SessionReader)
        hexapod_text=HEXAPOD_TEXT,
        balls=BALLS,
        plan=small_plan(N_TARGETS, 1),
        heating=heating or Heating(on_s=0.0, tau_s=2400.0, gain_C=GAIN),
        seed=seed,
        output="centres",
        fit_centres=True,
        point_noise_mm=1e-3,
        points_per_ball=25,
        cap_half_angle_deg=70.0,
    )
    return simulate_session(spec, truth_files=False)


def session(
    folder: Path, seed: int, heating: Heating | None = None, twin: SimulatedSession | None = None
) -> Path:
    """The twin's session (``twin``, else simulated) written to ``folder``, ``truth/`` left
    out, its session file stating the CMM's probing."""
    twin = twin or simulated(seed, heating)
    write_session(twin.files, folder)
    (folder / "session.yaml").write_text((folder / "session.yaml").read_text() + CMM)
    return folder


def test_smooth_jacobian_equals_the_brute_force_one(tmp_path: Path) -> None:
    result = process_session(session(tmp_path / "s", seed=4), interpolation="smooth")
    assert result.correction.smooth is not None and result.correction.smooth.used
    chain = pose_chain(result)
    centres, cov = result.centres.centres_mm, centre_covariance(result).cov_mm2
    full = brute_force_full(chain, centres, cov)
    m = full.shape[0] // 12
    slow = full.reshape(m, 12, m, 12).transpose(1, 3, 0, 2)[np.arange(12), np.arange(12)]
    fast = target_jacobian(chain, centres).between_targets(cov)
    scale = np.sqrt(np.diagonal(slow, axis1=1, axis2=2)).max(axis=1)
    assert np.all(np.abs(fast - slow).max(axis=(1, 2)) <= 1e-6 * scale**2)
    # every reference now moves every corrected pose a little
    assert target_jacobian(chain, centres).jac.shape[1] == 2 + N_TARGETS + 1


def test_a_calibration_weighs_smooth_poses_with_their_own_error(tmp_path: Path) -> None:
    """The joint covariance a calibration weighs the corrected poses with holds each pose's
    covariance as ``process`` reports it, the smooth fit's own error included."""
    result = process_session(
        session(tmp_path / "s", seed=1, heating=MID_SESSION), interpolation="smooth"
    )
    u = pose_uncertainty(result)
    excess = u.smooth_excess
    assert excess is not None and excess.shape_um is not None and excess.shape_um.max() > 0
    joint = joint_pose_covariance(result)
    m = len(result.correction.target_index)
    blocks = joint.reshape(m, 6, m, 6)[np.arange(m), :, np.arange(m)]
    np.testing.assert_allclose(blocks, u.covariance[:, 6:, 6:], rtol=1e-9, atol=1e-18)


REPLICAS = 50


@pytest.fixture(scope="module")
def replicas(
    tmp_path_factory: pytest.TempPathFactory,
) -> list[tuple[ProcessResult, PoseUncertainty]]:
    root = tmp_path_factory.mktemp("smooth")
    out = []
    reader = SessionReader()
    for seed in range(REPLICAS):
        result = reader.process(session(root / f"r{seed}", seed), interpolation="smooth")
        out.append((result, pose_uncertainty(result)))
    return out


def test_smooth_uncertainty_is_the_replicas_scatter(
    replicas: list[tuple[ProcessResult, PoseUncertainty]],
) -> None:
    used = [r.correction.smooth is not None and r.correction.smooth.used for r, _ in replicas]
    assert sum(used) >= 0.5 * REPLICAS  # 7 references only: kept in about 2 of 3 (measured)
    poses = np.array([r.correction.corrected for r, _ in replicas])
    claimed = np.array([u.corrected_u for _, u in replicas])
    observed = np.sqrt(np.var(poses, axis=0, ddof=1).mean(axis=0))
    ratio = np.sqrt((claimed**2).mean(axis=(0, 1))) / observed
    limit = 4 / np.sqrt(2 * (REPLICAS - 1))
    assert np.all(np.abs(ratio - 1) < limit), ratio.round(3)
    inside = np.abs(poses - poses.mean(axis=0)) <= 2 * claimed
    assert 0.92 <= inside.mean() <= 0.98, inside.mean()
    # the parts still add up, and the smooth fit shrinks the noise in the own part of the
    # corrected pose (its own error, added to the own part, aside)
    first = used.index(True)
    lin = pose_uncertainty(process_session(replicas[first][0].session.path))
    smooth_result, smooth_u = replicas[first]
    assert smooth_u.own_u is not None and lin.own_u is not None
    assert smooth_u.common_u is not None
    np.testing.assert_allclose(
        smooth_u.own_u**2 + smooth_u.common_u**2,
        np.concatenate([smooth_u.conventional_u, smooth_u.corrected_u], axis=1) ** 2,
        rtol=1e-9,
    )
    excess = smooth_excess(
        smooth_result, pose_chain(smooth_result), centre_covariance(smooth_result).cov_mm2
    )
    assert excess is not None
    added = np.diagonal(excess[0], axis1=1, axis2=2)[:, :3]
    noise_own = np.sqrt(smooth_u.own_u[:, 6:9] ** 2 - added)
    assert np.mean(noise_own) < np.mean(lin.own_u[:, 6:9])


def test_the_screen_and_poses_say_what_was_used(tmp_path: Path) -> None:
    folder = session(tmp_path / "smooth", seed=4)
    result = CliRunner().invoke(main, ["process", str(folder), "--interpolation", "smooth"])
    assert result.exit_code == 0, result.output
    assert "interpolation smooth: leave-one-out error" in result.output
    assert "smooth fit used" in result.output
    # what the smooth fit's own error added to u, and from which residuals
    assert "smooth fit's own error" in result.output
    assert "standardized residuals from the smooth fit" in result.output
    poses = pd.read_csv(folder / "results" / "poses.csv")
    assert set(poses["interpolation"]) == {"smooth"}
    # the default writes no such column
    assert CliRunner().invoke(main, ["process", str(folder), "--overwrite"]).exit_code == 0
    assert "interpolation" not in pd.read_csv(folder / "results" / "poses.csv").columns


def test_a_growth_step_falls_back_to_the_neighbours(tmp_path: Path) -> None:
    """Mats switched on mid-session at full power (tau 1 s): the growth jumps between two
    references, no smooth function follows it; the poses are the linear default's."""
    step = Heating(on_s=1450.0, tau_s=1.0, gain_C=GAIN)
    folder = session(tmp_path / "step", seed=4, heating=step)
    smooth = process_session(folder, interpolation="smooth")
    linear = process_session(folder)
    assert smooth.correction.smooth is not None and not smooth.correction.smooth.used
    np.testing.assert_array_equal(smooth.correction.corrected, linear.correction.corrected)
    # the fallback keeps linear's u: nothing of the smooth fit is added
    u_smooth, u_linear = pose_uncertainty(smooth), pose_uncertainty(linear)
    assert u_smooth.smooth_excess is None
    np.testing.assert_array_equal(u_smooth.corrected_u, u_linear.corrected_u)
    result = CliRunner().invoke(main, ["process", str(folder), "--interpolation", "smooth"])
    assert "the two neighbours kept (the smooth fit is not below 0.95x" in result.output
    assert set(pd.read_csv(folder / "results" / "poses.csv")["interpolation"]) == {"linear"}


#: mats switched on 1000 s into the session, warming with a 600 s time constant: the
#: growth bends sharply between two references, where a spline through seven references
#: cannot follow it (measured: its error in Tx 1.5x, in Tz 0.6x the noise's u)
MID_SESSION = Heating(on_s=1000.0, tau_s=600.0, gain_C=GAIN)


def test_smooth_u_holds_against_the_twins_truth(tmp_path: Path) -> None:
    """Claimed u of the corrected poses over their RMS error against the twin's truth, over
    seeded replicas where the smooth fit is used: within 0.85-1.15 per component. Without
    the smooth fit's own error (the propagated noise alone) Tx claimed 0.57x, Tz 0.80x."""
    claimed, noise_only, errors = [], [], []
    added = shaped = 0
    reader = SessionReader()
    for seed in range(REPLICAS):
        twin = simulated(seed, MID_SESSION)
        result = reader.process(
            session(tmp_path / f"r{seed}", seed, twin=twin), interpolation="smooth"
        )
        if result.correction.smooth is None or not result.correction.smooth.used:
            continue
        u = pose_uncertainty(result)
        assert u.smooth_excess is not None
        added += u.smooth_excess.excess_um > 0
        shaped += u.smooth_excess.shape_um is not None and u.smooth_excess.shape_um.max() > 0
        excess = smooth_excess(result, pose_chain(result), u.centres.cov_mm2)
        assert excess is not None
        # the twin's truth of the targets (truth/steps.csv's truecorr columns), by label
        labels = [result.session.plan.labels[i] for i in result.correction.target_index]
        rows = [STEPS.index(label) for label in labels]
        true_pose = twin.truth.corrected_pose[rows]
        errors.append(result.correction.corrected - true_pose)
        claimed.append(u.corrected_u)
        noise_only.append(np.sqrt(u.corrected_u**2 - np.diagonal(excess[0], axis1=1, axis2=2)))
    assert len(errors) >= 0.8 * REPLICAS  # smooth heating: the fit is kept (measured 49 of 50)
    # the log's shape reaches every target; the residuals exceed their noise and the
    # log's shape in some (measured 24 of 49; beyond their noise alone 46 of 49: the log
    # explains the rest of them)
    assert shaped == len(errors) and added >= 0.3 * len(errors), (shaped, added)

    def rms(x: list[np.ndarray]) -> np.ndarray:
        return np.sqrt(np.mean(np.square(x), axis=(0, 1)))

    ratio = rms(claimed) / rms(errors)
    assert np.all((0.85 <= ratio) & (ratio <= 1.15)), ratio.round(3)
    # the propagated noise alone (the u before the smooth fit's own error was added)
    # claimed too little in Tx and Tz: the term is what closes the gap
    before = rms(noise_only) / rms(errors)
    assert before[0] < 0.7 and before[2] < 0.85, before.round(3)
