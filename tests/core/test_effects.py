"""The twin's effects: each changes the truth by its analytic size on a hand-checked case."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.effects import (
    EFFECTS,
    Effect,
    ThermocoupleLog,
    first_order_lag,
    make_effect,
)
from hexatherm.core.geometry import pose_from_transform, transform_from_pose
from hexatherm.core.twin import cmm_readings, predict, predict_steps
from hexatherm.io.config import EFFECT_PARAMETERS
from tests.conftest import BALLS, make_hexapod, make_plan

ORIGIN2CMM = transform_from_pose([420.0, 310.0, 180.0, 0.3, -0.2, 35.0])
TARGETS = np.array([[5.0, -3.0, 4.0, 1.0, -2.0, 3.0], [-8.0, 6.0, -5.0, -2.5, 1.5, -4.0]])
LEGS = ("leg1", "leg2", "leg3", "leg4", "leg5", "leg6")
#: the conftest hexapod's legs: aluminium body 148 mm (23.1e-6/K) + steel screw (11.5e-6/K)
BODY_MM, CTE_BODY, CTE_SCREW = 148.0, 23.1e-6, 11.5e-6


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
    log = ThermocoupleLog(log_t, 20.5 + rise, [20.0, 20.4, 20.8, 21.6, 22.4])
    return hexapod, plan, times, log


def run(case, *effects):
    hexapod, plan, times, log = case
    return predict(hexapod, plan, times, log, BALLS, ORIGIN2CMM, effects)


def absolute(hexapod, steps):
    """True platform poses relative to the nominal frame O."""
    return pose_from_transform(steps.platform2origin_nominal, hexapod.convention)


def variable_length(q_mm):
    return q_mm - BODY_MM


# ------------------------------------------------------------------ one per effect
def test_leg_offset_makes_the_legs_longer_by_exactly_the_offset(case):
    offsets = np.array([0.002, -0.001, 0.0005, 0.003, -0.0025, 0.001])
    none = run(case)
    effect = run(case, make_effect("leg_offset", dict(zip(LEGS, offsets, strict=True))))
    np.testing.assert_allclose(
        effect.q_mm - none.q_mm, np.broadcast_to(offsets, (6, 6)), atol=1e-13, rtol=0
    )
    np.testing.assert_array_equal(effect.growth_mm, none.growth_mm)
    hexapod = case[0]
    # the true platform is where the longer legs put it
    q_true = hexapod.igm(absolute(hexapod, effect))
    np.testing.assert_allclose(
        q_true - hexapod.igm(absolute(hexapod, none)),
        np.broadcast_to(offsets, (6, 6)),
        atol=1e-9,
        rtol=0,
    )
    # a constant offset is not thermal: it is there in the reference state too
    np.testing.assert_allclose(
        effect.reference_q_mm - none.reference_q_mm,
        np.broadcast_to(offsets, (6, 6)),
        atol=1e-13,
        rtol=0,
    )


def test_leg_cte_error_scales_the_growth(case):
    errors = np.array([0.1, -0.05, 0.0, 0.2, -0.15, 0.03])
    none = run(case)
    effect = run(case, make_effect("leg_cte_error", dict(zip(LEGS, errors, strict=True))))
    np.testing.assert_allclose(effect.growth_mm, none.growth_mm * (1 + errors), rtol=1e-14)
    np.testing.assert_allclose(effect.q_mm - none.q_mm, none.growth_mm * errors, atol=1e-12, rtol=0)
    # by hand, leg 1 of step S1 (t = 1500 s): the log joins 22.5 (1200 s) and 23.5 (2400 s),
    # so every segment is at 22.75 degC
    q = none.q_cmd_mm[2, 0]
    by_hand = (CTE_BODY * BODY_MM + CTE_SCREW * (q - BODY_MM)) * (22.75 - 20.0) * 1.1
    assert effect.growth_mm[2, 0] == pytest.approx(by_hand, rel=1e-12)


def test_lag_closed_form_matches_a_fine_numerical_integration():
    rng = np.random.default_rng(7)
    times = np.concatenate([[0.0], np.cumsum(rng.integers(20, 400, 12))]).astype(float)
    values = 20.0 + np.cumsum(rng.normal(0.0, 1.0, (13, 2)), axis=0)
    tau = 350.0
    # RK4 on dy/dt = (x(t) - y)/tau with x joining the samples, 0.2 s steps (the samples
    # on the grid, so that every RK4 step sees a straight line)
    dt = 0.2
    grid = np.arange(0.0, times[-1] + 500.0 + dt / 2, dt)

    def x(t):
        return np.column_stack([np.interp(t, times, values[:, j]) for j in range(2)])

    y = np.empty((grid.size, 2))
    y[0] = values[0]
    xs, xh = x(grid), x(grid + dt / 2)
    for n in range(grid.size - 1):
        k1 = (xs[n] - y[n]) / tau
        k2 = (xh[n] - (y[n] + dt / 2 * k1)) / tau
        k3 = (xh[n] - (y[n] + dt / 2 * k2)) / tau
        k4 = (xs[n + 1] - (y[n] + dt * k3)) / tau
        y[n + 1] = y[n] + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    every = np.arange(0, grid.size, 251)
    exact = first_order_lag(times, values, tau, grid[every])
    np.testing.assert_allclose(exact, y[every], atol=1e-9, rtol=0)
    # at rest before t_0
    np.testing.assert_array_equal(first_order_lag(times, values, tau, [-100.0]), values[:1])


def test_leg_thermal_lag_on_a_ramp_by_hand(case):
    hexapod, plan, times, _ = case
    tau = 900.0
    # every leg ramps 1 K per 600 s from t_0 = 0 to 3600 s: T_eff = T - b tau (1 - e^(-t/tau))
    log = ThermocoupleLog([0.0, 3600.0], [[20.0] * 6, [26.0] * 6])
    none = predict(hexapod, plan, times, log, BALLS, ORIGIN2CMM)
    effect = predict(
        hexapod,
        plan,
        times,
        log,
        BALLS,
        ORIGIN2CMM,
        [make_effect("leg_thermal_lag", {"tau_s": tau})],
    )
    b = 6.0 / 3600.0
    t_eff = 20.0 + b * times - b * tau * (1.0 - np.exp(-times / tau))
    np.testing.assert_allclose(
        effect.leg_temperature_C, np.repeat(t_eff[:, None], 6, 1), atol=1e-12, rtol=0
    )
    # the growth changes by the sensitivity times the lag of the temperature
    sensitivity = CTE_BODY * BODY_MM + CTE_SCREW * variable_length(none.q_cmd_mm)
    lag = (20.0 + b * times - t_eff)[:, None]
    np.testing.assert_allclose(
        none.growth_mm - effect.growth_mm, sensitivity * lag, atol=1e-15, rtol=1e-12
    )


def test_steel_overheat_by_hand(case):
    ratio = 0.6
    none = run(case)
    effect = run(case, make_effect("steel_overheat", {"ratio": ratio}))
    _, _, times, log = case
    rise_since_t0 = log.legs_at(times) - log.legs_C[0]
    # only the screw (variable segment) runs hotter, by ratio times the rise since t_0
    extra = CTE_SCREW * variable_length(none.q_cmd_mm) * ratio * rise_since_t0
    np.testing.assert_allclose(effect.growth_mm - none.growth_mm, extra, atol=1e-15, rtol=1e-12)
    # by hand, leg 5 at S2 (t = 2700 s): the log says 20.5 + 8.25 there, 20.5 at t_0
    q = none.q_cmd_mm[4, 4]
    assert effect.growth_mm[4, 4] - none.growth_mm[4, 4] == pytest.approx(
        11.5e-6 * (q - 148.0) * 0.6 * 8.25, rel=1e-12
    )
    np.testing.assert_allclose(effect.segment_temperature_C[4, 4], [28.75, 28.75 + 0.6 * 8.25])


def test_base_expansion_scales_the_base_joints_about_their_centroid(case):
    alpha = 20e-6
    hexapod, _, times, log = case
    none = run(case)
    effect = run(case, make_effect("base_expansion", {"alpha_per_K": alpha}))
    # the conftest base: joints on a circle of radius 150 mm in z = -220, centroid (0, 0, -220)
    d_air = np.interp(times, log.times_s, log.air_C) - 20.0  # the air log starts at 20.0
    scale = 1.0 + alpha * d_air
    b = hexapod.base_joints_mm
    np.testing.assert_allclose(
        effect.base_joints_mm[:, :, :2], scale[:, None, None] * b[:, :2], atol=1e-12, rtol=0
    )
    np.testing.assert_allclose(effect.base_joints_mm[:, :, 2], -220.0, atol=1e-12, rtol=0)
    # the legs are as long as without it; the platform sits where the grown base puts it
    np.testing.assert_array_equal(effect.q_mm, none.q_mm)
    poses = absolute(hexapod, effect)
    np.testing.assert_allclose(
        hexapod.igm(poses, effect.base_joints_mm), effect.q_mm, atol=1e-10, rtol=0
    )
    assert np.abs(poses - absolute(hexapod, none))[:, :3].max() > 1e-4  # > 0.1 um: it shows


def test_cmm_drift_moves_every_coordinate_by_v_dt(case):
    v_um_per_h = np.array([12.0, -6.0, 3.0])
    drift = make_effect(
        "cmm_drift",
        dict(zip(("vx_um_per_h", "vy_um_per_h", "vz_um_per_h"), v_um_per_h, strict=True)),
    )
    hexapod, plan, times, log = case
    ball_times = times[:, None] + np.array([-50.0, 0.0, 50.0])
    none = run(case)
    effect = predict(hexapod, plan, times, log, BALLS, ORIGIN2CMM, [drift], ball_times_s=ball_times)
    # v dt at each ball's own time: 12 um/h over 1 h is 12 um
    expected = (ball_times - 0.0)[..., None] / 3600.0 * v_um_per_h * 1e-3
    np.testing.assert_allclose(
        effect.measured_centres_cmm_mm - none.centres_cmm_mm, expected, atol=1e-12, rtol=0
    )
    assert effect.measured_centres_cmm_mm[5, 0, 0] - none.centres_cmm_mm[5, 0, 0] == pytest.approx(
        12e-3 * 3250.0 / 3600.0, abs=1e-12
    )
    # the platform does not move: the CMM's reading does
    np.testing.assert_array_equal(effect.pose, none.pose)
    points = np.zeros((2, 4, 3))
    point_times = np.array([[0.0, 900.0, 1800.0, 3600.0]] * 2)
    np.testing.assert_allclose(
        cmm_readings(points, point_times, log, [drift])[1, 3], v_um_per_h * 1e-3, atol=1e-15
    )


# -------------------------------------------------------------------- composition
def test_effects_compose_in_the_spec_order(case):
    """Lag, then overheat (of the lagged temperature), then CTE error, then offsets."""
    hexapod, plan, times, log = case
    lag = make_effect("leg_thermal_lag", {"tau_s": 600.0})
    overheat = make_effect("steel_overheat", {"ratio": 0.5})
    cte = make_effect("leg_cte_error", dict.fromkeys(LEGS, 0.1))
    offset = make_effect("leg_offset", dict.fromkeys(LEGS, 0.001))
    given_backwards = run(case, offset, cte, overheat, lag)
    t_eff = first_order_lag(log.times_s, log.legs_C, 600.0, times)
    t_var = t_eff + 0.5 * (t_eff - log.legs_C[0])
    q_cmd = given_backwards.q_cmd_mm
    growth = (
        CTE_BODY * BODY_MM * (t_eff - 20.0) + CTE_SCREW * variable_length(q_cmd) * (t_var - 20.0)
    ) * 1.1
    np.testing.assert_allclose(given_backwards.growth_mm, growth, atol=1e-15, rtol=1e-12)
    np.testing.assert_allclose(given_backwards.q_mm, q_cmd + growth + 0.001, atol=1e-13, rtol=0)
    with pytest.raises(ValueError, match="given twice"):
        run(case, lag, make_effect("leg_thermal_lag", {"tau_s": 60.0}))


def test_the_reference_state_is_the_first_reference_steps(case):
    """Corrected truth: every step with R0's segment temperatures and base joints."""
    hexapod, plan, times, log = case
    effects = (
        make_effect("leg_thermal_lag", {"tau_s": 600.0}),
        make_effect("base_expansion", {"alpha_per_K": 20e-6}),
    )
    steps = run(case, *effects)
    r0 = 1
    assert steps.reference_index == r0
    growth0 = hexapod.legs.growth_mm(
        steps.q_cmd_mm, steps.segment_temperature_C[r0], per_segment=True
    )
    np.testing.assert_allclose(steps.reference_q_mm, steps.q_cmd_mm + growth0, atol=1e-13)
    frames0 = transform_from_pose(
        hexapod.fgm(
            steps.reference_q_mm,
            plan.poses,
            base_joints_mm=np.broadcast_to(steps.base_joints_mm[r0], (6, 6, 3)),
        ),
        hexapod.convention,
    )
    # relative to O in that state too (issue 35): O's own state is another one
    corrected = np.linalg.inv(frames0[0]) @ frames0
    np.testing.assert_allclose(
        steps.corrected_pose, pose_from_transform(corrected, hexapod.convention), atol=1e-10
    )
    np.testing.assert_allclose(steps.corrected_pose[0], 0.0, atol=1e-10)
    moved = np.abs(steps.pose[0] - pose_from_transform(frames0[0], hexapod.convention))
    assert moved.max() > 1e-4  # O warmed before R0: not where it stood when measured


