"""A hostile-input audit of ``process``'s options and ``diagnose``'s inputs (session 10).

Session shapes the options meet (times out of the plan's order, sessions too short
for the diagnosis' held-out check): each is refused in one line naming what is wrong
(exit status 1, no traceback, nothing written, no input touched), or processed as
before.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner, Result

from hexatherm.cli import main
from tests.audit import hashes, refusal, session_copy
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def swap_step_times(centres: Path, a: str, b: str) -> int:
    """Give the rows of step ``a`` the times of step ``b``'s and back (ball by ball);
    the line number of ``a``'s first row."""
    rows = list(csv.reader(centres.open(newline="")))
    first_a = next(i for i, r in enumerate(rows) if r[0] == a) + 1
    ra = [r for r in rows[1:] if r[0] == a]
    rb = [r for r in rows[1:] if r[0] == b]
    assert len(ra) == len(rb) > 0
    for x, y in zip(ra, rb, strict=True):
        x[5], y[5] = y[5], x[5]
    with centres.open("w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(rows)
    return first_a


@pytest.mark.parametrize("interpolation", ["linear", "smooth"])
def test_target_measured_after_its_later_reference_is_refused(
    tmp_path: Path, interpolation: str
) -> None:
    # S2 stamped at R2's times: its time lies outside [t(R1), t(R2)], and the weight
    # (t_S - t_b) / (t_a - t_b) of R2 was 2.0 (R1 -1.0): an extrapolation written as a
    # corrected pose, with no word on screen (seen: weight_after 2.0, dt_after_s -200)
    session = session_copy(tmp_path)
    line = swap_step_times(session / "centres.csv", "S2", "R2")
    before = hashes(session)
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["process", str(session), "-o", str(out), "--interpolation", interpolation]
    )
    message = refusal(result)
    assert "step S2" in message
    assert f"centres.csv:{line}" in message
    assert "R1" in message and "R2" in message
    assert not out.exists()
    assert hashes(session) == before


def test_target_times_in_order_still_processed(tmp_path: Path) -> None:
    # the control: the same session unswapped processes, every weight within [0, 1],
    # and S2's weight is its time's place between its references' times
    session = session_copy(tmp_path)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    rows = {r["label"]: r for r in csv.DictReader((out / "poses.csv").open())}
    w = np.array([float(r["weight_after"]) for r in rows.values()])
    assert np.all((w >= 0) & (w <= 1))
    s2 = rows["S2"]
    dtb, dta = float(s2["dt_before_s"]), float(s2["dt_after_s"])
    assert float(s2["weight_after"]) == pytest.approx(dtb / (dtb + dta))


@pytest.mark.parametrize("command", ["process", "diagnose"])
def test_empty_output_folder_is_a_usage_error(tmp_path: Path, command: str) -> None:
    # -o '' (an unset shell variable) was read as '.' and refused as
    # "-o .: the output folder contains the input ..." with exit 1, naming a folder the
    # user never gave; report -o '' is a usage error naming -o (exit 2) since ba86341
    session = session_copy(tmp_path, "with-hidden-effect")
    before = hashes(session)
    result = CliRunner().invoke(main, [command, str(session), "-o", ""])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error: ")]
    assert len(errors) == 1 and "'-o'" in errors[0] and "empty" in errors[0], result.output
    assert "-o ." not in result.output
    assert hashes(session) == before


def simulated_session(tmp_path: Path, n_targets: int, seed: int = 0) -> Path:
    """A session with no hidden effect (truth/effects.yaml: none) of 2 + 2 n_targets
    steps: ``plan --random`` then ``simulate --plan`` (legs warmed by mats, 0.5 um CMM
    noise)."""
    config = SHIPPED / "paper-zero-pose"
    hexapod, balls = str(config / "hexapod.yaml"), str(config / "balls.yaml")
    plan = tmp_path / f"plan{n_targets}.yaml"
    common = ["--hexapod", hexapod, "--balls", balls]
    result = CliRunner().invoke(
        main,
        ["plan", *common, "--random", str(n_targets), "--seed", "0"]
        + ["--box", "Tx=-5:5", "--box", "Ry=-1:1", "-o", str(plan)],
    )
    assert result.exit_code == 0, result.output
    session = tmp_path / f"s{n_targets}"
    result = CliRunner().invoke(
        main, ["simulate", "--plan", str(plan), *common, "-o", str(session), "--seed", str(seed)]
    )
    assert result.exit_code == 0, result.output
    assert "effects: []" in (session / "truth" / "effects.yaml").read_text()
    return session


