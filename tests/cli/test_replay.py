"""``hexatherm replay``: recorded sessions keep giving the same numbers."""

from __future__ import annotations

import shutil

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