def test_no_effect_is_the_plain_twin_at_the_logged_temperatures(case):
    hexapod, plan, times, log = case
    plain = predict_steps(hexapod, plan, log.legs_at(times), BALLS, ORIGIN2CMM)
    twin = run(case)
    for name in ("q_cmd_mm", "growth_mm", "pose", "corrected_pose", "centres_cmm_mm"):
        np.testing.assert_array_equal(getattr(twin, name), getattr(plain, name))
    np.testing.assert_array_equal(twin.measured_centres_cmm_mm, twin.centres_cmm_mm)


# ----------------------------------------------------------------------- registry
#: the spec's table of effects, written out independently of the code
SPEC_EFFECTS = {
    "leg_thermal_lag": ("tau_s",),
    "steel_overheat": ("ratio",),
    "leg_cte_error": tuple(f"leg{i}" for i in range(1, 7)),
    "base_expansion": ("alpha_per_K",),
    "cmm_drift": ("vx_um_per_h", "vy_um_per_h", "vz_um_per_h"),
    "leg_offset": tuple(f"leg{i}" for i in range(1, 7)),
}
#: hexatherm's extensions of the registry (docs/formats.md marks them as such)
EXTENSION_EFFECTS = {
    "ball_plate_expansion": ("alpha_per_K",),
    "leg_growth_quadratic": tuple(f"leg{i}" for i in range(1, 7)),
    "cmm_scale": ("sx_ppm", "sy_ppm", "sz_ppm"),
    "leg_backlash": tuple(f"leg{i}" for i in range(1, 7)),
}


