"""A recorded calibration campaign is replayed through calibrate too: a changed
parameter in ``expected/calibration/`` is a mismatch naming the file."""

from __future__ import annotations

import shutil
from pathlib import Path

from hexatherm.workflows.replay import replay_session

ROOT = Path(__file__).resolve().parents[2]


def test_the_recorded_calibration_replays_and_a_changed_parameter_is_found(tmp_path: Path) -> None:
    session = tmp_path / "calibration-geometry"
    shutil.copytree(ROOT / "sessions" / "calibration-geometry", session)
    clean = replay_session(session)
    assert clean.ok, clean.mismatches
    assert "calibration/parameters.csv" in clean.files
    path = session / "expected" / "calibration" / "parameters.csv"
    lines = path.read_text().splitlines(keepends=True)
    fields = lines[1].split(",")
    fields[3] = repr(float(fields[3]) + 1e-4)  # base1_x_mm calibrated 0.1 um off
    lines[1] = ",".join(fields)
    path.write_text("".join(lines))
    changed = replay_session(session)
    assert not changed.ok
    assert any("calibration/parameters.csv" in m for m in changed.mismatches), changed.mismatches
