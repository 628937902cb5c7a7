"""What reading a scanning session's DMIS output costs, paired against the code before
(a script, not a test; issue 37, item 2).

Run with ``python bench/dmis_read.py [--targets 1000] [--per-ball 400] [--pairs 3]
[--baseline DIR]``. It writes (once, cached in ``bench/.cache/``) the DMIS output of a
scanning campaign as a CMM would report it: O, R0, then every target followed by a
reference (2 N + 2 steps), 3 balls, ``--per-ball`` points per ball on a 70 deg cap of a
12.7 mm ball, 100 points a second, a ``DATE=``/``TIME=`` pair whenever the second changes,
each point ``FA(<step>_<ball>_<n>)=FEAT/POINT,CART,x,y,z,i,j,k`` (coordinates at 4
decimals, directions at 6) followed by its ``OUTPUT/FA(...)``, CRLF line ends, ``ENDFIL``
(1000 targets x 400 points: 2.4 million points, about 330 MB).

Each run is a fresh interpreter (``PYTHONPATH`` set to the checkout) that imports numpy,
pandas and the reader, then calls :func:`hexatherm.io.dmis.read_dmis` once; it reports
the read's wall and CPU time and the process's peak resident memory (``ru_maxrss``),
with the peak before the read (the imports) beside it. With ``--baseline DIR`` (a
checkout of the code before: ``git archive eaad5b3 | tar -x -C DIR``) the two
checkouts run alternately ``--pairs`` times and the medians of the paired ratios (now /
before) are printed: the machine is shared, so only paired ratios mean much; its load
is printed at the start and the end.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "bench" / ".cache"

CHILD = """
import json, resource, sys, time
import numpy, pandas
from hexatherm.io.dmis import read_dmis
peak_imports = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
wall, cpu = time.perf_counter(), time.process_time()
records = read_dmis(sys.argv[1])
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
print(json.dumps({
    "wall_s": wall, "cpu_s": cpu, "points": sum(len(r) for r in records),
    "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "imports_mb": peak_imports / 1024,
}))
"""


def step_names(n_targets: int) -> list[str]:
    names = ["O", "R0"]
    for i in range(1, n_targets + 1):
        names += [f"T{i}", f"R{i}"]
    return names


def write_scanning_dmis(path: Path, n_targets: int, per_ball: int, seed: int = 7) -> None:
    """The DMIS output of a simulated scanning campaign (see the module's notes)."""
    rng = np.random.default_rng(seed)
    balls = np.array([[400.0, 300.0, 200.0], [480.0, 330.0, 205.0], [440.0, 250.0, 210.0]])
    start = datetime(2024, 3, 5, 7, 30, tzinfo=UTC).timestamp()
    clock = start
    last_stamp = None
    tmp = path.with_suffix(".part")
    with open(tmp, "w", newline="\r\n") as out:
        out.write("DMISMN/'hexatherm scanning bench',04.0\nUNITS/MM,ANGDEC\n")
        out.write(f"FILNAM/'scan-{n_targets}-{per_ball}'\n")
        for step in step_names(n_targets):
            shift = rng.uniform(-20, 20, 3)
            clock += 20.0  # the move
            for b, centre in enumerate(balls + shift, start=1):
                polar = np.radians(70) * np.sqrt(rng.uniform(0, 1, per_ball))
                azimuth = rng.uniform(0, 2 * np.pi, per_ball)
                normal = np.column_stack(
                    (
                        np.sin(polar) * np.cos(azimuth),
                        np.sin(polar) * np.sin(azimuth),
                        np.cos(polar),
                    )
                )
                xyz = centre + 6.35 * normal + rng.normal(0, 5e-4, (per_ball, 3))
                for n in range(per_ball):
                    clock += 0.01
                    moment = datetime.fromtimestamp(int(clock), tz=UTC)
                    stamp = moment.strftime("DATE=%Y/%m/%d\nTIME=%H:%M:%S\n")
                    if stamp != last_stamp:
                        out.write(stamp)
                        last_stamp = stamp
                    x, y, z = xyz[n]
                    i, j, k = normal[n]
                    label = f"{step}_B{b}_{n + 1}"
                    out.write(
                        f"FA({label})=FEAT/POINT,CART,{x:.4f},{y:.4f},{z:.4f},"
                        f"{i:.6f},{j:.6f},{k:.6f}\nOUTPUT/FA({label})\n"
                    )
        out.write("ENDFIL\n")
    tmp.replace(path)


def dmis_file(n_targets: int, per_ball: int) -> Path:
    path = CACHE / f"scan-{n_targets}x{per_ball}.dmo"
    if not path.exists():
        CACHE.mkdir(parents=True, exist_ok=True)
        print(f"writing {path} ...", file=sys.stderr, flush=True)
        write_scanning_dmis(path, n_targets, per_ball)
    return path


def read_in_child(code: Path, path: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(code), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    done = subprocess.run(
        [sys.executable, "-c", CHILD, str(path)],
        env=env,
        cwd=code,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=1000)
    parser.add_argument("--per-ball", type=int, default=400)
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before")
    args = parser.parse_args()
    path = dmis_file(args.targets, args.per_ball)
    print(f"file: {path.name}, {path.stat().st_size / 1e6:.0f} MB")
    print(f"load average at the start: {os.getloadavg()[0]:.1f} (2 cores)")
    runs: dict[str, list[dict[str, float]]] = {"before": [], "now": []}
    for _ in range(args.pairs):
        if args.baseline:
            runs["before"].append(read_in_child(args.baseline, path))
        runs["now"].append(read_in_child(ROOT, path))
    keys = ("wall_s", "cpu_s", "peak_mb", "imports_mb")
    print("| code | points | " + " | ".join(keys) + " |")
    print("|---|---:|" + "---:|" * len(keys))
    for name, results in runs.items():
        if results:
            medians = [statistics.median(r[k] for r in results) for k in keys]
            cells = " | ".join(
                f"{m:.2f}" if k.endswith("_s") else f"{m:.0f}"
                for k, m in zip(keys, medians, strict=True)
            )
            print(f"| {name} | {int(results[0]['points']):,} | {cells} |")
    if args.baseline:
        ratios = {
            k: statistics.median(
                n[k] / b[k] for n, b in zip(runs["now"], runs["before"], strict=True)
            )
            for k in ("wall_s", "cpu_s", "peak_mb")
        }
        print(
            f"median of the {args.pairs} paired ratios now/before: "
            + ", ".join(f"{k} {v:.2f}" for k, v in ratios.items())
        )
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
