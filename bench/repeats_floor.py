"""Issue 35 item 3: the corrected poses' error over the single-frame noise floor, with O
and R0 measured k times while the legs heat, and where the rest of the error comes from.

Run with ``python bench/repeats_floor.py [SEEDS] [CASE ...]`` (default 30 seeds, every
case). Each case simulates SEEDS sessions under the conditions of
``tests/workflows/test_repeats_heating.py`` (6 targets between 7 references, steps about
200 s apart, 1 um point noise, 25 points over 70 deg, fitted centres, ``cmm:`` given,
thermocouple log, linear interpolation unless said; heating from the start, tau 2400 s,
unless said) and prints, RMS over seeds and targets of the corrected |dT| (um):

- ``error``: against the twin's truth;
- ``floor``: the single-frame noise floor, the error of the chain of the session
  evaluated on the true centres with the target steps' own measured (the bench's floor,
  ``bench/accuracy.py floor``): what a target's one frame costs whatever the rest;
- the error's parts measured the same way, each group of steps noisy alone: the target
  step (the floor), its two references (R1...), R0 (its repeats combined), O (its
  repeats combined); their squares add up to the noise's (the chain is linear at this
  noise);
- the same parts propagated (the chain's Jacobian by each step's centres times their
  claimed covariance): the method's floor for the plan, without replicas;
- ``any estimator``: the floor no estimator of this plan goes below, the target's frame
  and O's (its n repeats' mean): each is the only measurement of its pose; the
  references' and R0's parts could at best vanish (infinitely many, or a growth known
  without noise).

Cases (:data:`CASES`): ``x4`` (O and R0 x4, heating from the start), ``x4-before`` (the
same, the mats switched on at S1: the repeats before the heating), ``once``, ``x16``,
``x4-smooth`` (``--interpolation smooth``); estimators ``process`` does not have, the
same chain with other growth weights: ``quadratic`` (one parabola in time per leg through
every reference, R0 weighted by its measurements, its value at the target less its
value at R0: R0's noise averaged with the series'), ``spline-offset`` (``smooth``'s
spline so); ``-R2``: every reference after R0 measured twice in a row.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hexatherm.core.plan import Plan  # noqa: E402
from hexatherm.io.config import read_session  # noqa: E402
from hexatherm.workflows.process.carrying import carry_and_average  # noqa: E402
from hexatherm.workflows.process.measured import read_measured  # noqa: E402
from hexatherm.workflows.process.pipeline import process_session  # noqa: E402
from hexatherm.workflows.process.uncertainty import (  # noqa: E402
    centre_covariance,
    pose_chain,
    pose_uncertainty,
)
from hexatherm.workflows.simulate.twinsession import Heating, simulate_session  # noqa: E402
from tests.replicas import write_session  # noqa: E402
from tests.sessions import REFERENCE  # noqa: E402
from tests.workflows.test_repeats import CMM, GAIN, spec  # noqa: E402

#: name: (repeats, heating on at S1, interpolation: ``process``'s or the bench's own
#: estimators, every reference after R0 measured twice in a row)
CASES = {
    "x4": (4, False, "linear", False),
    "x4-before": (4, True, "linear", False),
    "once": (1, False, "linear", False),
    "x16": (16, False, "linear", False),
    "x4-smooth": (4, False, "smooth", False),
    "x4-quadratic": (4, False, "quadratic", False),
    "x16-quadratic": (16, False, "quadratic", False),
    "x4-spline-offset": (4, False, "spline-offset", False),
    "x16-quadratic-R2": (16, False, "quadratic", True),
    "x16-R2": (16, False, "linear", True),
}


def doubled(plan: Plan) -> Plan:
    """The plan with every reference after R0 measured twice in a row (``R1``, ``R1b``)."""
    steps = []
    for label, kind, pose in zip(plan.labels, plan.kinds, plan.poses.tolist(), strict=True):
        steps.append((label, kind, pose))
        if kind == "reference" and label[1:].isdigit() and label != "R0":
            steps.append((label + "b", kind, pose))
    return Plan.from_steps(steps, reference_pose=REFERENCE)


def spline_offset_weights(result) -> np.ndarray:
    """Growth weights (M, 6, N) of ``smooth``'s spline (its GCV smoothing, used whatever
    its cross-validation says) taken as the fit at each target less the fit at R0."""
    from hexatherm.core.correction import smooth_growth

    plan, c = result.session.plan, result.centres
    refs, t = plan.reference_indices, c.times_s
    q = result.steps.q_mm
    fit = smooth_growth(t[refs], q[refs] - q[refs[0]], t[plan.target_indices], c.measurements[refs])
    at0 = smooth_growth(t[refs], q[refs] - q[refs[0]], t[refs[:1]], c.measurements[refs])
    out = np.zeros((len(plan.target_indices), 6, len(t)))
    out[:, :, refs] = fit.weights - at0.weights
    out[:, :, refs[0]] += 1.0
    return out


def quadratic_weights(t: np.ndarray, refs: np.ndarray, targets: np.ndarray, counts: np.ndarray):
    """Growth weights (M, 6, N) of one parabola in time fitted per leg to every reference
    (R0 weighted by its measurements), its value at each target's time less its value at
    R0's: R0's noise averaged with the others' (``growth = W q - q_R0``)."""
    tr = (t[refs] - t[refs].mean()) / np.ptp(t[refs])
    design = np.vander(tr, 3)
    w = counts[refs].astype(float)
    hat = np.linalg.solve(design.T @ (w[:, None] * design), (w[:, None] * design).T)
    at = np.vander((t[targets] - t[refs].mean()) / np.ptp(t[refs]), 3) @ hat
    at0 = np.vander(tr[:1], 3) @ hat
    out = np.zeros((len(targets), 6, len(t)))
    out[:, :, refs] = (at - at0)[:, None, :]
    out[:, :, refs[0]] += 1.0
    return out


