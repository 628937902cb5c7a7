"""``hexatherm simulate``: sessions that process to their truth, reproducible, checked input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.plan import Plan
from hexatherm.core.planning import sequence_steps
from hexatherm.io.config import plan_to_yaml, read_session
from hexatherm.io.manifest import MANIFEST_NAME
from hexatherm.io.provenance import PROVENANCE_NAME
from tests.sessions import ROOT
from tests.shipped import SHIPPED

UM, URAD = 1e3, np.pi / 180 * 1e6
TARGETS = [
    [5.0, -3.0, 4.0, 1.0, -2.0, 3.0],
    [-8.0, 6.0, -5.0, -2.5, 1.5, -4.0],
    [12.0, 10.0, 2.0, 0.5, 3.0, -6.0],
    [-15.0, -12.0, 8.0, 3.0, -1.0, 7.0],
]

SCENARIO = """\
format: hexatherm-scenario/1
name: test-run
hexapod: {root}/configs/symetrie-like.yaml
balls: {root}/configs/balls-3.yaml
plan:
  reference_pose: [0, 0, -40, 0, 0, 0]
  cycles: 1
  targets: {targets}
origin_on_cmm: [450, 320, 210, 0.2, -0.1, 15]
start: 2024-03-05T08:00:00
seed: 11
timing: {{seconds_per_point: 5.0, seconds_per_move: 60}}
heating:
  air_C: [[0, 20.0], [10000, 30.0]]
  mats:
    - {{gain_C: 30.0, tau_s: 100000, power: [[0, null]]}}
    - {{gain_C: 50.0, tau_s: 100000, power: [[0, null]]}}
    - {{gain_C: 10.0, tau_s: 100000, power: [[0, null]]}}
    - {{gain_C: 20.0, tau_s: 100000, power: [[0, null]]}}
    - {{gain_C: 70.0, tau_s: 100000, power: [[0, null]]}}
    - {{gain_C: 25.0, tau_s: 100000, power: [[0, null]]}}
thermocouples: {{period_s: 30, noise_C: {tc_noise}}}
cmm: {{point_noise_um: {noise}, points_per_ball: 12, cap_angle_deg: 70}}
hexapod_repeatability_um: {repeatability}
output: {output}
hidden_effects: {effects}
"""


def scenario_text(
    *, noise=0.0, tc_noise=0.0, repeatability=0.0, output="centres", effects="[]", targets=None
):
    return SCENARIO.format(
        root=ROOT,
        targets=targets or TARGETS,
        noise=noise,
        tc_noise=tc_noise,
        repeatability=repeatability,
        output=output,
        effects=effects,
    )


def write_scenario(tmp_path, text):
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return path


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def simulate(tmp_path, text, out="s", *extra):
    result = run("simulate", write_scenario(tmp_path, text), "-o", tmp_path / out, *extra)
    assert result.exit_code == 0, result.output
    return tmp_path / out


def process(session):
    result = run("process", session)
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(session / "results" / "poses.csv")
    truth = pd.read_csv(session / "truth" / "steps.csv").set_index("label").loc[poses["label"]]
    return poses, truth


def columns(tag):
    return (
        [f"{a}_{tag}_mm" for a in ("Tx", "Ty", "Tz")],
        [f"{a}_{tag}_deg" for a in ("Rx", "Ry", "Rz")],
    )


def worst(poses, truth, got, want):
    (t_got, r_got), (t_want, r_want) = columns(got), columns(want)
    d_t = np.abs(poses[t_got].to_numpy() - truth[t_want].to_numpy()).max() * UM
    d_r = np.abs(poses[r_got].to_numpy() - truth[r_want].to_numpy()).max() * URAD
    return d_t, d_r


def files_of(folder: Path) -> dict[str, bytes]:
    """The session's files (not hexatherm's manifest and provenance, which record when
    and how they were written)."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name not in (MANIFEST_NAME, PROVENANCE_NAME)
    }


