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

import io
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.core.propagation import linear_covariance
from hexatherm.io.csvfile import centres_to_csv
from hexatherm.io.measurements import read_measurements
from hexatherm.workflows.process import errorterms
from hexatherm.workflows.process.measured import fit_points
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import centre_covariance, pose_chain, pose_uncertainty
from hexatherm.workflows.simulate.twinsession import Heating, TwinSessionSpec, simulate_session
from tests.replicas import SessionReader, write_session
from tests.sessions import BALLS, LEG_GAIN_C, ROOT, small_plan


@pytest.fixture(scope="module", autouse=True)
def noise_only() -> Iterator[None]:
    """These tests hold the claimed u against the scatter of noise replicas: the
    interpolation's own error between references (a bias, the same in every replica,
    tested against the twin's truth in test_interpolation_error.py) is left out of u."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(errorterms, "curvature_excess", lambda *args: None)
        yield


HEXAPOD_TEXT = (ROOT / "configs" / "symetrie-like.yaml").read_text()
GAIN = LEG_GAIN_C
REPLICAS = 100


@dataclass
class Parts:
    """What each replica claims beyond u: common and own parts (R, M, 12), mm and deg,
    and the between-target covariance (R, 12, M, M), mm^2 and deg^2."""

    common: list[np.ndarray] = field(default_factory=list)
    own: list[np.ndarray] = field(default_factory=list)
    between: list[np.ndarray] = field(default_factory=list)


#: simulated files per (seed, spec): a campaign's noise replicas are simulated once and
#: processed by every test that reads them (each writes its own copy to edit)
_SIMULATED: dict[tuple[int, tuple[tuple[str, object], ...]], dict[str, str]] = {}
#: every replica's session, hexapod, balls and plan files are read once per text
READER = SessionReader()


@pytest.fixture(scope="module", autouse=True)
def _forget_the_simulations() -> Iterator[None]:
    yield
    _SIMULATED.clear()  # some 30 MB of points files: not kept past this module


def simulated_files(seed: int, spec: dict[str, object]) -> dict[str, str]:
    key = (seed, tuple(sorted(spec.items())))
    if key not in _SIMULATED:
        session = TwinSessionSpec(
            name="r",  # one session file for every replica: read once (READER)
            hexapod_text=HEXAPOD_TEXT,
            balls=BALLS,
            plan=small_plan(4, 1),
            heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=GAIN),
            seed=seed,
            **spec,  # type: ignore[arg-type]
        )
        _SIMULATED[key] = simulate_session(session, truth_files=False).files
    return _SIMULATED[key]


def replicas(
    tmp_path: Path,
    edit: Callable[[Path], None] | None = None,
    parts: Parts | None = None,
    count: int = REPLICAS,
    **spec: object,
) -> tuple[np.ndarray, np.ndarray, str]:
    """Poses (R, M, 12) and claimed u (R, M, 12) of noise replicas, and the source line.

    ``edit(folder)`` changes each written session before it is processed; ``parts``
    collects the common and own parts and the between-target covariance."""
    poses, claimed = [], []
    description = ""
    spec = {"point_noise_mm": 1e-3, "points_per_ball": 25, "cap_half_angle_deg": 70.0, **spec}
    for seed in range(count):
        folder = tmp_path / f"r{seed}"
        write_session(simulated_files(seed, spec), folder)
        if edit is not None:
            edit(folder)
        result = READER.process(folder)
        u = pose_uncertainty(result)
        description = u.centres.description
        poses.append(
            np.concatenate([result.correction.conventional, result.correction.corrected], 1)
        )
        claimed.append(np.concatenate([u.conventional_u, u.corrected_u], 1))
        if parts is not None:
            assert u.common_u is not None and u.own_u is not None
            assert u.between_covariance is not None
            parts.common.append(u.common_u)
            parts.own.append(u.own_u)
            parts.between.append(u.between_covariance)
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
) -> tuple[Path, np.ndarray, np.ndarray, str, Parts]:
    folder = tmp_path_factory.mktemp("centres-without-u")
    parts = Parts()
    return (folder, *replicas(folder, parts=parts, output="centres", fit_centres=True), parts)


def test_centres_without_u_are_honest_in_every_component(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str, Parts],
) -> None:
    _, poses, claimed, description, _ = centres_without_u
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    # the screen says what it rests on: the cap's shape, its z part from the references
    assert "shape of a free-radius fit to 25 points over a 70 deg cap" in description
    assert "to the scatter of the 5 references' ball heights (Type A" in description
    assert "warning" not in description


def test_centres_without_u_of_another_touch_pattern_are_honest(tmp_path: Path) -> None:
    """A CMM program that spreads its points uniformly in polar angle from 5 to 80 deg (not
    the assumed equal-area 70 deg cap): the centres' error along z is smaller than the
    assumed shape's, and the references' heights say by how much (issue 24: Tz, Rx, Ry
    were claimed 1.38-1.46x the observed from the assumed shape alone)."""
    poses, claimed, description = replicas(
        tmp_path, output="centres", fit_centres=True, touch_polar_deg=(5.0, 80.0)
    )
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    assert "(Type A: second differences in time, 9 degrees of freedom)" in description


def short_session(folder: Path, seed: int, polar: bool) -> Path:
    """Two targets, one reference each: 3 references, 3 degrees of freedom in their
    heights; the touch pattern the assumed cap's, or polar angles uniform 5-80 deg."""
    session = TwinSessionSpec(
        name="s",
        hexapod_text=HEXAPOD_TEXT,
        balls=BALLS,
        plan=small_plan(2, 1),
        heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=GAIN),
        seed=seed,
        point_noise_mm=1e-3,
        output="centres",
        fit_centres=True,
        touch_polar_deg=(5.0, 80.0) if polar else None,
    )
    return write_session(simulate_session(session, truth_files=False).files, folder)


