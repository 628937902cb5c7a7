"""Issue 35: u without a thermocouple log under heating shapes the twin does not make.

Run with ``python bench/nolog_shapes.py [SEEDS] [CONDITION ...]`` (CONDITION: a part of
a condition's name). Each condition simulates SEEDS twin sessions whose legs follow a
history of ``tests/heatgen.py`` (an independent generator: two time constants, a ramp
then plateau, a step, a periodic air drift, legs heated unevenly) or the twin's own
heating of issue 35's last round (mid-session, a 30 min gap, a target past the last
reference), drops the thermocouple log, processes each with ``--interpolation linear``
and ``smooth``, and prints against the truth of the corrected poses (``truecorr``):
claimed u over the RMS error, Tx Ty Tz Rx Ry Rz, and the share of errors within 2u
(all six components), for linear over every session and for smooth where it was used
(its count said); ``E`` conditions over the target past the last reference alone.
3 balls, 25 points per ball over 70 deg, 1 um point noise, centres fitted, ``cmm:``
stating the probing, steps 200 s apart (3 balls x 60 s, 20 s moves).
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
from smooth_seeds import Config, one, plan_of  # noqa: E402

from hexatherm.workflows.simulate.twinsession import Heating  # noqa: E402
from tests import heatgen  # noqa: E402
from tests.sessions import LEG_GAIN_C  # noqa: E402


def _gap(n: int, seed: int) -> tuple[float, ...]:
    return tuple(1800.0 if i == 7 else 0.0 for i in range(n))


def _pairs(pairs: int) -> Callable[[], object]:
    return lambda: plan_of("TTR" * pairs + "T")


@dataclasses.dataclass(frozen=True)
class Condition:
    config: Config
    last_only: bool = False  # the target past the last reference alone


def _mats(on_s: float) -> Heating:
    return Heating(on_s=on_s, tau_s=600.0, gain_C=LEG_GAIN_C)


CONDITIONS = {
    # the independent generator, 6 targets between 7 references (O 90 s, R0 290 s, ...,
    # R6 2690 s)
    "two time constants (150 s, 3000 s) from 1000 s": Condition(
        Config(heating=heatgen.TwoTimeConstants(), log=False)
    ),
    "two time constants from the start": Condition(
        Config(heating=heatgen.TwoTimeConstants(on_s=0.0), log=False)
    ),
    "ramp 700-1700 s, then plateau": Condition(Config(heating=heatgen.RampPlateau(), log=False)),
    "a step at 1500 s (20 s wide)": Condition(Config(heating=heatgen.SmoothStep(), log=False)),
    "air wave (40 min), legs lagging 0-400 s": Condition(
        Config(heating=heatgen.AirWave(), log=False)
    ),
    "legs heated unevenly (600-1800 s)": Condition(Config(heating=heatgen.Uneven(), log=False)),
    "two time constants, a 30 min gap": Condition(
        Config(heating=heatgen.TwoTimeConstants(), log=False, pauses=_gap)
    ),
    # issue 35's last round, the twin's heating
    "twin: mid-session (mats on 1000 s, tau 600 s)": Condition(
        Config(heating=_mats(1000.0), log=False)
    ),
    "twin: from the start (tau 2400 s)": Condition(
        Config(heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=LEG_GAIN_C), log=False)
    ),
    "twin: no heating, noise only": Condition(
        Config(heating=Heating(gain_C=(0.0,) * 6), log=False)
    ),
    "twin: a 30 min gap": Condition(Config(heating=_mats(1000.0), log=False, pauses=_gap)),
    "E: twin, (TTR) x3, mats on at 1800 s": Condition(
        Config(heating=_mats(1800.0), log=False, plan=_pairs(3)), last_only=True
    ),
    "E: twin, (TTR) x4, mats on at 2100 s": Condition(
        Config(heating=_mats(2100.0), log=False, plan=_pairs(4)), last_only=True
    ),
    "E: two time constants, (TTR) x4, on at 2100 s": Condition(
        Config(heating=heatgen.TwoTimeConstants(on_s=2100.0), log=False, plan=_pairs(4)),
        last_only=True,
    ),
    "E: ramp, (TTR) x4, 1800-2600 s": Condition(
        Config(heating=heatgen.RampPlateau(1800.0, 2600.0), log=False, plan=_pairs(4)),
        last_only=True,
    ),
}


def summary(errors: list[np.ndarray], claimed: list[np.ndarray]) -> str:
    e, u = np.concatenate(errors), np.concatenate(claimed)
    ratio = np.sqrt(np.mean(u**2, axis=0) / np.mean(e**2, axis=0))
    within = float(np.mean(np.abs(e) <= 2 * u))
    return f"{' '.join(f'{r:.2f}' for r in ratio)}  within 2u {within:.0%}"


def main(seeds: int, only: list[str]) -> None:
    for name, cond in CONDITIONS.items():
        if only and not any(x in name for x in only):
            continue
        rows = []
        with tempfile.TemporaryDirectory() as tmp:
            for seed in range(seeds):
                rows.append(one(Path(tmp) / f"r{seed}", seed, cond.config))
        pick = (lambda a: a[-1:]) if cond.last_only else (lambda a: a)
        lin_e = [pick(r[2]) for r in rows]
        lin_u = [pick(r[3]) for r in rows]
        smooth = [r for r in rows if r[0] is not None]
        line = f"{name}: linear {summary(lin_e, lin_u)}"
        if smooth:
            line += (
                f" | smooth ({len(smooth)}/{seeds}) "
                f"{summary([pick(r[0]) for r in smooth], [pick(r[1]) for r in smooth])}"
            )
        print(line, flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 30, sys.argv[2:])
