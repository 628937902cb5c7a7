"""The analyses a user waits on, in CPU seconds (issue 26's table), paired with a baseline.

Each row is a whole ``hexatherm`` process on a simulated session cached in
``bench/.cache/`` (built on first use):

- ``diagnose``, 16 / 64 / 256 targets with ``leg_thermal_lag`` hidden (nominal size,
  1 um per probed point; :func:`hexatherm.workflows.simulate.campaigns.diagnosis_campaign`);
- ``process --mc 2000`` on the 122-step points campaign of ``bench/montecarlo.py``;
- ``calibrate --iterate``, 100 / 300 targets, and ``calibrate --level auto``, 100 targets
  (``tests.sessions.calibration_scenario``: the Symetrie-like hexapod with joint and
  offset errors, 12 points per ball, R around each target);
- ``report`` of the shipped 40-target session ``sessions/with-hidden-effect`` (the
  page, its four figures, linear uncertainty and quality checks).

CPU time is user + system of the child (``resource.getrusage(RUSAGE_CHILDREN)``), which
moves less with the machine's load than wall time. With ``--baseline DIR`` (a checkout
of the code before, e.g. ``git worktree add /tmp/before main``) every row runs the
baseline and this code alternately, ``--pairs`` times, and prints both medians and the
median of the paired ratios. ``process`` against its floor is ``bench/floor.py``'s.

With ``--bytecode`` the children compile their modules once into
``bench/.cache/pycache/`` (``PYTHONPYCACHEPREFIX``, one warm-up run per checkout) and
read them from there, as an installed wheel does, even where the environment sets
``PYTHONDONTWRITEBYTECODE`` (then every run compiles hexatherm's modules again: about
0.15 s of a ``diagnose``).

    python bench/analyses.py [--pairs 3] [--baseline DIR] [--rows diagnose-16,mc] [--bytecode]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
CACHE = ROOT / "bench" / ".cache"


def diagnosis_session(n_targets: int) -> Path:
    folder = CACHE / f"diagnose-{n_targets}"
    if not (folder / "session.yaml").is_file():
        from hexatherm.core.effects import make_effect
        from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
        from hexatherm.workflows.simulate.twinsession import write_twin_session

        hidden = (make_effect("leg_thermal_lag", NOMINAL_HIDDEN["leg_thermal_lag"]),)
        shutil.rmtree(folder, ignore_errors=True)
        write_twin_session(diagnosis_campaign(hidden, 1000, n_targets=n_targets), folder)
    return folder


def simulate_calibration(
    n_targets: int, seed: int, name: str, scenario: Path, folder: Path
) -> None:
    """Simulate the bench's calibration campaign into ``folder`` (its scenario written to
    ``scenario``): ``tests.sessions.calibration_scenario``'s hexapod with the geometry
    errors of seed 11, ``n_targets`` targets drawn with ``seed``, 12 points per ball on a
    70 deg cap at 0.3 um, 2 s a point, 20 s a move, thermocouples every 30 s at 0.02 K."""
    from hexatherm.io.scenario import read_scenario
    from hexatherm.workflows.simulate.run import simulate
    from hexatherm.workflows.simulate.twinsession import write_files
    from tests.sessions import calibration_scenario, calibration_targets

    text = calibration_scenario(
        calibration_targets(seed, n_targets),
        geometry_seed=11,
        seed=seed,
        name=name,
        points_per_ball=12,
        cmm={"point_noise_um": 0.3, "cap_angle_deg": 70},
        timing={"seconds_per_point": 2.0, "seconds_per_move": 20},
        thermocouples={"period_s": 30, "noise_C": 0.02},
    )
    scenario.parent.mkdir(parents=True, exist_ok=True)
    scenario.write_text(text)
    shutil.rmtree(folder, ignore_errors=True)
    write_files(simulate(read_scenario(scenario)).files, folder)


def calibration_session(n_targets: int) -> Path:
    folder = CACHE / f"calibrate-{n_targets}"
    if not (folder / "session.yaml").is_file():
        name = f"calibrate-{n_targets}"
        simulate_calibration(n_targets, 7, name, CACHE / f"{name}.yaml", folder)
    return folder


def mc_session() -> Path:
    sys.path.insert(0, str(ROOT / "bench"))
    from montecarlo import session  # type: ignore[import-not-found]

    return Path(session())


#: row name -> (what the issue's table calls it, the command's arguments, its target)
ROWS: dict[str, tuple[str, Callable[[], list[str]], str]] = {
    "diagnose-16": (
        "diagnose, 16 targets",
        lambda: ["diagnose", str(diagnosis_session(16))],
        "< 2 s",
    ),
    "diagnose-64": (
        "diagnose, 64 targets",
        lambda: ["diagnose", str(diagnosis_session(64))],
        "",
    ),
    "diagnose-256": (
        "diagnose, 256 targets",
        lambda: ["diagnose", str(diagnosis_session(256))],
        "< 5 s",
    ),
    "mc": (
        "process --mc 2000, 122 steps",
        lambda: ["process", str(mc_session()), "--mc", "2000"],
        "< 3 s",
    ),
    "iterate-100": (
        "calibrate --iterate, 100 targets",
        lambda: ["calibrate", str(calibration_session(100)), "--iterate"],
        "",
    ),
    "iterate-300": (
        "calibrate --iterate, 300 targets",
        lambda: ["calibrate", str(calibration_session(300)), "--iterate"],
        "< 10 s",
    ),
    "auto-100": (
        "calibrate --level auto, 100 targets",
        lambda: ["calibrate", str(calibration_session(100)), "--level", "auto"],
        "< 3 s",
    ),
    "report-40": (
        "report, 40-target session (shipped with-hidden-effect)",
        lambda: ["report", str(ROOT / "sessions" / "with-hidden-effect")],
        "< 2 s",
    ),
}


def cpu_seconds(code: Path, args: list[str], bytecode: bool = False) -> float:
    """CPU seconds (user + system) of ``python -m hexatherm ARGS -o OUT`` run from ``code``
    (``bytecode``: with compiled modules kept under ``bench/.cache/pycache/``)."""
    out = Path(tempfile.mkdtemp())
    env = dict(os.environ, PYTHONPATH=str(code))
    if bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(CACHE / "pycache")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(
        [sys.executable, "-m", "hexatherm", *args, "-o", str(out / "out")],
        cwd=code,
        env=env,
        check=True,
        capture_output=True,
    )
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    shutil.rmtree(out)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def median(values: list[float]) -> float:
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else 0.5 * (ordered[mid - 1] + ordered[mid])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before")
    parser.add_argument("--rows", default=",".join(ROWS), help=f"of {', '.join(ROWS)}")
    parser.add_argument("--bytecode", action="store_true", help="compiled modules, as installed")
    args = parser.parse_args()
    rows = [r.strip() for r in args.rows.split(",") if r.strip()]
    for row in rows:
        if row not in ROWS:
            parser.error(f"unknown row {row!r}")
    print(f"load average at the start: {os.getloadavg()[0]:.1f} (2-minute: see `uptime`)")
    if args.bytecode:
        print("modules compiled once, read from bench/.cache/pycache/ (as installed)")
    if args.baseline:
        print("| workload | before (s CPU) | now (s CPU) | now / before | target |")
        print("|---|---:|---:|---:|---|")
    else:
        print("| workload | now (s CPU) | target |")
        print("|---|---:|---|")
    for row in rows:
        title, make, target = ROWS[row]
        command = make()
        if args.bytecode:  # compile once (the modules a row imports)
            for code in (args.baseline, ROOT) if args.baseline else (ROOT,):
                cpu_seconds(code, command, bytecode=True)
        now, before = [], []
        for _ in range(args.pairs):
            if args.baseline:
                before.append(cpu_seconds(args.baseline, command, args.bytecode))
            now.append(cpu_seconds(ROOT, command, args.bytecode))
        if args.baseline:
            ratio = median([a / b for a, b in zip(now, before, strict=True)])
            print(
                f"| {title} | {median(before):.2f} | {median(now):.2f} | {ratio:.2f} | {target} |",
                flush=True,
            )
        else:
            print(f"| {title} | {median(now):.2f} | {target} |", flush=True)
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
