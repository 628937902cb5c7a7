"""How well ``hexatherm diagnose`` finds hidden effects: recovery, confusion, false additions.

Simulated campaigns (:func:`hexatherm.workflows.simulate.campaigns.diagnosis_campaign`: 16 targets,
2 cycles, 66 steps over 3.7 h, heating mats switched on/off/on, the air warming
by 4 K and cooling again) with one effect hidden at a time, at several sizes
(the nominal parameters of :data:`hexatherm.workflows.simulate.campaigns.NOMINAL_HIDDEN` scaled) and
CMM noise levels (standard deviation per probed point; centres are sphere fits
of 25 points). For each: how often the effect is named first, how often its
parameters are recovered (single parameter: within 25 %; several: inside the
fit's 95.45 % ellipsoid) and how often the held-out RMS at least halves. Then
the confusion between candidates at the nominal size, and the rate of false
additions on campaigns with nothing hidden.

    python bench/diagnose.py                     # about 10 minutes on 2 cores
    python bench/diagnose.py --seeds 2 --null-seeds 10 --sizes 1 --noises 1
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from hexatherm.core.diagnosis import Diagnosis
from hexatherm.core.effects import make_effect
from hexatherm.workflows.diagnose.run import read_for_diagnosis, run_diagnosis
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session


def run(
    names: tuple[str, ...], size: float, noise_um: float, seed: int, tmp: Path, n_targets: int = 16
) -> tuple[Diagnosis, dict[str, dict[str, float]]]:
    truth = {n: {p: v * size for p, v in NOMINAL_HIDDEN[n].items()} for n in names}
    hidden = tuple(make_effect(n, truth[n]) for n in names)
    folder = tmp / f"{'-'.join(names) or 'null'}-{size}-{noise_um}-{seed}"
    write_twin_session(
        diagnosis_campaign(hidden, seed, n_targets=n_targets, point_noise_um=noise_um), folder
    )
    return run_diagnosis(read_for_diagnosis(folder)).diagnosis, truth


def recovered(d: Diagnosis, name: str, truth: dict[str, float]) -> bool:
    fitted = {e.name: (i, e) for i, e in enumerate(d.final.effects)}
    if name not in fitted:
        return False
    i, effect = fitted[name]
    if len(truth) == 1:
        ((p, value),) = truth.items()
        return abs(effect.values[p] - value) <= 0.25 * abs(value)
    start = sum(len(e.parameters) for e in d.final.effects[:i])
    k = len(truth)
    diff = effect.vector() - np.array([truth[p] for p in effect.parameters])
    cov = d.final.covariance[start : start + k, start : start + k]
    return float(diff @ np.linalg.solve(cov, diff)) <= chi2.ppf(chi2.cdf(4.0, 1), k)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--null-seeds", type=int, default=40)
    parser.add_argument("--sizes", default="0.5,1,2", help="factors on the nominal parameters")
    parser.add_argument("--noises", default="0.5,1,2", help="CMM noise per point, um")
    args = parser.parse_args()
    sizes = [float(s) for s in args.sizes.split(",")]
    noises = [float(s) for s in args.noises.split(",")]
    started = time.perf_counter()
    confusion: dict[str, Counter[str]] = {}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        print("Recovery of one hidden effect (rates over seeds)\n")
        print(
            "| effect | size | noise (um/point) | named first | parameters | held-out halved "
            "| held-out RMS before -> after (um) |"
        )
        print("|---|---|---|---|---|---|---|")
        for name in NOMINAL_HIDDEN:
            for size in sizes:
                for noise in noises:
                    if size != 1.0 and noise != 1.0:
                        continue  # a cross, not a grid: size at 1 um, noise at nominal size
                    scaled = make_effect(
                        name, {p: v * size for p, v in NOMINAL_HIDDEN[name].items()}
                    )
                    if scaled.out_of_range():
                        print(
                            f"| {name} | {size:g} | {noise:g} | outside the effect's range: "
                            f"{'; '.join(scaled.out_of_range().values())} ||||"
                        )
                        continue
                    first = params = halved = 0
                    before, after = [], []
                    for seed in range(args.seeds):
                        d, truth = run((name,), size, noise, 1000 + seed, tmp)
                        top = d.added[0].effect.name if d.added else "nothing"
                        if size == 1.0 and noise == 1.0:
                            confusion.setdefault(name, Counter())[top] += 1
                        first += top == name
                        params += recovered(d, name, truth[name])
                        if d.added:
                            halved += (
                                d.added[0].heldout_rms_after_um
                                <= 0.5 * d.added[0].heldout_rms_before_um
                            )
                        before.append(d.baseline_heldout_rms_um)
                        after.append(d.final_heldout_rms_um)
                    n = args.seeds
                    print(
                        f"| {name} | {size:g} | {noise:g} | {first}/{n} | {params}/{n} | "
                        f"{halved}/{n} | {np.mean(before):.2f} -> {np.mean(after):.2f} |",
                        flush=True,
                    )
        print("\nConfusion at the nominal size, 1 um per point: hidden (rows) -> first added\n")
        columns = [*NOMINAL_HIDDEN, "nothing"]
        print("| hidden | " + " | ".join(columns) + " |")
        print("|---" * (len(columns) + 1) + "|")
        for name in NOMINAL_HIDDEN:
            counts = confusion.get(name, Counter())
            print(f"| {name} | " + " | ".join(str(counts[c]) for c in columns) + " |")
        false_added: Counter[str] = Counter()
        sessions_with = 0
        for seed in range(args.null_seeds):
            d, _ = run((), 1.0, 1.0, 5000 + seed, tmp)
            sessions_with += bool(d.added)
            false_added.update(a.effect.name for a in d.added)
        print(
            f"\nNothing hidden, 1 um per point: {sessions_with}/{args.null_seeds} campaigns "
            f"with a false addition ({dict(false_added) or 'none'})"
        )
    print(f"\n({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
