"""Metrology-grade least-squares sphere fits, vectorized over many spheres.

The fit minimises the sum of squared *geometric* (orthogonal) distances
``|p_i - c| - r`` of the points to the sphere, as ISO 10360-6 style reference
software does.  The algebraic (Kasa) fit, which minimises ``|p - c|^2 - r^2``
instead, is used only to start the iteration: it is biased on partial caps.

Algorithm
---------
1. Points are grouped by sphere, sorted by group (stable) and centred on their
   group centroid, so that far-from-origin coordinates do not cost precision.
2. Start: the linear Kasa fit, ``S c = sum(q |q|^2) / 2`` with the 3x3 scatter
   matrix ``S = sum q q^T`` of each group, solved by Cholesky where a cheap bound
   of its condition number is at most ``1e6``, else through its eigen-decomposition
   (whose eigenvalues the coplanarity test then reads).  With a fixed radius the
   start is the best (by geometric cost) of the Kasa centre and the two mirror
   points at distance ``sqrt(R^2 - rho^2)`` either side of the best-fit plane.
3. Gauss-Newton on the normal equations ``J^T J delta = -J^T e`` of all spheres
   at once (per-sphere sums with :func:`numpy.add.reduceat`, or, for spheres of
   equal point counts laid out one a row, dot products along the rows; a batched
   Cholesky solve written out over the spheres, LU where a matrix is not positive
   definite).  A step that increases a sphere's cost is
   rejected and retried with Levenberg-Marquardt damping
   ``J^T J + lambda diag(J^T J)``.  Gauss-Newton converges only linearly when
   the residuals are not small compared with the curvature of the data (noise
   of the order of the cap's sagitta); a sphere that still iterates after 3
   steps, or had a step rejected, adds the exact second-order term
   ``sum e_i d2e_i/dc2`` (a Newton step) whenever the matrix stays positive
   definite.  On metrology data (micrometre residuals) Gauss-Newton converges
   in about 3 iterations and this never comes into play.
4. A sphere has converged when its undamped (Gauss-Newton or Newton) step is
   at most ``tol_mm`` in every parameter, or when the step changes the
   residuals by less than floating-point rounding can resolve (RMS of
   ``J delta`` below ``64 eps max(r, rms|q|)``), whichever comes first.  Cost
   increases within the rounding error of the cost do not reject a step.
5. The first three steps of every sphere are taken as *plain passes*
   (:func:`_plain_passes`): one evaluation of the geometry per pass gives the
   cost that accepts the step before it, the next step, and, at convergence,
   the residuals and ``J^T J`` (carried by the last, sub-rounding step to first
   order) instead of a cost pass per step and a final pass.  The steps and
   tests are the general iteration's, so the centres are the same numbers; a
   sphere whose step raises the cost, or that needs more steps, is fitted again
   from its start by the general iteration (damping, Newton), as it always was.

Thresholds
----------
``COPLANAR_RTOL = 1e-6``
    A free-radius fit needs points that are not coplanar.  The ratio of the
    smallest to the largest singular value of the centred points of a group
    (computed as the square root of the eigenvalue ratio of ``S``) must be at
    least ``1e-6``.  Eigenvalues of ``S`` carry an absolute error of about
    ``eps * lambda_max``, so this ratio cannot be resolved below
    ``sqrt(eps) ~ 1.5e-8``: exactly coplanar points (e.g. on one circle) show
    ratios of 1e-8 and less, hence the margin.  A ratio of 1e-6 already makes
    the condition number of ``J^T J`` about 1e12 in the most favourable
    geometry (a thin equatorial belt), so nothing usable is rejected.  With a
    fixed radius the same test detects the mirror ambiguity: the centre could
    lie on either side of the plane of coplanar points.
``COND_MAX = 1e12``
    Largest accepted condition number of the normal matrix ``J^T J`` (its
    columns are dimensionless, so no scaling is needed).  Solving it in
    float64 loses about ``log10(cond)`` of the 16 significant digits; at 1e12
    the Gauss-Newton steps still carry about four correct digits, enough for
    the iteration to converge to rounding level, beyond that the solution is
    dictated by rounding.  Small caps with a free radius reach this limit
    first (the condition number grows like ``theta^-4`` with the cap
    half-angle ``theta``): fix the radius there.

Units: millimetres in, millimetres out; the RMS and form figures are in
micrometres.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hexatherm.core.geometry import inverse3
from hexatherm.errors import FitError

__all__ = [
    "COND_MAX",
    "COPLANAR_RTOL",
    "SphereFits",
    "fit_sphere",
    "fit_spheres",
    "probe_radius_mm",
]

COPLANAR_RTOL = 1e-6
"""Smallest accepted ratio of smallest to largest singular value of the centred points."""

COND_MAX = 1e12
"""Largest accepted condition number of the Gauss-Newton normal matrix ``J^T J``."""

_EPS = float(np.finfo(float).eps)
_ROUNDING_FACTOR = 64.0  # convergence floor: RMS of J delta below 64 eps * scale
_LAMBDA_START = 1e-3  # first Levenberg-Marquardt damping after a rejected step
_LAMBDA_MIN = 1e-9  # damping below this is switched off (pure Gauss-Newton)
_NEWTON_AFTER = 3  # iterations after which a sphere switches to Newton steps when possible
#: largest condition-number bound of a scatter matrix whose Kasa start is a Cholesky solve
#: (no eigenvalues); above it, the eigenvalues (the coplanarity test needs 1e12)
_KASA_COND = 1e6


@dataclass(frozen=True)
class SphereFits:
    """Least-squares fits of ``m`` spheres.

    Attributes
    ----------
    centre_mm : numpy.ndarray
        (m, 3) sphere centres.
    radius_mm : numpy.ndarray
        (m,) radii (the given radii for a fixed-radius fit).
    rms_um : numpy.ndarray
        (m,) RMS of the point-to-sphere distances, micrometres.
    form_um : numpy.ndarray
        (m,) form error: max minus min of the signed residuals, micrometres.
    cov_centre_mm2 : numpy.ndarray
        (m, 3, 3) covariance of the centre estimated from the residuals,
        ``s^2 (J^T J)^-1`` with ``s^2 = SSR / (n - p)``; NaN where ``n == p``
        (no redundancy: an interpolating sphere).
    n : numpy.ndarray
        (m,) number of points of each sphere.
    cap_half_angle_deg : numpy.ndarray
        (m,) half-angle of the cap covered by the points seen from the centre:
        the largest angle between the mean point direction and a point
        direction.  180 when the point directions cancel exactly (e.g. the six
        points on the axes).
    residuals_mm : numpy.ndarray
        (N,) signed residual ``|p - c| - r`` of each input point, in input
        order (positive outside the sphere).
    fixed_radius : bool
        Whether the radius was fixed rather than fitted.
    iterations : numpy.ndarray
        (m,) Gauss-Newton / Levenberg-Marquardt iterations used per sphere.
    """

    centre_mm: np.ndarray
    radius_mm: np.ndarray
    rms_um: np.ndarray
    form_um: np.ndarray
    cov_centre_mm2: np.ndarray
    n: np.ndarray
    cap_half_angle_deg: np.ndarray
    residuals_mm: np.ndarray
    fixed_radius: bool
    iterations: np.ndarray


# --------------------------------------------------------------------------------------
# Messages


def _raise_first(bad: NDArray[np.bool_], label: str, describe: Callable[[int], str]) -> None:
    """Raise a FitError naming the first flagged group (and how many others are flagged)."""
    idx = np.flatnonzero(bad)
    if idx.size == 0:
        return
    k = int(idx[0])
    msg = f"{label} {k}: {describe(k)}"
    if idx.size > 1:
        shown = ", ".join(str(int(i)) for i in idx[1:6])
        more = ", ..." if idx.size > 6 else ""
        msg += f" (also {label}s {shown}{more}; {idx.size} {label}s in all)"
    raise FitError(msg, index=k)


# --------------------------------------------------------------------------------------
# The dimension-generic engine (d = 3: spheres, d = 2: circles)


@dataclass(frozen=True)
class _Solution:
    centre: NDArray[np.float64]  # (m, d), in the centred coordinates
    radius: NDArray[np.float64]  # (m,)
    residuals: NDArray[np.float64]  # (N,), sorted order
    normal_matrix: NDArray[np.float64]  # (m, p, p) J^T J at the solution
    cost: NDArray[np.float64]  # (m,) sum of squared residuals
    iterations: NDArray[np.int64]  # (m,)
    coverage_deg: NDArray[np.float64]  # (m,) cap / arc half-angle


def _starts(counts: NDArray[np.int64]) -> NDArray[np.int64]:
    starts = np.zeros(counts.size, dtype=np.int64)
    np.cumsum(counts[:-1], out=starts[1:])
    return starts


def _geometry(
    q: NDArray[np.float64], c: NDArray[np.float64], r: NDArray[np.float64], counts: NDArray
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Vectors centre->point, their lengths and the residuals |q - c| - r."""
    v = q - np.repeat(c, counts, axis=0)
    dist = np.sqrt(np.einsum("ij,ij->i", v, v))
    e = dist - np.repeat(r, counts)
    return v, dist, e


