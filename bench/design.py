"""Pose selection for a calibration, measured at the design stage (issue 24, item 6).

Run with ``.venv/bin/python bench/design.py [--seeds N] [--candidates M] [--poses N]``.
For each seed, M candidate poses are drawn uniformly in the box +-20/+-20/+-15 mm,
+-4/+-4/+-8 deg of the Symetrie-like hexapod (as ``plan --random M --box ...`` would);
N of them are chosen by each design criterion of ``plan --calibration N
--calibration-criterion``, and the linear prediction (1 um, 5 urad per measured pose,
level ``joints``) of a calibrated pose's standard uncertainty is evaluated over all M
candidates (the stroke the user asked for): its worst value and its root mean square,
for Tx, Ty, Tz (um). Against: N poses drawn at random from the same candidates (the
median of 20 draws) and all M candidates measured (M/N times the poses). It prints a
row per seed and criterion, then the mean gains over random.

These are design-stage predictions: they say how much better the chosen poses identify
the geometry, not what a campaign's held-out error will be (``bench/calibration.py``
measures that, with thermal drift and noise).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hexatherm.core.calibration import predicted_sigma, select_poses  # noqa: E402
from hexatherm.io.config import read_hexapod  # noqa: E402

SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])
CRITERIA = ("d-optimal", "g-optimal", "i-optimal")
RANDOM_DRAWS = 20


def figures(sigma: np.ndarray) -> tuple[float, float]:
    """Worst and RMS standard uncertainty of Tx, Ty, Tz (um) over the evaluation poses."""
    t = sigma[:, :3]
    return float(t.max()), float(np.sqrt(np.mean(t**2)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--candidates", type=int, default=200)
    parser.add_argument("--poses", type=int, default=30)
    args = parser.parse_args()
    compare_designs(args.seeds, args.candidates, args.poses)


def compare_designs(seeds: int, m: int, n: int) -> None:
    """Print the table and the mean gains (see the module text): ``seeds`` seeds, ``m``
    candidates, ``n`` chosen (also ``bench/calibration.py --sections design``)."""
    nominal = read_hexapod(ROOT / "configs" / "symetrie-like.yaml")
    print(f"{m} candidates, {n} chosen, level joints, 1 um / 5 urad per pose; um, Tx/Ty/Tz")
    print("| seed | design | worst | RMS | random worst / worst | random RMS / RMS |")
    print("|---:|---|---:|---:|---:|---:|")
    gains: dict[str, list[tuple[float, float]]] = {c: [] for c in CRITERIA}
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        candidates = rng.uniform(-1, 1, (m, 6)) * SPAN
        draws = np.array(
            [
                figures(
                    predicted_sigma(
                        nominal, candidates[rng.choice(m, n, replace=False)], candidates
                    )
                )
                for _ in range(RANDOM_DRAWS)
            ]
        )
        random_worst, random_rms = np.median(draws, axis=0)
        print(
            f"| {seed} | random (median of {RANDOM_DRAWS}) | {random_worst:.3f} | "
            f"{random_rms:.3f} | 1 | 1 |"
        )
        for criterion in CRITERIA:
            chosen = select_poses(nominal, candidates, n, criterion=criterion)
            worst, rms = chosen.worst_sigma_um, chosen.mean_sigma_um
            gains[criterion].append((random_worst / worst, random_rms / rms))
            print(
                f"| {seed} | {criterion} | {worst:.3f} | {rms:.3f} | "
                f"{random_worst / worst:.2f} | {random_rms / rms:.2f} |"
            )
        worst, rms = figures(predicted_sigma(nominal, candidates, candidates))
        print(
            f"| {seed} | all {m} measured | {worst:.3f} | {rms:.3f} | "
            f"{random_worst / worst:.2f} | {random_rms / rms:.2f} |"
        )
    print()
    print("mean gain over random N (worst, RMS), range over seeds:")
    for criterion, values in gains.items():
        g = np.array(values)
        print(
            f"  {criterion:9}: worst {g[:, 0].mean():.2f}x ({g[:, 0].min():.2f}-"
            f"{g[:, 0].max():.2f}), RMS {g[:, 1].mean():.2f}x ({g[:, 1].min():.2f}-"
            f"{g[:, 1].max():.2f})"
        )


if __name__ == "__main__":
    main()
