"""Readers of the YAML contracts: round trips and errors that name file, line and field."""

from __future__ import annotations

import re

import numpy as np
import pytest

from hexatherm.errors import InputError
from hexatherm.io.config import (
    balls_to_yaml,
    hexapod_to_yaml,
    plan_to_yaml,
    read_balls,
    read_hexapod,
    read_plan,
    read_session,
)
from tests.sessions import BALLS, ROOT, make_session, small_plan

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"


def test_shipped_hexapod_is_realistic():
    hexapod = read_hexapod(HEXAPOD)
    q0 = hexapod.zero_pose_leg_length_mm()
    assert np.ptp(q0) < 1e-5 and 200 < q0[0] < 300
    assert hexapod.legs.materials[0] == ("aluminium", "steel")
    assert hexapod.legs.variable[0].tolist() == [False, True]
    assert not hexapod.check_stroke(hexapod.igm([0, 0, -40, 0, 0, 0])).any()


def test_hexapod_round_trip(tmp_path):
    hexapod = read_hexapod(HEXAPOD)
    path = tmp_path / "h.yaml"
    path.write_text(hexapod_to_yaml(hexapod))
    again = read_hexapod(path)
    np.testing.assert_array_equal(again.base_joints_mm, hexapod.base_joints_mm)
    np.testing.assert_array_equal(again.legs.cte_per_K, hexapod.legs.cte_per_K)
    assert again.convention == hexapod.convention


def test_plan_and_balls_round_trip(tmp_path):
    plan = small_plan(4)
    (tmp_path / "plan.yaml").write_text(plan_to_yaml(plan))
    again = read_plan(tmp_path / "plan.yaml")
    assert again.labels == plan.labels and again.kinds == plan.kinds
    np.testing.assert_array_equal(again.poses, plan.poses)
    (tmp_path / "balls.yaml").write_text(balls_to_yaml(BALLS))
    balls = read_balls(tmp_path / "balls.yaml")
    np.testing.assert_array_equal(balls.centres_mm, BALLS.centres_mm)


def edit(path, old, new):
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


@pytest.mark.parametrize(
    ("old", "new", "pattern"),
    [
        (
            "format: hexatherm-hexapod/1",
            "format: hexatherm-hexapod/2",
            r"hexapod.yaml:\d+: field 'format': expected format 'hexatherm-hexapod/1'",
        ),
        (
            "convention: symetrie",
            "convention: zyx",
            r"hexapod.yaml:8: field 'convention': expected one of symetrie, pi",
        ),
        (
            "length: variable}",
            "length: 20.0}",
            r"field 'legs.segments': exactly one segment must have 'length: variable', found 0",
        ),
        ("cte: 2.31e-05", "cte: lots", r"field 'legs.segments\[0\].cte': expected a number"),
        (
            "- [-115.70177, -137.888, -240.0]",
            "- [-115.70177, -137.888]",
            r"hexapod.yaml:10: field 'base_joints\[0\]': expected a list of 3 numbers",
        ),
        ("stroke: [220.0, 310.0]", "stroke: [220.0, 250.0]", "outside the stroke"),
        ("name: symetrie-like", "name: a\nname: b", r"hexapod.yaml:8: field 'name': duplicate"),
        ("stroke:", "strok:", r"field 'strok': unknown key"),
    ],
)
def test_hexapod_errors(tmp_path, old, new, pattern):
    path = tmp_path / "hexapod.yaml"
    path.write_text(HEXAPOD.read_text())
    edit(path, old, new)
    with pytest.raises(InputError, match=pattern):
        read_hexapod(path)


@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (
            lambda t: t.replace("  B3:\n    centre: [82.3, -47.5, 30.0]\n    diameter: 25.4\n", ""),
            r"balls.yaml:\d+: field 'balls': at least three balls are needed, got 2",
        ),
        (
            lambda t: t.replace("[-73.6, -42.5, 30.0]", "[0.0, 45.0, 30.0]").replace(
                "[82.3, -47.5, 30.0]", "[0.0, -10.0, 30.0]"
            ),
            r"field 'balls': the balls are collinear",
        ),
        (
            lambda t: t.replace("diameter: 25.4", "diameter: -1", 1),
            r"field 'balls.B1.diameter': must be positive",
        ),
        (lambda t: t.replace("B2:", "B_2:"), r"field 'balls.B_2': ball name must match"),
    ],
)
def test_balls_errors(tmp_path, mutate, pattern):
    path = tmp_path / "balls.yaml"
    path.write_text(mutate(balls_to_yaml(BALLS)))
    with pytest.raises(InputError, match=pattern):
        read_balls(path)


def test_plan_errors_point_at_the_step_line(tmp_path):
    text = plan_to_yaml(small_plan(3))
    lines = text.splitlines()
    # remove R1 and R2: S2 then has no adjacent reference
    kept = [ln for ln in lines if "label: R1," not in ln and "label: R2," not in ln]
    (tmp_path / "plan.yaml").write_text("\n".join(kept) + "\n")
    s2_line = next(i for i, ln in enumerate(kept, 1) if "label: S2," in ln)
    with pytest.raises(
        InputError,
        match=rf"plan.yaml:{s2_line}: field 'steps\[3\]': step S2: "
        "target has no reference step adjacent",
    ):
        read_plan(tmp_path / "plan.yaml")