def test_registry_matches_the_contract():
    registry = {name: tuple(cls.parameters) for name, cls in EFFECTS.items()}
    assert registry == {**SPEC_EFFECTS, **EXTENSION_EFFECTS}
    assert EFFECT_PARAMETERS == registry
    for cls in EFFECTS.values():
        assert len(cls.units) == len(cls.ranges) == len(cls.parameters)
        assert all(lo < hi for lo, hi in cls.ranges)
        assert cls.summary
    assert EFFECTS["base_expansion"].needs_air


def test_a_seventh_effect_is_one_class(case):
    class TableTilt(Effect):  # tilts the measured coordinates about the CMM's y axis
        name = "test_table_tilt"
        parameters = ("urad",)
        units = ("urad",)
        ranges = ((-100.0, 100.0),)
        summary = "the CMM table is tilted"

        def cmm_coordinates_mm(self, xyz_mm, times_s, log):
            angle = self.values["urad"] * 1e-6
            out = np.array(xyz_mm, dtype=float)
            out[..., 0] += angle * out[..., 2]
            return out

    try:
        effect = make_effect("test_table_tilt", {"urad": 10.0})
        steps = run(case, effect)
        shift = steps.measured_centres_cmm_mm - steps.centres_cmm_mm
        np.testing.assert_allclose(shift[..., 0], 1e-5 * steps.centres_cmm_mm[..., 2])
        assert effect.as_dict() == {"name": "test_table_tilt", "parameters": {"urad": 10.0}}
        assert type(effect).from_vector([10.0]) == effect
    finally:
        EFFECTS.pop("test_table_tilt", None)


