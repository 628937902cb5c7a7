"""``calibrate`` says whether to apply its geometry (issue 33 item 7): the same twin
campaign (30 targets, heating mats, ``sessions/calibration-geometry``'s scenario) with a
real geometry error (the shipped session: ``truth/geometry.csv``) and with none (the
scenario simulated again without ``geometry_errors:``): apply, with the controller's form
of the truth's offsets; keep, and no controller file. The tests' maths against hand
values."""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.calibration.model import true_leg_lengths
from hexatherm.core.calibration.significance import improvement, parameter_change_test
from hexatherm.core.geometry import to_um_urad, transform_from_pose
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.sim.symetrie import ManualClock, SimulatedHexapod
from hexatherm.devices.sim.symetriepmac import SymetriePmacSimulator
from hexatherm.devices.urls import controller_from_url
from hexatherm.io.config.hexapod import read_hexapod
from hexatherm.workflows.calibrate.run import read_campaign
from tests.shipped import SHIPPED as SHIPPED_SESSIONS

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = SHIPPED_SESSIONS / "calibration-geometry"


def test_the_parameters_change_test_and_the_paired_improvement_by_hand():
    # d = (3, 4), C = I: chi2 = 25 with 2 degrees of freedom, p = exp(-25/2)
    test = parameter_change_test([3.0, 4.0], np.eye(2))
    assert test.chi_square == pytest.approx(25.0) and test.dof == 2
    assert test.p == pytest.approx(math.exp(-12.5), rel=1e-9) and test.significant
    # a singular covariance (a gauge freedom): its rank, the change in its range
    cov = np.array([[1.0, 1.0], [1.0, 1.0]])
    test = parameter_change_test([0.5, 0.5], cov)
    assert test.dof == 1 and test.chi_square == pytest.approx(0.25)
    assert not test.significant  # p = 0.617
    # paired reduction of squared residuals: e = (3, 5, 7), mean 5, s = 2, u = 2/sqrt(3)
    before = np.array([[2.0, 0.0], [3.0, 0.0], [4.0, 0.0]])
    after = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    imp = improvement(before, after)
    assert imp.mean == pytest.approx(5.0) and imp.u == pytest.approx(2 / math.sqrt(3))
    assert imp.rms_before == pytest.approx(math.sqrt(29 / 3)) and imp.verdict(2.0) == 1
    assert improvement(after, before).verdict(2.0) == -1
    assert improvement(before, before).verdict(2.0) == 0


def test_the_change_tests_p_is_scipy_stats_own():
    # the former code: scipy.stats.chi2.sf (its import took about 1 s of calibrate's
    # start); changes of every size, singular covariances, a zero change (chi2 = 0)
    from scipy.stats import chi2

    rng = np.random.default_rng(5)
    for n in (1, 2, 6, 42, 48):
        for scale in (0.0, 1e-3, 1.0, 30.0):
            a = rng.normal(size=(n, max(1, n - 2)))
            cov = a @ a.T + (np.eye(n) if n < 6 else 0.0)
            test = parameter_change_test(rng.normal(size=n) * scale, cov)
            assert test.p == float(chi2.sf(test.chi_square, test.dof))
    assert parameter_change_test([0.0, 0.0], np.eye(2)).p == 1.0


