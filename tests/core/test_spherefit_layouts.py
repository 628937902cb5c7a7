"""The sphere fit's faster paths of issue 37 against the ones they replace: the padded
layout of equal point counts against the flat one (``reduceat``), the Cholesky solve
written out against LAPACK's, and the Kasa start without eigenvalues against the
eigen-decomposition's; on random and hostile spheres (shallow caps, few points, noise
up to the sagitta, nearly coplanar points, far from the origin)."""

from __future__ import annotations

import numpy as np
import pytest

import hexatherm.core.spherefit as sf
from hexatherm.core.spherefit import fit_spheres
from hexatherm.errors import FitError

from .test_spherefit import RADIUS, cap_directions


def _spheres(seed: int, counts: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """One sphere per count: caps from 8 to 180 deg, noise from 1e-7 to 0.1 of the cap's
    sagitta, centres up to 900 mm from the origin, points in file order."""
    rng = np.random.default_rng(seed)
    pts, groups = [], []
    for k, n in enumerate(counts):
        half = float(rng.choice([8.0, 12.0, 20.0, 45.0, 70.0, 150.0, 180.0]))
        u = cap_directions(n, half, rng, axis=rng.normal(size=3))
        sagitta = RADIUS * (1 - np.cos(np.radians(min(half, 90.0))))
        noise = sagitta * float(rng.choice([1e-7, 1e-4, 1e-2, 0.1]))
        centre = rng.uniform(-900.0, 900.0, 3)
        pts.append(centre + (RADIUS + rng.normal(0.0, noise, n))[:, None] * u)
        groups.append(np.full(n, k))
    return np.vstack(pts), np.concatenate(groups)


def _assert_same_fits(fits: sf.SphereFits, ref: sf.SphereFits, atol_mm: float = 1e-10) -> None:
    """Agreement far below what the files resolve (1e-7 mm): rounding and, where a step
    at the convergence test's edge is taken one pass later, that step (<= 1e-12 mm); a
    sphere of 4 or 5 points on a shallow cap with noise near the sagitta is determined
    only to its condition number times the rounding of the sums (1e-8 mm there)."""
    np.testing.assert_allclose(fits.centre_mm, ref.centre_mm, rtol=0, atol=atol_mm)
    np.testing.assert_allclose(fits.radius_mm, ref.radius_mm, rtol=0, atol=atol_mm)
    np.testing.assert_allclose(fits.residuals_mm, ref.residuals_mm, rtol=0, atol=atol_mm)
    np.testing.assert_allclose(fits.rms_um, ref.rms_um, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(fits.form_um, ref.form_um, rtol=1e-7, atol=1e-7)
    np.testing.assert_allclose(fits.cap_half_angle_deg, ref.cap_half_angle_deg, atol=1e-8)
    u = [1e3 * np.sqrt(np.diagonal(f.cov_centre_mm2, axis1=1, axis2=2)) for f in (fits, ref)]
    np.testing.assert_allclose(u[0], u[1], rtol=1e-6, atol=1e-9)
    assert np.abs(fits.iterations - ref.iterations).max() <= 1


CASES = {
    "equal counts": [25] * 300,
    "nearly equal (padded, masked)": [24, 25, 26, 25, 23] * 60,
    "few points": [4, 5, 4, 5, 5] * 40,
    "one sphere": [25],
}


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("fixed", [False, True])
@pytest.mark.parametrize("case", list(CASES))
def test_padded_layout_equals_the_flat_one(
    case: str, fixed: bool, seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    p, g = _spheres(seed, CASES[case])
    radius = None
    if fixed:  # a nominal radius a few micrometres off
        radius = RADIUS + np.random.default_rng(seed).normal(0.0, 3e-3, int(g.max()) + 1)
    fits = fit_spheres(p, g, radius_mm=radius)
    monkeypatch.setattr(sf, "PADDED_FILL", 0.0)  # every block flat, as before
    ref = fit_spheres(p, g, radius_mm=radius)
    _assert_same_fits(fits, ref, 1e-8 if case == "few points" else 1e-10)


def test_padded_layout_over_blocks_and_shuffled_points(monkeypatch: pytest.MonkeyPatch) -> None:
    """Several blocks (a small block size), the points in any order."""
    p, g = _spheres(3, [25] * 200 + [30] * 50)
    perm = np.random.default_rng(3).permutation(len(g))
    monkeypatch.setattr(sf, "BLOCK_POINTS", 1000)
    fits = fit_spheres(p[perm], g[perm])
    monkeypatch.setattr(sf, "PADDED_FILL", 0.0)
    _assert_same_fits(fits, fit_spheres(p[perm], g[perm]))


@pytest.mark.parametrize("padded", [True, False])
def test_an_ill_conditioned_sphere_is_named_alike_in_both_layouts(
    padded: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A 0.05 deg cap among good ones: the same error, naming the same sphere and its
    cap (the padded layout's directions flattened for the message)."""
    p, g = _spheres(4, [25] * 20)
    rng = np.random.default_rng(4)
    p[g == 7] = [1.0, 2.0, 3.0] + RADIUS * cap_directions(25, 0.05, rng)
    if not padded:
        monkeypatch.setattr(sf, "PADDED_FILL", 0.0)
    with pytest.raises(FitError) as raised:
        fit_spheres(p, g)
    message = str(raised.value)
    assert message.startswith("sphere 7: the normal equations are ill-conditioned")
    assert "cap of half-angle 0.0" in message


def _solve_before(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``_solve`` as it was: LAPACK's LU with pivoting, one matrix at a time."""
    return np.asarray(np.linalg.solve(a, b[..., None])[..., 0])


@pytest.mark.parametrize("p", [2, 3, 4])
def test_cholesky_solve_equals_lapack(p: int) -> None:
    rng = np.random.default_rng(p)
    m = 500
    # normal matrices from well to badly conditioned (column scales over 6 decades)
    x = rng.normal(size=(m, 30, p)) * 10.0 ** rng.uniform(-3.0, 3.0, (m, 1, p))
    a = np.swapaxes(x, 1, 2) @ x
    b = rng.normal(size=(m, p))
    ours, ref = sf._solve(a, b), _solve_before(a, b)
    # backward errors alike: both residuals at the rounding of a x
    scale = np.abs(a).max(axis=(1, 2)) * np.abs(ref).max(axis=1) + np.abs(b).max(axis=1)
    for x_ in (ours, ref):
        resid = np.abs(np.einsum("mij,mj->mi", a, x_) - b).max(axis=1)
        assert np.all(resid <= 1e-12 * scale)
    cond = np.linalg.cond(a)
    err = np.abs(ours - ref).max(axis=1) / np.abs(ref).max(axis=1)
    assert np.all(err <= 1e-15 * cond + 1e-13)


def test_cholesky_solve_falls_back_to_lapack_off_positive_definite() -> None:
    """An indefinite matrix: LU's answer; a singular one: LU's LinAlgError."""
    a = np.array([[[1.0, 2.0], [2.0, 1.0]], [[2.0, 0.0], [0.0, 3.0]]])
    b = np.array([[1.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(sf._solve(a, b), _solve_before(a, b), rtol=1e-15)
    with pytest.raises(np.linalg.LinAlgError):
        sf._solve(np.zeros((1, 3, 3)), np.ones((1, 3)))
    assert sf._solve(np.zeros((0, 4, 4)), np.zeros((0, 4))).shape == (0, 4)


@pytest.mark.parametrize("seed", [5, 6])
def test_kasa_start_without_eigenvalues_reaches_the_same_fits(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The eigen-decomposition for every scatter matrix (``_KASA_COND = 0``: as before)
    against the Cholesky start where the bound allows it; nearly coplanar spheres (a
    1 deg cap, ratio about 1e-4) go through the eigenvalues either way."""
    p, g = _spheres(seed, [25] * 100 + [9] * 50)
    rng = np.random.default_rng(seed)
    p[g == 3] = [5.0, 0.0, 0.0] + RADIUS * cap_directions(25, 2.0, rng)
    fits = fit_spheres(p, g, radius_mm=None)
    monkeypatch.setattr(sf, "_KASA_COND", 0.0)
    _assert_same_fits(fits, fit_spheres(p, g))


def test_padded_caps_equal_the_flat_ones_directions_cancelling_too(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The caps' half-angles from the padded directions: the six points on the axes (the
    directions cancel: 180 deg), a hemisphere and random caps, equal and ragged counts."""
    axes = np.vstack([np.eye(3), -np.eye(3)])
    p, g = _spheres(7, [6] * 30 + [7] * 3)
    p[g == 2] = [10.0, 0.0, 0.0] + RADIUS * axes
    rng = np.random.default_rng(7)
    p[g == 5] = RADIUS * cap_directions(6, 90.0, rng)
    fits = fit_spheres(p, g)
    monkeypatch.setattr(sf, "PADDED_FILL", 0.0)
    ref = fit_spheres(p, g)
    assert fits.cap_half_angle_deg[2] == 180.0
    np.testing.assert_allclose(fits.cap_half_angle_deg, ref.cap_half_angle_deg, atol=1e-9)


def test_padded_caps_when_spheres_finish_at_different_passes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Noiseless spheres finish a pass before noisy ones (the padded rows kept shrink);
    every sphere finishes within the passes, so the caps come from the padded layout."""
    rng = np.random.default_rng(8)
    pts, groups = [], []
    for k in range(200):
        u = cap_directions(25, 70.0, rng, axis=rng.normal(size=3))
        noise = 0.0 if k % 3 == 0 else 5e-4
        pts.append(rng.uniform(-500, 500, 3) + (RADIUS + rng.normal(0, noise, 25))[:, None] * u)
        groups.append(np.full(25, k))
    p, g = np.vstack(pts), np.concatenate(groups)
    fits = fit_spheres(p, g)
    assert fits.iterations.max() <= 3 and np.unique(fits.iterations).size > 1
    monkeypatch.setattr(sf, "PADDED_FILL", 0.0)
    _assert_same_fits(fits, fit_spheres(p, g))


def _covariance_before(normal: np.ndarray, cost: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``_covariance`` as it was: LAPACK's inverse of every normal matrix, its centre block."""
    p = normal.shape[1]
    dof = counts - p
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = np.where(dof > 0, cost / np.where(dof > 0, dof, 1), np.nan)
    return (s2[:, None, None] * np.linalg.inv(normal))[:, :3, :3]


@pytest.mark.parametrize("p", [3, 4])
def test_centre_covariance_by_the_schur_complement_equals_the_inverse(p: int) -> None:
    """Normal matrices of caps from 180 deg down to 0.1 deg (condition numbers past 1e6), an
    interpolating sphere (n == p: NaN): the same centre covariance as LAPACK's inverse,
    to the inverse's own rounding (condition number x eps)."""
    rng = np.random.default_rng(p)
    normals, counts = [], []
    for k in range(300):
        n = p if k == 0 else int(rng.integers(p + 1, 40))
        half = float(rng.choice([180.0, 70.0, 20.0, 5.0, 1.0, 0.3, 0.1]))
        u = cap_directions(n, half, rng, axis=rng.normal(size=3))
        jac = np.column_stack([-u, -np.ones(n)])[:, :p]
        normals.append(jac.T @ jac)
        counts.append(n)
    normal, count = np.array(normals), np.array(counts)
    cost = rng.uniform(1e-9, 1e-6, count.size)
    sol = sf._Solution(
        centre=np.zeros((count.size, 3)),
        radius=np.ones(count.size),
        residuals=np.zeros(count.sum()),
        normal_matrix=normal,
        cost=cost,
        iterations=np.ones(count.size, dtype=np.int64),
        coverage_deg=np.zeros(count.size),
    )
    ours, ref = sf._covariance(sol, count), _covariance_before(normal, cost, count)
    assert np.isnan(ours[0]).all() and np.isnan(ref[0]).all()
    cond = np.linalg.cond(normal[1:])
    assert cond.max() > 1e6  # some far from well conditioned
    size = np.abs(ref[1:]).max(axis=(1, 2))
    err = np.abs(ours[1:] - ref[1:]).max(axis=(1, 2))
    assert np.all(err <= 1e-13 * cond * size)
