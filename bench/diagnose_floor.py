"""`diagnose` on 16 targets against its floor, in CPU seconds (issue 37, item 3).

The floor is what any program that diagnoses like ``hexatherm diagnose`` must do, whatever
it computes: start Python, import numpy, pandas (the CSV reader), ``scipy.optimize``
(``least_squares``) and matplotlib's Figure and Agg canvas. The second floor adds one
figure like diagnose's first, with matplotlib's defaults: 6 x 2 panels of one 66-step line
each, saved as a PNG at 150 dpi. Each is a whole child process, one BLAS thread, run in
alternating triples with ``hexatherm diagnose`` on ``bench/analyses.py``'s 16-target
session (``--code DIR``: the code run, default this checkout).

    python bench/diagnose_floor.py [--triples 5] [--code DIR]
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


def cpu_seconds(args: list[str], code: Path) -> float:
    """CPU seconds (user + system) of the child ``python ARGS`` (one BLAS thread)."""
    env = dict(os.environ, PYTHONPATH=str(code), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, *args], cwd=code, env=env, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--triples", type=int, default=5)
    parser.add_argument("--code", type=Path, default=ROOT, help="the checkout run")
    args = parser.parse_args()
    from analyses import diagnosis_session, median  # type: ignore[import-not-found]

    session = diagnosis_session(16)
    print(f"load average at the start: {os.getloadavg()[0]:.1f}")
    rows: dict[str, list[float]] = {"imports": [], "imports + one figure": [], "diagnose": []}
    for _ in range(args.triples):
        rows["imports"].append(cpu_seconds(["-c", IMPORTS], args.code))
        rows["imports + one figure"].append(cpu_seconds(["-c", IMPORTS + FIGURE], args.code))
        out = Path(tempfile.mkdtemp())
        command = ["-m", "hexatherm", "diagnose", str(session), "-o", str(out / "out")]
        rows["diagnose"].append(cpu_seconds(command, args.code))
        shutil.rmtree(out)
    print("| | CPU, median (s) | range (s) | diagnose / it (median of triples) |")
    print("|---|---:|---:|---:|")
    for name, values in rows.items():
        ratio = median([d / v for d, v in zip(rows["diagnose"], values, strict=True)])
        print(
            f"| {name} | {median(values):.2f} | {min(values):.2f}-{max(values):.2f} "
            f"| {ratio:.2f}x |"
        )
    print(f"load average at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
