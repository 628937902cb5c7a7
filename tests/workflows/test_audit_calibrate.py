"""Hostile-input audit of ``hexatherm calibrate`` (session 10): sessions that do not
belong together, options at their edges. Each test here failed on the code before its
fix. The sessions are copies of the shipped ``sessions/calibration-geometry`` (30
targets) and ``sessions/calibration-campaign`` (60), fitted at level ``offsets`` where
a fit is needed (cheap)."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main

ROOT = Path(__file__).resolve().parents[2]
GEOMETRY = ROOT / "sessions" / "calibration-geometry"
CAMPAIGN = ROOT / "sessions" / "calibration-campaign"


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def copy_session(session: Path, to: Path) -> Path:
    """A copy of a shipped session without its expected outputs."""
    shutil.copytree(session, to, ignore=shutil.ignore_patterns("expected"))
    return to


def digests(*folders: Path) -> dict[str, str]:
    return {
        str(p): hashlib.sha256(p.read_bytes()).hexdigest()
        for folder in folders
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def refused_in_one_line(result) -> str:
    """The one line of a refusal (exit 1, no traceback)."""
    assert result.exit_code == 1, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    assert "Traceback" not in result.output
    return lines[0]


# ------------------------------------------------------------------ one session twice
# The same measurements in a file whose bytes differ (a blank line added, CRLF line
# endings, rows in another order) passed the SHA-256 check: the poses were counted twice
# and chi2/dof fell from 1.03 to 0.92, every u shrinking by sqrt(2).


def blank_line(text: str) -> str:
    return text + "\n"


def crlf(text: str) -> str:
    return text.replace("\n", "\r\n")


def reordered(text: str) -> str:
    header, *rows = text.splitlines()
    return "\n".join([header, *reversed(rows)]) + "\n"


@pytest.mark.parametrize("edit", [blank_line, crlf, reordered], ids=lambda f: f.__name__)
def test_the_same_measurements_in_other_bytes_are_refused(tmp_path: Path, edit) -> None:
    a = copy_session(GEOMETRY, tmp_path / "a")
    again = copy_session(GEOMETRY, tmp_path / "again")
    centres = again / "centres.csv"
    centres.write_bytes(edit(centres.read_text()).encode())
    assert centres.read_bytes() != (a / "centres.csv").read_bytes()
    before = digests(a, again)
    line = refused_in_one_line(run("calibrate", a, again, "-o", tmp_path / "out"))
    assert line.startswith(f"Error: {again / 'session.yaml'}: field 'measurements': ")
    assert f"all 186 of its measured ball centres are those of {a / 'session.yaml'}" in line
    assert "give each session once" in line
    assert not (tmp_path / "out").exists()
    assert digests(a, again) == before


def test_two_sessions_that_share_only_their_hexapod_are_taken(tmp_path: Path) -> None:
    a = copy_session(GEOMETRY, tmp_path / "a")
    b = copy_session(CAMPAIGN, tmp_path / "b")
    done = run("calibrate", a, b, "-o", tmp_path / "out", "--level", "offsets")
    assert done.exit_code == 0, done.output
    assert "calibrated from 90 corrected poses of 2 session(s)" in done.output
