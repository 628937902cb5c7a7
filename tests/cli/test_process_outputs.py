"""process never writes into, around or onto a session's files (issue 12, item 1)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def sessions(tmp_path: Path) -> Path:
    shutil.copytree(
        SHIPPED / "paper-zero-pose",
        tmp_path / "s",
        ignore=shutil.ignore_patterns("results"),
    )
    shutil.copytree(
        SHIPPED / "with-hidden-effect",
        tmp_path / "s2",
        ignore=shutil.ignore_patterns("results"),
    )
    return tmp_path


@pytest.mark.parametrize("target", ["s", ".", "s/expected"])
def test_an_output_that_is_or_holds_or_sits_in_an_input_is_refused(
    sessions: Path, target: str
) -> None:
    before = snapshot(sessions)
    result = CliRunner().invoke(
        main, ["process", str(sessions / "s"), "-o", str(sessions / target), "--overwrite"]
    )
    assert result.exit_code == 1, result.output
    message = result.output.strip().splitlines()
    assert len(message) == 1 and "-o" in message[0]
    # expected/ is not read by process, but holds files hexatherm did not vouch for
    assert ("input" if target != "s/expected" else "expected") in message[0]
    assert snapshot(sessions) == before


def test_overwrite_replaces_only_what_hexatherm_wrote(sessions: Path) -> None:
    run = ["process", str(sessions / "s"), "--overwrite"]
    assert CliRunner().invoke(main, run).exit_code == 0
    assert CliRunner().invoke(main, run).exit_code == 0  # its own results: replaced
    note = sessions / "s" / "results" / "my-notes.txt"
    note.write_text("the lab's own notes\n")
    result = CliRunner().invoke(main, run)
    assert result.exit_code == 1 and "my-notes.txt" in result.output
    assert note.read_text() == "the lab's own notes\n"