def test_diagnose_refuses_a_session_too_short_for_its_heldout_check(tmp_path: Path) -> None:
    # 4 steps (O, R0, S1, R1) of a twin without any hidden effect: diagnose added
    # leg_thermal_lag (tau_s 136 +- 28 s, held out on 2 steps) and wrote it into
    # hexapod.yaml; over 8 seeds 1 added an effect and 6 said NOT ADEQUATE of pure noise
    # (6 steps: 1 in 8 added one; 12 steps: none, all adequate)
    session = simulated_session(tmp_path, 1)
    before = hashes(session)
    out = tmp_path / "diagnosis"
    message = refusal(CliRunner().invoke(main, ["diagnose", str(session), "-o", str(out)]))
    assert "4 steps" in message and "at least 12" in message
    assert "session.yaml" in message
    assert not out.exists()
    assert hashes(session) == before


@pytest.fixture(scope="module")
def twelve_steps(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Result]:
    """The session of 12 steps (:func:`simulated_session` of 5 targets) and ``diagnose S
    -o D`` of it, made once: the tests read them, and copy what they change
    (:func:`twelve_steps_copy`)."""
    root = tmp_path_factory.mktemp("twelve")
    session = simulated_session(root, 5)
    out = root / "diagnosis"
    return session, out, CliRunner().invoke(main, ["diagnose", str(session), "-o", str(out)])


def twelve_steps_copy(tmp_path: Path, twelve_steps: tuple[Path, Path, Result]) -> Path:
    """A copy of the 12-step session in ``tmp_path`` (its own folder name, ``s5``)."""
    session = tmp_path / twelve_steps[0].name
    shutil.copytree(twelve_steps[0], session)
    return session


def test_diagnose_takes_a_session_of_twelve_steps(
    twelve_steps: tuple[Path, Path, Result],
) -> None:
    # the control at the limit: 12 steps, no hidden effect; nothing added (the truth)
    _, out, result = twelve_steps
    assert result.exit_code == 0, result.output
    assert "diagnosing s5: 12 steps" in result.output
    assert "result: added nothing" in result.output
    assert "thermal_model" not in (out / "hexapod.yaml").read_text()


@pytest.mark.parametrize("fixed", [False, True])
def test_smooth_interpolation_on_a_points_session(tmp_path: Path, fixed: bool) -> None:
    # a session of probed points (DMIS) has a registration weight per step and ball;
    # --interpolation smooth was a Python traceback (ValueError: operands could not be
    # broadcast, (22,3) against (3,3,2,11,3), in the smooth fit's own error: the 11
    # references' moved centres met the 22 steps' weights), with or without
    # --fixed-diameter, after the whole processing
    session = session_copy(tmp_path, "paper-zero-pose-dmis")
    before = hashes(session)
    out = tmp_path / "out"
    args = ["process", str(session), "-o", str(out), "--interpolation", "smooth"]
    result = CliRunner().invoke(main, args + (["--fixed-diameter"] if fixed else []))
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    assert "smooth fit's own error" in result.output
    assert hashes(session) == before
    # the twin's truth: every corrected translation within 3 u (k = 3) of the true pose
    # in the reference thermal state
    truth = {r["label"]: r for r in csv.DictReader((session / "truth" / "steps.csv").open())}
    rows = list(csv.DictReader((out / "poses.csv").open()))
    assert len(rows) == 10
    for row in rows:
        for axis in ("Tx", "Ty", "Tz"):
            error = float(row[f"{axis}_corr_mm"]) - float(
                truth[row["label"]][f"{axis}_truecorr_mm"]
            )
            assert abs(error) <= 3 * float(row[f"u_{axis}_corr_mm"]), (row["label"], axis)


# report takes no process option (tests/cli/test_report_results.py)
@pytest.mark.parametrize("command", ["process"])
def test_seed_without_monte_carlo_is_a_usage_error(tmp_path: Path, command: str) -> None:
    # --seed 5 without --mc: the linear propagation draws nothing, and the seed was
    # ignored without a word (results identical to --seed 0), as --hexapod without
    # --method twin is not; report takes the same two options
    session = session_copy(tmp_path)
    before = hashes(session)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, [command, str(session), "-o", str(out), "--seed", "5"])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error: ")]
    assert len(errors) == 1 and "'--seed'" in errors[0] and "--mc" in errors[0]
    assert not out.exists()
    assert hashes(session) == before
    if command == "report":
        return
    # with draws the seed is taken, and said
    result = CliRunner().invoke(
        main, ["process", str(session), "-o", str(out), "--seed", "5", "--mc", "2"]
    )
    assert result.exit_code == 0, result.output
    assert "Monte Carlo (2 draws, seed 5)" in result.output


