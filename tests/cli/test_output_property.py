"""A property of every command that writes: whatever the sequence of commands and
``-o`` targets, with or without ``--overwrite``, no input file is ever modified or
removed (issue 12, acceptance).

The tree is a lab's folder (two recorded sessions, the register sample, a scenario);
the commands are the ones that write (``process``, ``fit-spheres``, ``register``,
``plan``, ``simulate``; ``report`` and ``diagnose`` write through the same guard and
are covered case by case in ``test_output_guard.py``); the targets are the inputs
themselves, their folders, the lab, ``.`` and new paths. Later commands may read
what earlier ones wrote, and may try to write onto it.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.cli import main
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """format: hexatherm-scenario/1
hexapod: s/hexapod.yaml
balls: s/balls.yaml
plan: {targets: [[0.5, 0, 0, 0, 0, 0]], reference_pose: [0, 0, 0, 0, 0, 0], cycles: 1}
seed: 3
"""

COMMANDS = {
    "process": ["process", "s"],
    "fit-spheres": ["fit-spheres", "d/points.dmo"],
    "register": ["register", "r/points.csv", "--datums", "r/datums.yaml"],
    "plan": [
        "plan",
        "--hexapod",
        "s/hexapod.yaml",
        "--balls",
        "s/balls.yaml",
        "--grid",
        "2",
        "--box",
        "Tx=-1:1",
    ],
    "simulate": ["simulate", "scenario.yaml"],
}
TARGETS = [
    ".",
    "s",
    "s/results",
    "s/centres.csv",
    "s/hexapod.yaml",
    "s/expected",
    "d",
    "d/points.dmo",
    "r/datums.yaml",
    "new",
    "new/out.csv",
    "new/sub",
    "out.yaml",
]
OPERATIONS = st.lists(
    st.tuples(st.sampled_from(sorted(COMMANDS)), st.sampled_from(TARGETS), st.booleans()),
    min_size=1,
    max_size=4,
)


def files_of(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    lab = tmp_path_factory.mktemp("lab")
    for name, to in [
        ("paper-zero-pose", "s"),
        ("paper-zero-pose-dmis", "d"),
        ("register-datums", "r"),
    ]:
        shutil.copytree(SHIPPED / name, lab / to, ignore=shutil.ignore_patterns("results"))
    (lab / "scenario.yaml").write_text(SCENARIO)
    return lab


@settings(
    max_examples=15,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(OPERATIONS)
def test_no_sequence_of_commands_ever_modifies_or_removes_an_input(
    template: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, operations
) -> None:
    lab = tmp_path / f"lab{len(list(tmp_path.iterdir()))}"
    shutil.copytree(template, lab)
    monkeypatch.chdir(lab)
    originals = files_of(lab)
    for command, target, overwrite in operations:
        args = [*COMMANDS[command], "-o", target, *(["--overwrite"] if overwrite else [])]
        result = CliRunner().invoke(main, args)
        assert result.exit_code in (0, 1, 2), (args, result.output)
        assert "Traceback" not in result.output, (args, result.output)
        if result.exit_code == 1:  # refused: one line
            assert result.output.strip().count("\n") == 0, (args, result.output)
        elif result.exit_code == 2:  # click's usage error: its usage lines, then one line
            assert result.output.strip().splitlines()[-1].startswith("Error: "), result.output
        now = {name: data for name, data in files_of(lab).items() if name in originals}
        assert now == originals, (args, sorted(set(originals) - set(now)))
    os.chdir(tmp_path)
    shutil.rmtree(lab)