def test_plan_duplicate_label(tmp_path):
    text = plan_to_yaml(small_plan(2)).replace("label: S2,", "label: S1,")
    (tmp_path / "plan.yaml").write_text(text)
    with pytest.raises(InputError, match=r"plan.yaml:9: field 'steps\[4\]': step S1: duplicate"):
        read_plan(tmp_path / "plan.yaml")


def test_session_reads_and_names_missing_files(tmp_path):
    make_session(tmp_path / "s")
    session = read_session(tmp_path / "s")
    assert session.plan.labels[:3] == ("O", "R0", "S1")
    edit(tmp_path / "s" / "session.yaml", "centres.csv", "nothere.csv")
    with pytest.raises(
        InputError,
        match=r"session.yaml:\d+: field 'measurements\[0\]': file "
        "not found: .*nothere.csv",
    ):
        read_session(tmp_path / "s")
    with pytest.raises(InputError, match="missing: file not found"):
        read_session(tmp_path / "missing")


def test_yaml_syntax_error_has_line(tmp_path):
    path = tmp_path / "plan.yaml"
    path.write_text("format: hexatherm-plan/1\nsteps: [\n  {label: O\n")
    with pytest.raises(InputError, match=r"plan.yaml:\d+: invalid YAML"):
        read_plan(path)


def test_plan_file_errors(tmp_path):
    with pytest.raises(InputError, match=r"^.*nothere.yaml: file not found$"):
        read_plan(tmp_path / "nothere.yaml")
    with pytest.raises(InputError, match=r"^.*: is a directory, expected a file$"):
        read_plan(tmp_path)
    path = tmp_path / "plan.yaml"
    path.write_bytes(plan_to_yaml(small_plan(2)).encode() + b"# \xff\n")
    with pytest.raises(
        InputError,
        match=r"plan.yaml: not UTF-8 text \(invalid start byte at "
        r"byte \d+\)$",
    ):
        read_plan(path)
    path.write_text("\ufeff" + plan_to_yaml(small_plan(2)))  # a BOM is read past
    assert read_plan(path).labels[-1] == "R2"


def test_per_leg_segments_and_effects(tmp_path):
    text = HEXAPOD.read_text()
    per_leg = "  per_leg:\n" + "".join(
        f"  - - {{name: body, material: aluminium, cte: 2.31e-05, length: {150 + i}.0}}\n"
        "    - {name: screw, material: steel, cte: 1.15e-05, length: variable}\n"
        for i in range(6)
    )
    start = text.index("  segments:")
    text = (
        text[:start]
        + per_leg
        + ("thermal_model:\n  effects:\n  - {name: leg_thermal_lag, parameters: {tau_s: 1800.0}}\n")
    )
    path = tmp_path / "h.yaml"
    path.write_text(text)
    hexapod = read_hexapod(path)
    np.testing.assert_array_equal(hexapod.legs.total_fixed_length_mm, 150.0 + np.arange(6))
    assert hexapod.effects == ({"name": "leg_thermal_lag", "parameters": {"tau_s": 1800.0}},)
    again = tmp_path / "again.yaml"
    again.write_text(hexapod_to_yaml(hexapod))
    assert read_hexapod(again).effects == hexapod.effects
    path.write_text(text.replace("tau_s: 1800.0", "tau: 1800.0"))
    with pytest.raises(
        InputError,
        match=r"field 'thermal_model.effects\[0\].parameters.tau': "
        "unknown key; expected one of: tau_s",
    ):
        read_hexapod(path)
    path.write_text(text.replace("leg_thermal_lag", "leg_lag"))
    with pytest.raises(InputError, match=r"effects\[0\].name': expected one of leg_thermal_lag"):
        read_hexapod(path)


@pytest.mark.parametrize(
    ("effects", "field", "message"),
    [
        (
            "    - {name: leg_thermal_lag, parameters: {tau_s: -5}}\n",
            "thermal_model.effects[0].parameters.tau_s",
            "outside the sensible range",
        ),
        (
            "    - {name: leg_offset, parameters: {leg1: 0, leg2: 0, leg3: 0, leg4: 0, leg5: 0,"
            " leg6: 3.0}}\n",
            "thermal_model.effects[0].parameters.leg6",
            "outside the sensible range",
        ),
        (
            "    - {name: leg_thermal_lag, parameters: {tau_s: 900}}\n"
            "    - {name: leg_thermal_lag, parameters: {tau_s: 1800}}\n",
            "thermal_model.effects[1].name",
            "given twice",
        ),
    ],
)
def test_a_thermal_model_out_of_range_or_twice_is_refused(tmp_path, effects, field, message):
    """docs/formats.md D6: these reached diagnose and --method twin and gave tracebacks."""
    text = (ROOT / "configs" / "symetrie-like.yaml").read_text().rstrip()
    path = tmp_path / "hexapod.yaml"
    path.write_text(text + "\nthermal_model:\n  effects:\n" + effects)
    with pytest.raises(InputError, match=rf"field '{re.escape(field)}': .*{message}"):
        read_hexapod(path)
