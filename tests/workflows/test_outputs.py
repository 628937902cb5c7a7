"""poses.csv as a spreadsheet reads it: deviation columns in um/urad beside their u."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.csvout import RESOLUTION
from hexatherm.workflows.process import outputs
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


def test_a_long_campaign_s_screen_table_shows_its_ends_and_names_the_file_holding_all(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # issue 37: 10,000 targets made 20,000 screen lines; beyond SCREEN_TARGETS the screen
    # shows the first and last SCREEN_ENDS targets, the lines of the whole table, and says
    # where every target is. Here the bound is lowered to the paper session's 10 targets.
    monkeypatch.setattr(outputs, "SCREEN_TARGETS", 4)
    monkeypatch.setattr(outputs, "SCREEN_ENDS", 2)
    session = SHIPPED / "paper-zero-pose"
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    screen = result.stdout.splitlines()
    processed = process_session(session)
    whole = outputs.deviation_table(processed, None, pose_uncertainty(processed)).splitlines()
    assert len(whole) == 3 + 2 * 10 + 1  # heads, a value and a U line per target, spread
    poses = pd.read_csv(tmp_path / "out" / "poses.csv")
    assert len(poses) == 10  # the file holds every target
    note = (
        "... 6 more targets: every target's deviations (dTx_conv_um ...) and standard "
        f"uncertainties (u_dTx_conv_um ...) are in {tmp_path / 'out' / 'poses.csv'}"
    )
    assert screen[: 3 + 4 + 1 + 4 + 1] == [*whole[:7], note, *whole[-5:]]
    assert [line.split()[0] for line in screen[3:7:2] + screen[8:12:2]] == [
        poses["label"][i] for i in (0, 1, 8, 9)
    ]
    # the spread is over every target, as the file's columns give it
    spread = [float(v) for v in screen[12].replace("|", " ").split()[1:]]
    want = [
        np.ptp(poses[f"d{axis}_{tag}_{'um' if axis[0] == 'T' else 'urad'}"])
        for tag in ("conv", "corr")
        for axis in AXES
    ]
    np.testing.assert_allclose(spread, want, atol=2e-3)


def test_a_campaign_within_the_bound_shows_every_target() -> None:
    processed = process_session(SHIPPED / "paper-zero-pose")
    u = pose_uncertainty(processed)
    given = outputs.deviation_table(processed, None, u, 2.0, "poses.csv")
    assert given == outputs.deviation_table(processed, None, u)
    assert "more targets" not in given
