"""CSV files with ``;`` separators and decimal commas (a European spreadsheet's export)
read as their ``,`` twins, where targets, points, centres and temperatures are read
(issue 16, item 3)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.csvfile import read_measurement_csv
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def european(text: str) -> str:
    """What a spreadsheet set to a European locale exports for ``text``."""
    return text.replace(",", ";").replace(".", ",")


def test_points_and_centres_read_alike(tmp_path: Path) -> None:
    comma = SHIPPED / "paper-zero-pose" / "centres.csv"
    semi = tmp_path / "centres.csv"
    semi.write_text(european(comma.read_text()))
    a, b = read_measurement_csv(comma), read_measurement_csv(semi)
    np.testing.assert_array_equal(a.xyz_mm, b.xyz_mm)
    np.testing.assert_array_equal(a.time_s, b.time_s)
    assert list(a.label) == list(b.label) and list(a.ball) == list(b.ball)


def test_a_semicolon_session_gives_the_same_poses(tmp_path: Path) -> None:
    session = tmp_path / "s"
    shutil.copytree(SHIPPED / "paper-zero-pose", session)
    for name in ("centres.csv", "temperatures.csv"):
        (session / name).write_text(european((session / name).read_text()))
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    expected = pd.read_csv(SHIPPED / "paper-zero-pose" / "expected" / "poses.csv")
    got = pd.read_csv(tmp_path / "out" / "poses.csv")
    for column in ("Tx_corr_mm", "Ty_corr_mm", "Rz_corr_deg", "Tz_conv_mm"):
        np.testing.assert_allclose(got[column], expected[column], rtol=0, atol=1e-9)


def test_targets_with_semicolons_and_a_bad_line_named(tmp_path: Path) -> None:
    configs = ROOT / "configs"
    args = ["plan", "--hexapod", str(configs / "symetrie-like.yaml")]
    args += ["--balls", str(configs / "balls-3.yaml"), "--targets"]
    comma, semi = tmp_path / "c.csv", tmp_path / "s.csv"
    comma.write_text("# two targets\nTx,Ty,Tz,Rx,Ry,Rz\n1.5,0,0,0,0,0.25\n-1,0,2,0,0,0\n")
    semi.write_text(european(comma.read_text()))
    a = CliRunner().invoke(main, [*args, str(comma)])
    b = CliRunner().invoke(main, [*args, str(semi)])
    assert a.exit_code == b.exit_code == 0, b.output
    assert a.stdout == b.stdout and "pose: [1.5, 0, 0, 0, 0, 0.25]" in b.stdout
    semi.write_text(semi.read_text() + "1;0;0;0;0\n")
    bad = CliRunner().invoke(main, [*args, str(semi)])
    assert bad.exit_code == 1 and f"{semi}:5:" in bad.output
