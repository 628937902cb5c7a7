"""``hexatherm plan`` end to end: plan file, DMIS program read back, checklist, refusals."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.registration import register
from hexatherm.core.spherefit import fit_spheres
from hexatherm.io.config import read_balls, read_plan
from hexatherm.io.dmis import read_dmis

ROOT = Path(__file__).resolve().parents[2]
HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"
TARGETS = "Tx,Ty,Tz,Rx,Ry,Rz\n5,-3,2,0.5,-0.4,3\n-8,6,-4,-0.6,0.3,-5\n0,0,10,0,0,0\n"


def run(*args):
    return CliRunner().invoke(main, ["plan", *[str(a) for a in args]])


def base_args(tmp_path, targets=TARGETS):
    (tmp_path / "t.csv").write_text(targets)
    return ["--hexapod", HEXAPOD, "--balls", BALLS, "--targets", tmp_path / "t.csv"]


def test_plan_from_targets_csv(tmp_path):
    result = run(
        *base_args(tmp_path),
        "--points-per-ball",
        12,
        "--cycles",
        2,
        "-o",
        tmp_path / "plan.yaml",
        "--checklist",
        tmp_path / "check.md",
    )
    assert result.exit_code == 0, result.output
    plan = read_plan(tmp_path / "plan.yaml")
    targets = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    assert plan.labels[:3] == ("O", "R0", "S1") and len(plan.labels) == 2 + 2 * 6
    np.testing.assert_array_equal(plan.poses[plan.target_indices], np.tile(targets, (2, 1)))
    np.testing.assert_array_equal(plan.reference_pose, [0, 0, -40, 0, 0, 0])
    assert all(before >= 0 and after >= 0 for before, after in plan.adjacent_references())
    assert plan.points_per_ball == 12
    assert result.stdout == ""  # the plan went to the file
    check = (tmp_path / "check.md").read_text()
    rows = [line for line in check.splitlines() if re.match(r"\| \d+ \|", line)]
    assert len(rows) == len(plan.labels)
    assert rows[2].startswith("| 3 | S1 | target | 5, -3, 2, 0.5, -0.4, 3 | B1, B2, B3 | 36 |")
    assert "right before and/or right after" in check


def test_plan_to_stdout_and_reference_options(tmp_path):
    result = run(
        *base_args(tmp_path), "--reference", "0,0,-30,0,0,0", "--reference-every", "before"
    )
    assert result.exit_code == 0, result.output
    (tmp_path / "p.yaml").write_text(result.stdout)
    plan = read_plan(tmp_path / "p.yaml")
    assert plan.labels == ("O", "R0", "S1", "R1", "S2", "R2", "S3")
    np.testing.assert_array_equal(plan.reference_pose, [0, 0, -30, 0, 0, 0])
    assert plan.points_per_ball == 25


def test_grid_and_random_targets(tmp_path):
    args = ["--hexapod", HEXAPOD, "--balls", BALLS]
    grid = run(
        *args, "--grid", 3, "--box", "Tx=-5:5", "--box", "rz=-1:1", "-o", tmp_path / "g.yaml"
    )
    assert grid.exit_code == 0, grid.output
    targets = read_plan(tmp_path / "g.yaml")
    poses = targets.poses[targets.target_indices]
    assert len(poses) == 9
    assert {tuple(p) for p in poses[:, [0, 5]]} == {(a, b) for a in (-5, 0, 5) for b in (-1, 0, 1)}
    np.testing.assert_array_equal(poses[:, 1:5], 0)

    box = ["--box", "Tx=-20:20", "--box", "Ty=-20:20", "--box", "Tz=-20:25", "--box", "Rz=-8:8"]
    for name in ("r1", "r2"):
        result = run(*args, "--random", 6, "--seed", 11, *box, "-o", tmp_path / f"{name}.yaml")
        assert result.exit_code == 0, result.output
    a, b = read_plan(tmp_path / "r1.yaml"), read_plan(tmp_path / "r2.yaml")
    np.testing.assert_array_equal(a.poses, b.poses)
    poses = a.poses[a.target_indices]
    assert len(poses) == 6
    assert np.all(np.abs(poses[:, :2]) <= 20) and np.all((poses[:, 2] >= -20) & (poses[:, 2] <= 25))
    assert np.all(np.abs(poses[:, 5]) <= 8) and np.all(poses[:, 3:5] == 0)


def parse_program(text):
    """An independent reading of the DMIS program: nominals, touch points, outputs."""
    nominal, blocks, outputs, current = {}, {}, [], None
    for line in text.split("\r\n"):
        if m := re.fullmatch(r"F\((\w+-?\w*)\)=FEAT/SPHERE,OUTER,CART,(.+)", line):
            nominal[m.group(1)] = [float(v) for v in m.group(2).split(",")]
        elif m := re.fullmatch(r"MEAS/SPHERE,F\(([^)]+)\),(\d+)", line):
            assert current is None
            current = m.group(1)
            blocks[current] = {"n": int(m.group(2)), "points": []}
        elif line.startswith("PTMEAS/CART,"):
            assert current is not None
            blocks[current]["points"].append([float(v) for v in line[12:].split(",")])
        elif line == "ENDMES":
            current = None
        elif m := re.fullmatch(r"OUTPUT/FA\(([^)]+)\)", line):
            outputs.append(m.group(1))
    assert current is None
    return nominal, blocks, outputs


def poses_from_centres(labels, ball_names, centres, balls):
    """Register each step's centres and express every step relative to the origin step."""
    stacked = np.array([[centres[(label, ball)] for ball in ball_names] for label in labels])
    fit = register(stacked, balls.centres_mm)
    assert fit.rms_um.max() < 0.1
    return pose_from_transform(invert_transform(fit.platform2cmm[0]) @ fit.platform2cmm)