# --------------------------------------------------------------- twin = method
@pytest.mark.parametrize("output", ["centres", "points"])
def test_noise_free_session_processes_to_the_truth(tmp_path, output):
    """Heating linear in time (an air ramp of 3.6 K/h) plus slow mats (tau 28 h, curvature
    below 1e-8 K/s^2): interpolating the references in time is exact to a nanometre."""
    session = simulate(tmp_path, scenario_text(output=output))
    poses, truth = process(session)
    d_t, d_r = worst(poses, truth, "corr", "truecorr")
    assert d_t < 0.05 and d_r < 0.1, (d_t, d_r)
    d_t, d_r = worst(poses, truth, "conv", "true")
    assert d_t < 0.05 and d_r < 0.1, (d_t, d_r)
    # and the thermal error the correction took off is real: micrometres
    d_t, _ = worst(poses, truth, "conv", "truecorr")
    assert d_t > 5.0
    assert (session / ("centres.csv" if output == "centres" else "points.csv")).exists()


def test_serial_capture_replays_into_a_session_that_processes_to_the_truth(tmp_path):
    capture = simulate(tmp_path, scenario_text(output="serial"), "cap")
    assert (capture / "serial.log").exists() and not (capture / "session.yaml").exists()
    result = run(
        "acquire",
        capture / "plan.yaml",
        "--replay",
        capture / "serial.log",
        "--session",
        tmp_path / "sess",
        "--temperatures",
        capture / "temperatures.csv",
    )
    assert result.exit_code == 0, result.output
    session = tmp_path / "sess"
    (session / "truth").mkdir()
    (session / "truth" / "steps.csv").write_bytes((capture / "truth" / "steps.csv").read_bytes())
    poses, truth = process(session)
    # the stream carries 1 nm resolution: the twin and the method still agree
    d_t, d_r = worst(poses, truth, "corr", "truecorr")
    assert d_t < 0.05 and d_r < 0.1, (d_t, d_r)
    d_t, d_r = worst(poses, truth, "conv", "true")
    assert d_t < 0.05 and d_r < 0.1, (d_t, d_r)


def test_session_is_complete_and_truth_is_kept_apart(tmp_path):
    session = simulate(tmp_path, scenario_text(noise=0.5, tc_noise=0.02))
    read = read_session(session)
    assert read.plan.labels[:4] == ("O", "R0", "S1", "R1") and len(read.plan.labels) == 10
    assert read.plan.points_per_ball == 12
    assert [p.name for p in read.measurements] == ["centres.csv"]
    temps = pd.read_csv(session / "temperatures.csv")
    assert list(temps.columns) == ["time", *(f"leg{i}" for i in range(1, 7)), "air"]
    assert temps["time"].iloc[0] == "2024-03-05T08:00:00.000000"
    truth = sorted(p.name for p in (session / "truth").iterdir())
    assert truth == ["effects.yaml", "legs.csv", "scenario.yaml", "steps.csv", "temperatures.csv"]
    assert "truth" not in (session / "session.yaml").read_text()
    assert (session / "hexapod.yaml").read_text() == (
        ROOT / "configs" / "symetrie-like.yaml"
    ).read_text()


def test_a_hidden_effect_is_in_the_truth_only(tmp_path):
    """The truth has 2 % more thermal growth on leg 5; the session's files do not say so."""
    effects = (
        "[{name: leg_cte_error, parameters: "
        "{leg1: 0, leg2: 0, leg3: 0, leg4: 0, leg5: 0.02, leg6: 0}}]"
    )
    plain = simulate(tmp_path, scenario_text(), "plain")
    hidden = simulate(tmp_path, scenario_text(effects=effects), "hidden")
    assert (hidden / "hexapod.yaml").read_bytes() == (plain / "hexapod.yaml").read_bytes()
    recorded = yaml.safe_load((hidden / "truth" / "effects.yaml").read_text())
    assert recorded["effects"] == [
        {
            "name": "leg_cte_error",
            "parameters": {
                "leg1": 0.0,
                "leg2": 0.0,
                "leg3": 0.0,
                "leg4": 0.0,
                "leg5": 0.02,
                "leg6": 0.0,
            },
        }
    ]
    growth = {f.name: pd.read_csv(f / "truth" / "steps.csv")["dq_leg5_um"] for f in (plain, hidden)}
    np.testing.assert_allclose(growth["hidden"], 1.02 * growth["plain"], rtol=1e-12)
    # the conventional pose still measures the truth; and a CTE error cancels out of the
    # correction, which scales the references' growth (2 % too large as well) by s(q_S)/s(q_R)
    poses, truth = process(hidden)
    assert max(worst(poses, truth, "conv", "true")) < 0.05
    # ... but not out of O's carry to R0's state (issue 35), which takes the leg model's
    # growth from the log: 2 % of leg 5's growth between O and R0 (0.03 um, 0.14 urad)
    d_t, d_r = worst(poses, truth, "corr", "truecorr")
    assert d_t < 0.05 and d_r < 0.3, (d_t, d_r)


