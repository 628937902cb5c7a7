"""Hostile inputs to ``plan``, ``simulate``, ``register``, ``inspect`` and ``acquire``.

Each test pins a bug the audit found: it failed before the fix (checked) and asserts the
refusal (one line naming the file or option, exit 1 or 2, nothing written, inputs
untouched) or the numbers against an independent truth.
"""

from __future__ import annotations

import csv
import hashlib
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.spherefit import fit_spheres
from hexatherm.io.config import read_balls
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
DATUMS = SHIPPED / "register-datums"
HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


def digests(paths: list[Path]) -> dict[Path, str]:
    return {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in paths}


def one_line_error(result_output: str) -> str:
    lines = [line for line in result_output.splitlines() if line.startswith("Error")]
    assert len(lines) == 1, result_output
    assert "Traceback" not in result_output and "Warning" not in result_output
    return lines[0]


# ------------------------------------------------------------------------ register
def datum_rows() -> tuple[list[str], list[list[str]]]:
    with (DATUMS / "points.csv").open(newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def write_rows(path: Path, header: list[str], rows: list[list[str]]) -> None:
    path.write_text("".join(",".join(r) + "\n" for r in [header, *rows]))


def register(measurement: Path, out: Path) -> tuple[int, str]:
    result = CliRunner().invoke(
        main,
        ["register", str(measurement), "--datums", str(DATUMS / "datums.yaml"), "-o", str(out)],
    )
    return result.exit_code, result.output


def top_subset(tmp_path: Path, pick: list[int]) -> Path:
    """The sample measurement with only the top-face points ``pick`` (indices among them)."""
    header, rows = datum_rows()
    top = [r for r in rows if r[1] == "TOP"]
    path = tmp_path / "points.csv"
    write_rows(path, header, [r for r in rows if r[1] != "TOP"] + [top[k] for k in pick])
    return path


def test_register_refuses_a_top_face_probed_along_a_line(tmp_path: Path) -> None:
    # the sample's first three top-face points are one scan line (1.3 um off a straight
    # line over 120 mm): the face's tilt about that line is noise; it used to give a
    # balls file with centres 200 mm from the truth, and exit 0
    measurement = top_subset(tmp_path, [0, 1, 2])
    before = digests([measurement, DATUMS / "datums.yaml"])
    out = tmp_path / "balls.yaml"
    code, output = register(measurement, out)
    assert code == 1, output
    line = one_line_error(output)
    assert str(measurement) in line and "line" in line
    assert not out.exists()
    assert digests([measurement, DATUMS / "datums.yaml"]) == before


def test_register_takes_three_top_points_spread_over_the_face(tmp_path: Path) -> None:
    # the control: three points well apart over the face (not in a row) determine the
    # plane, and the balls come within a few um of the truth
    header, rows = datum_rows()
    top = np.array([[float(v) for v in r[2:5]] for r in rows if r[1] == "TOP"])
    centred = top - top.mean(axis=0)
    _, _, vt = np.linalg.svd(centred)
    u, v = centred @ vt[0], centred @ vt[1]
    pick = [int(np.argmin(u)), int(np.argmax(u)), int(np.argmax(np.abs(v)))]
    out = tmp_path / "balls.yaml"
    code, output = register(top_subset(tmp_path, pick), out)
    assert code == 0, output
    got, truth = read_balls(out), read_balls(DATUMS / "truth" / "balls.yaml")
    error_um = np.linalg.norm(got.centres_mm - truth.centres_mm, axis=1) * 1e3
    assert np.all(error_um < 20.0), error_um


# ------------------------------------------------------------------------ plan
def test_plan_names_the_option_whose_output_is_an_input(tmp_path: Path) -> None:
    targets = tmp_path / "targets.csv"
    targets.write_text("Tx,Ty,Tz,Rx,Ry,Rz\n1,0,0,0,0,0\n")
    before = digests([targets, HEXAPOD, BALLS])
    base = ["plan", "--hexapod", str(HEXAPOD), "--balls", str(BALLS), "--targets", str(targets)]
    for option, extra in (
        ("--dmis", ["--origin-on-cmm", "450,320,210,0,0,15"]),
        ("--checklist", []),
    ):
        out = tmp_path / f"plan{option}.yaml"
        result = CliRunner().invoke(main, [*base, "-o", str(out), option, str(targets), *extra])
        assert result.exit_code == 1, result.output
        line = one_line_error(result.output)
        assert f"{option} {targets}" in line and "choose another " + option in line, line
        assert not out.exists()
    assert digests([targets, HEXAPOD, BALLS]) == before


# ------------------------------------------------------------------------ origin_on_cmm
def scenario_text(origin: str) -> str:
    return (
        "format: hexatherm-scenario/1\n"
        f"hexapod: {HEXAPOD}\n"
        f"balls: {BALLS}\n"
        "plan: {targets: [[1, 0, 0, 0, 0, 0]], cycles: 1}\n"
        f"origin_on_cmm: {origin}\n"
        "cmm: {point_noise_um: 0.5}\n"
    )


def test_simulate_refuses_frame_o_placed_beyond_any_cmm(tmp_path: Path) -> None:
    # 1e308 mm used to end in a numpy LinAlgError traceback; 450 m (a value in um) was
    # simulated, and process then refused the centres it had written
    for origin in ("[1.0e+308, 0, 0, 0, 0, 15]", "[450000, 320, 210, 0, 0, 15]"):
        scenario = tmp_path / "scenario.yaml"
        scenario.write_text(scenario_text(origin))
        before = digests([scenario, HEXAPOD, BALLS])
        out = tmp_path / "session"
        result = CliRunner().invoke(main, ["simulate", str(scenario), "-o", str(out)])
        assert result.exit_code == 1, result.output
        line = one_line_error(result.output)
        assert f"{scenario}:5: field 'origin_on_cmm'" in line, line
        assert not out.exists()
        assert digests([scenario, HEXAPOD, BALLS]) == before


def test_simulate_takes_frame_o_far_out_but_on_a_cmm(tmp_path: Path) -> None:
    # the control: frame O 90 m out (a laser tracker's range) simulates, and the twin's
    # centres lie there
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(scenario_text("[90000, 320, 210, 0, 0, 15]"))
    out = tmp_path / "session"
    result = CliRunner().invoke(main, ["simulate", str(scenario), "-o", str(out)])
    assert result.exit_code == 0, result.output
    with (out / "centres.csv").open(newline="") as f:
        x_mm = [float(row["x"]) for row in csv.DictReader(f)]
    assert all(abs(x - 90000) < 200 for x in x_mm), x_mm


def test_plan_refuses_frame_o_placed_beyond_any_cmm(tmp_path: Path) -> None:
    # used to write a DMIS program driving the probe to x = 1e308 mm (308 digits)
    targets = tmp_path / "targets.csv"
    targets.write_text("1,0,0,0,0,0\n")
    out, dmis = tmp_path / "plan.yaml", tmp_path / "prog.dmi"
    result = CliRunner().invoke(
        main,
        [
            "plan",
            "--hexapod",
            str(HEXAPOD),
            "--balls",
            str(BALLS),
            "--targets",
            str(targets),
            "--origin-on-cmm",
            "1e308,0,0,0,0,15",
            "--dmis",
            str(dmis),
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 2, result.output
    assert "--origin-on-cmm" in one_line_error(result.output)
    assert not out.exists() and not dmis.exists()


# ------------------------------------------------------------------------ campaign size
def test_plan_refuses_more_target_steps_than_a_campaign_holds(tmp_path: Path) -> None:
    # 200 targets x 1000 cycles (200,000 target steps; the limit of --random and --grid
    # is 100,000 targets) used to be built; 20,000 x 1000 exhausted the memory
    targets = tmp_path / "targets.csv"
    targets.write_text("".join(f"{k / 100:.2f},0,0,0,0,0\n" for k in range(200)))
    out = tmp_path / "plan.yaml"
    base = ["plan", "--hexapod", str(HEXAPOD), "--balls", str(BALLS), "-o", str(out)]
    for source in (
        ["--targets", str(targets)],
        ["--random", "200", "--seed", "1", "--box", "Tx=-1:1"],
    ):
        result = CliRunner().invoke(main, [*base, *source, "--cycles", "1000"])
        assert result.exit_code in (1, 2), result.output
        line = one_line_error(result.output)
        assert "200 targets x 1,000 cycles" in line, line
        assert not out.exists()
    # the control: fewer cycles make a plan, every target measured in every cycle
    result = CliRunner().invoke(main, [*base, "--targets", str(targets), "--cycles", "5"])
    assert result.exit_code == 0, result.output
    assert out.read_text().count("kind: target") == 200 * 5


def test_simulate_refuses_an_inline_plan_beyond_a_campaign(tmp_path: Path) -> None:
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(
        scenario_text("[450, 320, 210, 0, 0, 15]").replace("cycles: 1", "cycles: 200000")
    )
    out = tmp_path / "session"
    result = CliRunner().invoke(main, ["simulate", str(scenario), "-o", str(out)])
    assert result.exit_code == 1, result.output
    line = one_line_error(result.output)
    assert f"{scenario}:4: field 'plan" in line and "1 targets x 200,000 cycles" in line, line
    assert not out.exists()


def test_plan_refuses_a_dmis_program_beyond_a_campaign(tmp_path: Path) -> None:
    # 300 targets at 10,000 points per ball (602 steps, 18 million touch points, 500
    # days of probing) filled the memory writing the program. The touch points are capped
    # now, at 5 million (issue 37: a scanning campaign of 2000 targets x 400 points);
    # 100 targets at 10,000 points a ball are 6 million
    targets = tmp_path / "targets.csv"
    targets.write_text("".join(f"{k / 100:.2f},0,0,0,0,0\n" for k in range(100)))
    out, dmis = tmp_path / "plan.yaml", tmp_path / "prog.dmi"
    args = ["plan", "--hexapod", str(HEXAPOD), "--balls", str(BALLS), "--targets", str(targets)]
    args += ["--origin-on-cmm", "450,320,210,0,0,15", "--dmis", str(dmis), "-o", str(out)]
    result = CliRunner().invoke(main, [*args, "--points-per-ball", "10000"])
    assert result.exit_code == 1, result.output
    line = one_line_error(result.output)
    assert "202 steps x 3 balls x 10,000 points" in line, line
    assert not out.exists() and not dmis.exists()
    # the control: the same plan with 25 points per ball has its program, a MEAS block
    # of 25 touch points per step and ball
    result = CliRunner().invoke(main, [*args, "--points-per-ball", "25"])
    assert result.exit_code == 0, result.output
    assert dmis.read_text().count("PTMEAS/") == (2 + 2 * 100) * 3 * 25


def test_simulate_refuses_more_touch_points_than_a_campaign_holds(tmp_path: Path) -> None:
    # cmm.points_per_ball 100,000,000 (4 steps x 3 balls) used to end in a numpy
    # _ArrayMemoryError traceback: the same cap as plan --dmis's, named at the field
    scenario = tmp_path / "scenario.yaml"
    text = scenario_text("[450, 320, 210, 0, 0, 15]")
    scenario.write_text(text.replace("point_noise_um: 0.5", "points_per_ball: 500000"))
    out = tmp_path / "session"
    result = CliRunner().invoke(main, ["simulate", str(scenario), "-o", str(out)])
    assert result.exit_code == 1, result.output
    line = one_line_error(result.output)
    assert f"{scenario}:6: field 'cmm.points_per_ball'" in line, line
    assert "4 steps x 3 balls x 500,000 points" in line, line
    assert not out.exists()


def test_register_refuses_two_balls_in_one_place(tmp_path: Path) -> None:
    # B2's points are B1's (the same ball probed twice, or a label typed twice): register
    # used to write a balls file with two coinciding balls, which the balls reader then
    # refused in plan and process ("the balls are collinear")
    header, rows = datum_rows()
    b1 = [r for r in rows if r[1] == "B1"]
    measurement = tmp_path / "points.csv"
    write_rows(
        measurement, header, [r for r in rows if r[1] != "B2"] + [[r[0], "B2", *r[2:]] for r in b1]
    )
    out = tmp_path / "balls.yaml"
    code, output = register(measurement, out)
    assert code == 1, output
    line = one_line_error(output)
    first_b2 = len(rows) - len(b1) + 2  # the header, then the rows but B2's, then B2's
    assert f"{measurement}:{first_b2}: field 'ball'" in line and "B2" in line, line
    assert not out.exists()


def test_register_refuses_balls_in_a_row(tmp_path: Path) -> None:
    # B3 probed where B1 and B2 put it in a row (B1's points moved by twice the vector
    # from B1's fitted centre to B2's):
    # the balls file written used to be refused by the balls reader afterwards
    header, rows = datum_rows()
    xyz = {
        b: np.array([[float(v) for v in r[2:5]] for r in rows if r[1] == b]) for b in ("B1", "B2")
    }
    fits = [fit_spheres(xyz[b], np.zeros(len(xyz[b]), dtype=int)) for b in ("B1", "B2")]
    shift = 2 * (fits[1].centre_mm[0] - fits[0].centre_mm[0])
    b1 = [r for r in rows if r[1] == "B1"]
    moved = [
        [r[0], "B3", *(f"{v:.6f}" for v in np.array([float(c) for c in r[2:5]]) + shift), r[5]]
        for r in b1
    ]
    measurement = tmp_path / "points.csv"
    write_rows(measurement, header, [r for r in rows if r[1] != "B3"] + moved)
    out = tmp_path / "balls.yaml"
    code, output = register(measurement, out)
    assert code == 1, output
    assert "collinear" in one_line_error(output)
    assert not out.exists()
