"""``hexatherm replay``: recorded sessions keep giving the same numbers."""

from __future__ import annotations

import shutil

import pandas as pd
from click.testing import CliRunner

from hexatherm.cli import main
from tests.shipped import SHIPPED


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def copy_paper_session(tmp_path):
    target = tmp_path / "sessions" / "paper-zero-pose"
    shutil.copytree(SHIPPED / "paper-zero-pose", target, ignore=shutil.ignore_patterns("results"))
    return target


def test_shipped_sessions_replay():
    result = run("replay", SHIPPED)
    assert result.exit_code == 0, result.output
    assert "paper-zero-pose" in result.output and "ok" in result.output


def test_a_changed_number_names_session_row_and_column(tmp_path):
    session = copy_paper_session(tmp_path)
    poses = session / "expected" / "poses.csv"
    lines = poses.read_text().splitlines(keepends=True)
    header = lines[0].rstrip("\n").split(",")
    column = header.index("Tz_corr_mm")
    fields = lines[3].rstrip("\n").split(",")
    fields[column] = repr(float(fields[column]) + 2e-7)
    lines[3] = ",".join(fields) + "\n"
    poses.write_text("".join(lines))
    result = run("replay", tmp_path / "sessions")
    assert result.exit_code == 1
    assert "paper-zero-pose/poses.csv: row 4 (S3), column Tz_corr_mm" in result.output, (
        result.output
    )
    # a change below the tolerance passes
    fields[column] = repr(float(fields[column]) - 2e-7 + 5e-8)
    lines[3] = ",".join(fields) + "\n"
    poses.write_text("".join(lines))
    assert run("replay", tmp_path / "sessions").exit_code == 0


def test_update_rewrites_expected_and_says_what_changed(tmp_path):
    session = copy_paper_session(tmp_path)
    legs = session / "expected" / "legs.csv"
    text = legs.read_text().splitlines(keepends=True)
    text[1] = text[1].replace("O,origin,", "O,reference,")
    legs.write_text("".join(text))
    result = run("replay", tmp_path / "sessions", "--update")
    assert result.exit_code == 0 and "updated" in result.output
    assert "changed: paper-zero-pose/legs.csv: row 2 (O), column kind" in result.output
    assert run("replay", tmp_path / "sessions").exit_code == 0


def test_no_sessions_is_an_error(tmp_path):
    result = run("replay", tmp_path)
    assert result.exit_code == 1 and "no session with an expected/ folder" in result.output


def test_serial_capture_replays_to_the_same_points_byte_for_byte(tmp_path):
    folder = SHIPPED / "serial-capture"
    result = run(
        "acquire",
        folder / "plan.yaml",
        "--replay",
        folder / "serial.log",
        "--session",
        tmp_path / "again",
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / "again" / "points.csv").read_bytes() == (folder / "points.csv").read_bytes()


def test_parameters_are_compared_at_the_resolution_of_their_row_unit():
    """parameters.csv writes its values at the resolution of each row's unit (1e-7 mm,
    1e-10 mm/mm): a last digit that flips on another CPU is within replay's tolerance, two
    steps are not (found on an AMD EPYC: calibration-geometry's base4_y_mm 31.2721083 came
    out 31.2721084)."""
    from hexatherm.workflows.replay import Comparison, compare_tables

    expected = pd.DataFrame(
        {
            "parameter": ["base4_y_mm", "gain1"],
            "unit": ["mm", "mm/mm"],
            "calibrated": [31.2721083, 1.0000000001],
            "max_abs_correlation": [0.8208, 0.5],
        }
    )
    for change, ok in (
        ((1e-7, 0.0, 0.0), True),
        ((0.0, 1e-10, 1e-4), True),
        ((2e-7, 0.0, 0.0), False),
        ((0.0, 3e-9, 0.0), False),
        ((0.0, 0.0, 2e-4), False),
    ):
        got = expected.copy()
        got.loc[0, "calibrated"] += change[0]
        got.loc[1, "calibrated"] += change[1]
        got.loc[0, "max_abs_correlation"] += change[2]
        result = Comparison("s")
        compare_tables("parameters.csv", expected, got, {}, result)
        assert result.ok is ok, (change, result.mismatches)
