"""Rebuild ``sessions/paper-zero-pose`` from the hexapod twin.

The paper's experiment (Kalas et al., section 4): 10 trials of the zero pose,
reference pose R = [0, 0, -40, 0, 0, 0], legs heated by mats so that legs 2 and 5
run hotter than 3 and 4 (and leg 5 hotter than leg 3), ~1 um CMM noise on the
ball centres. Run from the repository root:

    python sessions/make_paper_zero_pose.py [--overwrite]
"""

from __future__ import annotations

import sys
from pathlib import Path

from hexatherm.core.plan import Plan
from hexatherm.io.config import read_balls
from hexatherm.workflows.simulate.twinsession import Heating, TwinSessionSpec, write_twin_session

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]

README = """# paper-zero-pose

The experiment of Kalas et al., "Thermal deflection decoupled 6-DOF pose measurement of
hexapods", section 4, reproduced on the hexapod twin: the zero pose is measured in 10
trials while heating mats warm the legs, each trial with the reference pose
R = [0, 0, -40, 0, 0, 0] measured right before and after it.

- Hexapod: `configs/symetrie-like.yaml` (aluminium body 160 mm + steel screw).
- Balls: `configs/balls-3.yaml`, centres measured with 0.5 um (1 sigma, per axis; ~0.9 um
  in 3D) noise, what 25 points of a +-2 um MPE CMM give.
- Steps: O, R0, then S1, R1, ..., S10, R10; 3 balls x 60 s per step, 20 s moves.
- Heating: mats on at t = 5 min, first-order response (tau 40 min); plateaus above the
  20 degC air (drifting +0.1 K/h): legs 1..6 = 3.0, 7.0, 2.0, 3.0, 9.0, 3.5 K.
  Thermocouples logged every 30 s with 0.02 K noise (`temperatures.csv`, with `air`).
- `truth/steps.csv`: the twin's true poses (at measurement time and in the thermal state
  of R0), leg temperatures and growths; `hexatherm process` never reads it.
- `expected/`: the output of `hexatherm process` (used by the replay tests).

Made by `python sessions/make_paper_zero_pose.py --overwrite` (seed 2020).
What it shows: the conventional Tx, Tz and Rx drift by micrometres / microradians
from trial to trial as the legs warm; the corrected poses stay within the CMM noise.
"""


def main(overwrite: bool) -> None:
    steps = [("O", "origin", [0.0] * 6), ("R0", "reference", REFERENCE)]
    for i in range(1, 11):
        steps += [(f"S{i}", "target", [0.0] * 6), (f"R{i}", "reference", REFERENCE)]
    spec = TwinSessionSpec(
        name="paper-zero-pose",
        hexapod_text=(ROOT / "configs" / "symetrie-like.yaml").read_text(),
        balls=read_balls(ROOT / "configs" / "balls-3.yaml"),
        plan=Plan.from_steps(steps, reference_pose=REFERENCE),
        heating=Heating(
            air_C=20.0,
            air_drift_C_per_h=0.1,
            on_s=300.0,
            tau_s=2400.0,
            gain_C=(3.0, 7.0, 2.0, 3.0, 9.0, 3.5),
        ),
        thermocouple_noise_C=0.02,
        centre_noise_mm=0.5e-3,
        seed=2020,
        readme=README,
    )
    write_twin_session(spec, ROOT / "sessions" / "paper-zero-pose", overwrite=overwrite)


if __name__ == "__main__":
    main("--overwrite" in sys.argv[1:])
