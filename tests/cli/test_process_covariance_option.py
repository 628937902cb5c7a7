"""covariance.csv grows as the square of the targets (120 MB for 1000): written by default
up to 200 targets, on request above, never computed when not written."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

import hexatherm.workflows.process.uncertainty as uncertainty
from hexatherm.cli import main
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "paper-zero-pose"


def test_covariance_is_written_by_default_and_left_out_when_asked(tmp_path: Path) -> None:
    default = CliRunner().invoke(main, ["process", str(SESSION), "-o", str(tmp_path / "a")])
    assert default.exit_code == 0 and (tmp_path / "a" / "covariance.csv").is_file()
    off = CliRunner().invoke(
        main, ["process", str(SESSION), "-o", str(tmp_path / "b"), "--no-covariance"]
    )
    assert off.exit_code == 0, off.output
    assert not (tmp_path / "b" / "covariance.csv").exists()
    assert "--covariance writes covariance.csv" in off.output
    assert (tmp_path / "b" / "poses.csv").read_text() == (tmp_path / "a" / "poses.csv").read_text()


def test_above_the_bound_it_is_not_computed_unless_asked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(uncertainty, "BETWEEN_MAX_TARGETS", 5)  # paper-zero-pose has 10
    big = CliRunner().invoke(main, ["process", str(SESSION), "-o", str(tmp_path / "a")])
    assert big.exit_code == 0 and not (tmp_path / "a" / "covariance.csv").exists()
    asked = CliRunner().invoke(
        main, ["process", str(SESSION), "-o", str(tmp_path / "b"), "--covariance"]
    )
    assert asked.exit_code == 0 and (tmp_path / "b" / "covariance.csv").is_file()
