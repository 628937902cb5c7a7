"""No command writes into, around or onto its inputs (issue 12, item 1).

``process`` has its own tests (``test_process_outputs.py``); these are the other
commands that write: ``diagnose``, ``report``, ``fit-spheres``, ``register``,
``plan`` and ``simulate``. Every case is refused with one line naming the option,
before any work, and the whole tree of inputs is byte for byte as it was.
"""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

from hexatherm.cli import main
from hexatherm.io.manifest import read_manifest
from hexatherm.workflows.serve import TwinMachines
from tests.cli.test_run import machines
from tests.shipped import SHIPPED

__all__ = ["machines"]  # the twin's machines, a fixture

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """format: hexatherm-scenario/1
hexapod: {hexapod}
balls: {balls}
plan: {{targets: [[0.5, 0, 0, 0, 0, 0]], reference_pose: [0, 0, 0, 0, 0, 0], cycles: 1}}
seed: 3
"""


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    """A lab's folder: two recorded sessions, the register sample and a scenario."""
    for name, to in [
        ("paper-zero-pose", "s"),
        ("paper-zero-pose-dmis", "d"),
        ("register-datums", "r"),
    ]:
        shutil.copytree(SHIPPED / name, tmp_path / to)
    (tmp_path / "scenario.yaml").write_text(
        SCENARIO.format(
            hexapod=tmp_path / "s" / "hexapod.yaml", balls=tmp_path / "s" / "balls.yaml"
        )
    )
    return tmp_path


def cases(lab: Path) -> dict[str, tuple[list[str], str]]:
    s, d, r = lab / "s", lab / "d", lab / "r"
    plan = ["plan", "--hexapod", s / "hexapod.yaml", "--balls", s / "balls.yaml"]
    plan += ["--grid", "2", "--box", "Tx=-1:1"]
    return {
        "diagnose into its session": (["diagnose", s, "-o", s], "contains the input"),
        "diagnose around two sessions": (["diagnose", s, "-o", lab], "contains the input"),
        "report onto the centres": (["report", s, "-o", s / "centres.csv"], "is the input"),
        "report onto the hexapod file": (["report", s, "-o", s / "hexapod.yaml"], "is the input"),
        "fit-spheres onto its points": (
            ["fit-spheres", d / "points.dmo", "-o", d / "points.dmo"],
            "is the input",
        ),
        "register onto its measurement": (
            ["register", r / "points.csv", "--datums", r / "datums.yaml", "-o", r / "points.csv"],
            "is the input",
        ),
        "register onto its datums": (
            ["register", r / "points.csv", "--datums", r / "datums.yaml", "-o", r / "datums.yaml"],
            "is the input",
        ),
        "plan onto the hexapod file": ([*plan, "-o", s / "hexapod.yaml"], "is the input"),
        "plan's DMIS onto the balls": (
            [*plan, "--origin-on-cmm", "450,320,210,0,0,15", "--dmis", s / "balls.yaml"],
            "is the input",
        ),
        "simulate onto a recorded session": (
            ["simulate", lab / "scenario.yaml", "-o", d],
            "not written by hexatherm",
        ),
        "simulate around its scenario": (
            ["simulate", lab / "scenario.yaml", "-o", lab],
            "contains the input",
        ),
    }


CASES = list(cases(Path("/lab")))


@pytest.mark.parametrize("case", CASES)
def test_an_output_onto_or_around_an_input_is_refused_with_overwrite(lab: Path, case: str) -> None:
    args, why = cases(lab)[case]
    before = snapshot(lab)
    result = CliRunner().invoke(main, [str(a) for a in [*args, "--overwrite"]])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and why in lines[0], result.output
    assert "Traceback" not in result.output
    assert snapshot(lab) == before


