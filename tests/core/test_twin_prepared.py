"""``predict`` with a :class:`PreparedPlan` (the plan's part computed once, as the twin's
servers predict one pose at every CMM motion) is ``predict`` without one, bit for bit:
with and without effects (a base-joint effect makes the FGM start from the plan's poses
anew), with a true geometry, in and out of the reference state, and through
``TwinWorld.centres_at``, whose prepared poses are the general ``predict``'s answer at
every time."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.calibration import join_parameters
from hexatherm.core.effects import ThermocoupleLog, make_effect
from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.heating import Mat, MatHeating
from hexatherm.core.plan import Plan
from hexatherm.core.twin import PreparedPlan, TwinSteps, predict
from hexatherm.io.config import read_balls, read_hexapod
from hexatherm.workflows.serve import TwinWorld

ROOT = Path(__file__).resolve().parents[2]
HEXAPOD = read_hexapod(ROOT / "configs" / "symetrie-like.yaml")
BALLS = read_balls(ROOT / "configs" / "balls-3.yaml")
ORIGIN2CMM = transform_from_pose([450, 320, 210, 0, 0, 15], HEXAPOD.convention)
RNG = np.random.default_rng(11)
TRUTH = join_parameters(
    HEXAPOD.base_joints_mm + RNG.normal(0, 0.05, (6, 3)),
    HEXAPOD.platform_joints_mm + RNG.normal(0, 0.05, (6, 3)),
    RNG.normal(0, 0.03, 6),
    RNG.normal(0, 2e-4, 6),
)
EFFECTS = {
    "none": (),
    "legs": (
        make_effect("leg_thermal_lag", {"tau_s": 600.0}),
        make_effect("leg_offset", {f"leg{i}": 0.01 * i for i in range(1, 7)}),
        make_effect("cmm_drift", {"vx_um_per_h": 3.0, "vy_um_per_h": -2.0, "vz_um_per_h": 1.0}),
    ),
    "base": (make_effect("base_expansion", {"alpha_per_K": 12e-6}),),
}


def plan_and_log() -> tuple[Plan, np.ndarray, ThermocoupleLog]:
    targets = RNG.uniform(-1, 1, (5, 6)) * [8, 8, 5, 2, 2, 3]
    reference = [0, 0, -10, 0, 0, 0]
    steps = [("O", "origin", np.zeros(6)), ("R0", "reference", reference)]
    for i, pose in enumerate(targets):
        steps += [(f"S{i + 1}", "target", pose), (f"R{i + 1}", "reference", reference)]
    plan = Plan.from_steps(steps)
    t = 300.0 + np.arange(len(plan.labels)) * 90.0
    samples = np.arange(0.0, t.max() + 30.0, 30.0)
    legs = 20.0 + np.outer(1.0 - np.exp(-samples / 2400.0), [3, 5, 2, 4, 7, 2.5])
    return plan, t, ThermocoupleLog(samples, legs, 20.0 + 1e-4 * samples)


def assert_same_bits(a: TwinSteps, b: TwinSteps) -> None:
    for f in fields(TwinSteps):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            assert x.shape == y.shape and x.tobytes() == y.tobytes(), f.name
        else:
            assert x == y, f.name


@pytest.mark.parametrize("effects", sorted(EFFECTS))
@pytest.mark.parametrize("truth", [None, TRUTH], ids=["nominal", "true-geometry"])
@pytest.mark.parametrize("reference_state", [True, False])
def test_a_prepared_plan_predicts_the_same_bits(
    effects: str, truth: np.ndarray | None, reference_state: bool
) -> None:
    plan, t, log = plan_and_log()
    args = (HEXAPOD, plan, t, log, BALLS.centres_mm, ORIGIN2CMM, EFFECTS[effects])
    kw = {"reference_state": reference_state, "true_parameters": truth}
    plain = predict(*args, **kw)  # type: ignore[arg-type]
    prepared = PreparedPlan.of(HEXAPOD, plan, truth)
    assert prepared.start is not None
    for _ in range(2):  # and again: nothing of a call stays in the prepared plan
        assert_same_bits(predict(*args, **kw, prepared=prepared), plain)  # type: ignore[arg-type]
    # the effects moved the truth: the bits compared are not the trivial ones
    if effects != "none":
        other = predict(*args[:-1], **kw)  # type: ignore[arg-type]
        assert np.abs(other.centres_cmm_mm - plain.centres_cmm_mm).max() > 1e-4


def test_a_prepared_plan_of_another_plan_is_refused() -> None:
    plan, t, log = plan_and_log()
    other = Plan.from_steps([("O", "origin", np.zeros(6))])
    with pytest.raises(ValueError, match="another plan"):
        predict(
            HEXAPOD,
            plan,
            t,
            log,
            BALLS.centres_mm,
            ORIGIN2CMM,
            prepared=PreparedPlan.of(HEXAPOD, other),
        )


def world_of(heating: MatHeating, effects: str = "none", start_s: float = -1200.0) -> TwinWorld:
    """A twin world of the true geometry :data:`TRUTH` with ``heating`` and ``effects``."""
    return TwinWorld(
        HEXAPOD,
        BALLS,
        heating=heating,
        origin_on_cmm=[450.4, 320.3, 210.2, 0.1, -0.1, 15.2],
        effects=EFFECTS[effects],
        clock=lambda: 0.0,
        start_s=start_s,
        true_parameters=TRUTH,
    )


def own_prediction(world: TwinWorld, pose: np.ndarray, time_s: float) -> np.ndarray:
    """A one-step ``predict`` of ``pose`` from ``world``'s own log at ``time_s``: its
    balls on the CMM."""
    log = world.log(time_s)
    plan = Plan.from_steps([("O", "origin", [float(v) for v in pose])])
    return predict(
        HEXAPOD,
        plan,
        [log.times_s[-1]],
        log,
        BALLS.centres_mm,
        world.origin2cmm,
        world.effects,
        reference_state=False,
        true_parameters=TRUTH,
    ).measured_centres_cmm_mm[0]


@pytest.mark.parametrize("effects", ["none", "legs"])
def test_the_twins_balls_are_the_general_predictions_at_every_time(effects: str) -> None:
    """``centres_at`` keeps the poses it prepared; at each of many times and poses,
    visited and visited again, its centres are a one-step ``predict`` of its own log."""
    heating = MatHeating(tuple(Mat(g, 2400.0, ((0.0, np.inf),)) for g in (8, 12, 5, 10, 16, 6)))
    world = world_of(heating, effects)
    poses = RNG.uniform(-1, 1, (3, 6)) * [8, 8, 5, 2, 2, 3]
    for k, time_s in enumerate(np.arange(0.0, 600.0, 37.0)):
        pose = poses[k % 3]
        got = world.centres_at(pose, time_s)
        want = own_prediction(world, pose, time_s)
        assert got.tobytes() == want.tobytes()
    assert len(world._plans) == 3


def test_a_still_worlds_balls_are_predicted_once_per_pose_and_are_the_predictions() -> None:
    """Without effects the twin's centres rest on the pose and the legs' temperatures: while
    the mats are off (still legs) ``centres_at`` predicts each pose once, and once they
    heat, at every time; at every time and pose its centres are a one-step ``predict`` of
    its own log, bit for bit."""
    heating = MatHeating(tuple(Mat(g, 2400.0, ((300.0, np.inf),)) for g in (8, 12, 5, 10, 16, 6)))
    world = world_of(heating, start_s=0.0)
    predicted = []
    own = world._predict

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        predicted.append(args[1][0])
        return own(*args, **kwargs)

    world._predict = counted  # type: ignore[method-assign]
    poses = RNG.uniform(-1, 1, (3, 6)) * [8, 8, 5, 2, 2, 3]
    times = np.arange(0.0, 600.0, 23.0)
    for k, time_s in enumerate(times):
        pose = poses[k % 3]
        got = world.centres_at(pose, time_s)
        want = own_prediction(world, pose, time_s)
        assert got.tobytes() == want.tobytes()
    still = times[times <= 300.0]
    assert len(still) > 6  # each pose visited again while still
    # the mats come on at 300 s: before, one prediction per pose; after, one per time
    assert predicted == [*still[:3], *times[times > 300.0]]
