"""Accuracy benchmark of the thermal correction on simulated sessions (a script, not a test).

Run with ``.venv/bin/python bench/accuracy.py``. For seeded sessions of the
Symetrie-like hexapod (12 target poses over the workspace, 25 points per ball
probed on a 70 deg cap, 2 s per point, 20 s per move) it prints, against the
truth in the thermal state of the first reference R0, the RMS over targets and
seeds of the translation error |dT| (um) and of the rotation error |dR| (urad)
of:

(a) the conventional pose T(O, S) as measured;
(b) the paper's correction with one neighbouring reference, the one before
    (``process --interpolation before``);
(c) ours: the references on both sides interpolated linearly in time
    (``process``, the default).

Scenarios:

- heating ``slow``: mats on at 5 min, first-order response tau = 60 min
  (plateaus 3..9 K above a 20 degC air drifting +0.2 K/h);
  ``fast``: tau = 10 min, mats on at 5 min and off at 40 min (a sharp rise,
  then cooling);
- CMM point noise sigma 0, 0.5, 1, 2 um (each point along its normal; centres
  are the CMM's free-radius sphere fits), thermocouple noise 0.02 K, hexapod
  repeatability 0.1 um per leg when the CMM is noisy;
- references ``both`` sides (R S R S R ...: each target between two references)
  or ``one`` side (R S S R S S R ...: each target next to one reference only;
  there (b) and (c) are the same correction).

Noise-free cells use one seed, the others ``N_SEEDS``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hexatherm.core.heating import Mat, MatHeating
from hexatherm.core.plan import Plan
from hexatherm.core.planning import sequence_steps
from hexatherm.io.config import read_balls
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.simulate.twinsession import TwinSessionSpec, simulate_session, write_files

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]
TARGETS = [
    [-16.441, -11.846, 9.263, 1.662, -1.785, 6.634],
    [10.042, 15.125, 7.019, 2.909, -0.093, -0.724],
    [-9.376, -10.594, 4.134, 3.198, -0.97, 4.166],
    [14.19, 0.358, -7.771, -3.801, -1.999, -5.772],
    [7.169, 12.081, -13.004, -3.432, -2.497, -2.464],
    [17.538, -7.691, -5.247, 3.762, 0.591, 1.979],
    [-19.599, -19.981, 6.797, -2.927, 0.376, -3.041],
    [-6.128, 18.284, 8.103, -1.555, -3.168, -7.992],
    [19.362, 3.583, 0.985, 0.421, -2.743, 0.083],
    [-11.323, -13.137, 14.879, 1.907, -3.614, 5.761],
    [-2.599, -15.928, -1.476, 2.373, 3.451, -6.797],
    [-8.301, -0.051, -3.44, -1.9, -3.337, 3.035],
]
GAINS_C = (3.0, 7.0, 2.0, 3.0, 9.0, 3.5)
HEATING = {
    "slow": MatHeating(
        tuple(Mat(g, 3600.0, ((300.0, np.inf),)) for g in GAINS_C), (0.0, 36000.0), (20.0, 22.0)
    ),
    "fast": MatHeating(
        tuple(Mat(g, 600.0, ((300.0, 2400.0),)) for g in GAINS_C), (0.0, 36000.0), (20.0, 22.0)
    ),
}
NOISE_UM = (0.0, 0.5, 1.0, 2.0)
LAYOUTS = {"both": "both", "one": "alternate"}
N_SEEDS = 8
URAD_PER_DEG = np.pi / 180 * 1e6


def run(heating: str, layout: str, noise_um: float, seed: int, work: Path) -> np.ndarray:
    """Squared errors (targets, 3 methods, 2: |dT|^2 um^2, |dR|^2 urad^2) of one session."""
    plan = Plan.from_steps(
        sequence_steps(TARGETS, REFERENCE, reference_every=LAYOUTS[layout]),
        reference_pose=REFERENCE,
    )
    noisy = noise_um > 0
    spec = TwinSessionSpec(
        name="bench",
        hexapod_text=(ROOT / "configs" / "symetrie-like.yaml").read_text(),
        balls=read_balls(ROOT / "configs" / "balls-3.yaml"),
        plan=plan,
        heating=HEATING[heating],
        seconds_per_ball=25 * 2.0,
        seconds_per_move=20.0,
        thermocouple_noise_C=0.02 if noisy else 0.0,
        seed=seed,
        output="centres",
        points_per_ball=25,
        cap_half_angle_deg=70.0,
        point_noise_mm=noise_um * 1e-3,
        repeatability_mm=1e-4 if noisy else 0.0,
        fit_centres=True,
    )
    simulated = simulate_session(spec)
    folder = work / f"{heating}-{layout}-{noise_um}-{seed}"
    write_files(simulated.files, folder)
    truth = simulated.truth.corrected_pose[plan.target_indices]
    paper = process_session(folder, interpolation="before").correction
    ours = process_session(folder, interpolation="linear").correction
    out = np.empty((len(truth), 3, 2))
    for k, poses in enumerate((ours.conventional, paper.corrected, ours.corrected)):
        err = poses - truth
        out[:, k, 0] = (np.linalg.norm(err[:, :3], axis=1) * 1e3) ** 2
        out[:, k, 1] = (np.linalg.norm(err[:, 3:], axis=1) * URAD_PER_DEG) ** 2
    return out


def main() -> None:
    start = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for heating in HEATING:
            for layout in LAYOUTS:
                for noise in NOISE_UM:
                    seeds = range(N_SEEDS) if noise > 0 else range(1)
                    squares = np.concatenate(
                        [run(heating, layout, noise, s, Path(tmp)) for s in seeds]
                    )
                    rows.append((heating, layout, noise, np.sqrt(squares.mean(axis=0))))
                    print(".", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    print(
        "| heating | references | point noise (um) | (a) conventional um / urad "
        "| (b) paper, one R um / urad | (c) ours, interpolated um / urad |"
    )
    print("|---|---|---:|---:|---:|---:|")
    for heating, layout, noise, rms in rows:
        cells = " | ".join(f"{rms[k, 0]:.2f} / {rms[k, 1]:.1f}" for k in range(3))
        print(f"| {heating} | {layout} | {noise:g} | {cells} |")
    print(f"\n{len(rows)} cells, {time.perf_counter() - start:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