def test_fixed_diameter_on_a_centres_session_says_it_changes_nothing(tmp_path: Path) -> None:
    # --fixed-diameter on a session of ball centres: nothing to fit, the results are the
    # same byte for byte, and nothing said so (the user believes the radius was fixed)
    session = session_copy(tmp_path)
    plain, fixed = tmp_path / "plain", tmp_path / "fixed"
    assert CliRunner().invoke(main, ["process", str(session), "-o", str(plain)]).exit_code == 0
    result = CliRunner().invoke(
        main, ["process", str(session), "-o", str(fixed), "--fixed-diameter"]
    )
    assert result.exit_code == 0, result.output
    assert (fixed / "poses.csv").read_bytes() == (plain / "poses.csv").read_bytes()
    warnings = [line for line in result.output.splitlines() if "--fixed-diameter" in line]
    assert len(warnings) == 1 and warnings[0].startswith("warning: "), result.output
    assert "centres" in warnings[0]


def test_fixed_diameter_on_a_points_session_says_nothing_more(tmp_path: Path) -> None:
    session = session_copy(tmp_path, "paper-zero-pose-dmis")
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(out), "--fixed-diameter"])
    assert result.exit_code == 0, result.output
    assert "--fixed-diameter" not in result.output


@pytest.mark.parametrize(
    ("args", "words"),
    [
        # a reciprocal condition number is at most 1: min_rcond=2 (or inf, after "inf
        # disables a limit") failed every target's conditioning check (10 of 10)
        (["--quality-threshold", "min_rcond=2"], ["min_rcond", "at most 1"]),
        (["--quality-threshold", "min_rcond=inf"], ["min_rcond", "at most 1"]),
        # the same limit twice: the last one was taken without a word (--tolerance Tx
        # twice is refused)
        (
            ["--quality-threshold", "form_um=1", "--quality-threshold", "form_um=20"],
            ["form_um", "twice"],
        ),
    ],
)
def test_quality_threshold_edges_are_usage_errors(
    tmp_path: Path, args: list[str], words: list[str]
) -> None:
    session = session_copy(tmp_path)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(out), *args])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error: ")]
    assert len(errors) == 1 and "'--quality-threshold'" in errors[0], result.output
    assert all(w in errors[0] for w in words), errors[0]
    assert not out.exists()


def test_quality_min_rcond_above_one_in_the_session_file_is_refused(tmp_path: Path) -> None:
    session = session_copy(tmp_path)
    with (session / "session.yaml").open("a") as f:
        f.write("quality:\n  min_rcond: 2\n")
    before = hashes(session)
    out = tmp_path / "out"
    message = refusal(CliRunner().invoke(main, ["process", str(session), "-o", str(out)]))
    assert "session.yaml:" in message and "quality.min_rcond" in message
    assert "at most 1" in message
    assert not out.exists()
    assert hashes(session) == before


def test_quality_min_rcond_one_and_zero_are_taken(tmp_path: Path) -> None:
    # the edges: 1 fails every target (every Jacobian's rcond of paper-zero-pose is
    # 0.25), 0 turns the check off
    session = session_copy(tmp_path)
    for limit, failing in (("1", True), ("0", False)):
        out = tmp_path / f"out{limit}"
        args = ["process", str(session), "-o", str(out), "--quality-threshold"]
        result = CliRunner().invoke(main, [*args, f"min_rcond={limit}"])
        assert result.exit_code == 0, result.output
        rows = list(csv.DictReader((out / "quality.csv").open()))
        targets = [r for r in rows if r["kind"] == "target"]
        assert all((r["ok_conditioning"] == "False") == failing for r in targets)


