"""Monte Carlo speed on a 122-step points campaign (issue 14, part 5).

Simulates ``configs/scenarios/calibration-campaign.yaml`` with probed points (60 targets,
366 balls, 25 points each, 9,150 points) into ``bench/.cache``, then times
``hexatherm process --mc 2000`` and plain ``hexatherm process`` as whole processes,
alternating, and prints each run, the medians and the paired ratio (Monte Carlo over
linear). Target: ``--mc 2000`` under 5 s on this machine.

    python bench/montecarlo.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "bench" / ".cache" / "mc-campaign"


def session() -> Path:
    if (CACHE / "session.yaml").is_file():
        return CACHE
    scenario = (ROOT / "configs" / "scenarios" / "calibration-campaign.yaml").read_text()
    scenario = scenario.replace("output: centres", "output: points")
    scenario = scenario.replace(
        "../symetrie-like.yaml", str(ROOT / "configs" / "symetrie-like.yaml")
    )
    scenario = scenario.replace("../balls-3.yaml", str(ROOT / "configs" / "balls-3.yaml"))
    CACHE.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scenario.yaml"
        path.write_text(scenario)
        subprocess.run(
            [sys.executable, "-m", "hexatherm", "simulate", str(path), "-o", str(CACHE)],
            check=True,
            capture_output=True,
        )
    return CACHE


def timed(*args: str) -> float:
    out = Path(tempfile.mkdtemp())
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "hexatherm", "process", *args, "-o", str(out / "r")],
        check=True,
        capture_output=True,
    )
    elapsed = time.perf_counter() - start
    shutil.rmtree(out)
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    folder = str(session())
    mc, lin = [], []
    for i in range(args.repeat):
        mc.append(timed(folder, "--mc", "2000"))
        lin.append(timed(folder))
        print(f"run {i + 1}: --mc 2000 {mc[-1]:.2f} s, linear {lin[-1]:.2f} s")
    mc.sort()
    lin.sort()
    ratios = sorted(a / b for a, b in zip(mc, lin, strict=True))
    mid = args.repeat // 2
    print(f"median: --mc 2000 {mc[mid]:.2f} s, linear {lin[mid]:.2f} s, ratio {ratios[mid]:.1f}x")


if __name__ == "__main__":
    main()
