"""Issue 35 items 3-4: the carry of O to R0's thermal state, claimed/observed over seeds.

Run with ``python bench/carry_seeds.py [SEEDS] [CASE ...]`` (CASE: ``x4-log``, ``x4``,
``once``, ``once-log``; default all). Each case simulates SEEDS sessions under the
conditions of ``tests/workflows/test_repeats_heating.py`` (O and R0 measured 4 times or
once, 6 targets, heating from the start, tau 2400 s, 1 um point noise, 25 points over 70
deg, fitted centres, ``cmm:`` given, linear interpolation), with or without the
thermocouple log, processes each, and prints against the twin's truth of the corrected
poses (Tx Ty Tz Rx Ry Rz): the RMS error (um, urad), the mean error over its standard
error, the claimed u over the RMS error, the share of errors within 2u, and the claimed
u over the errors' scatter over the seeds (target by target: the noise alone, each
target's bias taken off).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from tests.workflows.test_repeats_heating import errors_and_claims  # noqa: E402

CASES = {"x4-log": (4, True), "x4": (4, False), "once": (1, False), "once-log": (1, True)}


def main() -> None:
    seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    cases = sys.argv[2:] or list(CASES)
    with tempfile.TemporaryDirectory() as tmp:
        for name in cases:
            repeats, log = CASES[name]
            e, u = errors_and_claims(Path(tmp) / name, range(seeds), log, repeats)
            rms = np.sqrt((e**2).mean(axis=(0, 1)))
            t = e.mean(axis=(0, 1)) / (e.std(axis=(0, 1), ddof=1) / np.sqrt(e[..., 0].size))
            ratio = np.sqrt((u**2).mean(axis=(0, 1))) / rms
            within = float((np.abs(e) <= 2 * u).mean())
            scatter = np.sqrt(e.var(axis=0, ddof=1).mean(axis=0))  # per target over seeds
            print(
                f"{name:9s} rms {np.round(rms, 2)}  t {np.round(t, 1)}  "
                f"claimed/observed {np.round(ratio, 2)}  within 2u {within:.1%}  "
                f"claimed/scatter {np.round(np.sqrt((u**2).mean(axis=(0, 1))) / scatter, 2)}",
                flush=True,
            )


if __name__ == "__main__":
    main()
