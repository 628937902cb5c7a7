"""poses.csv as a spreadsheet reads it: deviation columns in um/urad beside their u."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
from click.testing import CliRunner

from hexatherm.cli import main

ROOT = Path(__file__).resolve().parents[2]
AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


def test_deviation_columns_are_pose_minus_commanded_in_um_and_urad(tmp_path: Path) -> None:
    session = tmp_path / "s"
    shutil.copytree(
        ROOT / "sessions" / "paper-zero-pose", session, ignore=shutil.ignore_patterns("results")
    )
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(tmp_path / "out" / "poses.csv")
    for tag in ("conv", "corr"):
        for axis in AXES:
            unit, scale = ("um", 1e3) if axis[0] == "T" else ("urad", np.pi / 180 * 1e6)
            src = "mm" if unit == "um" else "deg"
            dev = (poses[f"{axis}_{tag}_{src}"] - poses[f"{axis}_cmd_{src}"]) * scale
            np.testing.assert_allclose(poses[f"d{axis}_{tag}_{unit}"], dev, atol=1e-6, rtol=0)
            u = poses[f"u_{axis}_{tag}_{src}"] * scale
            np.testing.assert_allclose(poses[f"u_d{axis}_{tag}_{unit}"], u, atol=1e-9, rtol=1e-12)
