"""Build ``sessions/register-datums``: a datum measurement for ``hexatherm register``.

A platform (top face 240 x 240 mm, two 8 mm bores at (-60, -60) and (60, -60) in the
datum frame, three 25.4 mm balls on stands) placed on the CMM at a known pose, probed as a
CMM would: 32 points on the top face, two rings of 8 points in each bore, 25 points on the
upper cap of each ball, 1 um of noise along every surface normal, the probe's radius
compensated, times 2 s apart. The balls' true positions in the platform frame go to
``truth/balls.yaml``; ``hexatherm register`` never reads it. Run from the repository root:

    python sessions/make_register_datums.py [--overwrite]
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.core.geometry import apply_transform, transform_from_pose
from hexatherm.core.touch import cap_directions
from hexatherm.io.config import balls_to_yaml
from hexatherm.io.records import seconds_to_iso
from hexatherm.session import Balls

ROOT = Path(__file__).resolve().parent.parent
FOLDER = ROOT / "sessions" / "register-datums"
SEED = 2026
NOISE_MM = 1e-3
#: where the platform sits on the CMM (platform2cmm as a pose), mm and deg
PLATFORM_ON_CMM = (412.5, 287.25, 151.0, 0.35, -0.2, 33.0)
#: the bores in the platform frame: the datum frame's origin is BORE1's centre on the
#: face, its X runs to BORE2, and ``origin_offset: [60, 60, 0]`` puts the platform origin
#: back at (0, 0): the platform frame of the balls file
BORES = {"BORE1": np.array([-60.0, -60.0]), "BORE2": np.array([60.0, -60.0])}
BORE_RADIUS_MM = 4.0
#: true balls in the platform frame (as configs/balls-3.yaml, with build tolerances)
TRUE_BALLS = Balls(
    ("B1", "B2", "B3"),
    np.array(
        [[0.0213, 90.0178, 30.0042], [-73.5979, -42.4861, 29.9957], [82.2851, -47.5122, 30.0109]]
    ),
    np.full(3, 25.4),
    True,
    2.0,
)
START = 1_781_000_000.0  # 2026-06-09T10:13:20Z

DATUMS = """format: hexatherm-datums/1
step: REG
plane: TOP
bores: [BORE1, BORE2]
origin_offset: [60.0, 60.0, 0.0]
balls: {B1: 25.4, B2: 25.4, B3: 25.4}
probe: {compensated: true, tip_diameter: 2.0}
"""

README = """# register-datums

A sample datum measurement for `hexatherm register`, the paper's ball-to-platform step:
one CMM measurement (label `REG`) of the platform's top face, its two bores and the three
balls, from which `register` writes the balls file (ball centres in the platform frame).

    hexatherm register sessions/register-datums/points.csv \\
        --datums sessions/register-datums/datums.yaml -o balls.yaml

- `points.csv`: 32 points on the top face (`TOP`), two rings of 8 points in each 8 mm bore
  (`BORE1`, `BORE2`), 25 points on the upper cap (70 deg) of each 25.4 mm ball (`B1`..`B3`),
  probe radius compensated, 1 um of noise along every surface normal, one point every 2 s.
- `datums.yaml`: which features are the plane and the bores, the platform origin in the datum
  frame (the first bore's centre moved by `origin_offset`), the balls' nominal diameters.
- `truth/balls.yaml`: the balls' true centres in the platform frame (build tolerances of
  10 to 20 um against `configs/balls-3.yaml`); `register` never reads it. With this noise,
  `register` recovers them within a few micrometres (`tests/workflows/test_register_sample.py`).
- Rebuilt by `python sessions/make_register_datums.py --overwrite` (seed 2026).
"""


def measurement() -> pd.DataFrame:
    """The datum measurement, one row per probed point (CMM frame, mm; ISO 8601 UTC)."""
    rng = np.random.default_rng(SEED)
    platform2cmm = transform_from_pose(PLATFORM_ON_CMM)
    rows: list[tuple[str, np.ndarray]] = []
    gx, gy = np.meshgrid(np.linspace(-105, 105, 6), np.linspace(-105, 105, 6))
    face = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    far = np.all([np.linalg.norm(face[:, :2] - b, axis=1) > 12 for b in BORES.values()], 0)
    face = face[far]
    face[:, 2] += rng.normal(scale=NOISE_MM, size=len(face))
    rows.append(("TOP", apply_transform(platform2cmm, face)))
    ang = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    radial = np.column_stack([np.cos(ang), np.sin(ang)])
    for name, centre in BORES.items():
        walls = []
        for depth in (-2.0, -5.0):
            r = BORE_RADIUS_MM + rng.normal(scale=NOISE_MM, size=8)
            walls.append(np.column_stack([centre + radial * r[:, None], np.full(8, depth)]))
        rows.append((name, apply_transform(platform2cmm, np.vstack(walls))))
    dirs = cap_directions(25, 70.0)  # the upper cap, around the CMM's +Z
    centres_cmm = apply_transform(platform2cmm, TRUE_BALLS.centres_mm)
    for name, centre in zip(TRUE_BALLS.names, centres_cmm, strict=True):
        r = 12.7 + rng.normal(scale=NOISE_MM, size=25)
        rows.append((name, centre + dirs * r[:, None]))
    frames, t = [], START
    for name, cmm in rows:
        times = t + 2.0 * np.arange(len(cmm))
        t = times[-1] + 20.0
        frames.append(
            pd.DataFrame(
                {
                    "label": "REG",
                    "ball": name,
                    "x": cmm[:, 0].round(6),
                    "y": cmm[:, 1].round(6),
                    "z": cmm[:, 2].round(6),
                    "time": [seconds_to_iso(s) for s in times],
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


def main() -> None:
    if FOLDER.exists():
        if "--overwrite" not in sys.argv[1:]:
            sys.exit(f"{FOLDER} exists; --overwrite to rebuild it")
        shutil.rmtree(FOLDER)
    (FOLDER / "truth").mkdir(parents=True)
    measurement().to_csv(FOLDER / "points.csv", index=False, lineterminator="\n")
    (FOLDER / "datums.yaml").write_text(DATUMS)
    (FOLDER / "truth" / "balls.yaml").write_text(balls_to_yaml(TRUE_BALLS))
    (FOLDER / "README.md").write_text(README)
    print(f"wrote {FOLDER}")


if __name__ == "__main__":
    main()
