"""Commands given a FIFO or a device where a file belongs: one line, exit 1, no hang.

The issue's cases: FIFOs hung ``fit-spheres``, ``inspect``, ``register``,
``plan --targets`` and ``session.yaml`` itself; ``/dev/zero`` ran until the kernel
killed the process. Each command runs in a thread joined with a timeout.
"""

from __future__ import annotations

import os
import shutil
import threading
from pathlib import Path

import pytest

from tests.shipped import SHIPPED
from tests.waiting import SAFETY_S

ROOT = Path(__file__).resolve().parents[2]
TIMEOUT_S = SAFETY_S  # a safety net against a hang, never what decides a pass


def run(*args: str | Path):
    from click.testing import CliRunner

    from hexatherm.cli import main

    outcome = {}

    def invoke() -> None:
        outcome["result"] = CliRunner().invoke(main, [str(a) for a in args])

    thread = threading.Thread(target=invoke, daemon=True)
    thread.start()
    thread.join(TIMEOUT_S)
    assert not thread.is_alive(), f"hexatherm {args[0]} did not return (blocked on a FIFO?)"
    return outcome["result"]


def fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


@pytest.mark.parametrize(
    "command",
    [
        "inspect",
        "fit-spheres",
        "fit-spheres-dev-zero",
        "register",
        "register-datums",
        "plan",
        "process-session-yaml",
    ],
)
def test_commands_refuse_fifos_and_devices(tmp_path: Path, command: str) -> None:
    config = ROOT / "configs"
    if command == "inspect":
        bad = fifo(tmp_path / "run.dmo")
        args = ["inspect", bad]
    elif command == "fit-spheres":
        bad = fifo(tmp_path / "points.csv")
        args = ["fit-spheres", bad, "-o", tmp_path / "out.csv"]
    elif command == "fit-spheres-dev-zero":
        bad = Path("/dev/zero")
        args = ["fit-spheres", bad, "-o", tmp_path / "out.csv"]
    elif command == "register":
        bad = fifo(tmp_path / "datums.csv")
        datums = SHIPPED / "register-datums" / "datums.yaml"
        args = ["register", bad, "--datums", datums, "-o", tmp_path / "balls.yaml"]
    elif command == "register-datums":
        bad = fifo(tmp_path / "datums.yaml")
        points = SHIPPED / "register-datums" / "points.csv"
        args = ["register", points, "--datums", bad, "-o", tmp_path / "balls.yaml"]
    elif command == "plan":
        bad = fifo(tmp_path / "targets.csv")
        args = [
            "plan",
            "--hexapod",
            config / "symetrie-like.yaml",
            "--balls",
            config / "balls-3.yaml",
            "--targets",
            bad,
            "-o",
            tmp_path / "plan.yaml",
        ]
    else:
        session = tmp_path / "s"
        shutil.copytree(
            SHIPPED / "paper-zero-pose",
            session,
            ignore=shutil.ignore_patterns("expected", "results"),
        )
        (session / "session.yaml").unlink()
        bad = fifo(session / "session.yaml")
        args = ["process", session]
    before = sorted(p.name for p in tmp_path.iterdir())
    result = run(*args)
    assert result.exit_code == 1, result.output
    kind = "character device" if command.endswith("dev-zero") else "named pipe (FIFO)"
    assert f"{bad}: is a {kind}, expected a regular file" in result.output, result.output
    assert "Traceback" not in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
