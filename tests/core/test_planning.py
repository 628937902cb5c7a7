"""Plan generation without I/O: order, targets, pose checks, timing, touch points."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hexatherm.core.planning import (
    build_plan,
    check_plan_poses,
    estimate_timing,
    grid_targets,
    parse_targets,
    pose_problems,
    random_targets,
    reference_gaps,
    sequence_steps,
)
from hexatherm.core.touch import cap_directions, touch_points
from hexatherm.errors import InputError, PlanError, PoseError
from hexatherm.io.config import read_hexapod

ROOT = Path(__file__).resolve().parents[2]
REF = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]


@pytest.fixture(scope="module")
def hexapod():
    return read_hexapod(ROOT / "configs" / "symetrie-like.yaml")


def independent_legs(hexapod, pose):
    """Leg lengths |t + R p - b| computed with scipy's rotation (independent of the IGM)."""
    rot = Rotation.from_euler("xyz", pose[3:], degrees=True).as_matrix()
    tips = pose[:3] + hexapod.platform_joints_mm @ rot.T
    return np.linalg.norm(tips - hexapod.base_joints_mm, axis=1)


# ---------------------------------------------------------------------- order
def test_every_target_has_a_reference_on_both_sides_by_default():
    targets = np.arange(18, dtype=float).reshape(3, 6)
    plan = build_plan(targets, REF, points_per_ball=7)
    assert plan.labels == ("O", "R0", "S1", "R1", "S2", "R2", "S3", "R3")
    assert plan.kinds == (
        "origin",
        "reference",
        "target",
        "reference",
        "target",
        "reference",
        "target",
        "reference",
    )
    assert plan.adjacent_references() == [(1, 3), (3, 5), (5, 7)]
    np.testing.assert_array_equal(plan.poses[[2, 4, 6]], targets)
    np.testing.assert_array_equal(plan.poses[0], np.zeros(6))
    assert all(np.array_equal(plan.poses[i], REF) for i in (1, 3, 5, 7))
    assert plan.points_per_ball == 7


def test_reference_every_before_and_after():
    targets = np.eye(6)[:2]
    before = build_plan(targets, REF, reference_every="before")
    assert before.labels == ("O", "R0", "S1", "R1", "S2")
    assert before.adjacent_references() == [(1, 3), (3, -1)]
    # the first reference must come before every target, so "after" ends up like "both"
    after = build_plan(targets, REF, reference_every="after")
    assert after.labels == build_plan(targets, REF).labels
    assert all(a >= 0 for _, a in after.adjacent_references())


def test_cycles_repeat_the_targets_in_order():
    targets = np.array([[1.0, 0, 0, 0, 0, 0], [0, 2.0, 0, 0, 0, 0]])
    plan = build_plan(targets, REF, cycles=3)
    np.testing.assert_array_equal(plan.poses[plan.target_indices], np.tile(targets, (3, 1)))
    assert [plan.labels[i] for i in plan.target_indices] == [f"S{i}" for i in range(1, 7)]
    with pytest.raises(PlanError, match="cycles"):
        sequence_steps(targets, REF, cycles=0)


# -------------------------------------------------------------------- targets
def test_parse_targets_with_header_comments_and_blank_lines():
    text = (
        "\ufeff# my targets\nTx, Ty, Tz, Rx, Ry, Rz\n\n1, 2, 3, 0.1, -0.2, 0.3\n# c\n"
        "-4,5,-6,0,0,1e-1\n"
    )
    poses, lines = parse_targets(text, "t.csv")
    np.testing.assert_array_equal(poses, [[1, 2, 3, 0.1, -0.2, 0.3], [-4, 5, -6, 0, 0, 0.1]])
    assert lines == [4, 6]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1,2,3,0,0,0\n1,2,x,0,0,0\n", "t.csv:2: field 'Tz': not a finite number: 'x'"),
        ("1,2,3,0,0,nan\n", "t.csv:1: field 'Rz': not a finite number"),
        ("Tx,Ty,Tz,Rx,Ry,Rz\n1,2,3,0,0,0,0\n", "t.csv:2: expected 6 comma-separated values"),
        ("X,Y,Z,A,B,C\n1,2,3,0,0,0\n", "t.csv:1: header must be Tx,Ty,Tz,Rx,Ry,Rz"),
        ("# nothing\n\n", "t.csv: no target poses"),
        ("1,2,3,0,0,0\nTx,Ty,Tz,Rx,Ry,Rz\n", "t.csv:2: field 'Tx': not a finite number"),
    ],
)
def test_parse_targets_names_file_line_and_field(text, message):
    with pytest.raises(InputError) as info:
        parse_targets(text, "t.csv")
    assert str(info.value).startswith(message)


