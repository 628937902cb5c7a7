"""``run`` against a hostile CMM and a hostile session folder (issue 22, item 9).

- A CMM that answers ``X(1e308)`` (or any coordinate no CMM reaches) is refused in one
  line naming the command and the answer; nothing is fitted from it.
- Messages print numbers plainly (``842.001``), never numpy's ``np.float64(842.001)``.
- ``run --resume`` reads ``run.yaml`` and ``steps.csv`` through the strict readers: a FIFO,
  a link to ``/dev/zero``, deep nesting and NaN are one line and a non-zero exit, never a
  hang, a memory blow-up or a traceback.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.devices.sim.ipp import Fault
from hexatherm.devices.sim.ipp.server import IppSimServer
from hexatherm.workflows.replay import replay_session
from hexatherm.workflows.serve import TwinMachines
from tests.cli.test_run import base, machines, write_plan  # noqa: F401  (the fixture)
from tests.shipped import SHIPPED

TARGET = [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]]


def _answer(server: IppSimServer, method: str, nth: int, value: str) -> None:
    """From the ``nth`` ``method`` on, the server answers ``X(value)`` in its data line."""
    original = getattr(server, f"_do_{method}")
    count = [0]

    def patched(session, call):  # type: ignore[no-untyped-def]
        lines = original(session, call)
        count[0] += 1
        if count[0] >= nth:
            lines = [re.sub(r"X\([^)]*\)", f"X({value})", lines[0], count=1)]
        return lines

    setattr(server, f"_do_{method}", patched)


def _one_line_error(result) -> str:  # type: ignore[no-untyped-def]
    assert result.exit_code == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output and "np.float64" not in result.output
    errors = [line for line in result.stderr.splitlines() if line.lower().startswith("error")]
    assert len(errors) == 1, result.stderr
    return errors[0]


@pytest.mark.parametrize("value", ["1e308", "-2.5e+05"])
def test_an_absurd_ptmeas_answer_is_one_line_naming_it(
    tmp_path: Path,
    machines: TwinMachines,  # noqa: F811
    value: str,
) -> None:
    _answer(machines.cmm, "PtMeas", 3, value)
    session = tmp_path / "s"
    result = CliRunner().invoke(
        main, [str(a) for a in base(write_plan(tmp_path, TARGET), machines, session)]
    )
    line = _one_line_error(result)
    shown = repr(float(value))
    assert re.search(rf"the CMM answered PtMeas \d+ with X\({re.escape(shown)}\), Y\(", line), line
    assert "not a finite coordinate within 100000 mm" in line and "--resume" in line
    assert "STOP" in machines.controller.received
    # nothing of that ball was kept: the ball is probed again on --resume
    assert (session / "points.csv").read_text().count("\n") == 1


def test_an_absurd_position_is_one_line_naming_the_get(
    tmp_path: Path,
    machines: TwinMachines,  # noqa: F811
) -> None:
    _answer(machines.cmm, "Get", 1, "1e308")
    result = CliRunner().invoke(
        main, [str(a) for a in base(write_plan(tmp_path, TARGET), machines, tmp_path / "s")]
    )
    line = _one_line_error(result)
    assert "the CMM answered Get(X(), Y(), Z()) with X(1e+308), Y(" in line, line
    assert not any(c.startswith("GoTo(X(1e") for c in machines.cmm.commands)


def test_replay_mismatches_print_plain_numbers(tmp_path: Path) -> None:
    recorded = tmp_path / "serial-capture"
    shutil.copytree(SHIPPED / "serial-capture", recorded)
    poses = pd.read_csv(recorded / "expected" / "poses.csv")
    poses.loc[0, "Tz_corr_mm"] = 842.001
    poses.to_csv(recorded / "expected" / "poses.csv", index=False)
    result = replay_session(recorded)
    text = "\n".join(result.mismatches)
    assert "expected 842.001, got " in text, text
    assert "np.float64" not in text


# ------------------------------------------------------------- resume's readers
@pytest.fixture
def stopped(tmp_path: Path, machines: TwinMachines):  # noqa: F811
    """A run stopped after its first ball (the CMM drops the connection at the 7th PtMeas)."""
    machines.cmm._faults.append(Fault("drop", 7, "PtMeas", after_lines=1))
    plan = write_plan(tmp_path, TARGET)
    session = tmp_path / "s"
    args = [str(a) for a in base(plan, machines, session)]
    first = CliRunner().invoke(main, [*args, "--reconnects", "0"])
    assert first.exit_code == 1 and "--resume" in first.output, first.output
    assert (session / "run.yaml").is_file() and (session / "steps.csv").is_file()
    return [*args, "--resume"], session


def _hostile(path: Path, kind: str) -> str:
    """Make ``path`` hostile; the words the refusal must say."""
    path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
        if path.name == ".run.lock":  # opened for writing: no reader, refused at once
            return "cannot lock"
        return "named pipe (FIFO), expected a regular file"
    if kind == "dev-zero":
        path.symlink_to("/dev/zero")
        return "expected a regular file"
    if kind == "deep":
        path.write_text("format: hexatherm-run/1\norigin_on_cmm: " + "[" * 5000 + "]" * 5000 + "\n")
        return "nested deeper than"
    assert kind == "nan"
    path.write_text(
        "format: hexatherm-run/1\norigin_on_cmm: [450, 320, .nan, 0, 0, 15]\n"
        "probe: {tool: Probe1, cap_angle_deg: 70, approach_mm: 2, clearance_mm: 5, travel_mm: 30}\n"
    )
    return "field 'origin_on_cmm[2]': expected a finite number"


@pytest.mark.parametrize(
    ("name", "kind"),
    [
        ("run.yaml", "fifo"),
        ("run.yaml", "dev-zero"),
        ("run.yaml", "deep"),
        ("run.yaml", "nan"),
        ("steps.csv", "fifo"),
        ("steps.csv", "dev-zero"),
        ("controller.log", "fifo"),
        ("points.csv", "fifo"),
        (".run.lock", "fifo"),
    ],
)
def test_resume_refuses_a_hostile_session_file_in_one_line(stopped, name: str, kind: str) -> None:
    args, session = stopped
    said = _hostile(session / name, kind)
    result = CliRunner().invoke(main, args)  # a FIFO opened for reading would block here
    line = _one_line_error(result)
    assert str(session / name) in line and said in line, line


def test_resume_refuses_a_step_the_plan_does_not_know(stopped) -> None:
    args, session = stopped
    with open(session / "steps.csv", "a") as handle:
        handle.write("S9" + ",0" * 10 + "\n")
    line = _one_line_error(CliRunner().invoke(main, args))
    assert f"{session / 'steps.csv'}:3: field 'label': step 'S9' is not in the plan" in line


def test_a_bad_fixed_radius_is_said_plainly() -> None:
    import numpy as np

    from hexatherm.core.spherefit import fit_spheres
    from hexatherm.errors import FitError

    with pytest.raises(FitError) as caught:
        fit_spheres(np.eye(3)[[0, 1, 2, 0, 1, 2]] * 5.0, radius_mm=np.array([-842.001]))
    assert str(caught.value).endswith("got -842.001") and "np.float64" not in str(caught.value)