def test_parameters_are_checked():
    with pytest.raises(ValueError, match="missing leg6"):
        make_effect("leg_offset", dict.fromkeys(LEGS[:5], 0.0))
    with pytest.raises(ValueError, match="unknown speed"):
        make_effect("leg_thermal_lag", {"tau_s": 10.0, "speed": 1.0})
    with pytest.raises(ValueError, match="finite"):
        make_effect("steel_overheat", {"ratio": float("nan")})
    with pytest.raises(ValueError, match="unknown effect 'leg_lag'"):
        make_effect("leg_lag", {})
    assert make_effect("leg_thermal_lag", {"tau_s": 0.5}).out_of_range() == {
        "tau_s": "0.5 is outside the sensible range [1, 86400] s"
    }


def test_base_expansion_needs_the_air_column(case):
    hexapod, plan, times, log = case
    no_air = ThermocoupleLog(log.times_s, log.legs_C)
    with pytest.raises(Exception, match="no 'air' column"):
        predict(
            hexapod,
            plan,
            times,
            no_air,
            BALLS,
            ORIGIN2CMM,
            [make_effect("base_expansion", {"alpha_per_K": 1e-5})],
        )


# -------------------------------------------------------- per-pose base joints
def test_per_pose_base_joints_in_igm_jacobian_and_fgm(rng):
    hexapod = make_hexapod()
    poses = rng.uniform(-1, 1, (5, 6)) * [10, 10, 5, 2, 2, 3]
    bases = hexapod.base_joints_mm + rng.normal(0, 0.5, (5, 6, 3))
    q = hexapod.igm(poses, bases)
    for n in range(5):
        np.testing.assert_allclose(q[n], hexapod.igm(poses[n], bases[n])[0], atol=1e-12)
    back = hexapod.fgm(q, base_joints_mm=bases)
    np.testing.assert_allclose(back, poses, atol=1e-9)
    jac = hexapod.jacobian(poses, bases)
    h = 1e-4
    for k in range(6):
        step = np.zeros(6)
        step[k] = h
        numeric = (hexapod.igm(poses + step, bases) - hexapod.igm(poses - step, bases)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-8)
    with pytest.raises(ValueError, match="base joints must have shape"):
        hexapod.igm(poses, bases[:2])