SHORT_REPLICAS = 60


def test_a_short_session_evaluates_its_heights_and_says_its_degrees_of_freedom(
    tmp_path: Path,
) -> None:
    """Issue 35: 3 references (3 degrees of freedom in their heights) kept the assumed
    cap, which claimed 1.23-1.42x the observed Tz, Rx, Ry, Tx of a touch pattern uniform in
    polar angle 5-80 deg (100 replicas). Now the heights are evaluated with their 3
    degrees of freedom, said with Student's k: claimed/observed 0.94-1.07 over 100
    replicas (0.93-1.09 with the assumed pattern), 90 % within 2u (t_3 wants k = 3.18 for
    95 %)."""
    poses, claimed = [], []
    for seed in range(SHORT_REPLICAS):
        result = READER.process(short_session(tmp_path / f"r{seed}", seed, polar=True))
        u = pose_uncertainty(result)
        poses.append(
            np.concatenate([result.correction.conventional, result.correction.corrected], 1)
        )
        claimed.append(np.concatenate([u.conventional_u, u.corrected_u], 1))
    ratio, coverage = claimed_over_observed(np.array(poses), np.array(claimed))
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio.round(3)
    assert 0.85 <= coverage <= 0.97, coverage
    description = u.centres.description
    assert "to the scatter of the 3 references' ball heights" in description
    assert "(Type A: second differences in time, 3 degrees of freedom)" in description
    assert "rests on 3 degrees of freedom of the references' heights: for 95 % take " in (
        description
    )
    assert "k = 3.18 (Student's t), not 2" in description


def test_the_old_isotropic_pool_was_half_the_truth_out_of_plane(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str, Parts],
) -> None:
    """The independent check of the diagnosis: isotropic s^2 I from the same residuals
    claims about half the observed scatter of Tz, Rx, Ry (issue 14 measured 0.46-0.53)."""
    folder, poses, _, _, _ = centres_without_u
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


@pytest.fixture(scope="module")
def points_replicas(tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, np.ndarray, str]:
    return replicas(tmp_path_factory.mktemp("points"), output="points")


def test_fitted_points_are_honest_in_every_component(
    points_replicas: tuple[np.ndarray, np.ndarray, str],
) -> None:
    poses, claimed, description = points_replicas
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    assert "sphere fits of the probed points" in description


#: replicas of the points campaign read another way: what each claims is compared with
#: what the points path claims for the same probed points, proven honest above
SAME_POINTS = 10


def test_the_same_points_in_dmis_give_the_same_poses_and_claims(
    points_replicas: tuple[np.ndarray, np.ndarray, str], tmp_path: Path
) -> None:
    """The twin writes the same probed points as a DMIS output file: the poses and the
    claimed u are the points path's (so as honest as they are, over 100 replicas)."""
    poses, claimed, description = replicas(tmp_path, count=SAME_POINTS, output="dmis")
    np.testing.assert_allclose(poses, points_replicas[0][:SAME_POINTS], rtol=0, atol=1e-9)
    np.testing.assert_allclose(claimed, points_replicas[1][:SAME_POINTS], rtol=1e-9, atol=0)
    assert "sphere fits of the probed points" in description