def test_a_hidden_overheat_biases_the_correction(tmp_path):
    """A screw that runs twice as hot breaks the leg model's scaling: corrected poses err."""
    session = simulate(
        tmp_path, scenario_text(effects="[{name: steel_overheat, parameters: {ratio: 1.0}}]")
    )
    poses, truth = process(session)
    assert max(worst(poses, truth, "conv", "true")) < 0.05
    d_t, d_r = worst(poses, truth, "corr", "truecorr")
    assert d_t > 0.3 and d_r > 1.0, (d_t, d_r)


def test_plan_file_and_the_hexapod_files_thermal_model(tmp_path):
    """A plan file is used as is; the hexapod file's effects are part of the truth."""
    plan = Plan.from_steps(
        sequence_steps(TARGETS[:2], [0, 0, -40, 0, 0, 0], reference_every="alternate"),
        points_per_ball=9,
    )
    (tmp_path / "plan.yaml").write_text(plan_to_yaml(plan))
    hexapod = (ROOT / "configs" / "symetrie-like.yaml").read_text() + (
        "thermal_model:\n  effects:\n  - {name: leg_offset, parameters: "
        "{leg1: 0.001, leg2: 0, leg3: 0, leg4: 0, leg5: 0, leg6: -0.002}}\n"
    )
    (tmp_path / "hexapod.yaml").write_text(hexapod)
    text = (
        scenario_text()
        .replace(f"hexapod: {ROOT}/configs/symetrie-like.yaml", "hexapod: hexapod.yaml")
        .replace("points_per_ball: 12, ", "")
    )
    text = text[: text.index("plan:")] + "plan: plan.yaml\n" + text[text.index("origin_on") :]
    session = simulate(tmp_path, text)
    assert (session / "plan.yaml").read_text() == plan_to_yaml(plan)
    assert (session / "hexapod.yaml").read_text() == hexapod
    assert len(pd.read_csv(session / "centres.csv")) == 5 * 3  # O R0 S1 S2 R1, 3 balls
    legs = pd.read_csv(session / "truth" / "legs.csv")
    steps = pd.read_csv(session / "truth" / "steps.csv")
    extra = legs["q_leg6_mm"] - legs["q_cmd_leg6_mm"] - steps["dq_leg6_um"] * 1e-3
    np.testing.assert_allclose(extra, -0.002, atol=1e-12)
    effects = yaml.safe_load((session / "truth" / "effects.yaml").read_text())["effects"]
    assert [e["name"] for e in effects] == ["leg_offset"]
    # the same effect hidden as well would be ambiguous
    write_scenario(
        tmp_path,
        text.replace(
            "hidden_effects: []",
            "hidden_effects: [{name: leg_offset, parameters: "
            "{leg1: 0, leg2: 0, leg3: 0, leg4: 0, leg5: 0, leg6: 0}}]",
        ),
    )
    result = run("simulate", tmp_path / "scenario.yaml", "-o", tmp_path / "again")
    assert result.exit_code == 1 and "hidden_effects[0].name" in result.output
    assert "thermal model already has leg_offset" in result.output


# --------------------------------------------------------------- reproducible
def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path):
    text = scenario_text(noise=1.0, tc_noise=0.05, repeatability=0.2, output="dmis")
    a = files_of(simulate(tmp_path, text, "a"))
    b = files_of(simulate(tmp_path, text, "b"))
    assert a == b
    c = files_of(simulate(tmp_path, text, "c", "--seed", "12"))
    assert set(c) == set(a)
    for name in ("points.dmo", "temperatures.csv", "truth/steps.csv"):
        assert c[name] != a[name], name
    assert c["plan.yaml"] == a["plan.yaml"]


