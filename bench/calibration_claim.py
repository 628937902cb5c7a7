"""What ``calibrate`` claims for a new pose, against the twin's truth, over many seeded
campaigns (issue 24, item 4; a script, not a test).

Run with ``.venv/bin/python bench/calibration_claim.py [--seeds N] [--targets N]
[--level joints|auto] [--heating none|static|warming|all]``. Each seed simulates a
campaign of the Symetrie-like hexapod whose true geometry differs from its hexapod file
(joints sigma 50 um, offsets sigma 30 um), ``--targets`` targets drawn in
+-20/+-20/+-15 mm, +-4/+-4/+-8 deg with a reference R between every two targets, 8
points per ball on a 70 deg cap with 0.3 um probing noise, thermocouples sampled every
30 s with 0.02 K noise; processes it (corrected poses) and calibrates it. The
calibrated model then predicts 200 new poses drawn in the same box (inside the stroke),
compared with where the twin puts them (R0's thermal state, relative to O as measured:
:func:`hexatherm.workflows.simulate.heldout.heldout_truth`).

Heating: ``none`` (legs at the leg model's 20 degC), ``static`` (legs at 21.3 degC, 1.3 K
above it), ``warming`` (21.3 degC and heating mats raising the legs 1 K with a 1 h time
constant from the start: the legs warm between O and R0 and over the campaign).

Printed per seed and pooled over the seeds (mean squares pooled, then the root), per
component: claimed/observed, claimed the RMS of the claimed standard uncertainty at the
new poses (the parameters' part and the level's model floor), observed the RMS of the
actual errors; the same for the parameters' part alone (the claim before issue 24); the
share of new poses whose error exceeds the report's worst U (k = 2) over the span, and
the 2u coverage of each new pose's own claim.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hexatherm.core.geometry import to_um_urad  # noqa: E402
from hexatherm.io.scenario import read_scenario  # noqa: E402
from hexatherm.workflows.calibrate.claim import pose_claim  # noqa: E402
from hexatherm.workflows.calibrate.run import calibrate, read_campaign  # noqa: E402
from hexatherm.workflows.simulate.heldout import heldout_truth  # noqa: E402
from hexatherm.workflows.simulate.run import scenario_spec, simulate  # noqa: E402
from hexatherm.workflows.simulate.twinsession import write_files  # noqa: E402
from tests.sessions import (  # noqa: E402
    CALIBRATION_SPAN,
    calibration_scenario,
    calibration_targets,
)

COMPONENTS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
MATS = ", ".join(["{gain_C: 1.0, tau_s: 3600, power: [[0, null]]}"] * 6)
HEATING = {
    "none": "",
    "static": "heating: {air_C: 21.3}\n",
    "warming": f"heating: {{air_C: 21.3, mats: [{MATS}]}}\n",
}
N_HELDOUT = 200


def one_seed(root: Path, seed: int, targets: int, level: str, heating: str) -> dict[str, object]:
    """Simulate, process, calibrate one campaign and compare its claim with the truth."""
    text = calibration_scenario(
        calibration_targets(seed, targets),
        geometry_seed=seed + 100,
        seed=seed,
        points_per_ball=8,
        cmm={"point_noise_um": 0.3},
        thermocouples={"period_s": 30, "noise_C": 0.02},
        timing={"seconds_per_point": 2.0, "seconds_per_move": 20},
        extra=HEATING[heating],
    )
    path = root / f"s{seed}-{heating}.yaml"
    path.write_text(text)
    scenario = read_scenario(path)
    folder = root / f"s{seed}-{heating}"
    write_files(simulate(scenario).files, folder)
    run = calibrate(read_campaign([folder]), level=level)
    draws = np.random.default_rng(1000 + seed).uniform(-1, 1, (N_HELDOUT, 6)) * CALIBRATION_SPAN
    nominal = run.campaign.nominal
    held = draws[~nominal.check_stroke(nominal.igm(draws)).any(axis=1)]
    claim = pose_claim(run, held)
    error = to_um_urad(run.fit.predict(held) - heldout_truth(scenario_spec(scenario), held))
    worst = pose_claim(run).worst_um_urad  # the report's worst over the span
    return {
        "level": run.fit.level,
        "claimed": np.mean(claim.sigma_um_urad**2, axis=0),
        "parameters": np.mean(claim.parameters_um_urad**2, axis=0),
        "observed": np.mean(error**2, axis=0),
        "beyond_worst": np.mean(np.abs(error) > 2.0 * worst, axis=0),
        "covered": np.mean(np.abs(error) <= 2.0 * claim.sigma_um_urad, axis=0),
        "floor": claim.floor.sigma_um_urad,
    }


def cells(values: np.ndarray) -> str:
    return " ".join(f"{v:6.3f}" for v in values)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--targets", type=int, default=20)
    parser.add_argument("--level", default="joints")
    parser.add_argument("--heating", default="all", choices=[*HEATING, "all"])
    parser.add_argument("--per-seed", action="store_true", help="print every seed's ratios")
    args = parser.parse_args()
    heatings = list(HEATING) if args.heating == "all" else [args.heating]
    header = " ".join(f"{c:>6}" for c in COMPONENTS)
    with tempfile.TemporaryDirectory() as tmp:
        for heating in heatings:
            rows = [
                one_seed(Path(tmp), seed, args.targets, args.level, heating)
                for seed in range(args.seeds)
            ]
            levels = sorted({str(r["level"]) for r in rows})
            print(
                f"\nheating {heating}: {args.seeds} seeds, {args.targets} targets, level "
                f"{args.level} (fitted: {', '.join(levels)}), {N_HELDOUT} new poses each"
            )
            print(f"{'':34} {header}")
            if args.per_seed:
                for seed, r in enumerate(rows):
                    ratio = np.sqrt(np.asarray(r["claimed"]) / np.asarray(r["observed"]))
                    print(f"  seed {seed:<3} claimed/observed{'':12} {cells(ratio)}")
            stack = {k: np.array([r[k] for r in rows]) for k in rows[0] if k != "level"}
            observed = stack["observed"].mean(axis=0)
            for name, key in (
                ("claimed/observed (pooled)", "claimed"),
                ("parameters alone/observed", "parameters"),
            ):
                print(f"  {name:32} {cells(np.sqrt(stack[key].mean(axis=0) / observed))}")
            ratios = np.sqrt(stack["claimed"] / stack["observed"])
            print(f"  {'per seed: lowest':32} {cells(ratios.min(axis=0))}")
            print(f"  {'per seed: highest':32} {cells(ratios.max(axis=0))}")
            print(f"  {'observed RMS (um, urad)':32} {cells(np.sqrt(observed))}")
            print(f"  {'floor (um, urad), mean':32} {cells(stack['floor'].mean(axis=0))}")
            print(
                f"  {'share beyond worst U (k=2)':32} {cells(stack['beyond_worst'].mean(axis=0))}"
            )
            print(f"  {'2u coverage of each pose':32} {cells(stack['covered'].mean(axis=0))}")


if __name__ == "__main__":
    main()