def flatten_legs(temperatures: Path, legs: tuple[int, ...] = (1, 2, 3, 4, 5, 6)) -> None:
    """Every row of the ``legs`` columns at 20.0 C (a logger stuck, or not connected)."""
    rows = list(csv.reader(temperatures.open(newline="")))
    columns = [rows[0].index(f"leg{i}") for i in legs]
    for row in rows[1:]:
        for c in columns:
            row[c] = "20.0"
    with temperatures.open("w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(rows)


def test_diagnose_and_process_say_when_thermocouples_never_change(
    tmp_path: Path, twelve_steps: tuple[Path, Path, Result]
) -> None:
    # a log whose leg columns are constant all session (a stuck logger): the twin then
    # predicts no thermal change at all, and diagnose named the heating's signature as
    # cmm_drift and leg_offset (with-hidden-effect, NOT ADEQUATE) with no word on the log
    session = twelve_steps_copy(tmp_path, twelve_steps)
    control = twelve_steps[2]  # diagnose of the session as simulated
    assert control.exit_code == 0, control.output
    assert "never changes" not in control.output
    flatten_legs(session / "temperatures.csv", (2, 5))
    before = hashes(session)
    for command, out in (("diagnose", "d1"), ("process", "p1")):
        result = CliRunner().invoke(main, [command, str(session), "-o", str(tmp_path / out)])
        assert result.exit_code == 0, result.output
        lines = [line for line in result.output.splitlines() if "never changes" in line]
        assert len(lines) == 1 and lines[0].startswith("warning: "), result.output
        assert "temperatures.csv" in lines[0] and "leg2, leg5" in lines[0]
        assert "leg1" not in lines[0]
    assert hashes(session) == before


def test_a_target_with_a_reference_on_one_side_only_is_said(tmp_path: Path) -> None:
    # plan --reference-every before: the last target has no reference after it and is
    # corrected from the one before alone (weight_after 0), the growth since left
    # uncorrected; poses.csv's ref_after was empty, and the screen said nothing
    session = session_copy(tmp_path)
    plan = session / "plan.yaml"
    lines = plan.read_text().splitlines(keepends=True)
    assert lines[-1].lstrip().startswith("- {label: R10,")
    plan.write_text("".join(lines[:-1]))
    rows = [r for r in (session / "centres.csv").read_text().splitlines(keepends=True)]
    (session / "centres.csv").write_text("".join(r for r in rows if not r.startswith("R10,")))
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    poses = {r["label"]: r for r in csv.DictReader((out / "poses.csv").open())}
    assert poses["S10"]["ref_after"] == "none" and float(poses["S10"]["weight_after"]) == 0
    lines = [line for line in result.output.splitlines() if "one side" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: "), result.output
    gap = float(poses["S10"]["dt_before_s"])
    assert "S10" in lines[0] and "R9" in lines[0] and f"{gap:.0f} s" in lines[0]
    # the whole session: no such line
    full = CliRunner().invoke(
        main, ["process", str(SHIPPED / "paper-zero-pose"), "-o", str(tmp_path / "f")]
    )
    assert full.exit_code == 0 and "one side" not in full.output


def test_few_monte_carlo_draws_are_said(tmp_path: Path) -> None:
    # --mc 2: every u of poses.csv is the standard deviation of 2 draws (on
    # paper-zero-pose 0.004 to 2.0 times the linear propagation's), written and printed
    # like any other; the relative standard uncertainty of such a u is 1/sqrt(2 (M - 1)),
    # 71 % for M = 2, 7.1 % for M = 101
    session = session_copy(tmp_path)
    result = CliRunner().invoke(
        main, ["process", str(session), "-o", str(tmp_path / "a"), "--mc", "2"]
    )
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if "Monte Carlo draws" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: "), result.output
    assert "71 %" in lines[0]
    result = CliRunner().invoke(
        main, ["process", str(session), "-o", str(tmp_path / "b"), "--mc", "101"]
    )
    assert result.exit_code == 0, result.output
    assert "Monte Carlo draws" not in result.output


def test_diagnose_model_needing_air_without_an_air_column_names_the_file(
    tmp_path: Path, twelve_steps: tuple[Path, Path, Result]
) -> None:
    # --hexapod whose thermal_model has base_expansion, on a log without 'air': the
    # refusal was "Error: field 'air': the temperatures have no 'air' column", naming no
    # file (process --method twin names temperatures.csv:1)
    session = twelve_steps_copy(tmp_path, twelve_steps)
    rows = list(csv.reader((session / "temperatures.csv").open(newline="")))
    assert rows[0][-1] == "air"
    with (session / "temperatures.csv").open("w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows(r[:-1] for r in rows)
    hexapod = tmp_path / "model.yaml"
    hexapod.write_text(
        (session / "hexapod.yaml").read_text()
        + "thermal_model:\n  effects:\n"
        + "  - {name: base_expansion, parameters: {alpha_per_K: 1.0e-5}}\n"
    )
    before = hashes(session)
    out = tmp_path / "d"
    message = refusal(
        CliRunner().invoke(
            main, ["diagnose", str(session), "-o", str(out), "--hexapod", str(hexapod)]
        )
    )
    assert "temperatures.csv:1: field 'air'" in message
    assert "base_expansion" in message and "model.yaml" in message
    assert not out.exists()
    assert hashes(session) == before


def test_process_overwrite_never_removes_its_twin_model(
    tmp_path: Path, twelve_steps: tuple[Path, Path, Result]
) -> None:
    # diagnose S -o D, then process S --method twin --hexapod D/hexapod.yaml -o D
    # --overwrite: D is hexatherm's (its manifest lists every file), so --overwrite
    # replaced it, and the --hexapod file the run had just read was deleted (the
    # model's file was not among the inputs the output was checked against)
    session = twelve_steps_copy(tmp_path, twelve_steps)
    folder = tmp_path / "D"
    assert twelve_steps[2].exit_code == 0, twelve_steps[2].output
    shutil.copytree(twelve_steps[1], folder)  # diagnose S -o D, as written
    model = folder / "hexapod.yaml"
    before = hashes(session, folder)
    args = ["process", str(session), "--method", "twin", "--hexapod", str(model)]
    for extra in ([], ["--overwrite"]):
        message = refusal(CliRunner().invoke(main, [*args, "-o", str(folder), *extra]))
        assert "hexapod.yaml" in message, message
        assert hashes(session, folder) == before
    # beside it, the same run writes
    result = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "P")])
    assert result.exit_code == 0, result.output
    assert hashes(session, folder) == before


