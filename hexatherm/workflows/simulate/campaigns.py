"""Simulated calibration campaigns with hidden effects, for checking the diagnosis.

A campaign here is what a lab would run to calibrate a hexapod: targets spread
over the workspace, measured in two cycles with a reference between every two
targets, while heating mats on the legs are switched on, off and on again and
the room's air drifts. The session's files know nothing of the hidden effects;
the truth does. The tests of ``hexatherm diagnose`` and ``bench/diagnose.py``
use these; the shipped ``sessions/with-hidden-effect`` is one of them written
as a scenario.

>>> spec = diagnosis_campaign((), seed=3, n_targets=4)
>>> len(spec.plan.labels), spec.point_noise_mm
(18, 0.001)
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib import resources

import numpy as np

from hexatherm.core.effects import Effect
from hexatherm.core.heating import Mat, MatHeating
from hexatherm.core.planning import build_plan
from hexatherm.session import Balls
from hexatherm.workflows.simulate.twinsession import TwinSessionSpec

#: half-widths of the box the targets are drawn from: mm and deg
WORKSPACE = (20.0, 20.0, 15.0, 4.0, 4.0, 8.0)
REFERENCE_POSE = (0.0, 0.0, -40.0, 0.0, 0.0, 0.0)
#: the balls of ``configs/balls-3.yaml``
BALLS = Balls(
    ("B1", "B2", "B3"),
    np.array([[0.0, 90.0, 30.0], [-73.6, -42.5, 30.0], [82.3, -47.5, 30.0]]),
    np.full(3, 25.4),
    True,
    2.0,
)


def hexapod_text() -> str:
    """The hexapod file of the campaigns: ``configs/symetrie-like.yaml``, as shipped inside
    the package (``hexatherm/data``, read with :mod:`importlib.resources`, so that it works
    from an installed wheel; a test keeps the two copies identical)."""
    return resources.files("hexatherm.data").joinpath("symetrie-like.yaml").read_text("utf-8")


def diagnosis_campaign(
    hidden: Sequence[Effect],
    seed: int,
    *,
    n_targets: int = 16,
    cycles: int = 2,
    point_noise_um: float = 1.0,
    air_rise_C: float = 4.0,
    repeatability_um: float = 0.2,
    name: str = "campaign",
) -> TwinSessionSpec:
    """A seeded campaign with ``hidden`` effects applied to the truth.

    Parameters
    ----------
    hidden : sequence of Effect
        Effects the data follows but the session's hexapod file does not name.
    seed : int
        Draws the targets, the mats' gains and all the noise.
    n_targets, cycles : int
        Targets (random in :data:`WORKSPACE`) and how often they are measured.
    point_noise_um : float
        The CMM's noise: standard deviation of each probed point along the
        surface normal. The centres are sphere fits of 25 points per ball on a
        70 degree cap (about 0.3 um per coordinate for 1 um).
    air_rise_C : float
        How much the air warms, by two thirds of the session, before falling back
        by half of it at the end (a day's warming, then the air conditioning).
    repeatability_um : float
        The hexapod's positioning noise per leg and step.

    Returns
    -------
    TwinSessionSpec
        Timing: 3 balls of 60 s and a 20 s move per step; thermocouples every 30 s
        with 0.02 K noise. Heating: mats on from 10 to 80 min and again from
        140 min, plateaus 2 to 9 K, leg time constant 20 min.
    """
    rng = np.random.default_rng([seed, 7])
    targets = rng.uniform(-1.0, 1.0, (n_targets, 6)) * WORKSPACE
    plan = build_plan(targets, REFERENCE_POSE, cycles=cycles)
    n_steps = len(plan.labels)
    duration = n_steps * (3 * 60.0 + 20.0)
    gains = rng.uniform(2.0, 9.0, 6)
    periods = ((600.0, 4800.0), (8400.0, float("inf")))
    heating = MatHeating(
        tuple(Mat(float(g), 1200.0, periods) for g in gains),
        (0.0, 2 * duration / 3, duration),
        (20.0, 20.0 + air_rise_C, 20.0 + air_rise_C / 2),
    )
    return TwinSessionSpec(
        name=name,
        hexapod_text=hexapod_text(),
        balls=BALLS,
        plan=plan,
        heating=heating,
        seconds_per_ball=60.0,
        seconds_per_move=20.0,
        sample_period_s=30.0,
        thermocouple_noise_C=0.02,
        seed=seed,
        points_per_ball=25,
        cap_half_angle_deg=70.0,
        point_noise_mm=point_noise_um * 1e-3,
        fit_centres=True,
        effects=tuple(hidden),
        repeatability_mm=repeatability_um * 1e-3,
    )


#: one hidden effect of each kind, sized to move the measured ball centres by a
#: few micrometres in a campaign of :func:`diagnosis_campaign` (its air warms by
#: 4 K: a base of aluminium, 25e-6/K, gives about 1.5 um)
NOMINAL_HIDDEN: dict[str, dict[str, float]] = {
    "leg_thermal_lag": {"tau_s": 1500.0},
    "steel_overheat": {"ratio": 1.0},
    "leg_cte_error": {
        "leg1": 0.2,
        "leg2": -0.15,
        "leg3": 0.1,
        "leg4": -0.2,
        "leg5": 0.15,
        "leg6": 0.25,
    },
    "base_expansion": {"alpha_per_K": 25e-6},
    "cmm_drift": {"vx_um_per_h": 3.0, "vy_um_per_h": -2.0, "vz_um_per_h": 4.0},
    "leg_offset": {
        "leg1": 0.05,
        "leg2": -0.04,
        "leg3": 0.03,
        "leg4": -0.05,
        "leg5": 0.04,
        "leg6": -0.03,
    },
}