def test_the_cmm_mapping_is_honest_when_it_states_the_probing(tmp_path: Path) -> None:
    """Centres fitted by the CMM, session.yaml stating its noise and touch pattern."""

    def state_the_cmm(folder: Path) -> None:
        session = folder / "session.yaml"
        text = session.read_text()
        session.write_text(text + "cmm: {point_noise_um: 1.0, points_per_ball: 25}\n")

    poses, claimed, description = replicas(
        tmp_path, state_the_cmm, output="centres", fit_centres=True
    )
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    assert description.startswith("session cmm: point noise 1 um, 25 points over a 70 deg cap")


def test_centres_with_u_are_honest_when_u_is(tmp_path: Path) -> None:
    """Centres with isotropic noise of 0.8 um, the file's covariance columns saying so (a
    scalar u_um is a cap fit's: issue 35)."""

    def add_u(folder: Path) -> None:
        centres = folder / "centres.csv"
        lines = centres.read_text().splitlines()
        head = ",diameter,u_x_um,u_y_um,u_z_um,r_xy,r_xz,r_yz"
        rows = [lines[0] + head] + [line + ",25.4,0.8,0.8,0.8,0,0,0" for line in lines[1:]]
        centres.write_text("\n".join(rows) + "\n")

    poses, claimed, description = replicas(
        tmp_path, add_u, output="centres", centre_noise_mm=0.8e-3, point_noise_mm=0.0
    )
    ratio, coverage = claimed_over_observed(poses, claimed)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)
    assert 0.92 <= coverage <= 0.98, coverage
    assert description.startswith("u_x_um .. r_yz of the centres file")


def replica_covariance(poses: np.ndarray) -> np.ndarray:
    """Observed covariance (12, M, M) of each output between targets over the replicas."""
    e = poses - poses.mean(axis=0)
    return np.einsum("ray,rby->yab", e, e) / (len(poses) - 1)


def test_common_and_own_parts_add_up_to_u(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str, Parts],
) -> None:
    _, _, claimed, _, parts = centres_without_u
    common, own, between = (np.array(x) for x in (parts.common, parts.own, parts.between))
    np.testing.assert_allclose(common**2 + own**2, claimed**2, rtol=1e-12, atol=0)
    diagonal = np.diagonal(between, axis1=-2, axis2=-1)  # (R, 12, M)
    np.testing.assert_allclose(np.swapaxes(diagonal, 1, 2), claimed**2, rtol=1e-12, atol=0)
    # O and R0 against one step and its interpolated references: both parts are large
    # (own 0.49 of u in one replica of 100, whose heights read off the heating's motion)
    assert np.all((common > 0.45 * claimed) & (own > 0.45 * claimed))


def test_differences_between_targets_scatter_as_their_own_parts(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str, Parts],
) -> None:
    """Two targets that share no reference (S1-S3, S1-S4, S2-S4) share O and R0 only: their
    difference cancels the common part, and scatters as the own parts in quadrature."""
    _, poses, _, _, parts = centres_without_u
    own = np.array(parts.own)
    r = len(poses)
    ratios = []
    for a, b in ((0, 2), (0, 3), (1, 3)):
        observed = np.std(poses[:, a] - poses[:, b], axis=0, ddof=1)
        ratios.append(observed / np.sqrt((own[:, a] ** 2 + own[:, b] ** 2).mean(axis=0)))
    ratio = np.array(ratios)
    limit = 4 / np.sqrt(2 * (r - 1))  # 4 sampling standard errors of a standard deviation
    assert np.all(np.abs(ratio - 1) < limit), ratio.round(3)
    assert abs(ratio.mean() - 1) < 0.1, ratio.mean()


def test_the_target_mean_scatters_as_the_common_part_claims(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str, Parts],
) -> None:
    """The mean over the targets carries the common part whole and the own parts divided
    down; its scatter over the replicas matches the claimed covariance's mean, most of it
    the common part."""
    _, poses, _, _, parts = centres_without_u
    common, between = np.array(parts.common), np.array(parts.between)
    r, m = poses.shape[:2]
    observed = np.std(poses.mean(axis=1), axis=0, ddof=1)  # (12,)
    claimed_var = between.mean(axis=(0, 2, 3))  # the mean of the (M, M) matrix
    ratio = observed / np.sqrt(claimed_var)
    limit = 4 / np.sqrt(2 * (r - 1))
    assert np.all(np.abs(ratio - 1) < limit), ratio.round(3)
    assert abs(ratio.mean() - 1) < 0.1, ratio.mean()
    common_share = (common**2).mean(axis=(0, 1)) / claimed_var
    assert np.all((common_share > 0.6) & (common_share <= 1.0)), common_share.round(3)


