"""The paper's claim, measured: calibration from thermally decoupled poses (a script, not
a test; issue 15, item 7); also calibrate's CPU time at scale and the pose-selection
criteria against random poses (issue 24, items 5 and 6).

Run with ``.venv/bin/python bench/calibration.py [--seeds N] [--sections LIST]``, LIST
of ``accuracy`` (the default), ``speed``, ``design`` (comma-separated, or ``all``):

- ``speed``: CPU seconds (user + system of the child) of a whole ``hexatherm calibrate
  SESSION --level L`` process (the CLI sets one BLAS thread), for one session of 100,
  300 and 1000 targets (``--targets``) at levels ``joints`` and ``auto`` (``--levels``),
  median of ``--repeats`` runs, with the machine's load average before and after. The
  sessions are ``bench/analyses.py``'s (cached in ``bench/.cache/``):
  ``tests.sessions.calibration_scenario``, the Symetrie-like hexapod with joint and
  offset errors, 12 points per ball on a 70 deg cap at 0.3 um, R around each target;
  with ``--sessions K`` the targets are split into K such sessions (seeds 7, 8, ...) of
  one true hexapod, all calibrated together.
- ``design``: ``bench/design.py`` over ``--seeds`` seeds (8 if not given): for 200
  candidate poses, 30 chosen by each criterion of ``plan --calibration-criterion``
  (d-optimal, g-optimal, i-optimal), the predicted worst and RMS standard uncertainty of
  a calibrated pose over all candidates, against 30 random candidates (median of 20
  draws) and against all 200 measured.

``accuracy``: for seeded campaigns of
the Symetrie-like hexapod whose true geometry differs from its hexapod file (joints
sigma 50 um, leg offsets sigma 30 um: ``geometry_errors:``), 30 targets drawn in
+-20/+-20/+-15 mm, +-4/+-4/+-8 deg with a reference R between every two targets, 12
points per ball on a 70 deg cap with 0.3 um probing noise, it simulates the campaign
(``simulate``), processes it, calibrates the ``joints`` level (42 parameters) and
prints the RMS translation error (um) of the calibrated model's predictions on 200
held-out poses in the reference thermal state, against the truth, from:

- ``drift-free``: the same campaign with the legs at the reference temperature;
- ``conventional``: the poses as measured, thermal drift included;
- ``decoupled``: the corrected poses (``process``: references on both sides, linear);
- ``decoupled, smooth``: the corrected poses with ``--interpolation smooth``.

- ``smooth, O/R0 x4``: the same, from a campaign whose O and R0 are measured 4 times.
- ``twin``: each measured pose corrected by the twin from the thermocouples alone
  (``--poses twin``), the twin's model being the scenario's true thermal model
  (:func:`hexatherm.workflows.calibrate.run.simulated_twin_campaign`): what a perfectly
  diagnosed twin gives.

Heating: ``none``; ``1 K`` (mats raising the legs about 1 K, a few um of growth); ``mats``
(about 10 K, tens of um: the paper's heating mats, switched on at minute 5, while a
campaign with O and R0 x4 is still measuring them); ``mats 15'`` (the same mats switched
on at minute 15, once the reference state is measured). Also printed: the nominal
model's error (relative to the measured O, as every pose is measured, and in a frame
fixed to the base, where O's own error adds), and the ratios decoupled / drift-free,
x4 / drift-free and conventional / decoupled.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from hexatherm.core.calibration import CalibrationModel, fit_calibration  # noqa: E402
from hexatherm.core.calibration.model import (  # noqa: E402
    compose_pose,
    nominal_parameters,
    relative_pose,
)
from hexatherm.core.hexapod import Hexapod  # noqa: E402
from hexatherm.core.planning import build_plan  # noqa: E402
from hexatherm.io.config import plan_to_yaml, read_hexapod  # noqa: E402
from hexatherm.io.scenario import read_scenario  # noqa: E402
from hexatherm.workflows.calibrate.run import (  # noqa: E402
    Campaign,
    read_campaign,
    simulated_twin_campaign,
)
from hexatherm.workflows.simulate.run import simulate  # noqa: E402
from hexatherm.workflows.simulate.twinsession import write_files  # noqa: E402

SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])
HEATING = {
    "none": "",
    "1 K": "heating:\n  mats: ["
    + ", ".join(["{gain_C: 1.0, tau_s: 3600, power: [[0, null]]}"] * 6)
    + "]\n",
    "mats": "heating:\n  mats: ["
    + ", ".join(
        f"{{gain_C: {g}, tau_s: 2400, power: [[300, null]]}}" for g in (8, 10, 12, 9, 11, 10)
    )
    + "]\n",
    "mats 15'": "heating:\n  mats: ["
    + ", ".join(
        f"{{gain_C: {g}, tau_s: 2400, power: [[900, null]]}}" for g in (8, 10, 12, 9, 11, 10)
    )
    + "]\n",
}


def scenario_text(seed: int, heating: str, plan_file: str | None = None) -> str:
    targets = np.random.default_rng(seed).uniform(-1, 1, (30, 6)) * SPAN
    rows = "\n".join(f"    - [{', '.join(f'{v:.4f}' for v in t)}]" for t in targets)
    plan = (
        f"plan: {plan_file}"
        if plan_file
        else f"""plan:
  reference_pose: [0, 0, -40, 0, 0, 0]
  points_per_ball: 12
  targets:
{rows}"""
    )
    return f"""format: hexatherm-scenario/1
