"""poses.csv as a spreadsheet reads it: deviation columns in um/urad beside their u."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.csvout import RESOLUTION
from hexatherm.workflows.process.outputs import poses_frame
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import pose_uncertainty
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
URAD_PER_DEG = np.pi / 180 * 1e6


def test_deviation_columns_are_pose_minus_commanded_in_um_and_urad() -> None:
    # in memory, where the point is the arithmetic: to 1e-6 um and urad (issue 16)
    result = process_session(SHIPPED / "paper-zero-pose")
    poses = poses_frame(result, pose_uncertainty(result))
    for tag in ("conv", "corr"):
        for axis in AXES:
            unit, scale = ("um", 1e3) if axis[0] == "T" else ("urad", URAD_PER_DEG)
            src = "mm" if unit == "um" else "deg"
            dev = (poses[f"{axis}_{tag}_{src}"] - poses[f"{axis}_cmd_{src}"]) * scale
            np.testing.assert_allclose(poses[f"d{axis}_{tag}_{unit}"], dev, atol=1e-6, rtol=0)
            u = poses[f"u_{axis}_{tag}_{src}"] * scale
            np.testing.assert_allclose(poses[f"u_d{axis}_{tag}_{unit}"], u, atol=1e-9, rtol=1e-12)


def test_written_deviations_agree_with_written_poses_within_the_resolution(
    tmp_path: Path,
) -> None:
    # from the file, every number rounded to its resolution: a deviation and the two
    # poses it comes from are each within half a step of their exact values
    session = tmp_path / "s"
    shutil.copytree(SHIPPED / "paper-zero-pose", session, ignore=shutil.ignore_patterns("results"))
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(tmp_path / "out" / "poses.csv")
    for tag in ("conv", "corr"):
        for axis in AXES:
            unit, scale = ("um", 1e3) if axis[0] == "T" else ("urad", URAD_PER_DEG)
            src = "mm" if unit == "um" else "deg"
            dev = (poses[f"{axis}_{tag}_{src}"] - poses[f"{axis}_cmd_{src}"]) * scale
            bound = RESOLUTION[unit] / 2 + 2 * scale * RESOLUTION[src] / 2 + 1e-9
            np.testing.assert_allclose(poses[f"d{axis}_{tag}_{unit}"], dev, atol=bound, rtol=0)
            u = poses[f"u_{axis}_{tag}_{src}"] * scale
            bound = RESOLUTION[unit] / 2 + scale * RESOLUTION[src] / 2 + 1e-9
            np.testing.assert_allclose(poses[f"u_d{axis}_{tag}_{unit}"], u, atol=bound, rtol=0)
