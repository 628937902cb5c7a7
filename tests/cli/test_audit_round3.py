"""A hostile-input audit, round 3 (issue 36): ``--overwrite`` across commands, lab templates
that do not end, escape their folder or sit beside huge files, and small tracebacks.

Each case is refused in one line (exit status 1, no traceback), nothing is written and
no input or other command's output is touched; or, for the positive cases, the same
command replaces its own output.
"""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.manifest import read_manifest
from hexatherm.io.outputs import output_dir
from hexatherm.io.provenance import run_context
from tests.audit import ROOT, hashes, refusal, session_copy

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


def invoke(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def write_plan(folder: Path) -> Path:
    """``plan -o folder/plan.yaml`` (with its DMIS program and checklist)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "t.csv").write_text("Tx,Ty,Tz,Rx,Ry,Rz\n5,-3,2,0.5,-0.4,3\n")
    made = invoke(
        "plan", "--hexapod", HEXAPOD, "--balls", BALLS, "--targets", folder / "t.csv",
        "-o", folder / "plan.yaml", "--dmis", folder / "plan.dmi",
        "--origin-on-cmm", "400,300,100,0,0,0", "--checklist", folder / "check.md",
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    return folder / "plan.yaml"


# ------------------------------------------------- item 4: --overwrite, same command only


def test_report_overwrite_does_not_replace_the_plan(tmp_path):
    plan = write_plan(tmp_path / "lab")
    session = session_copy(tmp_path)
    before = hashes(tmp_path / "lab", session)
    result = invoke("report", session, "-o", plan, "--overwrite")
    line = refusal(result)
    assert "plan.yaml (written by hexatherm plan, not report)" in line, line
    assert hashes(tmp_path / "lab", session) == before


def test_plan_overwrite_replaces_its_own_plan(tmp_path):
    plan = write_plan(tmp_path / "lab")
    first = plan.read_bytes()
    (tmp_path / "lab" / "t.csv").write_text("Tx,Ty,Tz,Rx,Ry,Rz\n1,2,3,0,0,0\n")
    again = invoke(
        "plan", "--hexapod", HEXAPOD, "--balls", BALLS, "--targets", tmp_path / "lab" / "t.csv",
        "-o", plan, "--overwrite",
    )  # fmt: skip
    assert again.exit_code == 0, again.output
    assert plan.read_bytes() != first
    assert read_manifest(plan.parent).commands["plan.yaml"] == "plan"


def test_a_file_without_a_record_of_its_command_is_not_replaced(tmp_path):
    """A file hexatherm's manifest lists without the command that wrote it (a script's,
    or an older hexatherm's) is not a report's to replace."""
    out = tmp_path / "out"
    with output_dir(out) as tmp:  # outside a command line: no command recorded
        (tmp / "report.html").write_text("<p>a script's page</p>\n")
    session = session_copy(tmp_path)
    before = hashes(out)
    line = refusal(invoke("report", session, "-o", out / "report.html", "--overwrite"))
    assert "report.html (written by hexatherm with no record of its command)" in line, line
    assert hashes(out) == before


def processed(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    session = session_copy(tmp_path)
    done = invoke("process", session, "--mc", 0)
    assert done.exit_code == 0, done.output
    return session, hashes(session / "results")


def test_diagnose_and_calibrate_overwrite_do_not_replace_process_results(tmp_path):
    session, results = processed(tmp_path)
    for command in ("diagnose", "calibrate"):
        line = refusal(invoke(command, session, "-o", session / "results", "--overwrite"))
        assert f"(written by hexatherm process, not {command})" in line, line
        assert hashes(session / "results") == results
    again = invoke("process", session, "--mc", 0, "--overwrite")  # its own: replaced
    assert again.exit_code == 0, again.output
    assert read_manifest(session / "results").commands["poses.csv"] == "process"


def test_process_overwrite_does_not_replace_a_diagnosis(tmp_path):
    session = session_copy(tmp_path)
    diagnosis = tmp_path / "diagnosis"
    with run_context("diagnose", [str(session)], {}), output_dir(diagnosis) as tmp:
        (tmp / "diagnosis.json").write_text("{}\n")
    before = hashes(diagnosis)
    line = refusal(invoke("process", session, "-o", diagnosis, "--overwrite"))
    assert "diagnosis.json, provenance.json (written by hexatherm diagnose, not process)" in line
    assert hashes(diagnosis) == before


def test_a_manifest_nested_past_the_parser_vouches_for_nothing(tmp_path):
    session, _ = processed(tmp_path)
    (session / "results" / ".hexatherm-manifest.json").write_text("[" * 200_000)
    before = hashes(session / "results")
    line = refusal(invoke("process", session, "--mc", 0, "--overwrite"))
    assert "not written by hexatherm: no .hexatherm-manifest.json" in line, line
    assert hashes(session / "results") == before