name: calibration-{seed}
hexapod: {ROOT / "configs" / "symetrie-like.yaml"}
balls: {ROOT / "configs" / "balls-3.yaml"}
seed: {seed}
{plan}
timing: {{seconds_per_point: 2.0, seconds_per_move: 20}}
cmm: {{point_noise_um: 0.3, cap_angle_deg: 70}}
thermocouples: {{period_s: 30, noise_C: 0.02}}
geometry_errors: {{seed: {seed + 1000}, joint_sigma_um: 50, offset_sigma_um: 30}}
{heating}"""


def campaign_folder(
    root: Path, seed: int, heating: str, repeats: int = 1
) -> tuple[Path, np.ndarray]:
    """Simulate the campaign (O and R0 measured ``repeats`` times); its folder and the true
    parameters."""
    tag = f"{seed}-{heating.replace(' ', '')}-{repeats}"
    plan_file = None
    if repeats > 1:
        targets = np.random.default_rng(seed).uniform(-1, 1, (30, 6)) * SPAN
        plan = build_plan(
            targets.round(4),
            [0, 0, -40, 0, 0, 0],
            points_per_ball=12,
            origin_repeats=repeats,
            reference0_repeats=repeats,
        )
        (root / f"plan-{tag}.yaml").write_text(plan_to_yaml(plan))
        plan_file = f"plan-{tag}.yaml"
    path = root / f"scenario-{tag}.yaml"
    path.write_text(scenario_text(seed, HEATING[heating], plan_file))
    scenario = read_scenario(path)
    folder = root / f"s-{tag}"
    write_files(simulate(scenario).files, folder)
    assert scenario.true_parameters is not None
    return folder, scenario.true_parameters


def heldout_error_um(campaign: Campaign, truth: np.ndarray, held: np.ndarray) -> float:
    """RMS translation error (um) of the calibrated predictions of ``held`` poses."""
    fit = fit_calibration(
        campaign.nominal, campaign.commanded, campaign.measured, campaign.weights_covariance
    )
    true_poses, _ = CalibrationModel(campaign.nominal, "joints+gains").predict(truth, held)
    error = (fit.predict(held) - true_poses)[:, :3] * 1e3
    return float(np.sqrt(np.mean(np.sum(error**2, axis=1))))


def rms_translation_um(errors: np.ndarray) -> float:
    """RMS length (um) of the translation part of pose errors (N, 6) in mm and deg."""
    return float(np.sqrt(np.mean(np.sum((errors[:, :3] * 1e3) ** 2, axis=1))))


def true_poses_both(
    nominal: Hexapod, truth: np.ndarray, commanded: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where the true geometry puts commanded poses: relative to its own frame O (what a
    measurement relative to the measured O sees), and relative to the nominal frame O
    (O's own error included: the pose in a frame fixed to the base)."""
    model = CalibrationModel(nominal, "joints+gains")
    relative, _ = model.predict(truth, commanded)
    true_origin, _ = model.origin(truth)
    nominal_origin, _ = model.origin(nominal_parameters(nominal))
    stand, _, _ = compose_pose(true_origin, relative, nominal.convention)
    absolute, _, _ = relative_pose(nominal_origin, stand, nominal.convention)
    return relative, absolute


SECTIONS = ("accuracy", "speed", "design")


