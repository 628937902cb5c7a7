"""``process`` against its floor (a script, not a test; issue 16, item 5).

Run with ``.venv/bin/python bench/floor.py [--targets 1000] [--pairs 7] [--bytecode]``. The floor is
what any script that processes the session must do anyway: start Python, import numpy
and pandas, and read the measurement file with ``pandas.read_csv``. On the simulated
points session of ``bench/speed.py`` (``--targets`` targets, 25 points per ball, cached
in ``bench/.cache/``) it times, in alternating pairs (the machine's load moves both
alike), the floor and ``hexatherm process DIR -o OUT --overwrite`` (reading, sphere
fits, registration, correction, uncertainty, quality checks, writing, provenance), and
prints every pair's ratio and their median, of wall time and of CPU time (user +
system: it moves less when other work shares the machine). The issue's target is 1.5x.

Both sides run on one BLAS thread: ``hexatherm`` sets ``OPENBLAS_NUM_THREADS`` (and
its kin) to 1 for itself unless the environment sets them, and the floor is given the
same, or it would be charged the CPU its BLAS threads spend starting (0.10-0.15 s of a
0.4 s floor on this 2-core machine) and the CPU ratio would flatter ``process``. With
``--bytecode`` hexatherm's modules are compiled once into ``bench/.cache/pycache/``
(``PYTHONPYCACHEPREFIX``) and read from there, as an installed copy reads them (numpy's
and pandas' are compiled when pip installs them); without it, where the environment
sets ``PYTHONDONTWRITEBYTECODE``, every run compiles them again.

With ``--baseline DIR`` (a checkout of the code before, e.g. ``git worktree add
/tmp/before main``) every pair becomes a triple, the floor, that code and this code,
both run as ``python -m hexatherm`` with ``PYTHONPATH`` set to their checkout, and both
ratios to the floor are printed, with the median of this code's CPU time over that
code's. ``--code DIR`` measures the checkout at ``DIR`` as "now" instead of this one
(a snapshot, e.g. ``git worktree add --detach /tmp/now HEAD``, so that editing this
checkout does not change what a long run measures). Each run writes its own output
folder (``floor-out-<pid>``), so two runs may share ``bench/.cache/``. ``--issue37``
(with ``--baseline``) runs issue 37's three rows one after the other, 1000 targets x 25
points a ball, 10,000 x 25 and the scanning session 1000 x 400, and prints their table:
the CPU ratios to the floor before and now, now over before, and the peak memories.

The second figure, paired the same way (``--plain-pairs``, default 3; 0 leaves it out):
``bench/straightforward.py`` (the same job done the straightforward way: the file read
line by line, one ``least_squares`` per sphere, one ``align_vectors`` per step, one
``root`` per pose; no uncertainty, no quality checks) against ``process``, alternating,
and the median of ``straightforward / process``.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from speed import CACHE, hexatherm_script, scanning_session, session  # noqa: E402

#: as ``hexatherm.cli`` sets them for itself (unless the environment does)
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
#: set by ``--bytecode``: hexatherm's modules compiled once, as installed
BYTECODE = False


#: runs a command and prints its peak resident memory (kB): ``ru_maxrss`` of the children
#: of this small process is that one command's
_PEAK = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
)
#: this run's output folder of ``process`` (its own: runs may share the cache)
OUT = str(CACHE / f"floor-out-{os.getpid()}")
#: the peak memory (MB) of the last run of :func:`timed`
LAST_PEAK_MB = [0.0]


def timed(command: list[str], code: Path | None = None) -> tuple[float, float]:
    """Wall time and CPU time (user + system, of the child) of one run, s; ``code``: a
    checkout to run from (``PYTHONPATH``). One BLAS thread unless the environment says.
    The run's peak resident memory goes to :data:`LAST_PEAK_MB`."""
    env = dict(os.environ)
    for name in BLAS_THREAD_VARIABLES:
        env.setdefault(name, "1")
    if code is not None:
        env["PYTHONPATH"] = str(code)
    if BYTECODE:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(CACHE / "pycache")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", _PEAK, *command],
        check=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        env=env,
        cwd=code,
        text=True,
    )
    wall = time.perf_counter() - start
    LAST_PEAK_MB[0] = int(done.stdout.split()[-1]) / 1024
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=1000)
    parser.add_argument("--pairs", type=int, default=7)
    parser.add_argument("--plain-pairs", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before")
    parser.add_argument("--code", type=Path, help="the checkout measured as now (default: this)")
    parser.add_argument("--bytecode", action="store_true", help="compiled modules, as installed")
    parser.add_argument(
        "--points-per-ball",
        type=int,
        default=25,
        help="a scanning probe's session when above 25 (issue 37: 400, 4 decimals)",
    )
    parser.add_argument(
        "--issue37",
        action="store_true",
        help="with --baseline: the issue's three rows (1000 x 25, 10,000 x 25, 1000 x 400 "
        "points a ball) one after the other, then their table",
    )
    args = parser.parse_args()
    global BYTECODE
    BYTECODE = args.bytecode
    if args.issue37:
        if args.baseline is None:
            parser.error("--issue37 compares with --baseline DIR")
        summaries = []
        for targets, per_ball in ISSUE37_ROWS:
            args.targets, args.points_per_ball = targets, per_ball
            folder, points, floor = _row(targets, per_ball)
            summaries.append(baseline(args, floor, folder, points.name))
        _issue37_table(summaries, args.pairs)
        return
    folder, points, floor = _row(args.targets, args.points_per_ball)
    ours = [*hexatherm_script(), "process", str(folder), "-o", OUT]
    ours.append("--overwrite")
    timed(ours)  # warm the file cache, write the output (and compile the modules) once
    print(
        "one BLAS thread on both sides"
        + (
            "; hexatherm's modules compiled once (as installed)"
            if BYTECODE
            else "; hexatherm's modules compiled at every run unless Python keeps bytecode"
        )
    )
    if args.baseline is not None:
        baseline(args, floor, folder, points.name)
        return
    pairs = []
    for _ in range(args.pairs):
        pairs.append((timed(floor), timed(ours)))
    print(f"process against its floor, {args.targets} targets ({points.name}), {len(pairs)} pairs")
    wall = f"{'floor (s)':>10} {'process (s)':>12} {'ratio':>7}"
    cpu = f"{'CPU floor':>10} {'CPU process':>12} {'ratio':>7}"
    print(f"{wall}   {cpu}")
    for (w_floor, c_floor), (w_ours, c_ours) in pairs:
        print(
            f"{w_floor:10.3f} {w_ours:12.3f} {w_ours / w_floor:7.2f}   "
            f"{c_floor:10.3f} {c_ours:12.3f} {c_ours / c_floor:7.2f}"
        )
    # wall time is what a user waits; CPU time (user + system) moves less when other
    # work shares the machine, so both are printed
    for what, k in (("wall", 0), ("CPU", 1)):
        ratios = [b[k] / a[k] for a, b in pairs]
        median = statistics.median(ratios)
        print(f"{what}: median ratio {median:.2f} (min {min(ratios):.2f}, max {max(ratios):.2f})")
    if args.plain_pairs > 0:
        straightforward(folder, ours, args.plain_pairs)


#: issue 37's rows: (targets, points per ball)
ISSUE37_ROWS = ((1000, 25), (10000, 25), (1000, 400))


def _row(targets: int, per_ball: int) -> tuple[Path, Path, list[str]]:
    """The session folder of a row (simulated once, then cached), its points file and
    the floor's command."""
    folder = session(targets, "points") if per_ball == 25 else scanning_session(targets, per_ball)
    measurement = [p for p in folder.glob("*.csv") if p.name != "temperatures.csv"]
    assert measurement, f"no measurement CSV in {folder}"
    points = measurement[0]
    floor = [sys.executable, "-c", f"import numpy, pandas; pandas.read_csv({str(points)!r})"]
    return folder, points, floor


def _issue37_table(summaries: list[dict[str, float]], pairs: int) -> None:
    """The rows side by side: medians of the CPU ratios and peak memories."""
    print(f"\nissue 37, CPU (user + system), medians of {pairs} alternating triples")
    print(
        f"{'row':>16} {'floor s':>8} {'before/floor':>13} {'now/floor':>10} {'now/before':>11}"
        f" {'floor MB':>9} {'before MB':>10} {'now MB':>7} {'now/floor MB':>13} {'load':>5}"
    )
    for row in summaries:
        print(
            f"{row['name']:>16} {row['floor_s']:8.3f} {row['before_ratio']:13.2f} "
            f"{row['now_ratio']:10.2f} {row['paired']:11.2f} {row['floor_mb']:9.0f} "
            f"{row['before_mb']:10.0f} {row['now_mb']:7.0f} "
            f"{row['now_mb'] / row['floor_mb']:13.2f} {row['load']:5.1f}"
        )


def baseline(
    args: argparse.Namespace, floor: list[str], folder: Path, name: str
) -> dict[str, float]:
    """Alternating triples: the floor, the code at ``args.baseline``, this code."""
    out = OUT
    command = [sys.executable, "-m", "hexatherm", "process", str(folder), "-o", out, "--overwrite"]
    here = args.code or Path(__file__).resolve().parents[1]
    timed(command, args.baseline)  # warm (and compile) both once
    timed(command, here)
    triples = []
    peaks = []  # MB: floor, before, now
    for _ in range(args.pairs):
        runs = []
        peak = []
        for code in (None, args.baseline, here):
            runs.append(timed(floor) if code is None else timed(command, code))
            peak.append(LAST_PEAK_MB[0])
        triples.append(tuple(runs))
        peaks.append(peak)
    print(f"process against its floor, {args.targets} targets ({name}), {len(triples)} triples")
    print(f"baseline: {args.baseline}; load average at the end {os.getloadavg()[0]:.1f}")
    print(f"{'CPU floor':>10} {'before':>8} {'now':>8} {'before/floor':>13} {'now/floor':>10}")
    for (_, floor_cpu), (_, before), (_, now) in triples:
        print(
            f"{floor_cpu:10.3f} {before:8.3f} {now:8.3f} "
            f"{before / floor_cpu:13.2f} {now / floor_cpu:10.2f}"
        )
    for what, k in (("wall", 0), ("CPU", 1)):
        before_r = statistics.median(t[1][k] / t[0][k] for t in triples)
        now_r = statistics.median(t[2][k] / t[0][k] for t in triples)
        paired = statistics.median(t[2][k] / t[1][k] for t in triples)
        print(
            f"{what}: median ratio to the floor, before {before_r:.2f}, now {now_r:.2f}; "
            f"now / before {paired:.2f}"
        )
    floor_mb, before_mb, now_mb = (statistics.median(p[k] for p in peaks) for k in range(3))
    print(
        f"peak memory: floor {floor_mb:.0f} MB, before {before_mb:.0f} MB "
        f"({before_mb / floor_mb:.2f}x), now {now_mb:.0f} MB ({now_mb / floor_mb:.2f}x)"
    )
    return {
        "name": f"{args.targets} x {args.points_per_ball}",
        "floor_s": statistics.median(t[0][1] for t in triples),
        "before_ratio": statistics.median(t[1][1] / t[0][1] for t in triples),
        "now_ratio": statistics.median(t[2][1] / t[0][1] for t in triples),
        "paired": statistics.median(t[2][1] / t[1][1] for t in triples),
        "floor_mb": floor_mb,
        "before_mb": before_mb,
        "now_mb": now_mb,
        "load": os.getloadavg()[0],
    }


def straightforward(folder: Path, ours: list[str], n_pairs: int) -> None:
    """Print ``bench/straightforward.py`` against ``process``, alternating pairs."""
    plain = [
        sys.executable,
        str(Path(__file__).resolve().parent / "straightforward.py"),
        str(folder),
        "-o",
        str(CACHE / "floor-plain"),
    ]
    pairs = [(timed(plain), timed(ours)) for _ in range(n_pairs)]
    print(f"straightforward script against process, {n_pairs} pairs")
    print(f"{'plain (s)':>10} {'process (s)':>12} {'ratio':>7}")
    for (w_plain, _), (w_ours, _) in pairs:
        print(f"{w_plain:10.3f} {w_ours:12.3f} {w_plain / w_ours:7.2f}")
    ratios = [a[0] / b[0] for a, b in pairs]
    print(
        f"wall: median ratio straightforward / process {statistics.median(ratios):.2f} "
        f"(min {min(ratios):.2f}, max {max(ratios):.2f})"
    )


if __name__ == "__main__":
    try:
        main()
    finally:
        shutil.rmtree(OUT, ignore_errors=True)