def test_grid_covers_the_box():
    lower, upper = [-10, 0, -2, 0, 0, -1], [10, 0, 2, 0, 0, 1]
    grid = grid_targets(lower, upper, 3)
    expected = [
        [tx, 0, tz, 0, 0, rz]
        for tx, tz, rz in itertools.product([-10, 0, 10], [-2, 0, 2], [-1, 0, 1])
    ]
    np.testing.assert_allclose(grid, expected)
    counts = grid_targets(lower, upper, [2, 5, 4, 5, 5, 1])
    assert counts.shape == (8, 6)  # Ty, Rx, Ry fixed; Rz one level: the middle
    np.testing.assert_array_equal(np.unique(counts[:, 5]), [0.0])
    with pytest.raises(PlanError, match="lower bound"):
        grid_targets([1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0], 2)


def test_random_targets_are_seeded_in_the_box_and_feasible():
    lower, upper = [-20, -20, -5, -2, -2, -5], [20, 20, 5, 2, 2, 5]
    a, _ = random_targets(lower, upper, 30, seed=7)
    b, _ = random_targets(lower, upper, 30, seed=7)
    np.testing.assert_array_equal(a, b)
    assert np.all(a >= lower) and np.all(a <= upper)
    np.testing.assert_array_equal(a, np.round(a, 3))
    assert not np.array_equal(a, random_targets(lower, upper, 30, seed=8)[0])
    # a feasibility test rejects half the box: every pose kept passes it
    poses, rejected = random_targets(lower, upper, 20, seed=1, feasible=lambda p: p[:, 0] > 0)
    assert len(poses) == 20 and np.all(poses[:, 0] > 0) and rejected > 0
    with pytest.raises(PlanError, match="reachable"):
        random_targets(lower, upper, 3, seed=1, feasible=lambda p: p[:, 0] > 100, max_draws=5)


# --------------------------------------------------------------------- checks
def test_stroke_check_agrees_with_independent_leg_lengths(hexapod):
    lo, hi = hexapod.stroke_mm
    poses = np.array(
        [
            [0, 0, 0, 0, 0, 0],
            [0, 0, 60, 0, 0, 0],
            [0, 0, -60, 0, 0, 0],
            [30, 0, 0, 0, 0, 0],
            [0, 0, 0, 0, 0, 45],
            [5, -5, 3, 1, -1, 2],
        ],
        float,
    )
    problems = pose_problems(hexapod, poses)
    for pose, problem in zip(poses, problems, strict=True):
        legs = independent_legs(hexapod, pose)
        outside = (legs < lo) | (legs > hi)
        assert (problem is not None and "stroke" in problem) == bool(outside.any()), pose
        for leg in np.flatnonzero(outside):
            assert f"leg {leg + 1} at {legs[leg]:.3f} mm" in problem
    assert problems[0] is None and problems[1] is not None and problems[2] is not None


def test_near_singular_pose_is_refused(hexapod):
    # a large twist about z brings a 6-6 hexapod close to its rotational singularity
    twisted = np.array([0, 0, 0, 0, 0, 89.0])
    jac = hexapod.jacobian(twisted)[0]
    sv = np.linalg.svd(jac, compute_uv=False)
    assert sv[-1] / sv[0] < 1e-2
    unbounded = type(hexapod)(
        hexapod.name, hexapod.convention, hexapod.base_joints_mm, hexapod.platform_joints_mm
    )  # no stroke: only the Jacobian counts
    assert "near-singular" in pose_problems(unbounded, [twisted])[0]
    assert pose_problems(unbounded, [twisted], min_rcond=1e-3) == [None]