def test_the_twin_still_makes_the_recorded_calibration_geometry(tmp_path):
    # sessions/calibration-geometry was recorded from its scenario by the twin as it is:
    # regenerated, its measurements, log and truth come out the same (today to the byte
    # on this machine; compared to 1e-9 of their unit, so that another numpy's last bits
    # do not fail it, while a change of the twin's draws, 0.1-1 um, does). Then the
    # recorded sessions stop being what their scenarios make: say so in docs/simulate.md
    # (four older sessions already are not, since 081bd0e)
    recorded = SHIPPED / "calibration-geometry"
    scenario = ROOT / "configs" / "scenarios" / "calibration-geometry.yaml"
    result = run("simulate", scenario, "-o", tmp_path / "again")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "again" / "plan.yaml").read_bytes() == (recorded / "plan.yaml").read_bytes()
    for name in ("centres.csv", "temperatures.csv", "truth/steps.csv"):
        again, before = pd.read_csv(tmp_path / "again" / name), pd.read_csv(recorded / name)
        pd.testing.assert_frame_equal(again, before, check_exact=False, rtol=0, atol=1e-9)


def test_existing_output_is_kept_without_overwrite(tmp_path):
    out = tmp_path / "s"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    result = run("simulate", write_scenario(tmp_path, scenario_text()), "-o", out)
    assert result.exit_code != 0 and "--overwrite" in result.output
    assert (out / "keep.txt").read_text() == "mine"
    # --overwrite replaces only what hexatherm wrote: keep.txt is named and kept
    foreign = run("simulate", write_scenario(tmp_path, scenario_text()), "-o", out, "--overwrite")
    assert foreign.exit_code == 1 and "keep.txt (not written by hexatherm" in foreign.output
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    (out / "keep.txt").unlink()
    simulate(tmp_path, scenario_text(), "s", "--overwrite")  # an empty folder is no one's
    first = (out / "centres.csv").read_bytes()
    simulate(tmp_path, scenario_text(), "s", "--overwrite")
    assert (out / "centres.csv").read_bytes() == first


def test_simulate_never_writes_into_or_around_its_inputs(tmp_path):
    scenario = write_scenario(tmp_path, scenario_text())
    around = run("simulate", scenario, "-o", tmp_path, "--overwrite")
    assert around.exit_code == 1 and "contains the input" in around.output
    assert scenario.exists()


# ---------------------------------------------------------------- bad input
BAD = [
    (
        "hidden_effects: []",
        "hidden_effects: [{name: leg_lag, parameters: {tau_s: 5}}]",
        "hidden_effects: [",
        "hidden_effects[0].name",
        "expected one of",
    ),
    (
        "hidden_effects: []",
        "hidden_effects:\n  - {name: leg_thermal_lag, parameters: {tau_s: -5}}",
        "{name: leg_thermal_lag",
        "hidden_effects[0].parameters.tau_s",
        "outside the sensible range",
    ),
    (
        "hidden_effects: []",
        "hidden_effects:\n  - name: leg_offset\n    parameters: "
        "{leg1: 0, leg2: 0, leg3: 0, leg4: 0, leg5: 0}",
        "    parameters:",
        "hidden_effects[0].parameters.leg6",
        "missing",
    ),
    (
        "point_noise_um: 0.0",
        "point_noise_um: abc",
        "cmm: {",
        "cmm.point_noise_um",
        "expected a number",
    ),
    ("point_noise_um: 0.0", "point_noise_um: 1, mpe_um: 2", "cmm: {", "cmm.mpe_um", "not both"),
    (
        "{gain_C: 50.0, tau_s: 100000, power: [[0, null]]}",
        "{gain_C: 50.0, tau_s: 100000, power: [[500, 100]]}",
        "power: [[500, 100]]",
        "heating.mats[1].power[0][1]",
        "must come after",
    ),
    (
        "    - {gain_C: 25.0, tau_s: 100000, power: [[0, null]]}\n",
        "",
        "{gain_C: 30.0",
        "heating.mats",
        "six mats",
    ),
    ("configs/symetrie-like.yaml", "configs/missing.yaml", "hexapod:", "hexapod", "file not found"),
    (
        "[-15.0, -12.0, 8.0, 3.0, -1.0, 7.0]",
        "[-15.0, -12.0, 80.0, 3.0, -1.0, 7.0]",
        "  targets:",
        "plan.targets[3]",
        "outside the hexapod's stroke",
    ),
    ("output: centres", "output: serial-ish", "output:", "output", "expected one of"),
    (
        "seconds_per_point: 5.0",
        "seconds_per_pont: 5.0",
        "timing:",
        "timing.seconds_per_pont",
        "unknown key",
    ),
    (
        "format: hexatherm-scenario/1",
        "format: hexatherm-plan/1",
        "format:",
        "format",
        "expected format",
    ),
]