def split_sessions(n_targets: int, n_sessions: int) -> list[Path]:
    """``n_targets`` in ``n_sessions`` sessions of one true hexapod (cached in
    ``bench/.cache/``), each as ``bench/analyses.py``'s calibration session: seeds 7, 8,
    ..., the same geometry errors (seed 11)."""
    from analyses import CACHE, simulate_calibration  # type: ignore[import-not-found]

    root = CACHE / f"calibrate-{n_targets}-in-{n_sessions}"
    folders = []
    for i in range(n_sessions):
        folder = root / f"s{i}"
        if not (folder / "session.yaml").is_file():
            name = f"calibrate-{n_targets}-in-{n_sessions}-{i}"
            simulate_calibration(n_targets // n_sessions, 7 + i, name, root / f"s{i}.yaml", folder)
        folders.append(folder)
    return folders


def speed(sizes: list[int], levels: list[str], repeats: int, sessions: int) -> None:
    """Print calibrate's CPU seconds per size and level (see the module text)."""
    sys.path.insert(0, str(ROOT / "bench"))
    from analyses import (  # type: ignore[import-not-found]
        calibration_session,
        cpu_seconds,
        median,
    )

    # simulated first, not timed
    folders = {
        n: [calibration_session(n)] if sessions == 1 else split_sessions(n, sessions) for n in sizes
    }
    print(
        f"hexatherm calibrate, {sessions} session(s), CPU s (user + system), median of "
        f"{repeats}; load average at the start {os.getloadavg()[0]:.1f} (1 min), "
        f"{os.getloadavg()[1]:.1f} (5 min)"
    )
    print("| targets | sessions | level | CPU s | runs (s) |")
    print("|---:|---:|---|---:|---|")
    for n in sizes:
        for level in levels:
            command = ["calibrate", *map(str, folders[n]), "--level", level]
            runs = [cpu_seconds(ROOT, command) for _ in range(repeats)]
            print(
                f"| {n} | {sessions} | {level} | {median(runs):.2f} | "
                + ", ".join(f"{r:.2f}" for r in runs)
                + " |",
                flush=True,
            )
    print(f"load average at the end {os.getloadavg()[0]:.1f} (1 min)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, help="accuracy: 3 if not given; design: 8")
    parser.add_argument("--sections", default="accuracy", help=f"of {', '.join(SECTIONS)}, all")
    parser.add_argument("--targets", default="100,300,1000", help="speed: session sizes")
    parser.add_argument("--levels", default="joints,auto", help="speed: calibrate levels")
    parser.add_argument("--repeats", type=int, default=3, help="speed: runs per row")
    parser.add_argument("--sessions", type=int, default=1, help="speed: targets split in")
    args = parser.parse_args()
    sections = SECTIONS if args.sections == "all" else args.sections.split(",")
    for section in sections:
        if section not in SECTIONS:
            parser.error(f"unknown section {section!r}")
    if "speed" in sections:
        speed(
            [int(n) for n in args.targets.split(",")],
            args.levels.split(","),
            args.repeats,
            args.sessions,
        )
    if "design" in sections:
        sys.path.insert(0, str(ROOT / "bench"))
        from design import compare_designs  # type: ignore[import-not-found]

        compare_designs(8 if args.seeds is None else args.seeds, 200, 30)
    if "accuracy" in sections:
        accuracy(3 if args.seeds is None else args.seeds)


def accuracy(seeds: int) -> None:
    """Print the held-out error table (see the module text)."""
    held = np.random.default_rng(99).uniform(-1, 1, (200, 6)) * SPAN
    nominal = read_hexapod(ROOT / "configs" / "symetrie-like.yaml")
    rows: dict[str, dict[str, list[float]]] = {h: {} for h in HEATING}
    nominal_error: list[float] = []
    nominal_absolute: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        for seed in range(seeds):
            free, truth = campaign_folder(root, seed, "none")
            drift_free = heldout_error_um(read_campaign([free], "conventional"), truth, held)
            true_poses, absolute = true_poses_both(nominal, truth, held)
            nominal_error.append(rms_translation_um(true_poses - held))
            nominal_absolute.append(rms_translation_um(absolute - held))
            for heating in HEATING:
                folder = free if heating == "none" else campaign_folder(root, seed, heating)[0]
                cells = rows[heating]
                cells.setdefault("drift-free", []).append(drift_free)
                repeated = campaign_folder(root, seed, heating, repeats=4)[0]
                for name, poses, interpolation, where in (
                    ("conventional", "conventional", "linear", folder),
                    ("decoupled", "corrected", "linear", folder),
                    ("decoupled, smooth", "corrected", "smooth", folder),
                    ("smooth, O/R0 x4", "corrected", "smooth", repeated),
                ):
                    campaign = read_campaign([where], poses, interpolation=interpolation)  # type: ignore[arg-type]
                    growth = campaign.results[0].correction
                    cells.setdefault(name, []).append(heldout_error_um(campaign, truth, held))
                twin = simulated_twin_campaign(folder)
                cells.setdefault("twin", []).append(heldout_error_um(twin, truth, held))
                drift = np.abs((growth.conventional - growth.corrected)[:, :3]).max() * 1e3
                cells.setdefault("largest thermal error of a pose (um)", []).append(drift)
            print(f"seed {seed} done", file=sys.stderr, flush=True)
    rms = lambda values: float(np.sqrt(np.mean(np.square(values))))  # noqa: E731
    print(
        f"Calibrated model's RMS translation error on 200 held-out poses (um), "
        f"{seeds} seeds; nominal model: {rms(nominal_error):.1f} um relative to the "
        f"measured O, {rms(nominal_absolute):.1f} um in a frame fixed to the base"
    )
    columns = [
        "drift-free",
        "conventional",
        "decoupled",
        "decoupled, smooth",
        "smooth, O/R0 x4",
        "twin",
        "largest thermal error of a pose (um)",
    ]
    print(
        f"{'heating':8} "
        + " ".join(f"{c[:18]:>18}" for c in columns)
        + f" {'dec/free':>9} {'x4/free':>9} {'twin/free':>9} {'conv/dec':>9}"
    )
    for heating, cells in rows.items():
        values = [rms(cells[c]) for c in columns]
        print(
            f"{heating:8} "
            + " ".join(f"{v:18.3f}" for v in values)
            + f" {values[2] / values[0]:9.2f} {values[4] / values[0]:9.2f}"
            + f" {values[5] / values[0]:9.2f}"
            + f" {values[1] / values[2]:9.2f}"
        )


if __name__ == "__main__":
    main()
