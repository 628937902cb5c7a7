"""The FGM never returns a pose of another assembly mode (issue 14, part 4).

Leg lengths have several poses (assembly modes). The right one is the pose the
platform reaches from the start pose when its legs move along the straight line from
the start's leg lengths to the given ones without meeting a singularity. The truth
here is an independent path follower: small fourth-order Runge-Kutta steps of
``dx/ds = J(x)^-1 (q - q0)``, each corrected by Newton, with the smallest singular
value of the Jacobian watched along the whole path (an SVD per step). The FGM must
either raise or return that pose; a pose past a singularity (the determinant of the
Jacobian of the other sign) is never returned.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import AssemblyModeError, ConvergenceError, HexathermError
from tests.conftest import make_hexapod, random_poses

#: a wide box: most of it out of stroke, some of it past singularities (mm, deg)
WIDE = np.array([100.0, 100.0, 80.0, 50.0, 50.0, 120.0])


def stroked(stroke_mm: tuple[float, float] | None = (200.0, 280.0)) -> Hexapod:
    plain = make_hexapod()
    return Hexapod(
        name="stroked",
        convention=plain.convention,
        base_joints_mm=plain.base_joints_mm,
        platform_joints_mm=plain.platform_joints_mm,
        stroke_mm=None if stroke_mm is None else np.array(stroke_mm),
        legs=plain.legs,
    )


def follow(
    hexapod: Hexapod, q: np.ndarray, start: np.ndarray, steps: int = 100
) -> tuple[np.ndarray, np.ndarray]:
    """The end of the leg path from ``start`` (M, 6) to ``q`` (M, 6), and the smallest
    singular value of the Jacobian met on the way (M,; 0 where the path is lost): the
    reference."""
    x = start.copy()
    q0 = hexapod.igm(x)
    dq = q - q0
    sigma = np.full(len(q), np.inf)

    def solve(x: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """J(x)^-1 rhs by SVD, zero where the path is lost; tracks sigma."""
        u, s, vt = np.linalg.svd(hexapod.jacobian(x))
        np.minimum(sigma, s[:, -1], out=sigma)
        alive = sigma > 1e-6
        coef = np.einsum("nji,nj->ni", u, rhs) / np.maximum(s, 1e-300)
        step = np.einsum("nji,nj->ni", vt, coef)
        step[~alive] = 0.0
        return step

    h = 1.0 / steps
    for k in range(steps):
        k1 = solve(x, dq)
        k2 = solve(x + h / 2 * k1, dq)
        k3 = solve(x + h / 2 * k2, dq)
        k4 = solve(x + h * k3, dq)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        x = x - solve(x, hexapod.igm(x) - (q0 + (k + 1) * h * dq))
    for _ in range(4):
        x = x - solve(x, hexapod.igm(x) - q)
    sigma[sigma <= 1e-6] = 0.0
    return x, sigma


def check_never_wrong(
    hexapod: Hexapod, poses: np.ndarray, max_iter: int = 40, **kwargs: object
) -> int:
    """Every pose: an error, or the reference's pose. Returns how many were returned."""
    q = hexapod.igm(poses)
    reference, sigma = follow(hexapod, q, np.zeros_like(poses))
    sign0 = np.sign(np.linalg.det(hexapod.jacobian(np.zeros(6))))[0]
    returned = 0
    for i in range(len(poses)):
        try:
            got = hexapod.fgm(q[i], max_iter=max_iter, **kwargs)[0]  # type: ignore[arg-type]
        except HexathermError as error:
            assert isinstance(error, ConvergenceError)  # AssemblyModeError, SingularityError
            continue
        returned += 1
        np.testing.assert_allclose(hexapod.igm(got)[0], q[i], atol=1e-9, rtol=0)
        # the path it claims to have followed exists, and it ends where the FGM says
        assert sigma[i] > 1e-3, (i, poses[i], sigma[i])
        np.testing.assert_allclose(got, reference[i], atol=1e-7, rtol=0, err_msg=f"pose {i}")
        assert np.sign(np.linalg.det(hexapod.jacobian(got)))[0] == sign0
    return returned


@settings(max_examples=8, deadline=None)
@given(arrays(np.float64, (6, 6), elements=st.floats(-1.0, 1.0)))
def test_out_of_stroke_is_an_error_or_the_right_pose(unit):
    """From the zero pose with a stroke: legs beyond it are refused, the rest is right."""
    hexapod = stroked()
    poses = unit * WIDE
    check_never_wrong(hexapod, poses)
    outside = hexapod.check_stroke(hexapod.igm(poses)).any(axis=1)
    for i in np.flatnonzero(outside):
        q = hexapod.igm(poses[i])
        if (hexapod.check_stroke(q - 0.1) & hexapod.check_stroke(q + 0.1)).any():
            with pytest.raises(AssemblyModeError, match="pose index 0 has leg"):
                hexapod.fgm(q)


