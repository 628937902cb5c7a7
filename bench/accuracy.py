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

``bench/accuracy.py floor`` (issue 14, part 2) measures instead the error of the
corrected pose over the **noise floor measured in the same run**: the error of a pose
with noise on the target step alone (the chain of the session evaluated on the true
centres, the target steps' centres replaced by the measured ones). 60 targets (12
poses, 5 cycles) between references (a campaign of about 5.7 h), point noise 1 um,
``N_SEEDS`` seeds. Heating:

- ``smooth``: tau = 60 min, mats on an hour before the session starts;
- ``on-off``: tau = 10 min, on at 1500 s and off at 5400 s (two kinks);
- ``step``: tau = 20 s, on at 5000 s (the growth jumps between two references).

With repeats the corrected poses refer to the mean thermal state of R0's measurements
(and O's): the twin's truth refers to the first R0, and O's and R0's drift during the
repeats largely cancel (O is averaged over the same minutes).

It prints RMS error / floor of |dT| and |dR| for the linear default, ``--interpolation
smooth``, and smooth with O and R0 measured ``REPEATS`` times (``plan --origin-repeats
--reference0-repeats``), and how often the smooth fit was kept.
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


# ----------------------------------------------------------------- error / floor
FLOOR_HEATING = {
    "smooth": MatHeating(tuple(Mat(g, 3600.0, ((-3600.0, np.inf),)) for g in GAINS_C)),
    "on-off": MatHeating(tuple(Mat(g, 600.0, ((1500.0, 5400.0),)) for g in GAINS_C)),
    "step": MatHeating(tuple(Mat(g, 20.0, ((5000.0, np.inf),)) for g in GAINS_C)),
}
REPEATS = 4
FLOOR_NOISE_UM = 1.0
FLOOR_CYCLES = 5


def floor_run(heating: str, repeats: int, interpolation: str, seed: int, work: Path):
    """Squared errors of the corrected poses and of the floor (targets, 2: |dT|^2 um^2,
    |dR|^2 urad^2) of one session, and whether the smooth fit was kept."""
    from hexatherm.workflows.process.uncertainty import pose_chain

    plan = Plan.from_steps(
        sequence_steps(
            TARGETS,
            REFERENCE,
            cycles=FLOOR_CYCLES,
            origin_repeats=repeats,
            reference0_repeats=repeats,
        ),
        reference_pose=REFERENCE,
    )
    spec = TwinSessionSpec(
        name="floor",
        hexapod_text=(ROOT / "configs" / "symetrie-like.yaml").read_text(),
        balls=read_balls(ROOT / "configs" / "balls-3.yaml"),
        plan=plan,
        heating=FLOOR_HEATING[heating],
        seconds_per_ball=25 * 2.0,
        seconds_per_move=20.0,
        seed=seed,
        output="centres",
        points_per_ball=25,
        cap_half_angle_deg=70.0,
        point_noise_mm=FLOOR_NOISE_UM * 1e-3,
        fit_centres=True,
    )
    simulated = simulate_session(spec)
    folder = work / f"floor-{heating}-{repeats}-{interpolation}-{seed}"
    write_files(simulated.files, folder)
    result = process_session(folder, interpolation=interpolation)  # type: ignore[arg-type]
    targets = plan.target_indices[repeats - 1 :]  # the repeats of O are not targets
    truth = simulated.truth.corrected_pose[targets]
    # the floor: the chain of the session on the true centres, only the targets' measured
    kept = np.array([plan.labels.index(label) for label in result.session.plan.labels])
    clean = simulated.truth.centres_cmm_mm[kept]
    mixed = clean.copy()
    reduced_targets = result.session.plan.target_indices
    mixed[reduced_targets] = result.centres.centres_mm[reduced_targets]
    chain = pose_chain(result)
    floor = chain(mixed)[:, 6:] - chain(clean)[:, 6:]
    out = np.empty((2, len(truth), 2))
    for k, err in enumerate((result.correction.corrected - truth, floor)):
        out[k, :, 0] = (np.linalg.norm(err[:, :3], axis=1) * 1e3) ** 2
        out[k, :, 1] = (np.linalg.norm(err[:, 3:], axis=1) * URAD_PER_DEG) ** 2
    smooth = result.correction.smooth
    return out, bool(smooth is not None and smooth.used)


def floor_table() -> None:
    """Print error / floor for linear, smooth and smooth + repeats, per heating."""
    start = time.perf_counter()
    methods = (
        ("linear", 1, "linear"),
        ("smooth", 1, "smooth"),
        ("smooth + repeats", REPEATS, "smooth"),
    )
    print(
        "| heating | method | error / floor, translation | error / floor, rotation "
        "| error um / urad | floor um / urad | smooth kept |"
    )
    print("|---|---|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for heating in FLOOR_HEATING:
            for name, repeats, interpolation in methods:
                runs = [
                    floor_run(heating, repeats, interpolation, seed, Path(tmp))
                    for seed in range(N_SEEDS)
                ]
                squares = np.concatenate([r for r, _ in runs], axis=1)  # (2, targets, 2)
                rms = np.sqrt(squares.mean(axis=1))  # (2: error, floor; 2: T, R)
                ratio = rms[0] / rms[1]
                kept = f"{sum(u for _, u in runs)}/{len(runs)}" if interpolation == "smooth" else ""
                print(
                    f"| {heating} | {name} | {ratio[0]:.2f} | {ratio[1]:.2f} "
                    f"| {rms[0, 0]:.2f} / {rms[0, 1]:.1f} | {rms[1, 0]:.2f} / {rms[1, 1]:.1f} "
                    f"| {kept} |",
                    flush=True,
                )
    print(
        f"\n{N_SEEDS} seeds x {len(TARGETS) * FLOOR_CYCLES} targets per cell, point noise "
        f"{FLOOR_NOISE_UM:g} um, "
        f"repeats {REPEATS}; {time.perf_counter() - start:.0f} s",
        file=sys.stderr,
    )


def main() -> None:
    if sys.argv[1:] == ["floor"]:
        floor_table()
        return
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
