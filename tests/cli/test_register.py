"""``hexatherm register`` on twin data: ball positions recovered from a datum measurement."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.geometry import apply_transform, transform_from_pose
from hexatherm.core.twin import probe_points
from hexatherm.io.config import read_balls
from tests.sessions import BALLS

BORE1, BORE2 = np.array([-60.0, -60.0, 0.0]), np.array([60.0, -60.0, 0.0])
DATUMS = """format: hexatherm-datums/1
plane: TOP
bores: [BORE1, BORE2]
origin_offset: [60.0, 60.0, 0.0]
balls: {B1: 25.4, B2: 25.4, B3: 25.4}
probe: {compensated: COMP, tip_diameter: 2.0}
"""


def datum_measurement(platform2cmm, compensated=True, noise_mm=0.0, seed=3):
    """Points (platform frame geometry -> CMM frame) of the top face, two bores and the balls."""
    rng = np.random.default_rng(seed)
    tip = 0.0 if compensated else 1.0
    gx, gy = np.meshgrid(np.linspace(-100, 100, 6), np.linspace(-100, 100, 6))
    face = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, tip)])
    face = face[np.linalg.norm(face[:, :2] - BORE1[:2], axis=1) > 10]
    ang = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    rows = [("TOP", face)]
    for name, centre in (("BORE1", BORE1), ("BORE2", BORE2)):
        ring = np.column_stack([(4.0 - tip) * np.cos(ang), (4.0 - tip) * np.sin(ang), np.zeros(8)])
        wall = np.vstack([ring + centre + [0, 0, -2.0], ring + centre + [0, 0, -5.0]])
        rows.append((name, wall))
    cmm_rows = [(n, apply_transform(platform2cmm, p)) for n, p in rows]
    centres = apply_transform(platform2cmm, BALLS.centres_mm)
    points, _ = probe_points(centres, 12.7 + tip, 25, 75.0, noise_mm, rng)
    cmm_rows += [(name, points[i]) for i, name in enumerate(BALLS.names)]
    frames = [
        pd.DataFrame(
            {"label": "REG", "ball": n, "x": p[:, 0], "y": p[:, 1], "z": p[:, 2], "time": 0.0}
        )
        for n, p in cmm_rows
    ]
    return pd.concat(frames, ignore_index=True)


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.mark.parametrize("compensated", [True, False])
def test_register_recovers_ball_positions(tmp_path, compensated):
    platform2cmm = transform_from_pose([410.0, 290.0, 150.0, 1.5, -2.0, 33.0])
    datum_measurement(platform2cmm, compensated).to_csv(tmp_path / "datums.csv", index=False)
    (tmp_path / "datums.yaml").write_text(DATUMS.replace("COMP", str(compensated).lower()))
    result = run(
        "register",
        tmp_path / "datums.csv",
        "--datums",
        tmp_path / "datums.yaml",
        "-o",
        tmp_path / "balls.yaml",
    )
    assert result.exit_code == 0, result.output
    balls = read_balls(tmp_path / "balls.yaml")
    assert balls.names == BALLS.names and balls.probe_compensated == compensated
    np.testing.assert_allclose(balls.centres_mm, BALLS.centres_mm, atol=1e-6)


def test_register_with_noise_is_close(tmp_path):
    platform2cmm = transform_from_pose([10.0, 20.0, 30.0, 0.0, 0.0, -70.0])
    datum_measurement(platform2cmm, noise_mm=1e-3).to_csv(tmp_path / "d.csv", index=False)
    (tmp_path / "datums.yaml").write_text(DATUMS.replace("COMP", "true"))
    assert (
        run(
            "register",
            tmp_path / "d.csv",
            "--datums",
            tmp_path / "datums.yaml",
            "-o",
            tmp_path / "balls.yaml",
            "--fixed-diameter",
        ).exit_code
        == 0
    )
    balls = read_balls(tmp_path / "balls.yaml")
    assert np.abs(balls.centres_mm - BALLS.centres_mm).max() < 0.01


def test_register_errors(tmp_path):
    platform2cmm = transform_from_pose([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    frame = datum_measurement(platform2cmm)
    frame[frame.ball != "BORE2"].to_csv(tmp_path / "d.csv", index=False)
    (tmp_path / "datums.yaml").write_text(DATUMS.replace("COMP", "true"))
    result = run(
        "register",
        tmp_path / "d.csv",
        "--datums",
        tmp_path / "datums.yaml",
        "-o",
        tmp_path / "balls.yaml",
    )
    assert result.exit_code == 1 and "no points of feature 'BORE2'" in result.output
    assert not (tmp_path / "balls.yaml").exists()
    (tmp_path / "datums.yaml").write_text(DATUMS.replace("COMP", "maybe"))
    result = run(
        "register",
        tmp_path / "d.csv",
        "--datums",
        tmp_path / "datums.yaml",
        "-o",
        tmp_path / "balls.yaml",
    )
    assert result.exit_code == 1 and "datums.yaml:6: field 'probe.compensated'" in result.output