@settings(max_examples=6, deadline=None)
@given(
    arrays(np.float64, (6, 5), elements=st.floats(-1.0, 1.0)),
    arrays(np.float64, (6,), elements=st.floats(80.0, 180.0)),
)
def test_past_a_singularity_is_an_error_or_the_right_pose(unit, rz_deg):
    """No stroke to hide behind: poses around and past the singularity at Rz = 90 deg."""
    hexapod = stroked(None)
    poses = np.column_stack([unit * WIDE[:5] / 4, rz_deg * np.sign(unit[:, 0] + 0.5)])
    check_never_wrong(hexapod, poses)


def test_the_wide_box_without_stroke_returns_only_right_poses():
    """A seeded sample of the wide box with no stroke check: the reference ends at
    another pose than the one the legs were computed from for a third of them (the
    other pose is past a singularity from zero, or only reached by another leg path);
    the FGM returns the reference's pose, given the steps these long paths need."""
    hexapod = stroked()
    poses = np.random.default_rng(14).uniform(-1, 1, (20, 6)) * WIDE
    assert check_never_wrong(hexapod, poses, max_iter=300, stroke_check=False) >= 18


def test_the_audit_case_is_refused():
    """A pose out of stroke whose leg lengths the old FGM matched with a pose of another
    assembly mode, 16 mm / 15 deg away, from the zero start."""
    hexapod = stroked()
    rng = np.random.default_rng(3)
    poses = rng.uniform(-1, 1, (40, 6)) * WIDE
    q = hexapod.igm(poses)
    reference, _ = follow(hexapod, q, np.zeros_like(poses))
    other = np.flatnonzero(np.abs(reference - poses).max(axis=1) > 1.0)
    assert other.size  # the sample has poses whose legs lead elsewhere from zero
    batch = q[[0, other[0]]] if other[0] != 0 else q[[other[0]]]
    with pytest.raises(AssemblyModeError, match="pose index") as info:
        hexapod.fgm(batch)
    assert info.value.index is not None


def test_error_names_the_pose():
    hexapod = stroked()
    poses = random_poses(np.random.default_rng(1), 6, scale=0.3)
    poses[4] = [0.0, 0.0, 60.0, 0.0, 0.0, 0.0]  # legs beyond the stroke
    with pytest.raises(AssemblyModeError, match="pose index 4 has leg") as info:
        hexapod.fgm(hexapod.igm(poses))
    assert info.value.index == 4
    # with a start at the pose the caller vouches for the branch: no stroke check
    back = hexapod.fgm(hexapod.igm(poses), initial_poses=poses + 1e-3)
    np.testing.assert_allclose(back, poses, atol=1e-9, rtol=0)


def test_realistic_workspace_from_zero_is_the_truth():
    """The certified path changes nothing where the old FGM was right."""
    hexapod = stroked((150.0, 350.0))
    poses = random_poses(np.random.default_rng(2), 500)
    q = hexapod.igm(poses)
    np.testing.assert_allclose(hexapod.fgm(q), poses, atol=1e-9, rtol=0)
    # from near starts (as process starts) the first step reaches the legs: plain Newton
    near = poses + np.random.default_rng(3).normal(0, 1e-3, poses.shape)
    np.testing.assert_allclose(hexapod.fgm(q, initial_poses=near), poses, atol=1e-9, rtol=0)


def test_a_long_path_needs_more_steps_and_says_so():
    hexapod = stroked((150.0, 350.0))
    q = hexapod.igm([[15.0, -15.0, 10.0, 4.0, -4.0, 10.0]])
    with pytest.raises(ConvergenceError, match="% of the way from its start pose"):
        hexapod.fgm(q, max_iter=2)
    np.testing.assert_allclose(
        hexapod.fgm(q), [[15.0, -15.0, 10.0, 4.0, -4.0, 10.0]], atol=1e-9, rtol=0
    )


def test_kantorovich_constants_bound_the_jacobian_change():
    """The curvature bound holds: |J(x) - J(y)| (scaled) <= L |x - y| on random pairs."""
    hexapod = make_hexapod("pi")
    bound = hexapod._curvature_bound()
    rng = np.random.default_rng(4)
    x = random_poses(rng, 400, scale=2.0)
    y = x + rng.normal(0, 1.0, x.shape) * np.array([3, 3, 3, 2, 2, 2])
    scale = bound.scale
    jx = hexapod.jacobian(x) / scale
    jy = hexapod.jacobian(y) / scale
    change = np.linalg.norm(jx - jy, ord=2, axis=(1, 2))
    dist = np.linalg.norm((x - y) * scale, axis=1)
    q_min = np.minimum(hexapod.igm(x).min(axis=1), hexapod.igm(y).min(axis=1))
    hess = (1.0 + 2.0 * bound.ratio_sq) / q_min[:, None] + 3.0 * bound.ratio_rho
    lip = np.sqrt((hess**2).sum(axis=1))
    assert np.all(change <= lip * dist)
    assert np.max(change / (lip * dist)) > 0.05  # and is not absurdly loose
