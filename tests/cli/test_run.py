"""``hexatherm run`` from the command line, against the twin's machines on accelerated time."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.planning import build_plan
from hexatherm.io.config import plan_to_yaml, read_balls, read_hexapod
from hexatherm.workflows.serve import AcceleratedClock, TwinMachines, TwinWorld
from tests.sessions import ROOT
from tests.workflows.test_run import HEATING, NOMINAL_ORIGIN, TRUE_ORIGIN, twin_machines

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


@pytest.fixture
def machines():
    clock = AcceleratedClock(100.0)
    world = TwinWorld(
        read_hexapod(HEXAPOD),
        read_balls(BALLS),
        heating=HEATING,
        origin_on_cmm=TRUE_ORIGIN,
        clock=clock,
        sleep=clock.sleep,
        cmm_move_s=0.1,
    )
    with twin_machines(world) as m:
        yield m


def write_plan(tmp_path: Path, targets: list[list[float]]) -> Path:
    plan = build_plan(targets, (0.0, 0.0, -40.0, 0.0, 0.0, 0.0), points_per_ball=6)
    path = tmp_path / "plan.yaml"
    path.write_text(plan_to_yaml(plan))
    return path


def invoke(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def base(plan: Path, m: TwinMachines, session: Path) -> list[object]:
    return [
        "run", plan, "--cmm", m.cmm_url, "--controller", m.controller_url,
        "--session", session, "--hexapod", HEXAPOD, "--balls", BALLS,
        "--origin-on-cmm", ",".join(str(v) for v in NOMINAL_ORIGIN),
        "--settle", "0.02", "--poll", "0.01", "--readback-tol-um", "2", "--no-fsync",
    ]  # fmt: skip


def test_run_then_process(tmp_path: Path, machines: TwinMachines) -> None:
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    session = tmp_path / "s"
    result = invoke(
        *base(plan, machines, session), "--temperature-port", machines.thermocouples_url
    )
    assert result.exit_code == 0, result.output
    # the thermocouples logged as the run went, attached to the session
    temperatures = pd.read_csv(session / "temperatures.csv")
    assert list(temperatures.columns) == ["time"] + [f"leg{k}" for k in range(1, 7)] + ["ch7"]
    assert len(temperatures) >= 2 and (temperatures["ch7"] == 20.0).all()
    assert "temperatures: temperatures.csv" in (session / "session.yaml").read_text()
    table = [line for line in result.stdout.splitlines() if line]
    assert table[0].startswith("label,ball,n,x,y,z") and len(table) >= 1 + 12
    assert "72 points in" in result.stderr and "session.yaml" in result.stderr
    processed = invoke("process", session)
    assert processed.exit_code == 0, processed.output
    poses = pd.read_csv(session / "results" / "poses.csv")
    assert list(poses["label"]) == ["S1"]
    # again into the same folder: refused, a resume is what continues a run
    again = invoke(*base(plan, machines, session))
    assert again.exit_code == 1 and "--resume" in again.output


def test_dry_run_names_the_step_out_of_the_stroke(tmp_path: Path, machines: TwinMachines) -> None:
    plan = write_plan(tmp_path, [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 60.0, 0.0, 0.0, 0.0]])
    result = invoke(*base(plan, machines, tmp_path / "s"), "--dry-run")
    assert result.exit_code == 1
    assert "step S2: pose [0, 0, 60, 0, 0, 0]" in result.output
    assert "Nothing was moved" in result.output
    assert machines.world.model.moves == 0 and machines.cmm.touches == 0
    ok = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    good = invoke(*base(ok, machines, tmp_path / "t"), "--dry-run")
    assert good.exit_code == 0, good.output
    assert "4 steps can be measured; nothing moved" in good.stderr


def test_dry_run_keeps_its_transcript_where_asked(tmp_path: Path, machines: TwinMachines) -> None:
    """issue 23: a dry run kept no transcript. It goes to --dry-run-transcript FILE (the
    session folder stays untouched), whether the tool check passes or not."""
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    kept = tmp_path / "dry.transcript"
    good = invoke(*base(plan, machines, tmp_path / "s"), "--dry-run", "--dry-run-transcript", kept)
    assert good.exit_code == 0, good.output
    text = kept.read_text()
    sent = [line for line in text.splitlines() if "StartSession()" in line]
    assert sent and "EndSession()" in text and "EnumTools()" in text
    assert f"wrote {kept} ({len(text.splitlines())} lines)" in good.stderr
    assert not (tmp_path / "s").exists() and machines.world.model.moves == 0
    # a refused tool: the transcript shows what the CMM answered
    bad = invoke(
        *base(plan, machines, tmp_path / "s"), "--dry-run", "--tool", "Probe9",
        "--dry-run-transcript", kept, "--overwrite",
    )  # fmt: skip
    assert bad.exit_code == 1, bad.output
    assert "Probe9" in bad.output and "wrote" in bad.stderr
    assert kept.read_text() != text and '\\"Probe1\\"' in kept.read_text()  # EnumTools' answer
    # never without --dry-run, never inside the session folder, never over a foreign file
    alone = invoke(*base(plan, machines, tmp_path / "s"), "--dry-run-transcript", kept)
    assert alone.exit_code == 2 and "go with --dry-run" in alone.output
    inside = invoke(
        *base(plan, machines, tmp_path / "s"), "--dry-run",
        "--dry-run-transcript", tmp_path / "s" / "t.txt",
    )  # fmt: skip
    assert inside.exit_code == 2 and not (tmp_path / "s").exists()
    foreign = tmp_path / "notes.txt"
    foreign.write_text("mine\n")
    refused = invoke(
        *base(plan, machines, tmp_path / "s"), "--dry-run", "--dry-run-transcript", foreign,
        "--overwrite",
    )  # fmt: skip
    assert refused.exit_code == 1 and foreign.read_text() == "mine\n"


def test_usage_errors(tmp_path: Path, machines: TwinMachines) -> None:
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    args = base(plan, machines, tmp_path / "s")
    cut = args.index("--origin-on-cmm")
    result = invoke(*args[:cut], *args[cut + 2 :])
    assert result.exit_code == 2 and "--origin-on-cmm is needed" in result.output
    result = invoke(*args, "--origin-on-cmm", "1,2,3")
    assert result.exit_code == 2 and "expected 6 finite numbers" in result.output
    result = invoke("run", plan, "--cmm", "ipp://127.0.0.1:1", "--controller", "x://h",
                    "--session", tmp_path / "r", "--resume")  # fmt: skip
    assert result.exit_code != 0


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--settle", "nan", "'nan' is not a number"),
        ("--poll", "inf", "must be finite"),
        ("--readback-tol-um", "nan", "'nan' is not a number"),
        ("--radius-tol-um", "-1", "must be >= 0"),
        ("--form-tol-um", "1e400", "must be finite"),
        ("--rms-tol-um", "nan", "'nan' is not a number"),
        ("--centre-tol-mm", "NaN", "'NaN' is not a number"),
        ("--max-gap", "nan", "'nan' is not a number"),
        ("--max-gap", "-5", "must be >= 0"),
        ("--cap-angle", "nan", "'nan' is not a number"),
        ("--cap-angle", "91", "must be <= 90"),
        ("--approach", "inf", "must be finite"),
        ("--clearance", "0", "must be >= 0.01"),
        ("--travel", "1e9", "must be <= 2000"),
        ("--in-position-timeout", "nan", "'nan' is not a number"),
        ("--ipp-timeout", "-inf", "must be finite"),
        ("--readings", "0", "not in the range"),
        ("--reconnects", "99999999999", "not in the range"),
        ("--temperature-baud", "0", "not in the range"),
        ("--origin-on-cmm", "nan,0,0,0,0,0", "expected 6 finite numbers"),
        ("--origin-on-cmm", "1e300,0,0,0,0,0", "is no machine's"),
        ("--cmm-limits", "0,0,0,inf,1,1", "expected 6 finite numbers"),
        ("--cmm-limits", "0,0,0,-1,1,1", "lower corner"),
    ],
)
def test_hostile_values_are_one_line_usage_errors(
    tmp_path: Path, option: str, value: str, message: str
) -> None:
    """NaN, infinities and absurd numbers never reach the machines nor give a traceback."""
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    args = [
        "run", plan, "--cmm", "ipp://127.0.0.1:1", "--controller", "symetrie://127.0.0.1:1",
        "--session", tmp_path / "s", "--hexapod", HEXAPOD, "--balls", BALLS,
        "--origin-on-cmm", ",".join(str(v) for v in NOMINAL_ORIGIN),
    ]  # fmt: skip
    result = invoke(*args, option, value)
    assert result.exit_code == 2, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert message in result.output and option in result.output
    assert not (tmp_path / "s").exists()
