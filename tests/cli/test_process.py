"""``hexatherm process`` end to end on twin sessions, and its refusals."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.workflows.process.outputs import CONTRACT_COLUMNS, pose_columns
from tests.sessions import make_session
from tests.shipped import SHIPPED

COMPONENTS = [
    ("Tx", "um"),
    ("Ty", "um"),
    ("Tz", "um"),
    ("Rx", "urad"),
    ("Ry", "urad"),
    ("Rz", "urad"),
]

UM, URAD = 1e3, np.pi / 180 * 1e6


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def pose_errors(poses, truth, tag):
    truth = truth.set_index("label").loc[poses["label"]]
    t = np.column_stack(
        [
            poses[f"{c}_{tag}_mm"].to_numpy() - truth[f"{c}_truecorr_mm"].to_numpy()
            for c in ("Tx", "Ty", "Tz")
        ]
    )
    r = np.column_stack(
        [
            poses[f"{c}_{tag}_deg"].to_numpy() - truth[f"{c}_truecorr_deg"].to_numpy()
            for c in ("Rx", "Ry", "Rz")
        ]
    )
    return np.abs(t).max() * UM, np.abs(r).max() * URAD


def test_process_noise_free_session_recovers_the_truth(tmp_path):
    # slow heating: the growth is linear in time between references, so the
    # interpolated correction is exact
    make_session(tmp_path / "s", n_targets=4, tau_s=1e6, gain=(300.0, 700, 200, 300, 900, 350))
    result = run("process", tmp_path / "s")
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(tmp_path / "s" / "results" / "poses.csv")
    assert list(poses.columns[: len(CONTRACT_COLUMNS)]) == CONTRACT_COLUMNS
    assert list(poses["label"]) == ["S1", "S2", "S3", "S4"]
    truth = pd.read_csv(tmp_path / "s" / "truth" / "steps.csv")
    t_err, r_err = pose_errors(poses, truth, "corr")
    assert t_err < 0.05 and r_err < 0.1
    c_err, _ = pose_errors(poses, truth, "conv")
    assert c_err > 1.0
    # the times are written back as ISO timestamps, like the input
    assert poses["time"].str.match(r"\d{4}-\d\d-\d\dT").all()
    legs = pd.read_csv(tmp_path / "s" / "results" / "legs.csv")
    assert len(legs) == 10 and legs.loc[1, "dq_leg1_um"] == 0.0
    # the table shows deviations in um/urad for every target
    assert "conventional - commanded" in result.output and "S4" in result.output


def test_process_refuses_to_overwrite(tmp_path):
    make_session(tmp_path / "s")
    assert run("process", tmp_path / "s").exit_code == 0
    again = run("process", tmp_path / "s")
    assert again.exit_code != 0 and "use --overwrite" in again.output
    assert run("process", tmp_path / "s", "--overwrite").exit_code == 0


def test_interpolation_option_changes_the_result(tmp_path):
    make_session(tmp_path / "s", n_targets=3, tau_s=1200.0)
    assert run("process", tmp_path / "s", "-o", tmp_path / "lin").exit_code == 0
    assert (
        run(
            "process", tmp_path / "s", "-o", tmp_path / "one", "--interpolation", "before"
        ).exit_code
        == 0
    )
    lin = pd.read_csv(tmp_path / "lin" / "poses.csv")
    one = pd.read_csv(tmp_path / "one" / "poses.csv")
    assert one["ref_after"].eq("none").all() and not lin["ref_after"].eq("none").any()
    assert np.abs(lin["Tx_corr_mm"] - one["Tx_corr_mm"]).max() > 1e-5


def replace_in(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def drop_line(path, startswith):
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(ln for ln in lines if not ln.startswith(startswith)))


def line_of(path, startswith):
    return next(
        i for i, ln in enumerate(path.read_text().splitlines(), 1) if ln.startswith(startswith)
    )


def set_field(path, startswith, column, value):
    lines = path.read_text().splitlines(keepends=True)
    i = next(i for i, ln in enumerate(lines) if ln.startswith(startswith))
    fields = lines[i].rstrip("\n").split(",")
    fields[column] = value
    lines[i] = ",".join(fields) + "\n"
    path.write_text("".join(lines))
    return i + 1


def duplicate_row(path, startswith):
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines) + next(ln for ln in lines if ln.startswith(startswith)))
    return len(lines) + 1


def drop_ball_b3(session):
    text = (session / "balls.yaml").read_text()
    start = text.index("  B3:")
    end = text.index("probe:")
    (session / "balls.yaml").write_text(text[:start] + text[end:])


def collinear(session):
    replace_in(session / "balls.yaml", "[-73.6, -42.5, 30.0]", "[0.0, 10.0, 30.0]")
    replace_in(session / "balls.yaml", "[82.3, -47.5, 30.0]", "[0.0, -20.0, 30.0]")


BAD_INPUTS = {
    "missing file": (
        lambda s: (s / "balls.yaml").unlink(),
        r"session.yaml:4: field 'balls': file not found",
    ),
    "wrong format": (
        lambda s: replace_in(s / "plan.yaml", "hexatherm-plan/1", "hexatherm-plan/9"),
        r"plan.yaml:1: field 'format': expected format 'hexatherm-plan/1'",
    ),
    "step missing a ball": (
        lambda s: drop_line(s / "centres.csv", "S2,B3,"),
        r"step S2: ball B3 not measured",
    ),
    "non-numeric coordinate": (
        lambda s: set_field(s / "centres.csv", "R1,B2,", 2, "12.x"),
        r"centres.csv:{line}: field 'x': not a finite number: '12.x'",
    ),
    "duplicate label": (
        lambda s: duplicate_row(s / "centres.csv", "S1,B1,"),
        r"centres.csv:{line}: field 'label': duplicate centre for step S1 ball "
        r"B1 \(also on line 8\)",
    ),
    "fewer than 3 balls": (
        drop_ball_b3,
        r"balls.yaml:3: field 'balls': at least three balls are needed",
    ),
    "collinear balls": (collinear, r"balls.yaml:3: field 'balls': the balls are collinear"),
    "no adjacent reference": (
        lambda s: (
            drop_line(s / "plan.yaml", "  - {label: R1,"),
            drop_line(s / "plan.yaml", "  - {label: R2,"),
        ),
        r"plan.yaml:8: field 'steps\[3\]': step S2: target has no reference step adjacent",
    ),
    "wrong number of fields": (
        lambda s: set_field(s / "centres.csv", "S3,B1,", 2, "1,2"),
        r"centres.csv:{line}: expected 6 comma-separated fields, found 7",
    ),
    "bad cmm noise": (
        lambda s: append(s / "session.yaml", "cmm: {mpe_um: zero}\n"),
        r"session.yaml:{line}: field 'cmm.mpe_um': expected a number",
    ),
}


def append(path, text):
    with path.open("a") as f:
        f.write(text)
    return len(path.read_text().splitlines())


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_exits_nonzero_names_the_place_and_writes_nothing(tmp_path, case):
    session = tmp_path / "s"
    make_session(session)
    mutate, pattern = BAD_INPUTS[case]
    line = mutate(session)
    before = sorted(p.name for p in session.iterdir())
    result = run("process", session)
    assert result.exit_code == 1
    assert result.output.startswith("Error: ") and "Traceback" not in result.output
    assert re.search(pattern.replace("{line}", str(line)), result.output), result.output
    assert sorted(p.name for p in session.iterdir()) == before  # no results/ folder


def test_help_and_version():
    result = run("--help")
    assert result.exit_code == 0 and "process" in result.output
    result = run("--version")
    assert result.exit_code == 0 and "hexatherm, version" in result.output


def test_commanded_pose_outside_the_stroke_is_reported(tmp_path):
    make_session(tmp_path / "s")
    replace_in(tmp_path / "s" / "hexapod.yaml", "stroke: [220.0, 310.0]", "stroke: [250.0, 310.0]")
    result = run("process", tmp_path / "s")
    assert result.exit_code == 0
    assert (
        "warning: step R0: commanded pose is outside the stroke [250.0, 310.0] mm" in result.output
    )


U_COLUMNS = [f"u_{c}" for c in pose_columns("conv") + pose_columns("corr")]


def test_process_writes_uncertainties_and_quality(tmp_path):
    make_session(tmp_path / "s", noise_mm=1e-3)
    result = run("process", tmp_path / "s")
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(tmp_path / "s" / "results" / "poses.csv")
    assert list(poses.columns[: len(CONTRACT_COLUMNS)]) == CONTRACT_COLUMNS
    start = list(poses.columns).index(U_COLUMNS[0])
    assert list(poses.columns[start : start + 12]) == U_COLUMNS
    assert (poses[U_COLUMNS] > 0).all().all()
    # 1 um per centre coordinate: corrected poses about 1 um, 15 urad
    assert 0.5e-3 < poses["u_Tx_corr_mm"].mean() < 3e-3
    assert "uncertainty: centres from registration residuals" in result.output
    assert "u (linear, k=1) of the corrected poses" in result.output
    assert "common to all targets" in result.output and "corrected    common Tx" in result.output
    assert (tmp_path / "s" / "results" / "covariance.csv").is_file()
    quality = pd.read_csv(tmp_path / "s" / "results" / "quality.csv")
    assert len(quality) == 8 and quality["failed"].eq("none").all()
    assert "quality checks of 8 steps:" in result.output
    assert "wrote " + str(tmp_path / "s" / "results" / "quality.csv") in result.output


def test_process_monte_carlo_option(tmp_path):
    make_session(tmp_path / "s", noise_mm=1e-3)
    assert run("process", tmp_path / "s", "-o", tmp_path / "lin").exit_code == 0
    result = run("process", tmp_path / "s", "-o", tmp_path / "mc", "--mc", 400, "--seed", 3)
    assert result.exit_code == 0, result.output
    assert "Monte Carlo (400 draws, seed 3) over linear propagation" in result.output
    assert "(centres drawn from their covariance)" in result.output  # a centres session
    assert "Monte Carlo draws" in result.output  # the progress bar (its label off a terminal)
    assert "Monte Carlo draws" not in run("process", tmp_path / "s", "-o", tmp_path / "l2").output
    lin = pd.read_csv(tmp_path / "lin" / "poses.csv")[U_COLUMNS].to_numpy()
    mc = pd.read_csv(tmp_path / "mc" / "poses.csv")[U_COLUMNS].to_numpy()
    assert np.all(np.abs(mc / lin - 1) < 0.25) and not np.allclose(mc, lin)
    bad = run("process", tmp_path / "s", "-o", tmp_path / "x", "--mc", 1)
    assert bad.exit_code == 2 and "at least 2 draws" in bad.output


def test_failed_quality_check_warns_or_exits_3_with_strict(tmp_path):
    make_session(tmp_path / "s", gain=(30.0, 7.0, 2.0, 3.0, 9.0, 3.5))  # legs heat fast
    result = run("process", tmp_path / "s")
    assert result.exit_code == 0, result.output
    assert "warning: quality checks failed at 3 step(s) (S1, S2, S3)" in result.output
    assert re.search(
        r"temperature +temperature_change_C +worst +[\d.]+ +\(limit <= 1\) +"
        r"FAILED at 3 step\(s\): S1, S2, S3",
        result.output,
    ), result.output
    strict = run("process", tmp_path / "s", "--overwrite", "--strict")
    assert strict.exit_code == 3
    assert "exit status 3 (--strict)" in strict.output
    quality = pd.read_csv(tmp_path / "s" / "results" / "quality.csv")  # still written
    assert quality.loc[quality["kind"] == "target", "failed"].eq("temperature").all()
    relaxed = run(
        "process",
        tmp_path / "s",
        "--overwrite",
        "--strict",
        "--quality-threshold",
        "temperature_change_C=inf",
    )
    assert relaxed.exit_code == 0, relaxed.output


@pytest.mark.parametrize(
    "value, message",
    [
        ("form=3", "unknown name 'form'; expected one of form_um"),
        ("form_um", "expected NAME=VALUE"),
        ("time_gap_s=soon", "'soon' is not a number"),
    ],
)
def test_bad_quality_threshold_is_refused_before_anything_is_written(tmp_path, value, message):
    make_session(tmp_path / "s")
    result = run("process", tmp_path / "s", "--quality-threshold", value)
    # a usage error (status 2, as the README's table says for a bad option)
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"Invalid value for '--quality-threshold': {value!r}: {message}" in result.output
    assert not (tmp_path / "s" / "results").exists()


def test_slow_dmis_read_shows_a_progress_bar_and_gives_the_same_poses(tmp_path):
    shutil.copytree(
        SHIPPED / "paper-zero-pose-dmis",
        tmp_path / "s",
        ignore=shutil.ignore_patterns("expected", "results"),
    )
    fast = run("process", tmp_path / "s", "-o", tmp_path / "fast")
    assert fast.exit_code == 0, fast.output
    assert "reading points.dmo" not in fast.output  # the fast path: done at once, no bar
    dmo = tmp_path / "s" / "points.dmo"
    lines = dmo.read_text().splitlines(keepends=True)
    dmo.write_text("".join(lines[:3] + ["$$ a comment: the general reader\n"] + lines[3:]))
    slow = run("process", tmp_path / "s", "-o", tmp_path / "slow")
    assert slow.exit_code == 0, slow.output
    assert "reading points.dmo" in slow.output
    pd.testing.assert_frame_equal(
        pd.read_csv(tmp_path / "slow" / "poses.csv"), pd.read_csv(tmp_path / "fast" / "poses.csv")
    )


def test_the_screen_shows_u_under_every_value_and_says_where_the_correction_is_not_significant(
    tmp_path,
):
    # issue 33 item 10: on the paper's session the rotations' corrections are of the order
    # of their U; the screen says which, recomputed here from poses.csv's own columns
    session = SHIPPED / "paper-zero-pose"
    result = run("process", session, "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(tmp_path / "out" / "poses.csv")
    lines = result.stdout.splitlines()
    rows = [line for line in lines if line.startswith("  U k=2")]
    assert len(rows) == len(poses)  # one U row under every target's row
    for row, (_, target) in zip(rows, poses.iterrows(), strict=True):
        shown = [float(v.lstrip("±")) for v in row.split()[2:] if v.startswith("±")]
        want = [
            2 * target[f"u_d{c}_{kind}_{u}"] for kind in ("conv", "corr") for c, u in COMPONENTS
        ]
        np.testing.assert_allclose(shown, want, atol=2e-3)  # the file's 4 decimals, rounded
    expected = []
    for name, unit in COMPONENTS:
        effect = (poses[f"d{name}_corr_{unit}"] - poses[f"d{name}_conv_{unit}"]).abs().max()
        big_u = 2 * poses[f"u_d{name}_corr_{unit}"].median()
        if effect < big_u - 2e-3:  # clear of the file's rounding
            expected.append(name)
        elif effect > big_u + 2e-3:
            assert f"correction of {name} " not in result.stdout
    assert expected  # the session has some: Rz
    for name in expected:
        assert f"not significant: the thermal correction of {name} (at most" in result.stdout