def test_the_between_target_covariance_is_the_replicas(
    centres_without_u: tuple[Path, np.ndarray, np.ndarray, str, Parts],
) -> None:
    """Correlations between targets, claimed against observed over the replicas: within
    0.1 on average, and every one within 4 standard errors (Fisher z)."""
    _, poses, _, _, parts = centres_without_u
    r, m = poses.shape[:2]
    claimed, observed = np.array(parts.between).mean(axis=0), replica_covariance(poses)

    def correlation(c: np.ndarray) -> np.ndarray:
        s = np.sqrt(np.diagonal(c, axis1=1, axis2=2))
        a, b = np.triu_indices(m, 1)
        return c[:, a, b] / (s[:, a] * s[:, b])

    rho_claimed, rho_observed = correlation(claimed), correlation(observed)
    assert np.all(rho_claimed > 0.4)  # O and R0 make every pair correlate
    assert np.mean(np.abs(rho_observed - rho_claimed)) < 0.1
    z = (np.arctanh(rho_observed) - np.arctanh(rho_claimed)) * np.sqrt(r - 3)
    assert np.all(np.abs(z) < 4), z.round(2)
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.4


def fit_spheres_round_trip(columns: tuple[str, ...] | None = None) -> Callable[[Path], None]:
    """An edit of a points session: its points fitted as ``fit-spheres`` does and written
    as ``centres.csv`` (with only ``columns`` of the extension columns when given), the
    session reading that file instead."""

    def edit(folder: Path) -> None:
        points = folder / "points.csv"
        fitted = fit_points(read_measurements(points)[0])
        text = centres_to_csv(fitted)
        if columns is not None:
            frame = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)
            text = frame[[*frame.columns[:6], *columns]].to_csv(index=False)
        (folder / "centres.csv").write_text(text)
        points.unlink()
        session = folder / "session.yaml"
        session.write_text(session.read_text().replace("points.csv", "centres.csv"))

    return edit


def test_fit_spheres_centres_carry_their_covariance_honestly(
    points_replicas: tuple[np.ndarray, np.ndarray, str], tmp_path: Path
) -> None:
    """fit-spheres -> centres file -> process: the per-axis u and correlations carry the
    cap fit's covariance (z about twice x and y), so every component claims what the
    points path claims for the same points, to the file's rounding, and is as honest as
    it is over 100 replicas (issue 24: read back as an isotropic u_um, Tz, Rx, Ry were
    claimed 25-34 % too small)."""
    poses, claimed, description = replicas(
        tmp_path, fit_spheres_round_trip(), count=SAME_POINTS, output="points"
    )
    np.testing.assert_allclose(poses, points_replicas[0][:SAME_POINTS], rtol=0, atol=1e-6)
    np.testing.assert_allclose(claimed, points_replicas[1][:SAME_POINTS], rtol=1e-3, atol=0)
    assert description.startswith("u_x_um .. r_yz of the centres file")


def test_a_scalar_u_um_is_shaped_as_a_cap_fit_and_said_so(
    points_replicas: tuple[np.ndarray, np.ndarray, str], tmp_path: Path
) -> None:
    """The same round trip with only the scalar u_um (other software's kind, issue 35):
    shaped as a free-radius fit to the plan's touch pattern, scaled so that its RMS over
    the axes is the file's u; the screen says what was assumed. Read as isotropic (u^2 I)
    it claimed 0.58-0.69 of the observed Tz, Rx, Ry and 1.35-1.69 of Ty, Rz; shaped,
    0.88-1.12 per component over 100 replicas, 95 % within 2u."""
    poses, claimed, description = replicas(
        tmp_path, fit_spheres_round_trip(("u_um",)), count=SAME_POINTS, output="points"
    )
    # the same centres as the points path: its 100 replicas' scatter is theirs
    np.testing.assert_allclose(poses, points_replicas[0][:SAME_POINTS], rtol=0, atol=1e-6)
    observed = np.sqrt(np.var(points_replicas[0], axis=0, ddof=1).mean(axis=0))
    ratio = np.sqrt((claimed**2).mean(axis=(0, 1))) / observed
    assert np.all((ratio > 0.8) & (ratio < 1.2)), ratio.round(3)
    centred = poses - points_replicas[0].mean(axis=0)
    coverage = float((np.abs(centred) <= 2 * claimed).mean())
    assert 0.9 <= coverage <= 0.99, coverage
    assert "shaped as a free-radius cap fit: u in x, y, z 0.59, 0.56, 1.53 x" in description
    assert "warning: the centres file's u_um is one number per centre; its shape is " in (
        description
    )
