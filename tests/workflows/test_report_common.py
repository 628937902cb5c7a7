"""Figure 6's common part (issue 25, item 5): the band of +-k u_common of the corrected
poses, and the verdict saying it is shared by all targets; the truth is poses.csv's
u_common_* columns (expected/, which replay holds equal to process)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import pose_uncertainty
from hexatherm.workflows.report import pose_figure, verdict, verdict_items
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "paper-zero-pose"
UNITS = ("um",) * 3 + ("urad",) * 3
NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


@pytest.fixture(scope="module")
def processed():
    result = process_session(SESSION)
    return result, pose_uncertainty(result)


def test_figure_6_shows_the_common_part_as_a_band(processed):
    result, uncertainty = processed
    poses = pd.read_csv(SESSION / "expected" / "poses.csv")
    k = 3.0
    fig = pose_figure(result, uncertainty, k)
    for j, ax in enumerate(fig.axes[:6]):
        bands = [c for c in ax.collections if c.get_gid() == "common"]
        assert len(bands) == 1, j
        vertices = bands[0].get_paths()[0].vertices
        expected = k * poses[f"u_common_d{NAMES[j]}_corr_{UNITS[j]}"].to_numpy()
        trials = np.arange(1, len(poses) + 1)
        for t, e in zip(trials, expected, strict=True):
            ys = vertices[np.isclose(vertices[:, 0], t), 1]
            # half a step of the file's resolution, times k
            assert ys.max() == pytest.approx(e, abs=k * 1e-3) and ys.min() == pytest.approx(
                -e, abs=k * 1e-3
            )
    _, labels = fig.axes[0].get_legend_handles_labels()
    assert any("shared by all targets" in label for label in labels)


def test_the_verdict_says_the_common_part_is_shared(processed):
    result, uncertainty = processed
    poses = pd.read_csv(SESSION / "expected" / "poses.csv")
    items = dict(verdict_items(verdict(result, uncertainty, None, 2.0)))
    text = items["Shared by all targets"]
    assert "O and R0" in text and "cancels" in text
    for name, unit in zip(NAMES, UNITS, strict=True):
        shown = float(re.search(rf"{name} (-?[\d.]+) ", text).group(1))
        largest = 2.0 * poses[f"u_common_d{name}_corr_{unit}"].max()
        assert shown == pytest.approx(largest, abs=0.01), name
    # the typical session: the common part is most of Rx's and Ry's U
    assert float(re.search(r"Rx (-?[\d.]+) ", text).group(1)) > 10