@pytest.mark.parametrize("actuals", ["spheres", "points"])
def test_dmis_program_read_back_gives_the_planned_poses(tmp_path, actuals):
    origin = "612.5,410,-95,0.4,-0.3,35"
    result = run(
        *base_args(tmp_path),
        "--points-per-ball",
        8,
        "-o",
        tmp_path / "plan.yaml",
        "--dmis",
        tmp_path / "prog.dmi",
        "--origin-on-cmm",
        origin,
        "--cap-angle",
        80,
    )
    assert result.exit_code == 0, result.output
    plan = read_plan(tmp_path / "plan.yaml")
    balls = read_balls(BALLS)
    raw = (tmp_path / "prog.dmi").read_bytes()
    assert raw.count(b"\r\n") == raw.count(b"\n")  # CRLF throughout
    text = raw.decode("ascii")
    assert text.splitlines()[-1] == "ENDFIL"
    nominal, blocks, outputs = parse_program(text)
    expected = [f"{label}_{ball}" for label in plan.labels for ball in balls.names]
    assert outputs == expected and list(blocks) == expected and list(nominal) == expected

    # the CMM answers at the nominal positions: the touch points as they were planned
    lines = ["DMISMN/'CMM answer',05.2", "UNITS/MM,ANGDEC", "DATE=2024/05/01"]
    for k, label in enumerate(plan.labels):
        lines.append(f"TIME=10:{k:02d}:00")
        for ball, diameter in zip(balls.names, balls.diameters_mm, strict=True):
            block = blocks[f"{label}_{ball}"]
            pts = np.array(block["points"])
            assert block["n"] == len(pts) == 8
            centre = np.array(nominal[f"{label}_{ball}"][:3])
            # on the ball, over its upper cap
            np.testing.assert_allclose(
                np.linalg.norm(pts[:, :3] - centre, axis=1), diameter / 2, atol=2e-5
            )
            np.testing.assert_allclose(
                pts[:, 3:], (pts[:, :3] - centre) / (diameter / 2), atol=2e-5
            )
            assert np.all(pts[:, 5] >= np.cos(np.radians(80)) - 1e-6)
            if actuals == "spheres":
                fit = fit_spheres(pts[:, :3])
                c, d = fit.centre_mm[0], 2 * fit.radius_mm[0]
                lines.append(
                    f"FA({label}_{ball})=FEAT/SPHERE,CART,{c[0]:.6f},{c[1]:.6f},{c[2]:.6f},{d:.6f}"
                )
            else:
                for n, p in enumerate(pts, start=1):
                    lines.append(
                        f"FA({label}_{ball}_{n})=FEAT/POINT,CART," + ",".join(f"{v:.6f}" for v in p)
                    )
    lines.append("ENDFIL")
    (tmp_path / "answer.dmo").write_text("\r\n".join(lines) + "\r\n")

    (records,) = read_dmis(tmp_path / "answer.dmo")
    centres = {}
    if actuals == "spheres":
        assert records.kind == "centres"
        for label, ball, xyz in zip(records.label, records.ball, records.xyz_mm, strict=True):
            centres[(str(label), str(ball))] = xyz
    else:
        assert records.kind == "points" and len(records) == len(expected) * 8
        keys = [f"{a}_{b}" for a, b in zip(records.label, records.ball, strict=True)]
        index = {key: i for i, key in enumerate(dict.fromkeys(keys))}
        fits = fit_spheres(records.xyz_mm, np.array([index[k] for k in keys]))
        for key, i in index.items():
            label, ball = key.split("_")
            centres[(label, ball)] = fits.centre_mm[i]
    poses = poses_from_centres(plan.labels, balls.names, centres, balls)
    np.testing.assert_allclose(poses[:, :3], plan.poses[:, :3], atol=1e-4)
    np.testing.assert_allclose(poses[:, 3:], plan.poses[:, 3:], atol=1e-5)

    # inspect lists the answer's actual features; given the program itself (it has none,
    # only nominals and MEAS), it says what the file is instead of a bare "0 features"
    program = CliRunner().invoke(main, ["inspect", str(tmp_path / "prog.dmi")])
    assert program.exit_code == 0, program.output
    assert "0 features" in program.output
    assert "is a DMIS program (nominal features and MEAS statements" in program.output
    answer = CliRunner().invoke(main, ["inspect", str(tmp_path / "answer.dmo")])
    assert answer.exit_code == 0, answer.output
    assert f"{len(records)} features" in answer.output and "DMIS program" not in answer.output