def _cost(
    q: NDArray[np.float64],
    c: NDArray[np.float64],
    r: NDArray[np.float64],
    counts: NDArray,
    starts: NDArray,
) -> NDArray[np.float64]:
    _, _, e = _geometry(q, c, r, counts)
    return np.add.reduceat(e * e, starts)


def _unit(v: NDArray[np.float64], dist: NDArray[np.float64]) -> NDArray[np.float64]:
    safe = np.where(dist > 0.0, dist, 1.0)
    return v / safe[:, None]


def _normal_equations(
    u: NDArray[np.float64],
    e: NDArray[np.float64],
    counts: NDArray,
    starts: NDArray,
    free: bool,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Per-group ``J^T J``, ``-J^T e`` and ``e^T e`` for J = [-u, -1] (free) or [-u]."""
    n_pts, d = u.shape
    ia, ib = np.triu_indices(d)
    nt = ia.size
    p = d + 1 if free else d
    ncol = nt + d + (d + 1 if free else 0) + 1
    # one row per quantity, the points along it: every row is written and summed
    # contiguously (a column per quantity took three times as long; the same sums)
    ut = np.ascontiguousarray(u.T)
    w = np.empty((ncol, n_pts))
    w[:nt] = ut[ia] * ut[ib]
    w[nt : nt + d] = ut * e
    if free:
        w[nt + d : nt + 2 * d] = ut
        w[nt + 2 * d] = e
    w[-1] = e * e
    s = np.add.reduceat(w, starts, axis=1).T
    m = counts.size
    a = np.empty((m, p, p))
    a[:, ia, ib] = s[:, :nt]
    a[:, ib, ia] = s[:, :nt]
    b = np.empty((m, p))
    b[:, :d] = s[:, nt : nt + d]
    if free:
        a[:, :d, d] = s[:, nt + d : nt + 2 * d]
        a[:, d, :d] = s[:, nt + d : nt + 2 * d]
        a[:, d, d] = counts
        b[:, d] = s[:, nt + 2 * d]
    return a, b, s[:, -1]


def _newton_term(
    u: NDArray[np.float64],
    e: NDArray[np.float64],
    dist: NDArray[np.float64],
    counts: NDArray,
    p: int,
) -> NDArray[np.float64]:
    """Per-group second-order term ``sum e_i d2(e_i)/dc2 = sum (e_i/|q_i-c|) (I - u_i u_i^T)``.

    The residual is linear in the radius, so only the centre block is non-zero.
    """
    d = u.shape[1]
    ia, ib = np.triu_indices(d)
    w = (e / np.where(dist > 0.0, dist, 1.0))[:, None]
    s = np.add.reduceat(np.concatenate([w, w * u[:, ia] * u[:, ib]], axis=1), _starts(counts))
    out = np.zeros((counts.size, p, p))
    out[:, ia, ib] = -s[:, 1:]
    out[:, ib, ia] = -s[:, 1:]
    diag = np.arange(d)
    out[:, diag, diag] += s[:, :1]
    return out


def _cholesky(a: NDArray[np.float64]) -> tuple[list[list[NDArray[np.float64]]], NDArray[np.bool_]]:
    """The Cholesky factors of the (m, p, p) symmetric matrices ``a`` written out over the
    m matrices at once (p is 2 to 4: a few dozen array operations instead of LAPACK's call
    per matrix): ``low[i][j]`` (j <= i) the (m,) entries, and where every pivot was
    positive (elsewhere the entries are NaN or infinite)."""
    m, p = a.shape[:2]
    low: list[list[NDArray[np.float64]]] = [[] for _ in range(p)]  # low[i][j], j <= i
    ok = np.ones(m, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for j in range(p):
            pivot = a[:, j, j] - sum((low[j][k] ** 2 for k in range(j)), np.zeros(m))
            ok &= pivot > 0.0
            root = np.sqrt(pivot)
            low[j].append(root)
            for i in range(j + 1, p):
                dot = sum((low[i][k] * low[j][k] for k in range(j)), np.zeros(m))
                low[i].append((a[:, i, j] - dot) / root)
    return low, ok


def _solve(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``x`` with ``a x = b`` for the (m, p, p) matrices ``a`` (normal equations: symmetric,
    positive definite) and ``b`` (m, p), or (m, p, r) for r right-hand sides: the
    Cholesky factors of :func:`_cholesky` and their two substitutions; where a pivot is
    not positive (or not finite), LU with pivoting for all of them
    (:func:`numpy.linalg.solve`, which raises ``LinAlgError`` on a singular matrix)."""
    m, p = b.shape[:2]
    many = b.ndim == 3
    if m == 0:
        return np.zeros(b.shape)
    low, ok = _cholesky(a)
    if not ok.all() or not all(np.all(np.isfinite(row[-1])) for row in low):
        solved = np.linalg.solve(a, b if many else b[..., None])
        return np.asarray(solved if many else solved[..., 0], dtype=np.float64)
    col = (lambda v: v[:, None]) if many else (lambda v: v)
    zero = np.zeros(b.shape[:1] + b.shape[2:])
    y: list[NDArray[np.float64]] = []
    for i in range(p):
        rest = sum((col(low[i][k]) * y[k] for k in range(i)), zero)
        y.append((b[:, i] - rest) / col(low[i][i]))
    x: list[NDArray[np.float64]] = [zero] * p
    for i in reversed(range(p)):
        rest = sum((col(low[k][i]) * x[k] for k in range(i + 1, p)), zero)
        x[i] = (y[i] - rest) / col(low[i][i])
    return np.stack(x, axis=1)


def _condition(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Condition numbers of the symmetric matrices ``a`` (m, p, p) where they may exceed
    :data:`COND_MAX`; elsewhere a bound below ``COND_MAX / 100`` (all that is asked of
    them: whether they exceed it). The bound costs a few array operations instead of an
    eigen-decomposition per matrix: where the pivots of a Cholesky elimination are all
    positive (positive definite), ``lambda_max <= tr`` and
    ``lambda_min >= det / (tr / (p - 1))**(p - 1)`` (the other eigenvalues' product at
    most that, by the mean of their sum, at most ``tr``), so that
    ``cond <= tr (tr / (p - 1))**(p - 1) / det``; the matrices it leaves in doubt get
    their eigenvalues."""
    bound = _condition_bound(a)
    doubt = ~(bound <= 1e-2 * COND_MAX)
    if not doubt.any():
        return bound
    lam = np.linalg.eigvalsh(a[doubt])
    with np.errstate(divide="ignore", invalid="ignore"):
        bound[doubt] = np.where(lam[:, 0] > 0.0, lam[:, -1] / lam[:, 0], np.inf)
    return bound


def _condition_bound(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """An upper bound of the condition numbers of :func:`_condition` (NaN where the
    elimination meets a pivot that is not positive): the determinant from the pivots of
    :func:`_cholesky` (the squares of its diagonal)."""
    m, p = a.shape[:2]
    if p < 2:
        return np.ones(m)
    low, ok = _cholesky(a)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        det = np.prod([low[j][j] ** 2 for j in range(p)], axis=0)
        det = np.where(ok, det, np.nan)
        trace = np.einsum("kii->k", a)
        return np.asarray(trace * (trace / (p - 1)) ** (p - 1) / det)


def _coverage_deg(u: NDArray[np.float64], counts: NDArray, starts: NDArray) -> NDArray[np.float64]:
    """Half-angle between the mean direction and the farthest point direction."""
    total = np.add.reduceat(u, starts, axis=0)
    norm = np.linalg.norm(total, axis=1)
    cancelled = norm <= 1e-12 * counts
    mean_dir = total / np.where(cancelled, 1.0, norm)[:, None]
    md = np.repeat(mean_dir, counts, axis=0)
    cos = np.einsum("ij,ij->i", u, md)
    # the farthest direction is the one of least cosine: its angle, from the sine and
    # the cosine (accurate at any angle), is computed for that one point of each group
    least = np.minimum.reduceat(cos, starts)
    at = np.flatnonzero(cos == np.repeat(least, counts))
    first = at[np.minimum(np.searchsorted(at, starts), at.size - 1)] if at.size else starts
    if not np.all((first >= starts) & (first < starts + counts)):  # a NaN: every point
        ang = np.degrees(np.arctan2(_sines(u, md), cos))
        return np.where(cancelled, 180.0, np.maximum.reduceat(ang, starts))
    cov = np.degrees(np.arctan2(_sines(u[first], mean_dir), cos[first]))
    return np.where(cancelled, 180.0, cov)


def _sines(u: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sine of the angle between unit vectors ``u`` and ``w``, row by row."""
    if u.shape[1] == 3:
        return np.asarray(np.linalg.norm(np.cross(u, w), axis=1))
    return np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])


