"""``--allow-truncated`` and ``--keep-later`` (issue 12, items 7 and 8): refused by
default, read past with a ``warning:`` line when asked, and the numbers are those of
the file as it should have been (an independent edit of the same file)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def copy(name: str, to: Path) -> Path:
    shutil.copytree(SHIPPED / name, to, ignore=shutil.ignore_patterns("results"))
    return to


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def poses(session: Path) -> pd.DataFrame:
    result = run("process", session, "--overwrite")
    assert result.exit_code == 0, result.output
    return pd.read_csv(session / "results" / "poses.csv")


def test_a_dmis_output_without_endfil(tmp_path: Path) -> None:
    cut = copy("paper-zero-pose-dmis", tmp_path / "cut")
    lines = (cut / "points.dmo").read_text().splitlines(keepends=True)
    assert lines[-1].strip() == "ENDFIL" and lines[-3].startswith("FA(R10_B3_25)")
    (cut / "points.dmo").write_text("".join(lines[:-2]))  # cut after the last point
    refused = run("process", cut)
    assert refused.exit_code == 1 and "ENDFIL" in refused.output
    assert "--allow-truncated" in refused.output and not (cut / "results").exists()
    allowed = run("process", cut, "--allow-truncated")
    assert allowed.exit_code == 0, allowed.output
    assert "warning: " in allowed.output and "points.dmo" in allowed.output
    # the truth: the same file, its last point removed by hand, ended properly
    whole = copy("paper-zero-pose-dmis", tmp_path / "whole")
    (whole / "points.dmo").write_text("".join(lines[:-3] + lines[-1:]))
    got = pd.read_csv(cut / "results" / "poses.csv")
    pd.testing.assert_frame_equal(got, poses(whole))
    # fit-spheres reads the same way
    assert run("fit-spheres", cut / "points.dmo").exit_code == 1
    fitted = run("fit-spheres", cut / "points.dmo", "--allow-truncated")
    assert fitted.exit_code == 0 and "warning: " in fitted.output


def test_a_ball_measured_twice_keeps_the_later_only_when_asked(tmp_path: Path) -> None:
    twice = copy("paper-zero-pose", tmp_path / "twice")
    text = (twice / "centres.csv").read_text()
    rows = text.splitlines(keepends=True)
    index = next(i for i, row in enumerate(rows) if row.startswith("S1,B1,"))
    fields = rows[index].split(",")
    fields[2] = f"{float(fields[2]) + 0.002:.6f}"  # re-measured 2 um further in x
    again = ",".join(fields)
    (twice / "centres.csv").write_text(text + again)
    refused = run("process", twice)
    assert refused.exit_code == 1 and "--keep-later" in refused.output
    assert f":{len(rows) + 1}:" in refused.output  # the later row's line is named
    kept = run("process", twice, "--keep-later")
    assert kept.exit_code == 0, kept.output
    assert "warning: " in kept.output
    truth = copy("paper-zero-pose", tmp_path / "truth")
    rows[index] = again
    (truth / "centres.csv").write_text("".join(rows))
    got = pd.read_csv(twice / "results" / "poses.csv")
    pd.testing.assert_frame_equal(got, poses(truth))


# report takes no process option (tests/cli/test_report_results.py)
@pytest.mark.parametrize("command", ["process"])
def test_a_temperature_log_cut_short(tmp_path: Path, command: str) -> None:
    cut = copy("paper-zero-pose", tmp_path / "cut")
    text = (cut / "temperatures.csv").read_text()
    (cut / "temperatures.csv").write_text(text.rstrip("\n")[:-2])  # mid-number
    refused = run(command, cut)
    assert refused.exit_code == 1 and "temperatures.csv" in refused.output
    assert "--allow-truncated" in refused.output
    allowed = run(command, cut, "--allow-truncated")
    assert allowed.exit_code == 0, allowed.output
    assert "warning: " in allowed.output and "temperatures.csv" in allowed.output


def test_inspect_lists_a_cut_file_only_when_asked(tmp_path: Path) -> None:
    lines = (SHIPPED / "paper-zero-pose-dmis" / "points.dmo").read_text()
    cut = tmp_path / "points.dmo"
    cut.write_text("".join(lines.splitlines(keepends=True)[:-2]))  # no ENDFIL
    refused = run("inspect", cut)
    assert refused.exit_code == 1 and "--allow-truncated" in refused.output
    listed = run("inspect", cut, "--allow-truncated", "--csv")
    assert listed.exit_code == 0, listed.output
    assert "warning: " in listed.output
    # the truth: the whole file's features but the last (the cut one)
    whole = run("inspect", SHIPPED / "paper-zero-pose-dmis" / "points.dmo", "--csv")
    assert whole.exit_code == 0, whole.output
    assert listed.stdout.splitlines() == whole.stdout.splitlines()[:-1]
    # a centres file with a ball measured twice: the later row when asked
    text = (SHIPPED / "paper-zero-pose" / "centres.csv").read_text()
    twice = tmp_path / "centres.csv"
    first = text.splitlines()[1]
    twice.write_text(text + first + "\n")
    assert run("inspect", twice).exit_code == 1
    kept = run("inspect", twice, "--keep-later", "--csv")
    assert kept.exit_code == 0, kept.output
    rows = [r for r in kept.stdout.splitlines() if r.startswith(f"{len(text.splitlines()) + 1},")]
    assert len(rows) == 1 and rows[0].split(",")[1] == "O_B1"
    assert not any(r.startswith("2,") for r in kept.stdout.splitlines())  # the earlier one


def test_fit_spheres_refuses_a_ball_in_two_files(tmp_path: Path) -> None:
    # a step's ball in two points files would be two centres rows that process refuses
    # ("measured again (already in an earlier file)"): fit-spheres refuses them too, with
    # or without --keep-later (which keeps the later of two within one file), as process
    # does across the files of a session
    points = SHIPPED / "serial-capture" / "points.csv"
    header, *rows = points.read_text().splitlines(keepends=True)
    again = tmp_path / "again.csv"
    again.write_text(header + "".join(r for r in rows if r.startswith("R0,")))
    for extra in ([], ["--keep-later"]):
        refused = run("fit-spheres", points, again, "-o", tmp_path / "centres.csv", *extra)
        assert refused.exit_code == 1
        assert refused.output.strip().splitlines()[-1] == (
            f"Error: {again}:2: field 'label': step R0 ball B1 is measured again "
            f"(already in {points})"
        )
        assert not (tmp_path / "centres.csv").exists()
    # the truth: the file split by steps into two gives the whole file's centres
    first = tmp_path / "first.csv"
    first.write_text(header + "".join(r for r in rows if r.startswith("O,")))
    rest = tmp_path / "rest.csv"
    rest.write_text(header + "".join(r for r in rows if not r.startswith("O,")))
    split = run("fit-spheres", first, rest, "-o", tmp_path / "split.csv")
    whole = run("fit-spheres", points, "-o", tmp_path / "whole.csv")
    assert split.exit_code == whole.exit_code == 0, split.output + whole.output
    assert (tmp_path / "split.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