def calibrate(session: Path, out: Path) -> tuple[dict, str]:
    result = CliRunner().invoke(main, ["calibrate", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    record = json.loads((out / "calibration.json").read_text())["recommendation"]
    return record, result.output


@pytest.fixture(scope="module")
def no_error_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped campaign's scenario without a geometry error, simulated."""
    root = tmp_path_factory.mktemp("no-error")
    doc = yaml.safe_load((SHIPPED / "truth" / "scenario.yaml").read_text())
    doc.pop("geometry_errors")
    doc.pop("readme", None)
    doc["hexapod"] = str(ROOT / "configs" / "symetrie-like.yaml")
    doc["balls"] = str(ROOT / "configs" / "balls-3.yaml")
    (root / "scenario.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    made = CliRunner().invoke(
        main, ["simulate", str(root / "scenario.yaml"), "-o", str(root / "s")]
    )
    assert made.exit_code == 0, made.output
    return root / "s"


def test_a_campaign_with_a_geometry_error_says_apply_and_writes_the_controllers_form(tmp_path):
    session = tmp_path / "calibration-geometry"
    shutil.copytree(SHIPPED, session, ignore=shutil.ignore_patterns("expected"))
    record, output = calibrate(session, tmp_path / "out")
    assert record["apply"] and record["parameters_significant"] and record["residuals_heldout"]
    assert "Recommendation: APPLY the calibrated geometry" in output
    assert record["translation_um2_mean_square_reduction"]["verdict"] == 1
    controller = yaml.safe_load((tmp_path / "out" / "controller.yaml").read_text())
    # the offsets against the twin's truth (truth/geometry.csv), within their U, and the
    # correction a controller adds: their opposite
    truth = pd.read_csv(SHIPPED / "truth" / "geometry.csv")
    true_offsets = truth.loc[truth["parameter"].str.endswith("_offset_mm"), "true"].to_numpy()
    nominal = truth.loc[truth["parameter"].str.endswith("_offset_mm"), "nominal"].to_numpy()
    for leg, want in zip(controller["legs"], true_offsets - nominal, strict=True):
        assert abs(leg["length_offset_mm"] - want) <= leg["length_offset_U_mm"], leg["leg"]
        assert leg["actuator_correction_mm"] == -leg["length_offset_mm"]
    assert "report.html" in [p.name for p in (tmp_path / "out").iterdir()]
    page = (tmp_path / "out" / "report.html").read_text()
    assert "Recommendation: APPLY" in page
    frames_drive_the_twin_as_controller_yaml_says(session, tmp_path / "out", controller)


def frames_drive_the_twin_as_controller_yaml_says(session: Path, out: Path, controller: dict):
    """``controller_frames``: the gpascii line, sent as it is to the gpascii twin (the
    sessions' nominal geometry: the controller's), makes the twin drive legs that the
    calibrated geometry (``hexapod.yaml``'s joints, ``legs:``' offsets and gains) turns
    into poses whose error at the campaign's targets is what the file predicts, and
    smaller than without the frames."""
    frames = controller["controller_frames"]
    predicted = frames["pose_error_at_targets_predicted"]
    # PI's values are the same transforms in PI's convention (R = Rx Ry Rz)
    for sym, pi in (
        ("user_frame_in_machine", "work_frame_in_zero"),
        ("object_frame_in_platform", "tool_frame_in_platform"),
    ):
        a = transform_from_pose(list(frames["symetrie"][sym]["pose"].values()), "symetrie")
        b = transform_from_pose(list(frames["pi"][pi]["pose"].values()), "pi")
        np.testing.assert_allclose(a, b, atol=1e-8)
    work = [float(v) for v in frames["pi"]["gcs_values"]["work"].split()[1::2]]
    np.testing.assert_allclose(work, list(frames["pi"]["work_frame_in_zero"]["pose"].values()))
    campaign = read_campaign([session])
    calibrated = read_hexapod(out / "hexapod.yaml")
    legs = controller["legs"]
    home = np.array([leg["home_length_mm"] for leg in legs])
    offsets = np.array([leg["length_offset_mm"] for leg in legs])
    gains = np.array([leg["gain"] for leg in legs])
    clock = ManualClock(0.0)
    model = SimulatedHexapod(campaign.nominal, clock=clock)
    with SymetriePmacSimulator(model) as sim:
        driver = controller_from_url(sim.url, clock=clock, sleep=clock.sleep)
        driver.connect()
        worst = {}
        for name, line in (("nominal_controller", None), ("with_these_frames", "set")):
            if line is not None:
                driver._query(frames["symetrie"]["gpascii_line"])
                while driver._values("c_cmd", 1)[0] > 0:
                    pass
                assert driver._values("c_cmd", 1)[0] == 0
            errors = []
            for pose in campaign.commanded:
                driver.move_absolute(pose)
                record = driver.wait_in_position(InPositionCriteria(settle_s=1.0, poll_s=0.5))
                q = true_leg_lengths(record.actuators_mm[None], home, offsets, gains)
                errors.append(to_um_urad(calibrated.fgm(q, initial_poses=pose[None])[0] - pose))
            err = np.array(errors)
            worst[name] = (
                np.linalg.norm(err[:, :3], axis=1).max(),
                np.linalg.norm(err[:, 3:], axis=1).max(),
            )
        driver.close()
    for name, (t_um, r_urad) in worst.items():
        assert t_um == pytest.approx(predicted[name]["max_translation_um"], abs=2e-3), name
        assert r_urad == pytest.approx(predicted[name]["max_rotation_urad"], abs=2e-2), name
    assert worst["with_these_frames"][0] < worst["nominal_controller"][0]
    assert worst["with_these_frames"][1] < worst["nominal_controller"][1]


def test_a_campaign_without_a_geometry_error_says_keep_the_controller(no_error_campaign, tmp_path):
    record, output = calibrate(no_error_campaign, tmp_path / "out")
    assert not record["apply"]
    assert "Recommendation: no significant change: keep the controller as it is." in output
    assert not (tmp_path / "out" / "controller.yaml").exists()
    page = (tmp_path / "out" / "report.html").read_text()
    assert "keep the controller as it is" in page and "Parameters&#x27; change" in page


def test_the_calibration_report_judges_the_calibrated_pose_error_against_the_labs_tolerances(
    tmp_path,
):
    session = tmp_path / "calibration-geometry"
    shutil.copytree(SHIPPED, session, ignore=shutil.ignore_patterns("expected"))
    lab = tmp_path / "lab.yaml"
    lab.write_text(
        "format: hexatherm-lab/1\nlab: Laboratoire Precision Sud\n"
        "tolerances: {Tx_um: 1.0, Tz_um: [-1.0, 2.0]}\n"
        "decision_rule: {rule: guarded-acceptance}\n"
    )
    out = tmp_path / "out"
    args = ["calibrate", str(session), "--level", "joints", "--lab", str(lab), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    page = (out / "report.html").read_text()
    block = page.split("Conformity of the calibrated pose error</h2>")[1].split("</table>")[0]
    assert "guarded acceptance, ILAC-G8:09/2019 4.2.2 (w = U)" in block
    cell = r'<td class="num">([-\d.]+)<span class="u">±\s([\d.]+)</span></td>'
    cell += r'<td class="num">[^<]*</td><td>([a-z ]+)</td>'
    rows = re.findall(r"<tr(?: class=\"fail\")?><td>([^<]+)</td>" + cell + cell, block)
    residuals = pd.read_csv(out / "residuals.csv").set_index("target")
    assert len(rows) == len(residuals) == 30
    decided = set()
    for label, dx, ux, cx, dz, uz, cz in rows:
        # the deviation: residuals.csv's calibrated residual; the decision by hand
        assert float(dx) == pytest.approx(residuals.loc[label, "dTx_um_calibrated"], abs=6e-4)
        assert float(dz) == pytest.approx(residuals.loc[label, "dTz_um_calibrated"], abs=6e-4)
        for got, d, u, lower, upper in ((cx, dx, ux, -1.0, 1.0), (cz, dz, uz, -1.0, 2.0)):
            low, high = lower + float(u), upper - float(u)  # the acceptance limits, w = U
            want = low <= float(d) <= high
            near = min(abs(float(d) - low), abs(float(d) - high))
            if near > 2e-3:  # clear of the page's rounding
                assert got == ("conforms" if want else "does not conform"), (label, d, u)
            decided.add(got)
    assert decided == {"conforms", "does not conform"}  # the tolerances cut through the data
