"""The garbage collector while a command starts (``hexatherm.cli.collector``): paused
while the command imports numpy, pandas and hexatherm, resumed (what was imported frozen)
once it has, and as the caller had it after the command line returns."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from hexatherm.cli import COMMANDS
from tests.shipped import SHIPPED

PACKAGE = Path(__file__).resolve().parents[2] / "hexatherm"

#: runs ``process`` in a fresh interpreter and prints, for every collection after numpy was
#: imported (numpy is imported by the command only), whether the imports were done (the
#: frozen objects) and the collector's state at the end
SCRIPT = """
import gc, sys
seen = []
def note(phase, info):
    if phase == "start" and "numpy" in sys.modules:
        seen.append(gc.get_freeze_count() > 0)
gc.callbacks.append(note)
{before}
from hexatherm.cli import main
try:
    main(["process", {session!r}, "-o", {out!r}])
except SystemExit as stop:
    assert not stop.code, stop.code
print(seen.count(False), seen.count(True), gc.isenabled())
"""


def _collections(tmp_path: Path, before: str = "") -> tuple[int, int, bool]:
    code = SCRIPT.format(
        before=before, session=str(SHIPPED / "paper-zero-pose"), out=str(tmp_path / "out")
    )
    words = subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True
    ).stdout.split()[-3:]
    return int(words[0]), int(words[1]), words[2] == "True"


def test_no_collection_while_a_command_imports(tmp_path: Path) -> None:
    """process: no collection runs between numpy's import and the end of the command's
    imports; collections run after them (the objects frozen); the collector is on after."""
    during, after, enabled = _collections(tmp_path)
    assert during == 0
    assert after > 0
    assert enabled


def test_a_caller_that_keeps_the_collector_off_keeps_it_off(tmp_path: Path) -> None:
    during, after, enabled = _collections(tmp_path, before="gc.disable()")
    assert (during, after, enabled) == (0, 0, False)


def test_every_command_resumes_the_collector() -> None:
    """Every command's function calls ``imports_done`` (a command that did not would run
    with the collector paused: ``run`` and ``serve-twin`` for hours)."""
    missing = []
    for name, (module, _) in COMMANDS.items():
        path = PACKAGE / Path(*module.split(".")[1:]).with_suffix(".py")
        tree = ast.parse(path.read_text(encoding="utf-8"))
        command = next(
            node
            for node in ast.walk(tree)
            if isinstance(node, ast.FunctionDef) and node.name == "command"
        )
        calls = {
            node.func.id
            for node in ast.walk(command)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        }
        if "imports_done" not in calls:
            missing.append(name)
    assert missing == []
