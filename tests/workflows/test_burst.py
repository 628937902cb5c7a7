"""A session whose points all arrived in one burst (one arrival time) still processes.

Issue 12, item 16: points are stamped with the time their bytes arrived; when a loaded
machine reads a whole stream in one go, every step gets the same time and the linear
interpolation between references is 0/0. The plan's order still puts each target between
its references: each weighs 1/2, and process says why.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.workflows.process.pipeline import process_session
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def test_a_burst_session_processes_with_equal_weights_and_says_so(tmp_path: Path) -> None:
    session = tmp_path / "burst"
    shutil.copytree(SHIPPED / "serial-capture", session)
    points = pd.read_csv(session / "points.csv")
    points["time"] = points["time"].iloc[0]
    points.to_csv(session / "points.csv", index=False)
    result = process_session(session)
    corr = result.correction
    both = (corr.before_index >= 0) & (corr.after_index >= 0)
    assert both.any()
    np.testing.assert_array_equal(corr.weight_after[both], 0.5)
    assert any("same time" in w and "1/2" in w for w in result.warnings)
    # the same session with its real times: the weights follow the times
    timed = process_session(SHIPPED / "serial-capture")
    assert not any("same time" in w for w in timed.warnings)
