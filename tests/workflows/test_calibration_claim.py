"""What a calibration claims for a NEW pose is what it gives (issue 24, item 4).

The twin is the truth: seeded campaigns are simulated (a true geometry off the hexapod
file, 0.3 um probing noise, the legs 1.3 K above the leg model's 20 degC at R0 and
warming under heating mats), processed and calibrated at the ``joints`` level; the
calibrated model then predicts poses it was not fitted to, drawn over the campaign's
span, and the twin says where those poses truly stand (in R0's thermal state, relative
to O as measured: :func:`~hexatherm.workflows.simulate.heldout.heldout_truth`). The
claimed standard uncertainty of each held-out pose (the parameters' part and the level's
model floor, :func:`~hexatherm.workflows.calibrate.claim.pose_claim`) is compared with
the RMS of the actual errors, per component, pooled over the seeds (one campaign is one
draw of its parameter errors: a single seed has a handful of degrees of freedom in a
component).

The floor itself is checked against the twin where nothing else is left: noise-free
campaigns, whose held-out error is the floor alone.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.geometry import to_um_urad
from hexatherm.io.scenario import read_scenario
from hexatherm.workflows.calibrate.claim import pose_claim, span_poses, stroke_radius
from hexatherm.workflows.calibrate.outputs import calibration_json, output_files
from hexatherm.workflows.calibrate.run import Calibration, calibrate, read_campaign
from hexatherm.workflows.simulate.heldout import heldout_truth
from hexatherm.workflows.simulate.run import scenario_spec, simulate
from hexatherm.workflows.simulate.twinsession import TwinSessionSpec
from tests.replicas import write_session
from tests.sessions import CALIBRATION_SPAN, calibration_scenario, calibration_targets

#: campaigns pooled (each about 0.2 s of CPU)
N_SEEDS = 40
N_TARGETS = 20
N_HELDOUT = 100
#: new poses of each campaign's claim by stroke region
N_SPAN = 500
COMPONENTS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
#: the legs at 21.3 degC (1.3 K above the leg model's reference) and warming 1 K
MATS = ", ".join(["{gain_C: 1.0, tau_s: 3600, power: [[0, null]]}"] * 6)
WARM = f"heating: {{air_C: 21.3, mats: [{MATS}]}}\n"


def campaign(
    root: Path,
    seed: int,
    noise_um: float = 0.3,
    thermocouple_noise_C: float = 0.02,
    heating: str = WARM,
) -> tuple[Calibration, TwinSessionSpec]:
    """A simulated campaign calibrated at the joints level, and its twin's spec
    (``heating``: the scenario's ``heating:`` text)."""
    text = calibration_scenario(
        calibration_targets(seed, N_TARGETS),
        geometry_seed=seed + 100,
        seed=seed,
        points_per_ball=8,
        cmm={"point_noise_um": noise_um},
        thermocouples={"period_s": 30, "noise_C": thermocouple_noise_C},
        timing={"seconds_per_point": 2.0, "seconds_per_move": 20},
        extra=heating,
    )
    path = root / f"s{seed}.yaml"
    path.write_text(text)
    scenario = read_scenario(path)
    folder = root / f"s{seed}"
    write_session(simulate(scenario, truth_files=False).files, folder)  # truth: heldout_truth
    return calibrate(read_campaign([folder]), level="joints"), scenario_spec(scenario)


def heldout_poses(run: Calibration, seed: int) -> np.ndarray:
    """New commanded poses over the campaigns' box, inside the stroke."""
    draws = np.random.default_rng(1000 + seed).uniform(-1, 1, (N_HELDOUT, 6)) * CALIBRATION_SPAN
    nominal = run.campaign.nominal
    return draws[~nominal.check_stroke(nominal.igm(draws)).any(axis=1)]


def by_third(values: np.ndarray, region: np.ndarray) -> np.ndarray:
    """The mean square (3, 6) of ``values`` (M, 6) in each stroke region."""
    return np.array([np.mean(values[region == k] ** 2, axis=0) for k in range(3)])


@pytest.fixture(scope="module")
def pooled(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    """Per seed and component: the mean square of the claimed u at the held-out poses,
    of the parameters' part alone, and of the actual errors (um^2, urad^2); and per
    stroke third of the held-out poses (inner, middle, outer: the thirds of
    ``calibration.json``'s ``by_region``), the same of the claim at each pose, of the
    region's claim as ``calibration.json`` states it (its RMS), of the one number for the
    whole stroke (``typical_rms_um_urad``), and of the errors."""
    root = tmp_path_factory.mktemp("claim")
    claimed, parameters, observed = [], [], []
    thirds: dict[str, list[np.ndarray]] = {"pose": [], "stated": [], "one": [], "observed": []}
    for seed in range(N_SEEDS):
        run, spec = campaign(root, seed)
        held = heldout_poses(run, seed)
        claim = pose_claim(run, held)
        error = to_um_urad(run.fit.predict(held) - heldout_truth(spec, held))
        claimed.append(np.mean(claim.sigma_um_urad**2, axis=0))
        parameters.append(np.mean(claim.parameters_um_urad**2, axis=0))
        observed.append(np.mean(error**2, axis=0))
        span = pose_claim(run, span_poses(run, N_SPAN))  # as calibrate's 2000, fewer
        record = json.loads(calibration_json(run, claim=span))["new_pose_claim"]
        regions = record["by_region"]["regions"]
        bounds = [regions[0]["radius_to"], regions[1]["radius_to"]]
        # the regions are of the campaign's box: the held-out poses inside it
        commanded = run.campaign.commanded
        box = np.all((held >= commanded.min(axis=0)) & (held <= commanded.max(axis=0)), axis=1)
        region = np.where(box, np.digitize(stroke_radius(run, held), bounds), -1)
        stated = np.array([list(r["rms_um_urad"].values()) for r in regions])
        typical = np.array(list(record["typical_rms_um_urad"].values()))
        thirds["pose"].append(by_third(claim.sigma_um_urad, region))
        thirds["stated"].append(stated**2)
        thirds["one"].append(np.tile(typical**2, (3, 1)))
        thirds["observed"].append(by_third(error, region))
    return {
        "claimed": np.array(claimed),
        "parameters": np.array(parameters),
        "observed": np.array(observed),
        **{f"thirds_{k}": np.array(v) for k, v in thirds.items()},
    }


def thirds_ratio(pooled: dict[str, np.ndarray], claim: str) -> np.ndarray:
    """Claimed over observed (3, 6) by stroke third, mean squares pooled over the seeds."""
    return np.sqrt(pooled[f"thirds_{claim}"].mean(axis=0) / pooled["thirds_observed"].mean(axis=0))


@pytest.mark.parametrize("claim", ["pose", "stated"])
def test_claimed_over_observed_within_15_percent_in_every_stroke_third(
    pooled: dict[str, np.ndarray], claim: str
) -> None:
    """Issue 35, item 5: the claim at each held-out pose, and the RMS claim of its stroke
    region as calibration.json states it, against the twin's truth, by stroke third."""
    ratio = thirds_ratio(pooled, claim)
    assert np.all((ratio > 0.85) & (ratio < 1.15)), ratio.round(3)


def test_one_number_for_the_whole_stroke_misses_the_outer_third(
    pooled: dict[str, np.ndarray],
) -> None:
    """What the regions mend: the typical U of the whole stroke over-claims the inner
    third and under-claims the outer one (as the audit found: 0.70-0.79 outer)."""
    ratio = thirds_ratio(pooled, "one")
    assert np.all(ratio[2] < 0.9) and np.all(ratio[0] > 1.05), ratio.round(3)


def test_claimed_over_observed_within_15_percent_per_component(
    pooled: dict[str, np.ndarray],
) -> None:
    ratio = np.sqrt(pooled["claimed"].mean(axis=0) / pooled["observed"].mean(axis=0))
    assert np.all((ratio > 0.85) & (ratio < 1.15)), dict(
        zip(COMPONENTS, ratio.round(3), strict=True)
    )


def test_the_parameters_alone_claim_too_little_in_tz(pooled: dict[str, np.ndarray]) -> None:
    """The campaigns have a floor worth claiming: without it (the claim before issue 24)
    Tz is claimed a third too small."""
    ratio = np.sqrt(pooled["parameters"].mean(axis=0) / pooled["observed"].mean(axis=0))
    assert ratio[2] < 0.8, dict(zip(COMPONENTS, ratio.round(3), strict=True))


@pytest.mark.parametrize("seed", [0, 1])
def test_floor_is_the_error_of_a_noise_free_calibration(tmp_path: Path, seed: int) -> None:
    """Without noise the parameters' part vanishes and the held-out error is the floor:
    the twin's truth (nonlinear, the legs' growth segment by segment) against the floor's
    linearised model, per component, RMS over new poses."""
    run, spec = campaign(tmp_path, seed, noise_um=0.001, thermocouple_noise_C=0.0)
    held = heldout_poses(run, seed)
    claim = pose_claim(run, held)
    error = to_um_urad(run.fit.predict(held) - heldout_truth(spec, held))
    observed = np.sqrt(np.mean(error**2, axis=0))
    floor = claim.floor.sigma_um_urad
    assert np.all(np.abs(floor / observed - 1.0) < 0.1), (floor, observed)
    assert floor[2] > 0.1  # Tz, um: the 15 ppm gain the joints cannot model
    # and pose by pose (issue 35, item 5): the floor at each pose is that pose's error,
    # larger at the ends of the stroke than one RMS for all says
    at = claim.floor.at(len(held))
    worst = np.argmax(error**2 / floor**2, axis=0)
    assert np.all(np.abs(np.abs(error) / at - 1.0)[worst, range(6)] < 0.2), (error, at)
    parameters = np.sqrt(np.mean(claim.parameters_um_urad**2, axis=0))
    assert np.all(parameters < 0.2 * floor), (parameters, floor)  # the floor alone
    # the gains absorb R0's growth; the legs' warming between O and R0 stayed in Tz until
    # process carried O to R0's state (issue 35): now nothing stays, and none is claimed
    gains = calibrate(run.campaign, level="joints+gains")
    claim = pose_claim(gains, held)
    error = to_um_urad(gains.fit.predict(held) - heldout_truth(spec, held))
    tz = np.sqrt(np.mean(error[:, 2] ** 2))
    assert tz < 0.01 and claim.floor.sigma_um_urad[2] < 0.01, (claim.floor.sigma_um_urad, tz)


def test_calibration_json_and_report_say_the_claim_and_its_floor(tmp_path: Path) -> None:
    run, _ = campaign(tmp_path, 3)
    files = output_files(run, [tmp_path / "s3" / "session.yaml"], tmp_path / "out")
    record = json.loads(files["calibration.json"])["new_pose_claim"]
    claim = pose_claim(run)
    worst = np.array(list(record["worst_um_urad"].values()))
    typical = np.array(list(record["typical_rms_um_urad"].values()))
    floor = np.array(list(record["floor_um_urad"].values()))
    assert np.allclose(worst, claim.worst_um_urad)
    assert np.allclose(typical, claim.typical_um_urad)
    assert np.all((floor <= typical) & (typical <= worst))
    assert np.allclose(floor, claim.floor.sigma_um_urad)
    assert floor[2] > 0.1
    assert "R0" in record["floor_method"] and record["floor_note"] == ""
    assert np.allclose(record["leg_temperature_R0_C"], 21.3, atol=0.1)
    page = files["report.html"]
    assert "Claimed uncertainty of a new calibrated pose" in page
    assert "model floor" in page
    # by stroke region and along each axis (issue 35, item 5): the thirds' RMS is the
    # claim's at the poses of each third, the axes' the claim at those poses
    regions = record["by_region"]["regions"]
    radius = stroke_radius(run, claim.poses)
    for region in regions:
        low, high = region["radius_from"], region["radius_to"]
        mine = (radius >= low) & (radius < (np.inf if high is None else high))
        assert region["n_poses"] == mine.sum() > 0
        rms_u = np.sqrt(np.mean(claim.sigma_um_urad[mine] ** 2, axis=0))
        assert np.allclose(list(region["rms_um_urad"].values()), rms_u)
    assert "outer third, worst" in page and "× half-width" in page
    tx = record["along_axes"][0]
    poses = np.tile((run.campaign.commanded.min(0) + run.campaign.commanded.max(0)) / 2, (5, 1))
    poses[:, 0] = tx["positions"]
    at = pose_claim(run, poses).sigma_um_urad
    assert np.allclose([list(u.values()) for u in tx["u_um_urad"]], at)
    assert at[0, 0] > at[2, 0] < at[4, 0]  # larger at the ends of Tx than at its centre


def test_no_thermocouple_log_no_floor_said(tmp_path: Path) -> None:
    run, _ = campaign(tmp_path, 4)
    results = [dataclasses.replace(r, temperatures=None) for r in run.campaign.results]
    bare = dataclasses.replace(run, campaign=dataclasses.replace(run.campaign, results=results))
    claim = pose_claim(bare)
    assert np.all(claim.floor.sigma_um_urad == 0.0)
    assert "no thermocouple log" in claim.floor.note
    assert np.allclose(claim.sigma_um_urad, claim.parameters_um_urad)


def test_screen_shows_the_claim_of_calibration_json(tmp_path: Path) -> None:
    campaign(tmp_path, 5)
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main,
        ["calibrate", str(tmp_path / "s5"), "-o", str(out), "--level", "joints"]
        + ["--coverage-factor", "3"],
    )
    assert result.exit_code == 0, result.output
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["level_chosen"] is None and doc["level_auto"] is False  # forced
    record = doc["new_pose_claim"]
    lines = {line.split()[0]: line.split() for line in result.stdout.splitlines() if line}
    for region in record["by_region"]["regions"]:  # the RMS U of each stroke third
        shown = np.array(lines[region["region"]][2:8], dtype=float)
        assert np.allclose(shown, 3.0 * np.array(list(region["rms_um_urad"].values())), atol=6e-4)
    assert "new" in lines and "(k = 3)" in result.stdout
    for name, key in (("worst", "worst_um_urad"), ("typical", "typical_rms_um_urad")):
        shown = np.array(lines[name][1:7], dtype=float)
        assert np.allclose(shown, 3.0 * np.array(list(record[key].values())), atol=6e-4)
    floor = np.array(lines["floor"][4:10], dtype=float)
    assert np.allclose(floor, list(record["floor_um_urad"].values()), atol=6e-4)


def test_report_says_the_claim_covers_only_the_model_when_it_does_not_explain(
    tmp_path: Path,
) -> None:
    """The offsets level leaves the 50 um joint errors in the residuals: the chi-square
    test fails, and the claim (parameters and floor) is said to cover only the model."""
    run, _ = campaign(tmp_path, 6)
    offsets = calibrate(run.campaign, level="offsets")
    assert not offsets.fit.explains_poses
    page = output_files(offsets, [tmp_path / "s6" / "session.yaml"], tmp_path / "o")["report.html"]
    assert "this claim covers only what it models" in page
    page = output_files(run, [tmp_path / "s6" / "session.yaml"], tmp_path / "o")["report.html"]
    assert "this claim covers only what it models" not in page
