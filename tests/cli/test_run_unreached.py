"""``hexatherm run`` with nothing listening: one message saying what happened, no folder.

The ports are bound and not listening (connections are refused at once, on any machine);
no wall-clock wait is involved.
"""

from __future__ import annotations

import errno
import os
import socket
from collections.abc import Iterator
from pathlib import Path

import pytest

from hexatherm.workflows.serve import TwinMachines
from tests.cli.test_run import BALLS, HEXAPOD, NOMINAL_ORIGIN, invoke, machines, write_plan

__all__ = ["machines"]


@pytest.fixture
def closed_ports() -> Iterator[tuple[int, int]]:
    """Two local ports nothing listens on (bound, so nothing else takes them meanwhile)."""
    a, b = socket.socket(), socket.socket()
    try:
        a.bind(("127.0.0.1", 0))
        b.bind(("127.0.0.1", 0))
        yield a.getsockname()[1], b.getsockname()[1]
    finally:
        a.close()
        b.close()


def args(plan: Path, cmm: str, controller: str, session: Path) -> list[object]:
    return [
        "run", plan, "--cmm", cmm, "--controller", controller, "--session", session,
        "--hexapod", HEXAPOD, "--balls", BALLS,
        "--origin-on-cmm", ",".join(str(v) for v in NOMINAL_ORIGIN), "--no-fsync",
    ]  # fmt: skip


def test_nothing_listening_says_so_once_and_leaves_no_folder(
    tmp_path: Path, closed_ports: tuple[int, int]
) -> None:
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    cmm_port, controller_port = closed_ports
    url = f"symetrie://127.0.0.1:{controller_port}"
    new = tmp_path / "nights" / "NEW"  # its parent does not exist either
    result = invoke(*args(plan, f"ipp://127.0.0.1:{cmm_port}", url, new))
    assert result.exit_code == 1
    why = f"[Errno {errno.ECONNREFUSED}] {os.strerror(errno.ECONNREFUSED)}"
    refused = f"cannot connect to the Symetrie API v2 controller at {url}: {why}"
    assert result.output == (
        f"Error: run stopped before any machine answered: {refused}. Nothing was moved (the "
        f"controller at {url} was not reached); nothing was recorded ({new} was not created)\n"
    )
    assert not new.exists() and not new.parent.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.yaml"]


def test_an_empty_folder_given_is_left_as_it_was(
    tmp_path: Path, closed_ports: tuple[int, int]
) -> None:
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    cmm_port, controller_port = closed_ports
    empty = tmp_path / "empty"
    empty.mkdir()
    result = invoke(
        *args(plan, f"ipp://127.0.0.1:{cmm_port}", f"pi://127.0.0.1:{controller_port}", empty)
    )
    assert result.exit_code == 1
    assert result.output.count("\n") == 1 and "STOP" not in result.output
    assert result.output.endswith(f"nothing was recorded ({empty} left as it was)\n")
    assert empty.is_dir() and list(empty.iterdir()) == []


def test_a_controller_that_answered_keeps_the_session(
    tmp_path: Path,
    machines: TwinMachines,  # noqa: F811
    closed_ports: tuple[int, int],
) -> None:
    """The controller answered (its state is in run.yaml), the CMM did not: the folder is
    kept, and the one message says the hexapod was sent STOP."""
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    session = tmp_path / "s"
    cmm = f"ipp://127.0.0.1:{closed_ports[0]}"
    result = invoke(*args(plan, cmm, machines.controller_url, session))
    assert result.exit_code == 1
    assert result.output.startswith("Error: run stopped at step O (origin), ball B1: ")
    assert result.output.count("\n") == 1 and result.output.count("STOP") == 1
    assert (
        f". The hexapod was sent STOP; 0 points in {session}; continue with --resume\n"
        in result.output
    )
    assert "STOP" in machines.controller.received
    assert "controller:" in (session / "run.yaml").read_text()
