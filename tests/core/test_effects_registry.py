"""The vectorized first-order lag and the wider registry of effects (issue 14, part 3)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.diagnosis import Observations, fit_model, rms_um
from hexatherm.core.effects import (
    EFFECTS,
    LegBacklash,
    ThermocoupleLog,
    first_order_lag,
    make_effect,
)
from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.core.registration import register
from hexatherm.core.twin import predict, twin_corrected
from tests.conftest import BALLS, make_hexapod, make_plan

ORIGIN2CMM = transform_from_pose([420.0, 310.0, 180.0, 0.3, -0.2, 35.0])
TARGETS = np.array([[5.0, -3.0, 4.0, 1.0, -2.0, 3.0], [-8.0, 6.0, -5.0, -2.5, 1.5, -4.0]])
LEGS = tuple(f"leg{i}" for i in range(1, 7))
NEW = ("ball_plate_expansion", "leg_growth_quadratic", "cmm_scale", "leg_backlash")
#: a value of each new effect's parameters, well inside their ranges
VALUES = {
    "ball_plate_expansion": {"alpha_per_K": 23e-6},
    "leg_growth_quadratic": dict(zip(LEGS, [0.2, -0.1, 0.05, 0.3, -0.25, 0.15], strict=True)),
    "cmm_scale": {"sx_ppm": 20.0, "sy_ppm": -15.0, "sz_ppm": 30.0},
    "leg_backlash": dict(zip(LEGS, [0.002, -0.001, 0.0015, 0.001, -0.002, 0.0005], strict=True)),
}


def lag_by_loop(times_s, values, tau_s, query_s):
    """The lag as it was computed before: the exact per-segment solution, sample by
    sample in a Python loop (the reference)."""
    t = np.asarray(times_s, dtype=float)
    x = np.asarray(values, dtype=float)
    flat = x.ndim == 1
    x = x.reshape(t.size, -1)
    h = np.diff(t)
    slope = np.zeros((t.size, x.shape[1]))
    moving = h > 0
    slope[:-1][moving] = np.diff(x, axis=0)[moving] / h[moving, None]

    def advance(y_j, x_j, b, d):
        decay = np.exp(-d / tau_s)
        rise = -np.expm1(-d / tau_s)
        return x_j + b * (d - tau_s * rise) + (y_j - x_j) * decay

    y = np.empty_like(x)
    y[0] = x[0]
    for j in range(t.size - 1):
        y[j + 1] = advance(y[j], x[j], slope[j], np.array(h[j]))
    q = np.asarray(query_s, dtype=float).reshape(-1)
    seg = np.clip(np.searchsorted(t, q, side="right") - 1, 0, t.size - 1)
    d = np.clip(q - t[seg], 0.0, None)[:, None]
    out = advance(y[seg], x[seg], slope[seg], d)
    return out[:, 0] if flat else out


@pytest.mark.parametrize("tau_s", [1.0, 120.0, 1800.0, 14400.0, 86400.0])
@pytest.mark.parametrize("m", [1, 2, 3, 7, 64, 1500])
def test_lag_equals_the_loop(tau_s, m):
    rng = np.random.default_rng(m)
    gaps = np.where(rng.random(m) < 0.15, 0.0, rng.uniform(1.0, 60.0, m))
    t = 1000.0 + np.cumsum(gaps)  # uneven, some times repeated
    x = 20.0 + np.cumsum(rng.normal(0, 0.3, (m, 6)), axis=0)
    query = np.concatenate([rng.uniform(t[0] - 100, t[-1] + 500, 300), t])
    got = first_order_lag(t, x, tau_s, query)
    np.testing.assert_allclose(got, lag_by_loop(t, x, tau_s, query), atol=1e-12, rtol=0)
    one = first_order_lag(t, x[:, 2], tau_s, query)
    np.testing.assert_allclose(one, lag_by_loop(t, x[:, 2], tau_s, query), atol=1e-12, rtol=0)


def test_lag_of_a_step_is_the_exponential():
    """A second truth: a step at t = 0 held afterwards relaxes as 1 - exp(-t/tau)."""
    t = np.array([-1e-9, 0.0, 1e5])
    x = np.array([0.0, 1.0, 1.0])
    query = np.linspace(0.0, 5000.0, 11)
    got = first_order_lag(t, x, 600.0, query)
    np.testing.assert_allclose(got, 1.0 - np.exp(-query / 600.0), atol=1e-12, rtol=0)


# ------------------------------------------------------------------ new effects
@pytest.fixture
def case():
    """Hexapod, plan (O R0 S1 R1 S2 R2), step times and a log of heated legs and air."""
    hexapod = make_hexapod()
    plan = make_plan(TARGETS)
    times = np.array([300.0, 900.0, 1500.0, 2100.0, 2700.0, 3300.0])
    log_t = np.array([0.0, 600.0, 1200.0, 2400.0, 3600.0])
    rise = np.array(
        [
            [0, 0, 0, 0, 0, 0],
            [1, 2, 0.5, 1, 3, 1],
            [2, 4, 1, 2, 5, 1.5],
            [3, 6, 1.5, 2.5, 8, 2],
            [3.5, 7, 2, 3, 9, 3.5],
        ]
    )
    log = ThermocoupleLog(log_t, 21.0 + rise, [20.0, 20.4, 20.8, 21.6, 22.4])
    return hexapod, plan, times, log


def run(case, *effects, **kwargs):
    hexapod, plan, times, log = case
    return predict(hexapod, plan, times, log, BALLS, ORIGIN2CMM, effects, **kwargs)


def test_the_registry_has_the_new_effects_with_ranges():
    for name in NEW:
        cls = EFFECTS[name]
        assert len(cls.parameters) == len(cls.units) == len(cls.ranges) == len(VALUES[name])
        assert all(lo < hi for lo, hi in cls.ranges)
        assert make_effect(name, VALUES[name]).out_of_range() == {}
        too_big = {p: 2 * hi - lo for p, (lo, hi) in zip(cls.parameters, cls.ranges, strict=True)}
        assert set(make_effect(name, too_big).out_of_range()) == set(cls.parameters)
        neutral = cls.from_vector(cls.neutral())
        assert all(v == 0.0 for v in neutral.values.values())
    assert EFFECTS["ball_plate_expansion"].needs_air


@pytest.mark.parametrize("name", NEW)
def test_zero_parameters_give_exactly_the_baseline(case, name):
    base = run(case)
    zero = run(case, EFFECTS[name].from_vector(np.zeros(len(EFFECTS[name].parameters))))
    for field in ("q_mm", "pose", "corrected_pose", "centres_cmm_mm", "measured_centres_cmm_mm"):
        np.testing.assert_array_equal(getattr(zero, field), getattr(base, field), err_msg=field)


def test_ball_plate_expansion_by_hand(case):
    hexapod, plan, times, log = case
    alpha = VALUES["ball_plate_expansion"]["alpha_per_K"]
    ball_t = times[:, None] + np.array([0.0, 40.0, 80.0])
    base = run(case, ball_times_s=ball_t)
    got = run(
        case,
        make_effect("ball_plate_expansion", VALUES["ball_plate_expansion"]),
        ball_times_s=ball_t,
    )
    # the platform does not move; each ball sits scaled about the platform origin
    np.testing.assert_array_equal(got.q_mm, base.q_mm)
    d_air = np.interp(ball_t, log.times_s, log.air_C) - 20.0
    balls = (1.0 + alpha * d_air)[..., None] * BALLS
    frames = ORIGIN2CMM @ base.platform2origin_nominal
    expected = np.einsum("nij,nkj->nki", frames[:, :3, :3], balls) + frames[:, None, :3, 3]
    np.testing.assert_allclose(got.centres_cmm_mm, expected, atol=1e-12, rtol=0)
    # a distance between two balls grows by alpha dT times its length (about 1e-4 mm here)
    grown = np.linalg.norm(got.centres_cmm_mm[-1, 0] - got.centres_cmm_mm[-1, 1])
    assert grown - np.linalg.norm(BALLS[0] - BALLS[1]) > 1e-5


def test_leg_growth_quadratic_by_hand(case):
    hexapod, plan, times, log = case
    c_um = np.array(list(VALUES["leg_growth_quadratic"].values()))
    base = run(case)
    got = run(case, make_effect("leg_growth_quadratic", VALUES["leg_growth_quadratic"]))
    temps = np.column_stack([np.interp(times, log.times_s, log.legs_C[:, i]) for i in range(6)])
    extra_mm = 1e-3 * c_um * (temps - 20.0) ** 2  # the leg model's reference is 20 C
    np.testing.assert_allclose(got.q_mm - base.q_mm, extra_mm, atol=1e-13, rtol=0)
    # the reference state: every step at the first reference's temperatures
    r = got.reference_index
    np.testing.assert_allclose(
        got.reference_q_mm - base.reference_q_mm,
        np.broadcast_to(extra_mm[r], (6, 6)),
        atol=1e-13,
        rtol=0,
    )
    # with a lag the quadratic term follows the lagged temperature
    lag = make_effect("leg_thermal_lag", {"tau_s": 600.0})
    both = run(case, lag, make_effect("leg_growth_quadratic", VALUES["leg_growth_quadratic"]))
    lagged = first_order_lag(log.times_s, log.legs_C, 600.0, times)
    np.testing.assert_allclose(
        both.q_mm - run(case, lag).q_mm, 1e-3 * c_um * (lagged - 20.0) ** 2, atol=1e-13, rtol=0
    )


def test_cmm_scale_by_hand(case):
    got = run(case, make_effect("cmm_scale", VALUES["cmm_scale"]))
    scale = 1.0 + 1e-6 * np.array([20.0, -15.0, 30.0])
    np.testing.assert_allclose(
        got.measured_centres_cmm_mm, got.centres_cmm_mm * scale, atol=1e-12, rtol=0
    )
    np.testing.assert_array_equal(got.centres_cmm_mm, run(case).centres_cmm_mm)


def test_leg_backlash_by_hand():
    """Down 10 mm (every leg shorter), stay, up 10 mm (longer), down, up and turned."""
    hexapod = make_hexapod()
    down, up, turned = [0, 0, -10.0, 0, 0, 0], [0, 0, 10.0, 0, 0, 0], [0, 0, 10.0, 0, 0, 3.0]
    steps = [("O", "origin", [0.0] * 6), ("R0", "reference", down), ("S1", "target", down)]
    steps += [("R1", "reference", down), ("S2", "target", up), ("R2", "reference", down)]
    steps += [("S3", "target", turned), ("R3", "reference", down)]
    plan = Plan.from_steps(steps, reference_pose=down)
    q_cmd = hexapod.igm(plan.poses)
    signs = np.array([[0.0] * 6] + [[-1.0] * 6] * 3 + [[1.0] * 6, [-1.0] * 6])
    signs = np.vstack([signs, np.sign(q_cmd[6] - q_cmd[5]), [-1.0] * 6])
    b = np.array(list(VALUES["leg_backlash"].values()))
    log = ThermocoupleLog([0.0, 1e4], [[20.0] * 6] * 2, [20.0, 20.0])
    times = np.arange(8) * 100.0
    effect = make_effect("leg_backlash", VALUES["leg_backlash"])
    got = predict(hexapod, plan, times, log, BALLS, ORIGIN2CMM, [effect])
    np.testing.assert_allclose(got.q_mm - q_cmd, signs * b, atol=1e-13, rtol=0)
    # not thermal: the same in the reference state
    np.testing.assert_allclose(got.reference_q_mm - q_cmd, signs * b, atol=1e-13, rtol=0)
    # the order of the moves is the order in time, not in the plan
    later = predict(hexapod, plan, times[::-1], log, BALLS, ORIGIN2CMM, [effect])
    back = LegBacklash.directions(q_cmd, np.arange(8)[::-1])
    np.testing.assert_allclose(later.q_mm - q_cmd, back * b, atol=1e-13, rtol=0)
    assert np.all(back[7] == 0) and np.all(back[6] == np.sign(q_cmd[6] - q_cmd[7]))
    assert np.all(back[1] == -1.0) and np.all(back[0] == 1.0)  # R0 after S1: stays; O: up


@pytest.mark.parametrize("name", NEW)
def test_the_twin_corrects_with_each_effect(case, name):
    """Measured centres from a twin with the effect, corrected by a twin with it: the
    true corrected pose (the measurement side of each effect taken off)."""
    hexapod, plan, times, log = case
    effect = make_effect(name, VALUES[name])
    truth = run(case, effect)
    frames = register(truth.measured_centres_cmm_mm, BALLS).platform2cmm
    got = twin_corrected(hexapod, plan, times, log, BALLS, frames, [effect])
    # a scale about the CMM origin is not rigid: the twin places O at the measured
    # origin frame, itself off by the scale (ppm x 0.5 m); second order, below 1 nm
    atol = 1e-6 if name == "cmm_scale" else 1e-9
    np.testing.assert_allclose(got[:, :3], truth.corrected_pose[:, :3], atol=atol, rtol=0)
    np.testing.assert_allclose(got[:, 3:], truth.corrected_pose[:, 3:], atol=atol, rtol=0)


@pytest.mark.parametrize("name", NEW)
def test_the_diagnosis_fits_each_effect(case, name):
    """The diagnosis's fit (its candidates are the registry) recovers each effect's
    parameters from noise-free centres simulated with it."""
    hexapod, plan, times, log = case
    targets = np.random.default_rng(5).uniform(-1, 1, (10, 6)) * [15, 15, 8, 4, 4, 8]
    plan = make_plan(targets)
    times = np.linspace(100.0, 3500.0, len(plan.labels))
    effect = make_effect(name, VALUES[name])
    truth = predict(hexapod, plan, times, log, BALLS, ORIGIN2CMM, [effect])
    obs = Observations(plan, times, truth.measured_centres_cmm_mm, BALLS, log, 1e-3)
    fit = fit_model(hexapod, obs, (), [EFFECTS[name]])
    np.testing.assert_allclose(
        fit.effects[0].vector(),
        effect.vector(),
        rtol=1e-3,
        atol=float(1e-3 * EFFECTS[name].scales()[0]),
    )
    assert rms_um(fit.residual_mm) < 0.01