def _ill_conditioned(
    cond: NDArray[np.float64],
    coverage: NDArray[np.float64] | Callable[[], NDArray[np.float64]],
    label: str,
    free: bool,
) -> None:
    """Refuse the first group whose normal equations are ill-conditioned; ``coverage``
    (the cap or arc half-angles, or what computes them) is read for the message only."""
    bad = ~(cond <= COND_MAX)
    if not bad.any():
        return
    cover = coverage() if callable(coverage) else coverage
    region = "cap" if label == "sphere" else "arc"
    what = "centre and radius" if free else "centre"
    # Only the sphere fit offers a fixed radius (the circle fit does not).
    fixable = free and label == "sphere"
    advice = f"measure a larger {region}"
    if fixable:
        advice = "fix the radius or " + advice

    def describe(k: int) -> str:
        return (
            f"the normal equations are ill-conditioned (condition number {cond[k]:.3g} > "
            f"{COND_MAX:.0e}): the points cover a {region} of half-angle "
            f"{cover[k]:.3g} deg, too small to determine the {what}; {advice}"
        )

    _raise_first(bad, label, describe)


def _fit_nspheres(
    q: NDArray[np.float64],
    counts: NDArray[np.int64],
    radius: NDArray[np.float64] | None,
    *,
    tol_mm: float,
    max_iter: int,
    label: str,
) -> _Solution:
    """Geometric least-squares fit of m hyperspheres (d = 2 or 3) to grouped points.

    ``q`` holds the points sorted by group and centred on their group centroid,
    ``counts`` the group sizes (all groups non-empty), ``radius`` None (free)
    or the (m,) fixed radii.
    """
    m = counts.size
    d = q.shape[1]
    free = radius is None
    starts = _starts(counts)
    flat = "coplanar" if d == 3 else "collinear"

    need = d + 1 if free else d
    kind = "free-radius" if free else "fixed-radius"
    _raise_first(
        counts < need,
        label,
        lambda k: f"only {counts[k]} points; a {kind} fit needs at least {need}",
    )

    # Scatter matrices and degeneracy (coplanarity) test.
    ia, ib = np.triu_indices(d)
    points = _layout(q, counts, free)
    s_up, t, sum_q2 = points.moments()
    scatter = np.empty((m, d, d))
    scatter[:, ia, ib] = s_up
    scatter[:, ib, ia] = s_up
    # the eigenvalues decide the degeneracy and give the Kasa start; where the cheap
    # bound of the condition number (no eigenvalues) shows the scatter matrix well
    # conditioned, neither is needed: it passes, and the start is a Cholesky solve
    # (a fixed radius needs the best-fit plane's normal: its eigenvectors, always)
    easy = _condition_bound(scatter) <= _KASA_COND if free else np.zeros(m, dtype=bool)
    hard = ~easy
    lam = np.full((m, d), np.nan)
    vec = np.full((m, d, d), np.nan)
    if hard.any():
        lam[hard], vec[hard] = np.linalg.eigh(scatter[hard])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.sqrt(np.clip(lam[:, 0], 0.0, None) / lam[:, -1])
    ratio = np.where(lam[:, -1] > 0.0, ratio, 0.0)
    if easy.any():
        ratio[easy] = 1.0 / np.sqrt(_KASA_COND)  # at least this: far above COPLANAR_RTOL

    def degenerate(k: int) -> str:
        if lam[k, -1] <= 0.0:
            return "all points coincide"
        msg = (
            f"the points are {flat} or nearly so (smallest/largest singular value of the "
            f"centred points {ratio[k]:.3g} < {COPLANAR_RTOL:.0e})"
        )
        if free:
            return msg + "; the radius cannot be determined"
        side = "plane" if d == 3 else "line"
        return (
            msg + f"; with a fixed radius the centre could lie on either side of their "
            f"{side} (two mirror solutions): measure points off that {side}"
        )

    _raise_first(~(ratio >= COPLANAR_RTOL), label, degenerate)

    # Algebraic (Kasa) start, decoupled because the points are centred:
    # c = S^-1 sum(q |q|^2) / 2,  r^2 = mean|q|^2 + |c|^2.
    mean_q2 = sum_q2 / counts
    c = np.empty((m, d))
    if easy.any():
        c[easy] = _solve(scatter[easy], t[easy]) / 2.0
    if hard.any():
        t_eig = np.einsum("mji,mj->mi", vec[hard], t[hard]) / (2.0 * lam[hard])
        c[hard] = np.einsum("mij,mj->mi", vec[hard], t_eig)
    if free:
        r = np.sqrt(mean_q2 + np.einsum("ij,ij->i", c, c))
    else:
        r = np.asarray(radius, dtype=float)
        # Mirror candidates either side of the best-fit plane (line), through the
        # in-plane part of the Kasa centre; keep the best of the three by geometric cost.
        normal = vec[:, :, 0]
        a_in = c - np.einsum("ij,ij->i", c, normal)[:, None] * normal
        qa = q - np.repeat(a_in, counts, axis=0)
        depth = np.einsum("ij,ij->i", q, np.repeat(normal, counts, axis=0))
        rho2 = np.add.reduceat(np.einsum("ij,ij->i", qa, qa) - depth**2, starts) / counts
        h = np.sqrt(np.clip(r**2 - rho2, 0.0, None))
        cands = [c, a_in + h[:, None] * normal, a_in - h[:, None] * normal]
        costs = np.stack([_cost(q, cc, r, counts, starts) for cc in cands])
        best = np.argmin(costs, axis=0)
        c = np.stack(cands)[best, np.arange(m)]

    radius_scale = np.sqrt(mean_q2)
    fast = _plain_passes(points, c, r, radius_scale, free, tol_mm, label, max_iter)
    lam_lm = np.zeros(m)
    iterations = np.zeros(m, dtype=np.int64)
    # the spheres the plain passes left (a step that raised the cost, slow convergence)
    # start again from the start: the general iteration below, as if alone
    active = ~fast.done
    last_step = np.full(m, np.inf)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        if idx.size == m:
            qs, cnt, st = q, counts, starts
        else:
            cnt = counts[idx]
            st = _starts(cnt)
            qs = q[np.repeat(active, counts)]
        ca, ra = c[idx], r[idx]
        v, dist, e = _geometry(qs, ca, ra, cnt)
        u = _unit(v, dist)
        a, b, cost = _normal_equations(u, e, cnt, st, free)
        # Gauss-Newton converges only linearly when the residuals are large compared
        # with the curvature of the data (noise ~ sagitta); spheres that are still
        # iterating after 3 steps, or had a step rejected, add the exact second-order
        # term (a Newton step) whenever that keeps the matrix positive definite.
        base = a
        slow = (iterations[idx] >= _NEWTON_AFTER) | (lam_lm[idx] > 0.0)
        if slow.any():
            pm = np.repeat(slow, cnt)
            hess = a[slow] + _newton_term(u[pm], e[pm], dist[pm], cnt[slow], a.shape[1])
            ev = np.linalg.eigvalsh(hess)
            pos_def = ev[:, 0] > 1e-12 * ev[:, -1]
            base = a.copy()
            base[slow] = np.where(pos_def[:, None, None], hess, a[slow])
        try:
            step = _solve(base, b)
        except np.linalg.LinAlgError:
            cond = np.zeros(m)
            cond[idx] = _condition(a)
            cover = np.zeros(m)
            cover[idx] = _coverage_deg(u, cnt, st)
            _ill_conditioned(cond, cover, label, free)
            raise FitError(
                f"singular normal equations for {label}s {idx.tolist()}", index=int(idx[0])
            ) from None
        # Converged when the undamped step is below tol or below rounding.
        jd = np.sqrt(np.clip(np.einsum("ki,kij,kj->k", step, a, step), 0.0, None))
        scale = np.maximum(np.abs(ra), radius_scale[idx])
        small = (np.max(np.abs(step), axis=1) <= tol_mm) | (
            jd <= _ROUNDING_FACTOR * _EPS * scale * np.sqrt(cnt)
        )
        lam_a = lam_lm[idx]
        damp = (lam_a > 0.0) & ~small
        if damp.any():
            ad = base[damp].copy()
            diag = np.einsum("kii->ki", ad)
            diag += lam_a[damp, None] * np.einsum("kii->ki", a[damp])
            step[damp] = _solve(ad, b[damp])
        c_new = ca + step[:, :d]
        r_new = ra + step[:, d] if free else ra
        cost_new = _cost(qs, c_new, r_new, cnt, st)
        # Cost changes below the rounding error of the cost itself (each residual
        # carries ~ eps * scale) cannot reject a step: near the solution the
        # Gauss-Newton steps still improve the fit but no longer the computed cost.
        cost_tol = 16.0 * _EPS * scale * np.sqrt(cnt * cost)
        accept = small | (cost_new <= cost + cost_tol)
        c[idx[accept]] = c_new[accept]
        if free:
            r[idx[accept]] = r_new[accept]
        lam_a = np.where(accept, lam_a / 10.0, np.maximum(lam_a * 10.0, _LAMBDA_START))
        lam_lm[idx] = np.where(lam_a < _LAMBDA_MIN, 0.0, lam_a)
        iterations[idx] += 1
        last_step[idx] = np.max(np.abs(step), axis=1)
        active[idx[small]] = False

    def diverge(k: int) -> str:
        if free and r[k] > 100.0 * radius_scale[k]:
            return f", growing far beyond the point spread: the points look {flat} within noise"
        return ""

    _raise_first(
        active,
        label,
        lambda k: (
            f"the geometric fit did not converge in {max_iter} iteration"
            f"{'' if max_iter == 1 else 's'} "
            f"(last step {last_step[k]:.3g} mm, tolerance {tol_mm:.3g} mm, radius "
            f"{r[k]:.6g} mm{diverge(k)})"
        ),
    )

    c[fast.done] = fast.centre[fast.done]
    r[fast.done] = fast.radius[fast.done]
    iterations[fast.done] = fast.iterations[fast.done]
    e, u, a, cost = fast.residuals, fast.unit, fast.normal_matrix, fast.cost
    left = ~fast.done
    if left.any():  # the final geometry of the spheres the general iteration fitted
        on = np.repeat(left, counts)
        cnt = counts[left]
        v, dist, e_left = _geometry(q[on], c[left], r[left], cnt)
        u[on] = _unit(v, dist)
        e[on] = e_left
        a[left], _, cost[left] = _normal_equations(u[on], e_left, cnt, _starts(cnt), free)
    coverage = None if left.any() else points.final_coverage()
    if coverage is None:
        coverage = _coverage_deg(u, counts, starts)
    _ill_conditioned(_condition(a), coverage, label, free)
    if free:
        _raise_first(
            ~(r > 0.0), label, lambda k: f"the fit converged to a non-positive radius {r[k]:.6g}"
        )
    return _Solution(
        centre=c,
        radius=r,
        residuals=e,
        normal_matrix=a,
        cost=cost,
        iterations=iterations,
        coverage_deg=coverage,
    )