GROUPS = ("target", "references", "R0", "O")


def replica(
    folder: Path, seed: int, repeats: int, before: bool, interpolation: str, double: bool
) -> dict:
    """One session's corrected errors and their parts, (M, 3) um each."""
    s = spec(folder, seed, repeats=repeats, n_targets=6)
    if double:
        s = dataclasses.replace(s, plan=doubled(s.plan))
    if before:  # the mats on when the first target is measured
        probe = simulate_session(s, truth_files=False)
        write_session(probe.files, folder)
        (folder / "session.yaml").write_text((folder / "session.yaml").read_text() + CMM)
        times = read_measured(read_session(folder))[2].times_s
        on = float(times[s.plan.labels.index("S1")]) - 1.0
        s = dataclasses.replace(s, heating=Heating(on_s=on, tau_s=2400.0, gain_C=GAIN))
    simulated = simulate_session(s, truth_files=False)
    write_session(simulated.files, folder)
    (folder / "session.yaml").write_text((folder / "session.yaml").read_text() + CMM)
    ours = interpolation if interpolation in ("linear", "smooth") else "linear"
    result = process_session(folder, interpolation=ours)  # type: ignore[arg-type]
    targets = [i for i, label in enumerate(s.plan.labels) if label.startswith("S")]
    truth = simulated.truth.corrected_pose[targets]
    chain = pose_chain(result)
    plan = result.session.plan
    if interpolation == "quadratic":
        t = result.centres.times_s
        weights = quadratic_weights(
            t, plan.reference_indices, plan.target_indices, result.centres.measurements
        )
        chain = dataclasses.replace(chain, growth_weights=weights)
    if interpolation == "spline-offset":
        chain = dataclasses.replace(chain, growth_weights=spline_offset_weights(result))
    measured = result.centres.centres_mm
    out = {"error": (chain(measured)[:, 6:9] - truth[:, :3]) * 1e3}
    # the clean centres of the reduced steps: the truth combined as the measured are
    session = read_session(folder)
    _, _, full, temperatures = read_measured(session)
    clean_full = dataclasses.replace(full, centres_mm=simulated.truth.centres_cmm_mm)
    clean = carry_and_average(session, clean_full, temperatures)[1].centres_mm
    groups = {
        "target": list(plan.target_indices),
        "references": list(plan.reference_indices[1:]),
        "R0": [int(plan.reference_indices[0])],
        "O": [plan.origin_index],
    }
    at_clean = chain(clean)[:, 6:9]
    out["noise"] = (chain(measured)[:, 6:9] - at_clean) * 1e3
    for name, steps in groups.items():
        mixed = clean.copy()
        mixed[steps] = measured[steps]
        out[name] = (chain(mixed)[:, 6:9] - at_clean) * 1e3
    # propagated: the chain's Jacobian by each step's centres, their claimed covariance
    cov = centre_covariance(result).cov_mm2
    h = 1e-5
    base = chain(measured)[:, 6:9]
    var = {name: np.zeros_like(base) for name in groups}
    for name, steps in groups.items():
        for step in steps:
            jac = np.zeros(base.shape + (measured.shape[1], 3))
            for ball in range(measured.shape[1]):
                for axis in range(3):
                    plus = measured.copy()
                    plus[step, ball, axis] += h
                    jac[..., ball, axis] = (chain(plus)[:, 6:9] - base) / h
            var[name] += np.einsum("mcka,kab,mckb->mc", jac, cov[step], jac) * 1e6
    for name in groups:
        out["u " + name] = np.sqrt(var[name])
    out["claimed"] = pose_uncertainty(result).corrected_u[:, :3] * 1e3
    return out


def rms(x: np.ndarray) -> float:
    """RMS of |dT| over seeds and targets, (..., 3) um."""
    return float(np.sqrt(np.mean(np.sum(np.square(x), axis=-1))))


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    cases = sys.argv[2:] or list(CASES)
    print(
        "| case | error | floor | error/floor | noise | parts: target refs R0 O "
        "| propagated: target refs R0 O | method's floor (propagated) "
        "| any estimator | claimed/observed Tx Ty Tz |"
    )
    print("|---|---:|---:|---:|---:|---|---|---:|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in cases:
            runs = [
                replica(Path(tmp) / f"{name}-{seed}", seed, *CASES[name]) for seed in range(seeds)
            ]
            r = {key: np.concatenate([run[key] for run in runs]) for key in runs[0]}
            floor = rms(r["target"])
            parts = " ".join(f"{rms(r[g]):.2f}" for g in GROUPS)
            u = {g: rms(r["u " + g]) for g in GROUPS}
            method = np.sqrt(sum(v**2 for v in u.values())) / u["target"]
            best = np.sqrt(u["target"] ** 2 + u["O"] ** 2) / u["target"]
            ratio = np.sqrt(np.mean(r["claimed"] ** 2, axis=0) / np.mean(r["error"] ** 2, axis=0))
            claim = " ".join(f"{v:.2f}" for v in ratio)
            if CASES[name][2] not in ("linear", "smooth"):
                claim = "(u is process's, not the bench estimator's)"
            print(
                f"| {name} | {rms(r['error']):.2f} | {floor:.2f} | "
                f"{rms(r['error']) / floor:.2f} | {rms(r['noise']):.2f} | {parts} | "
                + " ".join(f"{u[g]:.2f}" for g in GROUPS)
                + f" | {method:.2f} | {best:.2f} | {claim} |",
                flush=True,
            )
    print(f"\n{seeds} seeds x 6 targets per case, |dT| in um", file=sys.stderr)


if __name__ == "__main__":
    main()