def test_check_plan_poses_names_the_step_source_and_pose(hexapod):
    plan = build_plan([[0, 0, 1, 0, 0, 0], [0, 0, 75, 0, 0, 0]], REF)
    sources = [None, None, "t.csv:2", None, "t.csv:3", None]
    with pytest.raises(PoseError) as info:
        check_plan_poses(hexapod, plan, sources=sources)
    message = str(info.value)
    assert message.startswith("step S2 (t.csv:3): pose [0, 0, 75, 0, 0, 0]: outside the stroke")
    assert info.value.step == "S2"


# --------------------------------------------------------------------- timing
def test_timing_and_reference_gaps():
    plan = build_plan(np.zeros((2, 6)) + [1, 0, 0, 0, 0, 0], REF, points_per_ball=10)
    timing = estimate_timing(plan, n_balls=3, seconds_per_point=4.0, seconds_per_move=60.0)
    step = 60.0 + 3 * 10 * 4.0
    np.testing.assert_allclose(timing.start_s, np.arange(6) * step)
    np.testing.assert_allclose(timing.time_s, np.arange(6) * step + 60 + 60)
    assert timing.total_s == 6 * step
    gaps = reference_gaps(plan, timing.time_s)
    assert [(g.target, g.reference) for g in gaps] == [
        ("S1", "R0"),
        ("S1", "R1"),
        ("S2", "R1"),
        ("S2", "R2"),
    ]
    assert all(g.gap_s == pytest.approx(step) for g in gaps)
    partial = reference_gaps(plan, [0, 10, 20, np.nan, np.nan, np.nan])
    assert [(g.target, g.reference, g.gap_s) for g in partial] == [("S1", "R0", 10.0)]


# --------------------------------------------------------------- touch points
def test_cap_directions_spread_over_the_cap():
    for n, cap in ((1, 75.0), (5, 60.0), (25, 75.0), (100, 90.0)):
        u = cap_directions(n, cap)
        np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1.0)
        polar = np.degrees(np.arccos(u[:, 2]))
        assert polar.max() < cap
        if n >= 5:
            # spread: no two points closer than a fraction of the even spacing
            area = 2 * np.pi * (1 - np.cos(np.radians(cap)))
            spacing = np.sqrt(area / n)
            d = np.linalg.norm(u[:, None] - u[None], axis=-1) + np.eye(n) * 9
            assert d.min() > 0.5 * spacing
            assert polar.max() > 0.75 * cap  # reaches out to the rim
    with pytest.raises(PlanError):
        cap_directions(0)


def test_touch_points_are_on_the_balls_at_their_nominal_place():
    balls = np.array([[0.0, 90.0, 30.0], [-73.6, -42.5, 30.0], [82.3, -47.5, 30.0]])
    diameters = np.array([25.4, 25.4, 20.0])
    plan = build_plan([[3, -2, 1, 0.5, -0.3, 2.0]], REF, points_per_ball=9)
    origin = [450.0, 320.0, 210.0, 0.2, -0.1, 15.0]
    tp = touch_points(plan, balls, diameters, origin, cap_half_angle_deg=70)
    o2c = Rotation.from_euler("xyz", origin[3:], degrees=True)
    for i, pose in enumerate(plan.poses):
        s2o = Rotation.from_euler("xyz", pose[3:], degrees=True)
        centres = o2c.apply(s2o.apply(balls) + pose[:3]) + origin[:3]
        np.testing.assert_allclose(tp.centres_mm[i], centres, atol=1e-9)
        radial = tp.points_mm[i] - centres[:, None]
        np.testing.assert_allclose(
            np.linalg.norm(radial, axis=-1),
            np.broadcast_to(diameters[:, None] / 2, (3, 9)),
            atol=1e-9,
        )
        np.testing.assert_allclose(
            tp.normals[i], radial / (diameters[:, None, None] / 2), atol=1e-9
        )
        # upper cap: every normal points up, within the cap's half-angle of the CMM's +z
        assert np.all(tp.normals[i][..., 2] > np.cos(np.radians(70)) - 1e-12)