#: Gauss-Newton passes taken by every sphere before the general iteration (pure
#: Gauss-Newton in both: the general one adds Newton's term from its 4th step on)
_PLAIN_PASSES = _NEWTON_AFTER


@dataclass(frozen=True)
class _Plain:
    done: NDArray[np.bool_]  # (m,) converged in the plain passes; the rest: not computed
    centre: NDArray[np.float64]  # (m, d)
    radius: NDArray[np.float64]  # (m,)
    residuals: NDArray[np.float64]  # (N,) at the centre and radius
    unit: NDArray[np.float64]  # (N, d) directions centre -> point
    normal_matrix: NDArray[np.float64]  # (m, p, p)
    cost: NDArray[np.float64]  # (m,)
    iterations: NDArray[np.int64]  # (m,)


#: the padded layout (:class:`_PaddedPoints`) when the spheres padded to the most points
#: of any of them hold at most this many times the points (equal counts: 1)
PADDED_FILL = 1.25


class _FlatPoints:
    """The active spheres' points one after the other, any counts: the sums by
    :func:`numpy.add.reduceat`, the centres repeated to every point."""

    def __init__(self, q: NDArray[np.float64], counts: NDArray[np.int64], free: bool) -> None:
        self.q, self.cnt, self.st, self.free = q, counts, _starts(counts), free
        self.at: NDArray[np.intp] | None = None  # the active points (None: all)
        self.residuals_out = np.empty(q.shape[0])
        self.unit_out = np.empty_like(q)

    def evaluate(
        self, c: NDArray[np.float64], r: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``J^T J``, ``-J^T e`` and ``e^T e`` of the active spheres at ``c``, ``r``."""
        v, dist, e = _geometry(self.q, c, r, self.cnt)
        self.u, self.e = _unit(v, dist), e
        return _normal_equations(self.u, e, self.cnt, self.st, self.free)

    def moments(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Per sphere: the scatter matrix's upper triangle ``sum q_i q_j`` (i <= j),
        ``sum q |q|^2`` and ``sum |q|^2`` (the Kasa start's sums)."""
        q = self.q
        ia, ib = np.triu_indices(q.shape[1])
        q2 = np.einsum("ij,ij->i", q, q)
        s_up = np.add.reduceat(q[:, ia] * q[:, ib], self.st, axis=0)
        return s_up, np.add.reduceat(q * q2[:, None], self.st, axis=0), np.add.reduceat(q2, self.st)

    def coverage(self) -> NDArray[np.float64]:
        return _coverage_deg(self.u, self.cnt, self.st)

    def final_coverage(self) -> NDArray[np.float64] | None:
        """The caps' half-angles from the directions written (None: the caller computes
        them from its own)."""
        return None

    def write(self, step: NDArray[np.float64]) -> None:
        """The residuals carried by ``step`` and the directions, of every active sphere
        (in place: a sphere that goes on is written again when it finishes)."""
        d = self.q.shape[1]
        moved = np.einsum("ij,ij->i", self.u, np.repeat(step[:, :d], self.cnt, axis=0))
        if self.free:
            moved += np.repeat(step[:, d], self.cnt)
        rows = slice(None) if self.at is None else self.at
        self.residuals_out[rows] = self.e - moved
        self.unit_out[rows] = self.u

    def keep(self, go: NDArray[np.bool_]) -> None:
        pm = np.repeat(go, self.cnt)
        self.at = pm.nonzero()[0] if self.at is None else self.at[pm]
        self.q, self.cnt = self.q[pm], self.cnt[go]
        self.st = _starts(self.cnt)

    def results(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self.residuals_out, self.unit_out


class _PaddedPoints:
    """The active spheres' points as a (d, m, w) array, one sphere a row padded to the
    most points ``w`` (the padding weighs nothing: its residuals and directions are
    zero): the centres broadcast along the rows and the sums are dot products along
    them, no repeat and no ``reduceat``. The same sums as :class:`_FlatPoints`' (their
    rounding aside: numpy's dot products add in another order)."""

    def __init__(self, q: NDArray[np.float64], counts: NDArray[np.int64], free: bool) -> None:
        m, width, d = counts.size, int(counts.max()), q.shape[1]
        self.free, self.d, self.cnt = free, d, counts
        self.mask: NDArray[np.bool_] | None = None
        if np.all(counts == width):
            self.q = np.ascontiguousarray(q.T).reshape(d, m, width)
        else:
            self.mask = np.arange(width) < counts[:, None]  # row-major: the points' order
            self.q = np.zeros((d, m, width))
            self.q[:, self.mask] = q.T
        self.full_mask, self.full_counts = self.mask, counts
        self.idx = np.arange(m)
        self.residuals_out = np.zeros((m, width))
        self.unit_out = np.zeros((d, m, width))

    def evaluate(
        self, c: NDArray[np.float64], r: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """``J^T J``, ``-J^T e`` and ``e^T e`` of the active spheres at ``c``, ``r``."""
        d, free = self.d, self.free
        v = self.q - c.T[:, :, None]
        dist = np.sqrt(np.einsum("imw,imw->mw", v, v))
        e = dist - r[:, None]
        u = v / np.where(dist > 0.0, dist, 1.0)
        if self.mask is not None:
            e *= self.mask
            u *= self.mask
        self.u, self.e = u, e
        m = c.shape[0]
        p = d + 1 if free else d
        a = np.empty((m, p, p))
        b = np.empty((m, p))
        for i in range(d):
            for j in range(i, d):
                a[:, i, j] = a[:, j, i] = np.einsum("mw,mw->m", u[i], u[j])
            b[:, i] = np.einsum("mw,mw->m", u[i], e)
        if free:
            a[:, :d, d] = a[:, d, :d] = np.einsum("imw->mi", u)
            a[:, d, d] = self.cnt
            b[:, d] = np.einsum("mw->m", e)
        return a, b, np.einsum("mw,mw->m", e, e)

    def _flat_unit(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """(d, m, w) directions as (N, d), the points' order."""
        flat = u.reshape(self.d, -1) if self.mask is None else u[:, self.mask]
        return np.ascontiguousarray(flat.T)

    def moments(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`_FlatPoints.moments`, as dot products along the rows."""
        q, d = self.q, self.d
        ia, ib = np.triu_indices(d)
        s_up = np.stack([np.einsum("mw,mw->m", q[i], q[j]) for i, j in zip(ia, ib, strict=True)], 1)
        q2 = np.einsum("imw,imw->mw", q, q)
        return s_up, np.einsum("imw,mw->mi", q, q2), np.einsum("mw->m", q2)

    def coverage(self) -> NDArray[np.float64]:
        return _coverage_deg(self._flat_unit(self.u), self.cnt, _starts(self.cnt))

    def final_coverage(self) -> NDArray[np.float64] | None:
        """:func:`_coverage_deg` of every sphere from the directions written (all of
        them: the caller asks only when the passes fitted every sphere), along the rows:
        the farthest direction is the first of least cosine, as there. None where a
        cosine is not finite (:func:`_coverage_deg`'s own fallback decides)."""
        u, mask, counts = self.unit_out, self.full_mask, self.full_counts
        total = np.einsum("imw->mi", u)
        norm = np.linalg.norm(total, axis=1)
        cancelled = norm <= 1e-12 * counts
        mean_dir = total / np.where(cancelled, 1.0, norm)[:, None]
        cos = np.einsum("imw,mi->mw", u, mean_dir)
        if mask is not None:
            cos[~mask] = np.inf
        if not np.all(np.isfinite(cos) | np.isposinf(cos)) or np.any(np.isposinf(cos.min(1))):
            return None
        rows = np.arange(cos.shape[0])
        first = np.argmin(cos, axis=1)
        cov = np.degrees(np.arctan2(_sines(u[:, rows, first].T, mean_dir), cos[rows, first]))
        return np.asarray(np.where(cancelled, 180.0, cov))

    def write(self, step: NDArray[np.float64]) -> None:
        """The residuals carried by ``step`` and the directions, of every active sphere."""
        d = self.d
        moved = np.einsum("imw,mi->mw", self.u, step[:, :d])
        if self.free:
            moved += step[:, d, None]
            if self.mask is not None:
                moved *= self.mask
        self.residuals_out[self.idx] = self.e - moved
        self.unit_out[:, self.idx] = self.u

    def keep(self, go: NDArray[np.bool_]) -> None:
        self.q, self.idx, self.cnt = self.q[:, go], self.idx[go], self.cnt[go]
        if self.mask is not None:
            self.mask = self.mask[go]

    def results(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        if self.full_mask is None:
            residuals = self.residuals_out.reshape(-1)
            return residuals, np.ascontiguousarray(self.unit_out.reshape(self.d, -1).T)
        unit = np.ascontiguousarray(self.unit_out[:, self.full_mask].T)
        return self.residuals_out[self.full_mask], unit


_Points = _FlatPoints | _PaddedPoints


def _layout(q: NDArray[np.float64], counts: NDArray[np.int64], free: bool) -> _Points:
    """Spheres of equal (or nearly equal: :data:`PADDED_FILL`) point counts laid out one a
    row (:class:`_PaddedPoints`), others one after the other (:class:`_FlatPoints`)."""
    m = counts.size
    if m > 0 and counts.max() * m <= PADDED_FILL * q.shape[0]:
        return _PaddedPoints(q, counts, free)
    return _FlatPoints(q, counts, free)


def _plain_passes(
    points: _Points,
    c: NDArray[np.float64],
    r: NDArray[np.float64],
    radius_scale: NDArray[np.float64],
    free: bool,
    tol_mm: float,
    label: str,
    max_iter: int,
) -> _Plain:
    """Undamped Gauss-Newton steps from the start ``c``, ``r``, all spheres at once, each
    pass's geometry serving three ends: the cost that accepts the step before it, the
    step after it, and, when that step is below the tolerance or rounding (as the general
    iteration judges it), the sphere's residuals and ``J^T J``: the centre and radius
    take that last step, as in the general iteration, which then computes the residuals
    and ``J^T J`` once more, at the point reached; here the residuals and their sum of
    squares are carried there to first order (``e + J delta``; the step is at most
    ``tol_mm``, or what rounding resolves) and ``J^T J`` is the point before's.

    The steps, the conditioning check of the first pass and the convergence test are
    the general iteration's own. A step that raises the cost beyond its rounding (which
    the general iteration would damp), a singular matrix, or no convergence within
    :data:`_PLAIN_PASSES` passes leaves the sphere not ``done``: it is fitted again from
    its start by the general iteration, which then takes the same steps as it always
    did. ``points``: the spheres' points in their layout (:func:`_layout`)."""
    m, d = c.shape
    p = d + 1 if free else d
    counts = points.cnt
    done = np.zeros(m, dtype=bool)
    centre = c.copy()
    radius = r.copy()
    normal = np.zeros((m, p, p))
    cost_out = np.zeros(m)
    iterations = np.zeros(m, dtype=np.int64)
    idx = np.arange(m)
    cnt = counts
    ca, ra = c, r
    prev_cost = prev_tol = None
    for k in range(min(_PLAIN_PASSES, max_iter)):
        a, b, cost = points.evaluate(ca, ra)
        if k == 0:
            _ill_conditioned(_condition(a), points.coverage, label, free)
        scale = np.maximum(np.abs(ra), radius_scale[idx])
        ok = np.ones(idx.size, dtype=bool)
        if prev_cost is not None and prev_tol is not None:
            ok = cost <= prev_cost + prev_tol
        try:
            step = _solve(a, b)
        except np.linalg.LinAlgError:
            break
        quad = np.einsum("ki,kij,kj->k", step, a, step)
        jd = np.sqrt(np.clip(quad, 0.0, None))
        small = (np.max(np.abs(step), axis=1) <= tol_mm) | (
            jd <= _ROUNDING_FACTOR * _EPS * scale * np.sqrt(cnt)
        )
        fin = ok & small
        if fin.any():
            ids = idx[fin]
            done[ids] = True
            centre[ids] = ca[fin] + step[fin, :d]
            if free:
                radius[ids] = ra[fin] + step[fin, d]
            normal[ids] = a[fin]
            # the residuals and their sum of squares carried by the last step to first
            # order, e + J delta, J = [-u, -1] (exact for the sum, |e + J delta|^2 =
            # e.e + 2 delta.J^T e + delta.J^T J delta with J^T e = -b): the step is
            # below 1e-12 mm, its second order below rounding
            cost_out[ids] = np.maximum(
                cost[fin] - 2.0 * np.einsum("ki,ki->k", step[fin], b[fin]) + quad[fin], 0.0
            )
            iterations[ids] = k + 1
            # written for every sphere of the pass, in place (no gather of the finished
            # ones' points): a sphere that goes on is written again when it finishes,
            # or by the general iteration
            points.write(step)
        go = ok & ~small
        if not go.any():
            break
        c_next = ca + step[:, :d]
        r_next = ra + step[:, d] if free else ra
        prev_tol = 16.0 * _EPS * scale * np.sqrt(cnt * cost)
        prev_cost = cost
        if not go.all():
            points.keep(go)
            idx, cnt = idx[go], cnt[go]
            c_next, r_next = c_next[go], r_next[go]
            prev_cost, prev_tol = prev_cost[go], prev_tol[go]
        ca, ra = c_next, r_next
    residuals, unit = points.results()
    return _Plain(done, centre, radius, residuals, unit, normal, cost_out, iterations)


#: points of the spheres fitted together in one block: a block's arrays (a few MB) stay in
#: the CPU's caches, and a scanning probe's millions of points are fitted block after block
#: in bounded memory (every sphere's fit depends on its own points only)
BLOCK_POINTS = 1 << 15


def _fit_in_blocks(
    points: NDArray[np.float64],
    centroid: NDArray[np.float64],
    counts: NDArray[np.int64],
    radius: NDArray[np.float64] | None,
    *,
    tol_mm: float,
    max_iter: int,
    block_points: int = BLOCK_POINTS,
) -> _Solution:
    """:func:`_fit_nspheres` of the spheres, ``points`` sorted by sphere and centred on
    their sphere's ``centroid`` block by block, in blocks of about ``block_points`` points
    (one sphere's points always in one block). A sphere that cannot be fitted makes the
    whole set be fitted at once, so that the error names the same sphere, with the same
    others, as a fit of all of them in one go."""
    ends = np.cumsum(counts)

    def at_once() -> _Solution:
        q = points - np.repeat(centroid, counts, axis=0)
        return _fit_nspheres(q, counts, radius, tol_mm=tol_mm, max_iter=max_iter, label="sphere")

    if ends.size == 0 or ends[-1] <= block_points:
        return at_once()
    # spheres where the running point count crosses each multiple of block_points (sorted,
    # so one unique makes the block bounds)
    cuts = np.searchsorted(ends, np.arange(block_points, ends[-1], block_points))
    bounds = np.unique(np.concatenate(([0], cuts, [counts.size])))
    parts = []
    try:
        for a, b in zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True):
            first = int(ends[a - 1]) if a else 0
            q = points[first : int(ends[b - 1])] - np.repeat(centroid[a:b], counts[a:b], axis=0)
            parts.append(
                _fit_nspheres(
                    q,
                    counts[a:b],
                    None if radius is None else radius[a:b],
                    tol_mm=tol_mm,
                    max_iter=max_iter,
                    label="sphere",
                )
            )
    except FitError:
        return at_once()
    return _Solution(
        **{
            f.name: np.concatenate([getattr(part, f.name) for part in parts])
            for f in dataclasses.fields(_Solution)
        }
    )


def _covariance(sol: _Solution, counts: NDArray[np.int64]) -> NDArray[np.float64]:
    """The centre's covariance (m, 3, 3): the centre block of ``s^2 (J^T J)^-1`` with
    ``s^2 = SSR / (n - p)`` (NaN if n == p). That block is the inverse of the centre
    block's Schur complement ``A - b b^T / n`` (free radius: ``J^T J = [[A, b], [b^T,
    n]]``; a fixed radius: ``A``), inverted by its adjugate (:func:`inverse3`: no LAPACK
    call per sphere)."""
    a = sol.normal_matrix
    p = a.shape[1]
    dof = counts - p
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = np.where(dof > 0, sol.cost / np.where(dof > 0, dof, 1), np.nan)
    centre = a[:, :3, :3]
    if p == 4:
        column = a[:, :3, 3]
        centre = centre - column[:, :, None] * column[:, None, :] / a[:, 3, 3, None, None]
    return s2[:, None, None] * inverse3(centre)


# --------------------------------------------------------------------------------------
# Public API


def _as_points(points_mm: ArrayLike, dim: int = 3) -> NDArray[np.float64]:
    try:
        pts = np.asarray(points_mm, dtype=float)
    except (TypeError, ValueError) as exc:
        raise FitError(f"points_mm must be a numeric (N, {dim}) array: {exc}") from None
    if pts.ndim != 2 or pts.shape[1] != dim:
        raise FitError(f"points_mm must have shape (N, {dim}), got {pts.shape}")
    return pts


def _as_groups(groups: ArrayLike | None, n_points: int) -> NDArray[np.int64]:
    if groups is None:
        return np.zeros(n_points, dtype=np.int64)
    g = np.asarray(groups)
    if g.shape != (n_points,):
        raise FitError(f"groups must have shape ({n_points},) like the points, got {g.shape}")
    if n_points and not np.issubdtype(g.dtype, np.integer):
        raise FitError(f"groups must be integer sphere indices, got dtype {g.dtype}")
    g = g.astype(np.int64, copy=False)
    if n_points and g.min() < 0:
        i = int(np.argmin(g))
        raise FitError(f"groups must be >= 0: point {i} has group {int(g[i])}")
    return g


def fit_spheres(
    points_mm: ArrayLike,
    groups: ArrayLike | None = None,
    *,
    radius_mm: ArrayLike | None = None,
    tol_mm: float = 1e-12,
    max_iter: int = 50,
) -> SphereFits:
    """Fit many spheres at once by geometric least squares.

    Parameters
    ----------
    points_mm : array_like
        (N, 3) measured points, mm.
    groups : array_like of int, optional
        (N,) sphere index ``0 .. m-1`` of each point, in any order, groups of any
        sizes.  Every index up to the largest must be used.  None: one sphere.
    radius_mm : float or array_like, optional
        Fix the radius (scalar for all spheres, or (m,)); only the centre is
        fitted (3 parameters), which is much better conditioned on small caps.
        None (default): the radius is fitted as well (4 parameters).
    tol_mm : float
        Convergence tolerance on the Gauss-Newton step, mm (a step that is
        below floating-point resolution also counts as converged).
    max_iter : int
        Maximum Gauss-Newton / Levenberg-Marquardt iterations per sphere.

    Returns
    -------
    SphereFits
        Per-sphere centre, radius, RMS, form, centre covariance, cap half-angle,
        and the per-point residuals in input order.

    Raises
    ------
    FitError
        With the offending sphere index: non-finite coordinates; fewer than 4
        points (3 with a fixed radius); coplanar points (relative spread below
        :data:`COPLANAR_RTOL`; with a fixed radius the centre would be
        ambiguous between two mirror positions); normal equations with a
        condition number above :data:`COND_MAX`; no convergence within
        ``max_iter`` iterations.  Also for malformed arguments.

    Notes
    -----
    Only the iteration loop is in Python; every iteration handles all the
    spheres that have not converged yet with :func:`numpy.add.reduceat` (or dot
    products along the rows of spheres of equal point counts) and a batched
    Cholesky solve.  See the module docstring for the algorithm and the thresholds.

    Examples
    --------
    Two spheres, the second one given as probe-tip centres on a 10 deg to 70 deg
    band of polar angles:

    >>> import numpy as np
    >>> axes = np.vstack([np.eye(3), -np.eye(3)])
    >>> theta = np.radians([10, 40, 70, 40, 70, 70])
    >>> phi = np.radians([0, 0, 60, 180, 180, 300])
    >>> u = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    >>> pts = np.vstack([[100.0, 0.0, 50.0] + 12.7 * axes, [0.0, 200.0, 0.0] + 5.5 * u])
    >>> fits = fit_spheres(pts, [0] * 6 + [1] * 6)
    >>> print(np.round(fits.centre_mm, 9) + 0.0)
    [[100.   0.  50.]
     [  0. 200.   0.]]
    >>> print(np.round(fits.radius_mm, 9), fits.n, np.round(fits.cap_half_angle_deg, 1))
    [12.7  5.5] [6 6] [180.   72.8]
    """
    pts = _as_points(points_mm)
    n_points = pts.shape[0]
    g = _as_groups(groups, n_points)
    if not (np.isfinite(tol_mm) and tol_mm > 0):
        raise FitError(f"tol_mm must be a positive number, got {tol_mm!r}")
    if int(max_iter) != max_iter or max_iter < 1:
        raise FitError(f"max_iter must be a positive integer, got {max_iter!r}")
    m = int(g.max()) + 1 if n_points else 1
    counts = np.bincount(g, minlength=m).astype(np.int64)

    bad_rows = np.asarray(~np.isfinite(pts).all(axis=1), dtype=bool)
    if bad_rows.any():
        first_row = np.flatnonzero(bad_rows)
        by_group = np.zeros(m, dtype=bool)
        by_group[g[first_row]] = True
        row_of = {int(g[i]): int(i) for i in first_row[::-1]}
        _raise_first(
            by_group,
            "sphere",
            lambda k: (
                f"point {row_of[k]} has a non-finite coordinate {pts[row_of[k]].tolist()} "
                f"({int(bad_rows[g == k].sum())} such points in this sphere)"
            ),
        )

    radius: NDArray[np.float64] | None = None
    if radius_mm is not None:
        try:
            rad = np.asarray(radius_mm, dtype=float)
        except (TypeError, ValueError) as exc:
            raise FitError(f"radius_mm must be numeric: {exc}") from None
        if rad.ndim == 0:
            rad = np.full(m, float(rad))
        elif rad.shape != (m,):
            raise FitError(f"radius_mm must be a scalar or have shape ({m},), got {rad.shape}")
        _raise_first(
            ~(np.isfinite(rad) & (rad > 0)),
            "sphere",
            lambda k: f"the fixed radius must be finite and positive, got {float(rad[k])!r}",
        )
        radius = rad.copy()

    # points already in group order (a file's spheres one after the other) need no sort
    in_order = bool(np.all(g[1:] >= g[:-1]))
    order = None if in_order else np.argsort(g, kind="stable")
    ps = pts if order is None else pts[order]
    need = 4 if radius is None else 3
    kind = "free-radius" if radius is None else "fixed-radius"
    _raise_first(
        counts < need,
        "sphere",
        lambda k: f"only {counts[k]} points; a {kind} fit needs at least {need}",
    )
    starts = _starts(counts)
    centroid = np.add.reduceat(ps, starts, axis=0) / counts[:, None]
    sol = _fit_in_blocks(ps, centroid, counts, radius, tol_mm=float(tol_mm), max_iter=int(max_iter))

    if order is None:
        residuals = sol.residuals
    else:
        residuals = np.empty(n_points)
        residuals[order] = sol.residuals
    e = sol.residuals
    form = np.maximum.reduceat(e, starts) - np.minimum.reduceat(e, starts)
    cov = _covariance(sol, counts)
    return SphereFits(
        centre_mm=centroid + sol.centre,
        radius_mm=sol.radius.copy(),
        rms_um=1e3 * np.sqrt(sol.cost / counts),
        form_um=1e3 * form,
        cov_centre_mm2=cov,
        n=counts,
        cap_half_angle_deg=sol.coverage_deg,
        residuals_mm=residuals,
        fixed_radius=radius is not None,
        iterations=sol.iterations,
    )


def fit_sphere(
    points_mm: ArrayLike,
    *,
    radius_mm: float | None = None,
    tol_mm: float = 1e-12,
    max_iter: int = 50,
) -> SphereFits:
    """Fit one sphere: :func:`fit_spheres` with a single group (results have m = 1).

    Parameters
    ----------
    points_mm : array_like
        (N, 3) points, mm.
    radius_mm : float, optional
        Fixed radius; None to fit it.
    tol_mm, max_iter
        As for :func:`fit_spheres`.

    Returns
    -------
    SphereFits
        With arrays of length 1 (``centre_mm[0]``, ``radius_mm[0]``, ...).

    Examples
    --------
    A fixed-radius fit on a 30 deg cap:

    >>> import numpy as np
    >>> t = np.radians(30.0)
    >>> phi = np.radians(np.arange(0, 360, 60))
    >>> u = np.c_[np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.full(6, np.cos(t))]
    >>> u = np.vstack([u, [0.0, 0.0, 1.0]])
    >>> fit = fit_sphere([10.0, -5.0, 3.0] + 2.0 * u, radius_mm=2.0)
    >>> print(np.round(fit.centre_mm[0], 9) + 0.0, fit.fixed_radius)
    [10. -5.  3.] True
    >>> print(round(float(fit.cap_half_angle_deg[0]), 6))
    30.0
    """
    return fit_spheres(points_mm, None, radius_mm=radius_mm, tol_mm=tol_mm, max_iter=max_iter)


def probe_radius_mm(ball_diameter_mm: float, tip_diameter_mm: float, compensated: bool) -> float:
    """Radius to expect (or to fix) when fitting points probed on a ball.

    Parameters
    ----------
    ball_diameter_mm : float
        Diameter of the measured ball.
    tip_diameter_mm : float
        Diameter of the probe tip (stylus ball).
    compensated : bool
        True if the points are already compensated to the ball surface; False
        if they are probe-tip centre points, which lie on a sphere of radius
        ball radius + tip radius (the ball is probed from outside).

    Returns
    -------
    float
        The radius of the sphere the points lie on, mm.

    Examples
    --------
    >>> probe_radius_mm(25.4, 2.0, compensated=False)
    13.7
    >>> probe_radius_mm(25.4, 2.0, compensated=True)
    12.7
    """
    ball = float(ball_diameter_mm)
    tip = float(tip_diameter_mm)
    if not (np.isfinite(ball) and ball > 0):
        raise FitError(f"ball diameter must be finite and positive, got {ball_diameter_mm!r}")
    if not (np.isfinite(tip) and tip >= 0):
        raise FitError(f"tip diameter must be finite and non-negative, got {tip_diameter_mm!r}")
    return ball / 2.0 if compensated else (ball + tip) / 2.0


def refine_spheres(
    points_mm: ArrayLike,
    centre_mm: ArrayLike,
    radius_mm: ArrayLike,
    *,
    fixed_radius: bool = False,
    iterations: int = 3,
    normal_points_mm: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Gauss-Newton refits of many spheres of equal point counts, from a close start.

    For Monte Carlo draws of probed points around spheres already fitted by
    :func:`fit_spheres`: every sphere has the same number of points, and the start
    (the fitted centre and radius) is within micrometres of the answer, so a few
    undamped Gauss-Newton steps of the same geometric least-squares problem converge
    without the general fit's preconditions, damping and diagnostics. The normal
    matrix ``J^T J`` of the first step is kept for the later ones (the gradient
    ``J^T e`` is recomputed every step, so the answer is the exact least-squares fit;
    the convergence is linear, with a rate of about the start's error over the radius).
    Broadcasts over any leading axes (draws, spheres).

    Parameters
    ----------
    points_mm : array_like, shape (..., n, 3)
        The points of each sphere.
    centre_mm : array_like, shape (..., 3)
        Start centres (broadcast against the points' leading axes).
    radius_mm : array_like, shape (...)
        Start radii; the radius of a fixed-radius fit.
    fixed_radius : bool
        Fit the centre only (3 parameters) instead of centre and radius (4).
    iterations : int
        Gauss-Newton steps.
    normal_points_mm : array_like, shape (..., n, 3), optional
        Points to build ``J^T J`` from, at the start (e.g. the unperturbed points of
        Monte Carlo draws: one matrix per sphere for all draws). Any points close to
        the answer give the same fixed point. Default: the points themselves.

    Returns
    -------
    centre_mm : ndarray, shape (..., 3)
    radius_mm : ndarray, shape (...)

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> d = rng.normal(size=(25, 3)); d[:, 2] = np.abs(d[:, 2]) + 1.0
    >>> d /= np.linalg.norm(d, axis=1, keepdims=True)
    >>> pts = [1.0, 2.0, 3.0] + 12.7 * d + rng.normal(scale=1e-3, size=(25, 3))
    >>> ref = fit_spheres(pts)
    >>> c, r = refine_spheres(pts, ref.centre_mm[0] + 2e-3, ref.radius_mm[0] - 1e-3)
    >>> bool(np.allclose(c, ref.centre_mm[0], atol=1e-11)), bool(abs(r - ref.radius_mm[0]) < 1e-11)
    (True, True)
    """
    pts = np.asarray(points_mm, dtype=float)
    if pts.ndim < 2 or pts.shape[-1] != 3:
        raise FitError(f"points must have shape (..., n, 3), got {pts.shape}")
    n = pts.shape[-2]
    p = 3 if fixed_radius else 4
    if n < p:
        raise FitError(f"need at least {p} points per sphere, got {n}")
    if int(iterations) != iterations or iterations < 1:
        raise FitError(f"iterations must be a positive integer, got {iterations!r}")
    lead = pts.shape[:-2]
    c = np.array(np.broadcast_to(np.asarray(centre_mm, dtype=float), (*lead, 3)))
    r = np.array(np.broadcast_to(np.asarray(radius_mm, dtype=float), lead))
    px, py, pz = (np.ascontiguousarray(pts[..., i]) for i in range(3))  # (..., n) each
    inverse = None
    for _ in range(int(iterations)):
        vx, vy, vz = px - c[..., 0:1], py - c[..., 1:2], pz - c[..., 2:3]
        dist = np.sqrt(vx * vx + vy * vy + vz * vz)
        e = dist - r[..., None]  # residuals; J = [-u, -1], u = v / dist
        w = e / dist
        # J^T e of the centre, as dot products over the points (einsum: no product
        # arrays, and its dot products run 3x faster than a sum over a short last axis)
        parts = [np.einsum("...n,...n->...", v, w) for v in (vx, vy, vz)]
        if not fixed_radius:
            parts.append(np.einsum("...n->...", e))
        if inverse is None:
            # J^T J of the first step, kept: the fixed point (J^T e = 0 with the current J)
            # is the exact least-squares fit; only the rate is linear, and tiny this close
            if normal_points_mm is None:
                ux, uy, uz = vx / dist, vy / dist, vz / dist
                at = lead
            else:
                q = np.asarray(normal_points_mm, dtype=float)
                at = q.shape[:-2]
                start = np.broadcast_to(np.asarray(centre_mm, dtype=float), (*at, 3))
                qv = q - start[..., None, :]
                qd = np.sqrt(np.einsum("...i,...i->...", qv, qv))
                ux, uy, uz = (qv[..., i] / qd for i in range(3))
            p_ = 3 if fixed_radius else 4
            a = np.empty((*at, p_, p_))
            comps = (ux, uy, uz)
            for i in range(3):
                for j in range(i, 3):
                    a[..., i, j] = a[..., j, i] = (comps[i] * comps[j]).sum(-1)
                if not fixed_radius:
                    a[..., i, 3] = a[..., 3, i] = comps[i].sum(-1)
            if not fixed_radius:
                a[..., 3, 3] = n
            inverse = np.linalg.inv(a)
        # inverse @ gradient written out: a matrix product per sphere and draw costs more
        # than the arithmetic (p x p, p = 3 or 4), products of whole arrays do not
        step = []
        for i in range(p):
            row = inverse[..., i, 0] * parts[0]
            for j in range(1, p):
                row = row + inverse[..., i, j] * parts[j]
            step.append(row)
        c = c + np.stack(step[:3], axis=-1)
        if not fixed_radius:
            r = r + step[3]
    return c, r