def test_bad_targets_line_names_file_line_field_and_writes_nothing(tmp_path):
    outputs = [tmp_path / "plan.yaml", tmp_path / "prog.dmi", tmp_path / "check.md"]
    result = run(
        *base_args(tmp_path, "Tx,Ty,Tz,Rx,Ry,Rz\n1,2,3,0,0,0\n1,2,3mm,0,0,0\n"),
        "-o",
        outputs[0],
        "--dmis",
        outputs[1],
        "--origin-on-cmm",
        "0,0,0,0,0,0",
        "--checklist",
        outputs[2],
    )
    assert result.exit_code == 1
    assert f"{tmp_path / 't.csv'}:3: field 'Tz': not a finite number: '3mm'" in result.stderr
    assert "Traceback" not in result.output
    assert not any(p.exists() for p in outputs)


def test_pose_outside_stroke_names_step_line_and_pose_and_writes_nothing(tmp_path):
    outputs = [tmp_path / "plan.yaml", tmp_path / "check.md"]
    result = run(
        *base_args(tmp_path, "1,0,0,0,0,0\n0,0,80,0,0,0\n"),
        "-o",
        outputs[0],
        "--checklist",
        outputs[1],
    )
    assert result.exit_code == 1
    assert (
        f"step S2 ({tmp_path / 't.csv'}:2): pose [0, 0, 80, 0, 0, 0]: outside the stroke "
        "[220, 310] mm: leg 1 at"
    ) in result.stderr
    assert not any(p.exists() for p in outputs)
    reference = run(
        *base_args(tmp_path, "1,0,0,0,0,0\n"), "--reference", "0,0,-90,0,0,0", "-o", outputs[0]
    )
    assert reference.exit_code == 1
    assert (
        "step R0 (--reference): pose [0, 0, -90, 0, 0, 0]: outside the stroke" in reference.stderr
    )
    assert not outputs[0].exists()


def test_near_singular_pose_is_refused(tmp_path):
    # without a stroke only the Jacobian stops a twist of 89 deg (reciprocal condition 7e-3)
    no_stroke = tmp_path / "hexapod.yaml"
    no_stroke.write_text(re.sub(r"(?m)^stroke:.*$", "", HEXAPOD.read_text()))
    args = ["--hexapod", no_stroke, *base_args(tmp_path, "1,0,0,0,0,5\n0,0,0,0,0,89\n")[2:]]
    result = run(*args, "-o", tmp_path / "plan.yaml")
    assert result.exit_code == 1
    assert (
        f"step S2 ({tmp_path / 't.csv'}:2): pose [0, 0, 0, 0, 0, 89]: near-singular "
        "Jacobian" in result.stderr
    )
    assert not (tmp_path / "plan.yaml").exists()
    assert run(*args, "--min-rcond", 1e-3, "-o", tmp_path / "plan.yaml").exit_code == 0


