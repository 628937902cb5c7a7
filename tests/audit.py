"""Helpers of the hostile-input audit tests: inputs' digests, session copies, refusals."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

from click.testing import Result

from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[1]


def hashes(*folders: Path) -> dict[str, str]:
    """SHA-256 of every file under ``folders`` (but links): to show no input was touched."""
    return {
        str(p): hashlib.sha256(p.read_bytes()).hexdigest()
        for folder in folders
        for p in sorted(folder.rglob("*"))
        if p.is_file() and not p.is_symlink()
    }


def session_copy(tmp_path: Path, name: str = "paper-zero-pose") -> Path:
    """A copy of the shipped session ``name`` in ``tmp_path`` (without its expected/)."""
    folder = tmp_path / name
    shutil.copytree(SHIPPED / name, folder, ignore=shutil.ignore_patterns("expected"))
    return folder


def refusal(result: Result) -> str:
    """The one line of a refusal: exit status 1, no traceback, click's ``Error:`` line."""
    assert isinstance(result.exception, SystemExit), result.exception
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.startswith("Error: ")]
    assert len(lines) == 1, result.output
    return lines[0]
