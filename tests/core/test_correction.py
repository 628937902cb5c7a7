"""The thermal method on twin data: exact without noise, interpolation beats one neighbour."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.carry import carry_motion, leg_growth
from hexatherm.core.correction import choose_references, correct
from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.core.registration import register
from hexatherm.core.twin import leg_temperatures_at, predict_steps
from hexatherm.errors import PlanError, StepError
from tests.conftest import BALLS, REFERENCE_POSE, make_hexapod, make_plan, random_poses

ORIGIN2CMM = transform_from_pose([420.0, 310.0, 180.0, 0.3, -0.2, 35.0])
UM, URAD = 1e3, np.pi / 180 * 1e6


def run(hexapod, plan, times, temps, interpolation="linear"):
    """The twin's steps and the correction, O carried to R0's state by the leg model
    (:mod:`hexatherm.core.carry`) as ``process`` carries it from a thermocouple log."""
    twin = predict_steps(hexapod, plan, temps, BALLS, ORIGIN2CMM)
    frames = register(twin.centres_cmm_mm, BALLS).platform2cmm
    origin, r0 = plan.origin_index, plan.reference_indices[0]
    grown = leg_growth(hexapod.legs, hexapod.igm(plan.poses[origin]), temps[origin], temps[r0])
    shift = carry_motion(hexapod, plan.poses[origin][None], grown[None])[0]
    steps, corr = correct(hexapod, plan, times, frames, interpolation, origin_shift=shift)
    return twin, steps, corr


def errors(corr, truth):
    err = corr - truth
    return np.abs(err[:, :3]).max() * UM, np.abs(err[:, 3:]).max() * URAD


def heated(times, tau_s=2400.0, rise=(3.0, 6.0, 2.0, 2.5, 7.0, 3.0)):
    """Smooth, non-linear heating from 20 degC (first-order approach to a plateau)."""
    return 20.0 + np.asarray(rise) * (1.0 - np.exp(-np.asarray(times)[:, None] / tau_s))


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_noise_free_twin_is_corrected_exactly(convention, rng):
    hexapod = make_hexapod(convention)
    plan = make_plan(random_poses(rng, 12))
    times = np.arange(len(plan.labels)) * 240.0 + rng.uniform(0, 60, len(plan.labels))
    times.sort()
    # thermocouples sampled at the references only: temperatures are linear between
    # references, so interpolating the growth in time is exact
    refs = plan.reference_indices
    temps = leg_temperatures_at(times[refs], heated(times[refs]), times)
    temps[0] = temps[refs[0]] - [0.3, 0.1, 0.2, 0.0, 0.4, 0.1]  # O at another state still
    twin, steps, corr = run(hexapod, plan, times, temps)
    truth = twin.corrected_pose[corr.target_index]
    t_err, r_err = errors(corr.corrected, truth)
    assert t_err < 0.05 and r_err < 0.1
    # the conventional pose is the true pose at measurement time ...
    np.testing.assert_allclose(corr.conventional, twin.pose[corr.target_index], atol=1e-10)
    # ... and off by micrometres from the corrected truth
    c_err, _ = errors(corr.conventional, truth)
    assert c_err > 5.0
    # the growth subtracted is the true change of the legs since R0
    true_growth = twin.growth_mm[corr.target_index] - hexapod.legs.growth_mm(
        twin.q_cmd_mm[corr.target_index], temps[refs[0]]
    )
    np.testing.assert_allclose(corr.growth_mm, true_growth, atol=1e-6)  # 1 nm


def test_interpolation_beats_one_neighbour_on_nonlinear_heating(rng):
    hexapod = make_hexapod()
    plan = make_plan(random_poses(rng, 10, scale=0.5))
    times = np.arange(len(plan.labels)) * 300.0
    temps = heated(times)  # thermocouples follow the smooth curve at every step
    twin, _, both = run(hexapod, plan, times, temps, "linear")
    truth = twin.corrected_pose[both.target_index]
    e_both = errors(both.corrected, truth)
    for single in ("before", "after", "nearest"):
        _, _, one = run(hexapod, plan, times, temps, single)
        e_one = errors(one.corrected, truth)
        assert e_one[0] > 5 * e_both[0] and e_one[1] > 5 * e_both[1], (single, e_one, e_both)


def test_one_sided_references_are_used_as_they_come():
    plan = Plan.from_steps(
        [
            ("O", "origin", [0] * 6),
            ("R0", "reference", REFERENCE_POSE),
            ("S1", "target", [0] * 6),
            ("R1", "reference", REFERENCE_POSE),
            ("S2", "target", [1, 0, 0, 0, 0, 0]),
        ]
    )
    before, after, w = choose_references(plan, np.arange(5.0) * 10, "linear")
    np.testing.assert_array_equal(before, [1, 3])
    np.testing.assert_array_equal(after, [3, -1])
    np.testing.assert_allclose(w, [0.5, 0.0])


def test_target_without_adjacent_reference_names_the_step():
    steps = [
        ("O", "origin", [0] * 6),
        ("R0", "reference", REFERENCE_POSE),
        ("S1", "target", [1, 0, 0, 0, 0, 0]),
        ("S2", "target", [2, 0, 0, 0, 0, 0]),
        ("S3", "target", [3, 0, 0, 0, 0, 0]),
        ("R1", "reference", REFERENCE_POSE),
    ]
    with pytest.raises(StepError, match="step S2: target has no reference step adjacent"):
        Plan.from_steps(steps)


@pytest.mark.parametrize(
    ("steps", "message"),
    [
        ([("R0", "reference", REFERENCE_POSE)], "step R0: the first step must be the origin"),
        ([("O", "origin", [0] * 6), ("O", "reference", REFERENCE_POSE)], "step O: duplicate"),
        (
            [("O", "origin", [0] * 6), ("R_0", "reference", REFERENCE_POSE)],
            r"step R_0: label must match",
        ),
        (
            [
                ("O", "origin", [0] * 6),
                ("R0", "reference", REFERENCE_POSE),
                ("R1", "reference", [0, 0, -30, 0, 0, 0]),
            ],
            "step R1: reference pose differs",
        ),
        (
            [
                ("O", "origin", [0] * 6),
                ("S1", "target", [0] * 6),
                ("R0", "reference", REFERENCE_POSE),
            ],
            "step S1: target comes before the first",
        ),
        (  # several at fault: the first is named (the checks run over all steps at once)
            [
                ("O", "origin", [0] * 6),
                ("R0", "reference", REFERENCE_POSE),
                ("S1", "target", [0] * 6),
                ("R1", "reference", [0, 0, -30, 0, 0, 0]),
                ("R2", "reference", [0, 0, -20, 0, 0, 0]),
            ],
            "step R1: reference pose differs",
        ),
        (
            [
                ("O", "origin", [0] * 6),
                ("S1", "target", [0] * 6),
                ("S2", "target", [0] * 6),
                ("R0", "reference", REFERENCE_POSE),
            ],
            "step S1: target comes before the first",
        ),
        (
            [("O", "origin", [0] * 6), ("S1", "target", [0, np.nan, 0, 0, 0, 0])],
            "step S1: pose has a non-finite value",
        ),
        ([("O", "origin", [0] * 6), ("O2", "origin", [0] * 6)], "only one origin"),
        ([("O", "origin", [0] * 6), ("X", "tagret", [0] * 6)], "unknown kind 'tagret'"),
    ],
)
def test_plan_errors_name_the_step(steps, message):
    with pytest.raises(StepError, match=message):
        Plan.from_steps(steps)


def test_choose_references_weights():
    plan = make_plan(np.zeros((2, 6)))  # O R0 S1 R1 S2 R2
    times = np.array([0.0, 10.0, 20.0, 50.0, 65.0, 70.0])
    before, after, w = choose_references(plan, times, "linear")
    np.testing.assert_array_equal(before, [1, 3])
    np.testing.assert_array_equal(after, [3, 5])
    np.testing.assert_allclose(w, [0.25, 0.75])
    before, after, w = choose_references(plan, times, "nearest")
    np.testing.assert_array_equal(before, [1, -1])
    np.testing.assert_array_equal(after, [-1, 5])
    np.testing.assert_allclose(w, [0.0, 1.0])


def test_references_measured_at_the_same_time_weigh_one_half():
    """A burst of data stamped on arrival: O, R0, S1 and R1 share one time. The plan's order
    puts S1 between R0 and R1, and the times say no more: each reference weighs 1/2."""
    plan = make_plan(np.zeros((2, 6)))  # O R0 S1 R1 S2 R2
    times = np.array([0.0, 10.0, 10.0, 10.0, 20.0, 30.0])
    before, after, w = choose_references(plan, times, "linear")
    np.testing.assert_array_equal(before, [1, 3])
    np.testing.assert_array_equal(after, [3, 5])
    np.testing.assert_allclose(w, [0.5, 0.5])


def test_references_in_reverse_time_order_are_refused():
    plan = make_plan(np.zeros((1, 6)))  # O R0 S1 R1
    with pytest.raises(PlanError, match="step S1: its references are not in time order"):
        choose_references(plan, np.array([0.0, 20.0, 15.0, 10.0]), "linear")