def test_refusals(tmp_path):
    args = base_args(tmp_path)
    (tmp_path / "plan.yaml").write_text("keep me")
    exists = run(*args, "-o", tmp_path / "plan.yaml")
    assert exists.exit_code == 1 and "use --overwrite" in exists.stderr
    assert (tmp_path / "plan.yaml").read_text() == "keep me"
    # --overwrite replaces only what hexatherm wrote: this file is the user's
    foreign = run(*args, "-o", tmp_path / "plan.yaml", "--overwrite")
    assert foreign.exit_code == 1 and "plan.yaml (not written by hexatherm" in foreign.stderr
    assert (tmp_path / "plan.yaml").read_text() == "keep me"
    (tmp_path / "plan.yaml").unlink()
    assert run(*args, "-o", tmp_path / "plan.yaml").exit_code == 0
    assert run(*args, "-o", tmp_path / "plan.yaml", "--overwrite").exit_code == 0
    # an input is never an output, --overwrite or not
    onto = run(*args, "-o", tmp_path / "t.csv", "--overwrite")
    assert onto.exit_code == 1 and "is the input" in onto.stderr
    assert (tmp_path / "t.csv").read_text().startswith("Tx")
    no_origin = run(*args, "--dmis", tmp_path / "p.dmi")
    assert no_origin.exit_code == 2 and "--origin-on-cmm" in no_origin.stderr
    two = run(*args, "--grid", 2, "--box", "Tx=-1:1")
    assert two.exit_code == 2 and "exactly one of" in two.stderr
    bad_box = run("--hexapod", HEXAPOD, "--balls", BALLS, "--grid", 2, "--box", "Tq=1:2")
    assert bad_box.exit_code == 2 and "AXIS=MIN:MAX" in bad_box.stderr
    bad_pose = run(*args, "--reference", "0,0,-40,0,0")
    assert bad_pose.exit_code == 2 and "six finite numbers" in bad_pose.stderr


def test_time_gap_warning(tmp_path):
    result = run(
        *base_args(tmp_path),
        "--points-per-ball",
        40,
        "--seconds-per-point",
        6,
        "--seconds-per-move",
        30,
        "--max-gap",
        600,
        "-o",
        tmp_path / "plan.yaml",
        "--checklist",
        tmp_path / "check.md",
    )
    assert result.exit_code == 0, result.output
    # a step takes 30 s + 3 balls x 40 points x 6 s = 12.5 min > 10 min
    assert "warning: S1 and its reference R0 are expected 12.5 min apart" in result.stderr
    check = (tmp_path / "check.md").read_text()
    assert "## Warnings" in check and "S3 and R3 are expected 12 min apart" in check
    quiet = run(
        *base_args(tmp_path),
        "--points-per-ball",
        40,
        "--seconds-per-point",
        6,
        "--max-gap",
        800,
        "-o",
        tmp_path / "plan2.yaml",
    )
    assert "warning:" not in quiet.stderr


def test_dmis_program_labels_hold_no_minus_and_read_back(tmp_path):
    """A DMIS label holds letters, digits and '_': the repeats O-2, R0-2 are written
    O__2, R0__2, and the CMM's answer with those labels reads back as O-2, R0-2 (and
    an older output that wrote O-2_B1 still reads)."""
    result = run(
        *base_args(tmp_path),
        "--origin-repeats",
        2,
        "--points-per-ball",
        4,
        "-o",
        tmp_path / "plan.yaml",
        "--dmis",
        tmp_path / "prog.dmi",
        "--origin-on-cmm",
        "450,320,210,0,0,15",
    )
    assert result.exit_code == 0, result.output
    plan = read_plan(tmp_path / "plan.yaml")
    assert "O-2" in plan.labels
    text = (tmp_path / "prog.dmi").read_text()
    labels = re.findall(r"\bFA?\(([^)]*)\)", text)
    assert labels and all(re.fullmatch(r"[A-Za-z0-9_]+", label) for label in labels)
    assert "O__2_B1" in labels and "R0__2_B3" in labels
    answer = ["DMISMN/'CMM answer',05.2", "UNITS/MM,ANGDEC", "DATE=2024/05/01", "TIME=10:00:00"]
    sphere, point = "SPHERE,CART,1,2,3,25.4", "POINT,CART,1,2,3"
    for label, kind in (("O__2_B1", sphere), ("O-2_B2", sphere), ("O__2_B3_7", point)):
        answer.append(f"FA({label})=FEAT/{kind}")
    answer.append("ENDFIL")
    (tmp_path / "answer.dmo").write_text("\r\n".join(answer) + "\r\n")
    centres, points = read_dmis(tmp_path / "answer.dmo")
    assert list(centres.label) == ["O-2", "O-2"] and list(centres.ball) == ["B1", "B2"]
    assert list(points.label) == ["O-2"] and list(points.ball) == ["B3"]
