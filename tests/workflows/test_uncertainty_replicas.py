"""Claimed uncertainty against the scatter of noise replicas, per kind of input.

One simulated session (the twin's truth: thermal drift, four targets) is measured again
and again with new CMM noise; each replica is processed and its uncertainty propagated.
Over the replicas, the standard deviation of every pose component (conventional and
corrected, pooled over the targets) is compared with the uncertainty each replica
claims, and the share of errors within 2u (from the replicas' mean) is counted.

The centres-without-u case is the one issue 14 found at half its size: three coplanar
balls leave registration residuals in their plane only, while a cap fit's error is
largest along the cap axis (Tz, Rx, Ry).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.propagation import linear_covariance
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import centre_covariance, pose_chain, pose_uncertainty
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    TwinSessionSpec,
    simulate_session,
    write_files,
)
from tests.sessions import BALLS, ROOT, small_plan

HEXAPOD_TEXT = (ROOT / "configs" / "symetrie-like.yaml").read_text()
GAIN = (3.0, 7.0, 2.0, 3.0, 9.0, 3.5)
REPLICAS = 60


def replicas(tmp_path: Path, **spec: object) -> tuple[np.ndarray, np.ndarray, str]:
    """Poses (R, M, 12) and claimed u (R, M, 12) of noise replicas, and the source line."""
    poses, claimed = [], []
    description = ""
    for seed in range(REPLICAS):
        folder = tmp_path / f"r{seed}"
        session = TwinSessionSpec(
            name=folder.name,
            hexapod_text=HEXAPOD_TEXT,
            balls=BALLS,
            plan=small_plan(4, 1),
            heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=GAIN),
            seed=seed,
            point_noise_mm=1e-3,
            points_per_ball=25,
            cap_half_angle_deg=70.0,
            **spec,  # type: ignore[arg-type]
        )
        write_files(simulate_session(session).files, folder)
        result = process_session(folder)
        u = pose_uncertainty(result)
        description = u.centres.description
        poses.append(
            np.concatenate([result.correction.conventional, result.correction.corrected], 1)
        )
        claimed.append(np.concatenate([u.conventional_u, u.corrected_u], 1))
    return np.array(poses), np.array(claimed), description


def claimed_over_observed(poses: np.ndarray, claimed: np.ndarray) -> tuple[np.ndarray, float]:
    """Per component (12): RMS claimed u over the replicas' standard deviation (pooled over
    targets); and the share of |pose - replica mean| <= 2u over everything."""
    observed = np.sqrt(np.var(poses, axis=0, ddof=1).mean(axis=0))
    ratio = np.sqrt((claimed**2).mean(axis=(0, 1))) / observed
    inside = np.abs(poses - poses.mean(axis=0)) <= 2 * claimed
    return ratio, float(inside.mean())


@pytest.fixture(scope="module")
def centres_without_u(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, np.ndarray, np.ndarray, str]:
    folder = tmp_path_factory.mktemp("centres-without-u")
    return (folder, *replicas(folder, output="centres", fit_centres=True))


def test_centres_without_u_are_honest_in_every_component(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str],
) -> None:
    _, poses, claimed, description = centres_without_u
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    # the screen says what it rests on, and that Tz, Rx, Ry are not seen by the residuals
    assert "shape of a free-radius fit to 25 points over a 70 deg cap" in description
    assert "warning: the residuals see" in description


def test_the_old_isotropic_pool_was_half_the_truth_out_of_plane(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str],
) -> None:
    """The independent check of the diagnosis: isotropic s^2 I from the same residuals
    claims about half the observed scatter of Tz, Rx, Ry (issue 14 measured 0.46-0.53)."""
    folder, poses, _, _ = centres_without_u
    observed = np.sqrt(np.var(poses, axis=0, ddof=1).mean(axis=0))
    # one replica again, with the isotropic pool instead of the cap shape
    result = process_session(folder / "r0")
    r = result.registration.residuals_mm
    var = (r**2).sum() / (r.shape[0] * (3 * r.shape[1] - 6))
    cov = np.broadcast_to(var * np.eye(3), centre_covariance(result).cov_mm2.shape)
    out = linear_covariance(pose_chain(result), result.centres.centres_mm, cov)
    u_iso = np.sqrt(np.diagonal(out, axis1=-2, axis2=-1)).mean(axis=0)
    ratio = u_iso / observed
    # Tz, Rx, Ry of the conventional pose: about half
    assert np.all(ratio[[2, 3, 4]] < 0.7), ratio.round(3)


@pytest.mark.parametrize("output", ["points", "dmis"])
def test_fitted_points_are_honest_in_every_component(tmp_path: Path, output: str) -> None:
    poses, claimed, description = replicas(tmp_path, output=output)
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    assert "sphere fits of the probed points" in description
