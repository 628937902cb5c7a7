"""`diagnose` on 16 targets against its floor, in CPU seconds (issue 37, item 3).

The floor is what any program that diagnoses like ``hexatherm diagnose`` must do, whatever
it computes: start Python, import numpy, pandas (the CSV reader), ``scipy.optimize``
(``least_squares``) and matplotlib's Figure and Agg canvas. The second floor adds one
figure like diagnose's first, with matplotlib's defaults: 6 x 2 panels of one 66-step line
each, saved as a PNG at 150 dpi. Each is a whole child process, one BLAS thread, run in
alternating triples with ``hexatherm diagnose`` on ``bench/analyses.py``'s 16-target
session (``--code DIR``: the code run, default this checkout). With ``--baseline DIR`` (a
checkout of the code before) ``diagnose`` of that code runs in each round too (before
and now in turn first), and the median of now over before is printed; each round is
printed as it ends, with the load average then and its own now / before. With
``--bytecode`` hexatherm's modules are compiled once into ``bench/.cache/pycache/`` and
read from there, as an installed copy reads them (numpy's, scipy's and matplotlib's are
compiled when pip installs them).

    python bench/diagnose_floor.py [--triples 5] [--code DIR] [--baseline DIR] [--bytecode]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

IMPORTS = (
    "import numpy, pandas, scipy.optimize\n"
    "import matplotlib.figure, matplotlib.backends.backend_agg\n"
)

FIGURE = """
import io
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

fig = Figure(figsize=(11.5, 11.0))
FigureCanvasAgg(fig)
x = np.linspace(0.0, 3.6, 66)
for k, ax in enumerate(fig.subplots(6, 2, sharex=True).flat):
    ax.plot(x, np.sin(x * (k + 1)), "o-", markersize=3, linewidth=0.8)
fig.savefig(io.BytesIO(), format="png", dpi=150)
"""


#: set by ``--bytecode``: hexatherm's modules compiled once, as installed
BYTECODE = [False]


def cpu_seconds(args: list[str], code: Path) -> float:
    """CPU seconds (user + system) of the child ``python ARGS`` (one BLAS thread)."""
    env = dict(os.environ, PYTHONPATH=str(code), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    if BYTECODE[0]:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(ROOT / "bench" / ".cache" / "pycache")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, *args], cwd=code, env=env, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _diagnose(session: Path, code: Path) -> float:
    """CPU seconds of ``hexatherm diagnose`` of ``session`` run from ``code``."""
    out = Path(tempfile.mkdtemp())
    try:
        command = ["-m", "hexatherm", "diagnose", str(session), "-o", str(out / "out")]
        return cpu_seconds(command, code)
    finally:
        shutil.rmtree(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triples", type=int, default=5)
    parser.add_argument("--code", type=Path, default=ROOT, help="the checkout run")
    parser.add_argument("--baseline", type=Path, help="a checkout of the code before")
    parser.add_argument("--bytecode", action="store_true", help="compiled modules, as installed")
    args = parser.parse_args()
    BYTECODE[0] = args.bytecode
    from analyses import diagnosis_session, median  # type: ignore[import-not-found]

    session = diagnosis_session(16)
    print(f"load average at the start: {os.getloadavg()[0]:.1f}")
    rows: dict[str, list[float]] = {"imports": [], "imports + one figure": []}
    codes = {"diagnose": args.code}
    if args.baseline is not None:
        codes = {"diagnose before": args.baseline, **codes}
    rows.update({name: [] for name in codes})
    for code in codes.values():  # once each first: compiled (with --bytecode), files cached
        _diagnose(session, code)
    for round_ in range(args.triples):
        rows["imports"].append(cpu_seconds(["-c", IMPORTS], args.code))
        rows["imports + one figure"].append(cpu_seconds(["-c", IMPORTS + FIGURE], args.code))
        # before and now in turn first (one order kept in every round, load 9-10: now /
        # before 1.05; the same codes in turn: 0.98)
        for name, code in sorted(codes.items(), reverse=bool(round_ % 2)):
            rows[name].append(_diagnose(session, code))
        # each round as it ends, with the load then (a shared machine's load moves)
        times = ", ".join(f"{name} {values[-1]:.2f} s" for name, values in rows.items())
        paired = ""
        if args.baseline is not None:
            paired = f"; now / before {rows['diagnose'][-1] / rows['diagnose before'][-1]:.3f}"
        print(f"round {round_ + 1}, load {os.getloadavg()[0]:.1f}: {times}{paired}", flush=True)
    print("| | CPU, median (s) | range (s) | diagnose / it (median of triples) |")
    print("|---|---:|---:|---:|")
    for name, values in rows.items():
        ratio = median([d / v for d, v in zip(rows["diagnose"], values, strict=True)])
        print(
            f"| {name} | {median(values):.2f} | {min(values):.2f}-{max(values):.2f} "
            f"| {ratio:.2f}x |"
        )
    if args.baseline is not None:
        paired = median(
            [n / b for n, b in zip(rows["diagnose"], rows["diagnose before"], strict=True)]
        )
        print(f"diagnose now / before, median of the rounds: {paired:.2f}")
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
