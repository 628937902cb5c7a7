"""Quality checks: each fires on a session made to fail it, and none on a good session."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hexatherm.core.plan import Plan
from hexatherm.errors import HexathermError, InputError, InputWarning
from hexatherm.io.config import read_session
from hexatherm.session import QualityLimits
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.quality import (
    CHECKS,
    parse_threshold,
    quality_checks,
    session_thresholds,
)
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    TwinSessionSpec,
    simulate_session,
    write_files,
)
from tests.sessions import BALLS, LEG_GAIN_C, REFERENCE, ROOT, small_plan

HEXAPOD_TEXT = (ROOT / "configs" / "symetrie-like.yaml").read_text()
GAIN = LEG_GAIN_C


def session(folder, *, plan=None, gain=GAIN, output="points", noise_mm=0.5e-3, **kw):
    spec = TwinSessionSpec(
        name=folder.name,
        hexapod_text=HEXAPOD_TEXT,
        balls=BALLS,
        plan=plan or small_plan(3, 1),
        heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=gain),
        seed=2,
        output=output,
        point_noise_mm=noise_mm,
        **kw,
    )
    write_files(simulate_session(spec).files, folder)
    return folder


def failing(folder, **kw):
    """{check: labels of the steps where it failed}."""
    report = quality_checks(process_session(folder), **kw)
    frame = report.frame
    return {
        check: frame.loc[report.failing(check), "label"].tolist()
        for check in CHECKS
        if report.failing(check).any()
    }


def edit_points(folder, label, ball, dx=0.0, dz=0.0, first_only=False):
    frame = pd.read_csv(folder / "points.csv", dtype={"time": str})
    rows = np.flatnonzero((frame["label"] == label) & (frame["ball"] == ball))
    rows = rows[:1] if first_only else rows
    frame.loc[rows, "x"] += dx
    frame.loc[rows, "z"] += dz
    frame.to_csv(folder / "points.csv", index=False, float_format="%.9f")


def replace_in(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def test_good_session_passes_every_check(tmp_path):
    result = process_session(session(tmp_path / "s"))
    report = quality_checks(result)
    frame = report.frame
    assert not report.any_failed and report.failed_steps == []
    assert list(frame.columns[:2]) == ["label", "kind"] and len(frame) == 8
    assert (frame["failed"] == "").all()
    # every value is there: points (form, radius), temperatures, targets
    targets = frame["kind"] == "target"
    assert (
        frame[["form_um", "diameter_dev_um", "distance_dev_um", "registration_rms_um"]]
        .notna()
        .all()
        .all()
    )
    assert (
        frame.loc[targets, ["time_gap_s", "temperature_change_C", "jacobian_rcond"]]
        .notna()
        .all()
        .all()
    )
    assert frame.loc[~targets, "time_gap_s"].isna().all()
    assert all("ok" in line for line in report.summary())


def test_form_error(tmp_path):
    s = session(tmp_path / "s")
    edit_points(s, "S2", "B1", dz=0.03, first_only=True)  # one point 30 um off the ball
    assert failing(s) == {"form": ["S2"]}


def test_diameter_deviation(tmp_path):
    s = session(tmp_path / "s")
    replace_in(s / "balls.yaml", "diameter: 25.4", "diameter: 25.45")  # a 50 um wrong diameter
    assert failing(s) == {"diameter": ["O", "R0", "S1", "R1", "S2", "R2", "S3", "R3"]}
    # the check reads as fits.csv: fitted minus nominal diameter, not half of it
    frame = quality_checks(process_session(s)).frame
    assert frame["diameter_dev_um"].abs().min() > 40.0


def test_a_radius_limit_of_old_is_read_as_the_diameter_limit(tmp_path):
    s = session(tmp_path / "s")
    text = (s / "session.yaml").read_text()
    (s / "session.yaml").write_text(text + "quality: {radius_dev_um: 7}\n")
    with pytest.warns(InputWarning, match="read as diameter_dev_um: 14"):
        thresholds = session_thresholds(process_session(s).session)
    assert thresholds.diameter_dev_um == 14.0
    with pytest.warns(InputWarning, match="diameter_dev_um=10"):
        assert parse_threshold("radius_dev_um=5") == ("diameter_dev_um", 10.0)


def test_inter_ball_distance_and_registration(tmp_path):
    s = session(tmp_path / "s")
    edit_points(s, "R2", "B3", dx=0.025)  # ball B3 of R2 25 um off: distances and residual
    assert failing(s) == {"distance": ["R2"], "registration": ["R2"]}
    # a registration residual beyond a tighter limit, with distances within theirs
    assert failing(session(tmp_path / "t"), thresholds=QualityLimits(registration_rms_um=0.05)) == {
        "registration": ["O", "R0", "S1", "R1", "S2", "R2", "S3", "R3"]
    }


def test_time_gap(tmp_path):
    # the hexapod takes 800 s to move: targets 980 s from their references; little heating
    s = session(tmp_path / "s", seconds_per_move=800.0, gain=(0.3,) * 6)
    assert failing(s) == {"time_gap": ["S1", "S2", "S3"]}


def test_temperature_change(tmp_path):
    s = session(tmp_path / "s", gain=(30.0, 7.0, 2.0, 3.0, 9.0, 3.5))  # leg 1 heats fast
    assert set(failing(s)) == {"temperature"}
    # no temperatures file: not checked, and it says so ("na", not True; "n/a" on screen)
    replace_in(s / "session.yaml", "temperatures: temperatures.csv\n", "")
    report = quality_checks(process_session(s))
    frame = report.frame
    assert frame["temperature_change_C"].isna().all() and (frame["ok_temperature"] == "na").all()
    line = next(x for x in report.summary() if x.lstrip().startswith("temperature"))
    assert "n/a (could not run: no thermocouple log in the session)" in line


def test_fgm_conditioning(tmp_path):
    # a target at Rz = 89.5 deg, next to the hexapod's singularity at 90 deg
    plan = Plan.from_steps(
        [
            ("O", "origin", [0.0] * 6),
            ("R0", "reference", REFERENCE),
            ("S1", "target", [1.0, 2.0, 0.0, 0.1, 0.2, 3.0]),
            ("R1", "reference", REFERENCE),
            ("S2", "target", [0.0, 0.0, 0.0, 0.0, 0.0, 89.5]),
            ("R2", "reference", REFERENCE),
        ],
        reference_pose=REFERENCE,
    )
    s = session(tmp_path / "s", plan=plan, output="centres", noise_mm=0.0)
    assert failing(s) == {"conditioning": ["S2"]}


def test_centres_session_skips_the_sphere_checks(tmp_path):
    frame = quality_checks(process_session(session(tmp_path / "s", output="centres"))).frame
    assert frame["form_um"].isna().all() and frame["diameter_dev_um"].isna().all()
    assert (frame["ok_form"] == "na").all() and (frame["ok_diameter"] == "na").all()


def test_thresholds_parse_and_refuse():
    assert parse_threshold("time_gap_s=900") == ("time_gap_s", 900.0)
    assert parse_threshold(" form_um = inf") == ("form_um", float("inf"))
    for bad, message in (
        ("form_um", "expected NAME=VALUE"),
        ("form=5", "unknown name 'form'"),
        ("form_um=abc", "'abc' is not a number"),
        ("form_um=-1", ">= 0"),
    ):
        with pytest.raises(HexathermError, match=message):
            parse_threshold(bad)
    with pytest.raises(ValueError, match="form_um"):
        QualityLimits(form_um=float("nan"))


def test_session_file_limits_apply_and_the_command_line_overrides_them(tmp_path):
    s = session(tmp_path / "s", gain=(30.0, 7.0, 2.0, 3.0, 9.0, 3.5))  # leg 1 heats fast
    assert set(failing(s)) == {"temperature"}
    with (s / "session.yaml").open("a") as f:
        f.write("quality: {temperature_change_C: .inf, form_um: 0.001}\n")
    assert set(failing(s)) == {"form"}  # the session's limits, by default
    result = process_session(s)
    assert result.session.quality == {"temperature_change_C": np.inf, "form_um": 0.001}
    limits = session_thresholds(result.session, {"form_um": 50.0})
    assert (limits.form_um, limits.temperature_change_C, limits.time_gap_s) == (50.0, np.inf, 600.0)
    assert not failing(s, thresholds=limits)


BAD_QUALITY = {
    "unknown": (
        "quality: {form: 5}",
        r":{first}: field 'quality.form': unknown key; expected one of: "
        "form_um, ",
    ),
    "negative": (
        "quality: {time_gap_s: -1}",
        r":{first}: field 'quality.time_gap_s': expected a "
        r"number >= 0 \(.inf turns the check off\), got -1",
    ),
    "text": ("quality:\n  form_um: five", r":{second}: field 'quality.form_um': expected a number"),
    "list": ("quality: [form_um]", r":{first}: field 'quality': expected a mapping"),
}


@pytest.mark.parametrize("case", sorted(BAD_QUALITY))
def test_bad_quality_mapping_names_file_line_and_field(tmp_path, case):
    s = session(tmp_path / "s", noise_mm=0.0)
    text, pattern = BAD_QUALITY[case]
    first = len((s / "session.yaml").read_text().splitlines()) + 1  # the appended line
    with (s / "session.yaml").open("a") as f:
        f.write(text + "\n")
    pattern = pattern.replace("{first}", str(first)).replace("{second}", str(first + 1))
    with pytest.raises(InputError, match=r"session\.yaml" + pattern):
        read_session(s)