@pytest.mark.parametrize(
    ("old", "new", "line_marker", "field", "message"), BAD, ids=[b[3] for b in BAD]
)
def test_bad_scenario_names_file_line_and_field_and_writes_nothing(
    tmp_path, old, new, line_marker, field, message
):
    text = scenario_text()
    assert old in text
    text = text.replace(old, new, 1)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if line_marker in t)
    path = write_scenario(tmp_path, text)
    result = run("simulate", path, "-o", tmp_path / "out")
    assert result.exit_code == 1
    assert f"{path}:{line}: field '{field}': " in result.output, result.output
    assert message in result.output
    assert not (tmp_path / "out").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["scenario.yaml"]  # no temporary folder


# ------------------------------------------------------------ simulate --plan
HEXAPOD, BALLS_FILE = ROOT / "configs" / "symetrie-like.yaml", ROOT / "configs" / "balls-3.yaml"


def planned(tmp_path: Path) -> Path:
    plan = tmp_path / "plan.yaml"
    made = run(
        "plan", "--hexapod", HEXAPOD, "--balls", BALLS_FILE, "--random", "4", "--seed", "3",
        "--box", "Tx=-10:10", "--box", "Rz=-2:2", "-o", plan,
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    return plan


def test_a_plan_simulates_as_a_typical_session_and_its_scenario_reproduces_it(tmp_path):
    """plan -> simulate --plan -> process, a lab's first steps without writing a scenario:
    the corrected poses are the truth's within the CMM noise, the conventional ones carry
    the mats' heating; the scenario kept in truth/ gives the same session, byte for byte."""
    plan = planned(tmp_path)
    inputs = {p: p.read_bytes() for p in (plan, HEXAPOD, BALLS_FILE)}
    first = tmp_path / "first"
    result = run(
        "simulate", "--plan", plan, "--hexapod", HEXAPOD, "--balls", BALLS_FILE, "-o", first
    )
    assert result.exit_code == 0, result.output
    assert all(p.read_bytes() == text for p, text in inputs.items())
    poses, truth = process(first)
    d_t, d_r = worst(poses, truth, "corr", "truecorr")
    assert d_t < 3.0 and d_r < 15.0, (d_t, d_r)  # 0.5 um point noise
    d_t, _ = worst(poses, truth, "conv", "truecorr")
    assert d_t > 3.0  # 3 K of mats: micrometres of thermal error
    scenario = yaml.safe_load((first / "truth" / "scenario.yaml").read_text())
    assert scenario["cmm"] == {"point_noise_um": 0.5} and scenario["plan"] == "../plan.yaml"
    again = tmp_path / "again"
    result = run("simulate", first / "truth" / "scenario.yaml", "-o", again)
    assert result.exit_code == 0, result.output
    session_files = {k: v for k, v in files_of(first).items() if not k.startswith("results")}
    assert files_of(again) == session_files


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["SCENARIO", "--plan", "PLAN"], "give a SCENARIO file or --plan PLAN, one of them"),
        ([], "give a SCENARIO file or --plan PLAN, one of them"),
        (["--plan", "PLAN", "--hexapod", "HEXAPOD"], "--plan needs --hexapod and --balls"),
        (["SCENARIO", "--balls", "BALLS"], "--hexapod and --balls go with --plan"),
    ],
)
def test_simulate_plan_options_are_usage_errors_when_mixed(tmp_path, args, message):
    plan = planned(tmp_path)
    names = {
        "SCENARIO": write_scenario(tmp_path, scenario_text()),
        "PLAN": plan,
        "HEXAPOD": HEXAPOD,
        "BALLS": BALLS_FILE,
    }
    result = run("simulate", *[names.get(a, a) for a in args], "-o", tmp_path / "out")
    assert result.exit_code == 2 and message in result.output, result.output
    assert not (tmp_path / "out").exists()


def test_simulate_plan_names_a_bad_plan_file(tmp_path):
    plan = planned(tmp_path)
    plan.write_text(plan.read_text().replace("kind: target", "kind: targte", 1))
    result = run(
        "simulate",
        "--plan",
        plan,
        "--hexapod",
        HEXAPOD,
        "--balls",
        BALLS_FILE,
        "-o",
        tmp_path / "o",
    )
    assert result.exit_code == 1, result.output
    assert f"{plan}:" in result.output and "targte" in result.output
    assert not (tmp_path / "o").exists()