def test_a_one_sided_target_under_the_smooth_fit_is_said_extrapolated(tmp_path: Path) -> None:
    # with the smooth fit used, a target after the last reference gets the spline
    # evaluated beyond the references' times: an extrapolation, not the reference alone
    from tests.workflows.test_uncertainty_smooth import session as smooth_session

    folder = smooth_session(tmp_path / "s", 1)
    plan = folder / "plan.yaml"
    lines = plan.read_text().splitlines(keepends=True)
    assert lines[-1].lstrip().startswith("- {label: R6,")
    plan.write_text("".join(lines[:-1]))
    centres = folder / "centres.csv"
    rows = centres.read_text().splitlines(keepends=True)
    centres.write_text("".join(r for r in rows if not r.startswith("R6,")))
    out = tmp_path / "out"
    args = ["process", str(folder), "-o", str(out), "--interpolation", "smooth"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "smooth fit used" in result.output
    lines = [line for line in result.output.splitlines() if "one side" in line]
    assert len(lines) == 1 and "S6" in lines[0] and "R5" in lines[0], result.output
    assert "extrapolated" in lines[0] and "alone" not in lines[0]


def test_coverage_factor_without_tolerances_says_it_changes_nothing(tmp_path: Path) -> None:
    # --coverage-factor 3 without any tolerance: nothing is judged, poses.csv is the
    # same byte for byte, and nothing said so (U = 3u is written nowhere)
    session = session_copy(tmp_path)
    plain, k3 = tmp_path / "plain", tmp_path / "k3"
    assert CliRunner().invoke(main, ["process", str(session), "-o", str(plain)]).exit_code == 0
    result = CliRunner().invoke(
        main, ["process", str(session), "-o", str(k3), "--coverage-factor", "3"]
    )
    assert result.exit_code == 0, result.output
    assert (k3 / "poses.csv").read_bytes() == (plain / "poses.csv").read_bytes()
    lines = [line for line in result.output.splitlines() if "--coverage-factor" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: "), result.output
    # with a tolerance it is used, and nothing is said
    result = CliRunner().invoke(
        main,
        ["process", str(session), "-o", str(tmp_path / "t"), "--coverage-factor", "3"]
        + ["--tolerance", "Tx=2um"],
    )
    assert result.exit_code == 0, result.output
    assert "k = 3" in result.output and "warning: --coverage-factor" not in result.output


def test_twin_without_a_thermocouple_log_is_one_line_before_any_work(tmp_path: Path) -> None:
    # --method twin on a session without temperatures: the whole session was processed,
    # a warning printed ("no thermocouple log ... the correction rests on the
    # references alone"), and only then the refusal: two lines where one is the rule
    session = session_copy(tmp_path)
    text = (session / "session.yaml").read_text()
    (session / "session.yaml").write_text(text.replace("temperatures: temperatures.csv\n", ""))
    before = hashes(session)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(out), "--method", "twin"])
    message = refusal(result)
    assert "session.yaml" in message and "temperatures" in message
    assert result.output.strip() == message, result.output
    assert not out.exists()
    assert hashes(session) == before
