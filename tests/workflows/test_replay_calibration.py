"""A recorded calibration campaign is replayed through calibrate too: a changed
parameter in ``expected/calibration/`` is a mismatch naming the file."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd

from hexatherm.workflows.replay import replay_session
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def test_the_recorded_calibration_replays_and_a_changed_parameter_is_found(tmp_path: Path) -> None:
    session = tmp_path / "calibration-geometry"
    shutil.copytree(SHIPPED / "calibration-geometry", session)
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


def test_a_parameter_one_step_off_in_its_rows_unit_replays_and_three_do_not() -> None:
    """parameters.csv writes each value at its row's unit's resolution (mm: 1e-7); a value
    on a rounding boundary flips by a step on another CPU (31.2721083 against
    31.2721084 on an AMD EPYC): 1.5 steps pass, as for the columns with a unit."""
    from hexatherm.workflows.replay import DEFAULT_TOLERANCES, Comparison, compare_tables

    expected = pd.DataFrame(
        {
            "name": ["base4_y_mm", "leg1_gain"],
            "unit": ["mm", "mm/mm"],
            "calibrated": [31.2721083, 1.0000000001],
            "max_abs_correlation": [0.8208, 0.5],
        }
    )
    for shift, gain, corr, ok in (
        (1e-7, 1e-10, 1e-4, True),
        (3e-7, 0.0, 0.0, False),
        (0.0, 3e-10, 0.0, False),
        (0.0, 0.0, 3e-4, False),
    ):
        got = expected.copy()
        got["calibrated"] += [shift, gain]
        got["max_abs_correlation"] += corr
        result = Comparison("s")
        compare_tables("parameters.csv", expected, got, DEFAULT_TOLERANCES, result)
        assert result.ok is ok, (shift, gain, corr, result.mismatches)