def test_dot_inside_a_session_is_a_clean_refusal(
    lab: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(lab / "s")
    before = snapshot(lab)
    for args in (["diagnose", ".", "-o", "."], ["simulate", lab / "scenario.yaml", "-o", "."]):
        result = CliRunner().invoke(main, [str(a) for a in [*args, "--overwrite"]])
        assert result.exit_code == 1 and "-o ." in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    assert snapshot(lab) == before


def test_a_single_file_output_is_replaced_only_while_hexatherm_vouches_for_it(lab: Path) -> None:
    d = lab / "d"
    out = lab / "out" / "centres.csv"
    run = ["fit-spheres", str(d / "points.dmo"), "-o", str(out)]
    assert CliRunner().invoke(main, run).exit_code == 0
    assert sorted(read_manifest(out.parent).files) == ["centres.csv"]
    first = out.read_bytes()
    assert CliRunner().invoke(main, [*run, "--overwrite"]).exit_code == 0
    assert out.read_bytes() == first
    out.write_bytes(first + b"# checked by J. Doe\n")  # the lab's edit: now it is theirs
    edited = CliRunner().invoke(main, [*run, "--overwrite"])
    assert edited.exit_code == 1 and "changed since hexatherm wrote it" in edited.output
    assert out.read_bytes().endswith(b"# checked by J. Doe\n")


# ---------------------------------------------------------------- recording commands
# Issue 22, item 1: ``run --session`` and ``acquire --session`` wrote into an existing
# recorded session (plan.yaml and balls.yaml replaced even when no machine answered).

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


def checksums(folder: Path) -> dict[str, str]:
    """Every entry under ``folder`` (hidden ones too): SHA-256 of files, "folder" for folders."""
    return {
        str(p.relative_to(folder)): "folder"
        if p.is_dir()
        else hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
    }


def record(
    command: str, plan: Path, session: Path, *extra: object, controller: str | None = None
) -> list[str]:
    """``run`` with no machine answering (or only ``controller``: then the run reaches it,
    the CMM refuses, and the folder it recorded is kept), or ``acquire`` on a port where
    nothing comes."""
    if command == "run":
        args: list[object] = [
            "run", plan, "--cmm", "ipp://127.0.0.1:1",
            "--controller", controller or "symetrie://127.0.0.1:1",
            "--session", session, "--hexapod", HEXAPOD, "--balls", BALLS,
            "--origin-on-cmm", "450,320,210,0,0,15", "--no-fsync", "--reconnects", "0",
        ]  # fmt: skip
    else:
        args = [
            "acquire", plan, "--hexapod", HEXAPOD, "--balls", BALLS, "--port", "loop://",
            "--session", session, "--auto", "--idle-timeout", "0.2", "--read-timeout", "0.05",
        ]  # fmt: skip
    return [str(a) for a in [*args, *extra]]


@pytest.fixture
def recorded(lab: Path) -> Path:
    """A copy of sessions/paper-zero-pose, and its plan outside of it."""
    shutil.copy(lab / "s" / "plan.yaml", lab / "plan.yaml")
    return lab / "s"


@pytest.mark.parametrize("command", ["run", "acquire"])
def test_a_recording_command_refuses_a_recorded_session(
    lab: Path, recorded: Path, command: str
) -> None:
    before = checksums(lab)
    result = CliRunner().invoke(main, record(command, lab / "plan.yaml", recorded))
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    assert f"--session {recorded}: {command} records only into a new or empty folder" in lines[0]
    assert "session.yaml (a session)" in lines[0] and "nothing was written" in lines[0]
    assert checksums(lab) == before


@pytest.mark.parametrize("command", ["run", "acquire"])
def test_a_recording_command_refuses_a_simulated_session_its_manifest_vouches_for(
    lab: Path, recorded: Path, command: str
) -> None:
    sim = lab / "sim"
    made = CliRunner().invoke(main, ["simulate", str(lab / "scenario.yaml"), "-o", str(sim)])
    assert made.exit_code == 0, made.output
    before = checksums(lab)
    result = CliRunner().invoke(main, record(command, lab / "plan.yaml", sim))
    assert result.exit_code == 1, result.output
    assert "session.yaml (a session)" in result.output
    assert f"written by hexatherm as an output, not by {command}" in result.output
    assert checksums(lab) == before


@pytest.mark.parametrize("command", ["run", "acquire"])
def test_a_recording_command_refuses_a_folder_with_a_foreign_file(
    lab: Path, recorded: Path, command: str
) -> None:
    folder = lab / "new"
    folder.mkdir()
    (folder / "notes.txt").write_text("cell 3, operator J. Doe\n")
    before = checksums(lab)
    result = CliRunner().invoke(main, record(command, lab / "plan.yaml", folder))
    assert result.exit_code == 1, result.output
    assert f"notes.txt (not recorded by hexatherm {command})" in result.output
    assert checksums(lab) == before
    # --session around its own plan: the output guard's first rule
    (folder / "notes.txt").unlink()
    shutil.copy(lab / "plan.yaml", folder / "plan.yaml")
    before = checksums(lab)
    around = CliRunner().invoke(main, record(command, folder / "plan.yaml", folder))
    assert around.exit_code == 1 and "contains the input" in around.output, around.output
    assert checksums(lab) == before


def test_run_starts_again_only_in_a_folder_it_recorded_unchanged(
    lab: Path, recorded: Path, machines: TwinMachines
) -> None:
    """A run refused before anything was probed (the controller answered, the CMM did not)
    can be started again in its folder (and writes its manifest); a file added there, or
    one of its files edited, is refused."""
    folder = lab / "new"
    live = {"controller": machines.controller_url}
    first = CliRunner().invoke(main, record("run", lab / "plan.yaml", folder, **live))
    assert first.exit_code == 1 and "Connection refused" in first.output, first.output
    manifest = read_manifest(folder)
    assert manifest is not None and manifest.recorder == "run"
    assert {"plan.yaml", "balls.yaml", "ipp.transcript", "run.yaml"} <= set(manifest.files)
    again = CliRunner().invoke(main, record("run", lab / "plan.yaml", folder, **live))
    assert again.exit_code == 1 and "Connection refused" in again.output, again.output
    (folder / "notes.txt").write_text("mine\n")
    before = checksums(lab)
    refused = CliRunner().invoke(main, record("run", lab / "plan.yaml", folder, **live))
    assert refused.exit_code == 1 and "notes.txt (not written by hexatherm)" in refused.output
    assert checksums(lab) == before
    (folder / "notes.txt").unlink()
    with open(folder / "run.yaml", "a") as handle:
        handle.write("# checked\n")
    before = checksums(lab)
    edited = CliRunner().invoke(main, record("run", lab / "plan.yaml", folder, **live))
    assert edited.exit_code == 1 and "run.yaml (changed since hexatherm wrote it)" in edited.output
    assert checksums(lab) == before


def test_resume_continues_only_a_folder_the_same_command_recorded(
    lab: Path, recorded: Path, machines: TwinMachines
) -> None:
    """A run stopped by a CMM that did not answer left serial.log (the file acquire
    resumes from): ``acquire --resume`` must not take that folder for its own."""
    folder = lab / "new"
    args = record(
        "run", lab / "plan.yaml", folder, "--temperature-port", machines.thermocouples_url,
        controller=machines.controller_url,
    )  # fmt: skip
    first = CliRunner().invoke(main, args)
    assert first.exit_code == 1, first.output
    assert (folder / "serial.log").is_file()
    before = checksums(lab)
    resumed = CliRunner().invoke(main, record("acquire", lab / "plan.yaml", folder, "--resume"))
    assert resumed.exit_code == 1, resumed.output
    assert "--resume continues a folder hexatherm acquire recorded" in resumed.output
    assert "written by hexatherm run" in resumed.output
    assert checksums(lab) == before


# ---------------------------------------------------------------- nested and linked outputs
# Issue 22, item 2: ``process --overwrite`` deleted outputs nested in results/ and
# replaced a simulated session that results/ was a link to.


def process(*args: object) -> Result:
    return CliRunner().invoke(main, ["process", *[str(a) for a in args]])


def test_process_overwrite_never_deletes_an_output_nested_in_its_results(lab: Path) -> None:
    s = lab / "s"
    assert process(s).exit_code == 0
    smooth = process(s, "-o", s / "results" / "smooth", "--interpolation", "smooth")
    assert smooth.exit_code == 0, smooth.output
    before = checksums(lab)
    refused = process(s, "--overwrite")
    assert refused.exit_code == 1, refused.output
    assert "smooth/ (another output, not listed by this folder's manifest)" in refused.output
    assert checksums(lab) == before
    # an older results folder moved inside the new one
    (s / "results" / "smooth").rename(lab / "smooth")
    (s / "results").rename(s / "old")
    assert process(s).exit_code == 0
    (s / "old").rename(s / "results" / "old")
    before = checksums(lab)
    refused = process(s, "--overwrite")
    assert refused.exit_code == 1 and "old/ (another output" in refused.output, refused.output
    assert checksums(lab) == before
    # moved away, the results are hexatherm's alone and replaced
    (s / "results" / "old").rename(lab / "old")
    kept = checksums(lab / "old")
    replaced = process(s, "--overwrite")
    assert replaced.exit_code == 0, replaced.output
    assert checksums(lab / "old") == kept
    assert (s / "results" / "poses.csv").read_bytes() == (lab / "old" / "poses.csv").read_bytes()


def test_process_overwrite_never_replaces_a_simulated_session_results_links_to(lab: Path) -> None:
    sim = lab / "sim"
    made = CliRunner().invoke(main, ["simulate", str(lab / "scenario.yaml"), "-o", str(sim)])
    assert made.exit_code == 0, made.output
    assert read_manifest(sim) is not None and (sim / "session.yaml").is_file()
    s = lab / "s"
    (s / "results").symlink_to(sim, target_is_directory=True)
    before, session = checksums(lab), checksums(sim)
    for args in ([s, "--overwrite"], [s, "-o", sim, "--overwrite"]):
        refused = process(*args)
        assert refused.exit_code == 1, refused.output
        assert "session.yaml (a session)" in refused.output, refused.output
        assert checksums(lab) == before and checksums(sim) == session
    assert (s / "results").is_symlink()
    # simulate itself still replaces its own session
    again = CliRunner().invoke(
        main, ["simulate", str(lab / "scenario.yaml"), "-o", str(sim), "--overwrite"]
    )
    assert again.exit_code == 0, again.output
    assert checksums(sim).keys() == session.keys()


def test_overwrite_never_replaces_what_a_recording_command_recorded(
    lab: Path, recorded: Path, machines: TwinMachines
) -> None:
    """A run's folder lists its files in its manifest: that makes them the run's, not an
    output --overwrite may replace (a whole folder, or one of its logs)."""
    folder = lab / "new"
    live = {"controller": machines.controller_url}
    first = CliRunner().invoke(main, record("run", lab / "plan.yaml", folder, **live))
    assert first.exit_code == 1 and "Connection refused" in first.output, first.output
    before = checksums(lab)
    simulate = ["simulate", lab / "scenario.yaml", "-o", folder, "--overwrite"]
    refused = CliRunner().invoke(main, [str(a) for a in simulate])
    assert refused.exit_code == 1 and "(recorded by hexatherm run)" in refused.output
    fit = ["fit-spheres", lab / "d" / "points.dmo", "-o", folder / "steps.csv", "--overwrite"]
    refused = CliRunner().invoke(main, [str(a) for a in fit])
    assert refused.exit_code == 1, refused.output
    assert "steps.csv (recorded by hexatherm run)" in refused.output
    assert checksums(lab) == before
    # an output written beside the recording is the output's: replaced by --overwrite,
    # and something a new recording did not create
    beside = ["fit-spheres", lab / "d" / "points.dmo", "-o", folder / "centres.csv"]
    assert CliRunner().invoke(main, [str(a) for a in beside]).exit_code == 0
    manifest = read_manifest(folder)
    assert manifest is not None and manifest.recorder == "run" and "centres.csv" in manifest.files
    assert "centres.csv" not in manifest.recorded and "steps.csv" in manifest.recorded
    replaced = CliRunner().invoke(main, [str(a) for a in [*beside, "--overwrite"]])
    assert replaced.exit_code == 0, replaced.output
    before = checksums(lab)
    again = CliRunner().invoke(main, record("run", lab / "plan.yaml", folder, **live))
    assert again.exit_code == 1, again.output
    assert "centres.csv (written by hexatherm as an output, not recorded by run)" in again.output
    assert checksums(lab) == before
