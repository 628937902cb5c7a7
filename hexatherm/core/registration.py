"""Rigid registration of measured ball centres to the balls file.

For a step, the three (or more) ball centres measured in the CMM frame M are
matched to the same balls' centres known in the platform frame P. The rigid
transform ``platform2cmm`` minimising ``sum w_k |platform2cmm(b_k) - c_k|^2`` is
the Kabsch/Umeyama solution with the reflection excluded (determinant +1), for
many steps at once. Its rotation is computed in Horn's quaternion form (the same
minimiser), written out as array operations over all steps; steps where that
form would lose digits (a rotation the weighted balls hardly determine) get the
SVD of the Kabsch/Umeyama method.

>>> import numpy as np
>>> from hexatherm.core.geometry import transform_from_pose, apply_transform
>>> balls = np.array([[100.0, 0, 10], [-50, 86.6, 10], [-50, -86.6, 10]])
>>> platform2cmm = transform_from_pose([300, 200, 100, 1, 2, 3])
>>> centres = apply_transform(platform2cmm, balls)
>>> fit = register(centres, balls)
>>> bool(np.allclose(fit.platform2cmm, platform2cmm, atol=1e-12))
True
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import cross_columns, inverse3
from hexatherm.errors import RegistrationError
from hexatherm.typing import FloatArray

#: smallest/largest singular value ratio of the centred ball layout below which
#: the balls are called collinear
COLLINEAR_RATIO = 1e-6


@dataclass(frozen=True)
class Registration:
    """Result of registering N steps.

    Attributes
    ----------
    platform2cmm : ndarray, shape (N, 4, 4)
        Transform taking platform coordinates to CMM coordinates.
    residuals_mm : ndarray, shape (N, k, 3)
        Measured minus registered ball centres.
    rms_um : ndarray, shape (N,)
        RMS of the residual distances, micrometres.
    """

    platform2cmm: FloatArray
    residuals_mm: FloatArray
    rms_um: FloatArray


def check_ball_layout(balls_mm: npt.ArrayLike) -> FloatArray:
    """Return the ball centres (k, 3), checked: k >= 3, finite, not collinear.

    >>> check_ball_layout([[0, 0, 0], [1, 0, 0], [2, 0, 0]])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hexatherm.errors.RegistrationError: the balls are collinear (or nearly): ...
    """
    balls = np.asarray(balls_mm, dtype=float)
    if balls.ndim != 2 or balls.shape[1] != 3:
        raise RegistrationError(f"ball centres must have shape (k, 3), got {balls.shape}")
    if balls.shape[0] < 3:
        raise RegistrationError(
            f"at least 3 balls are needed to register a frame, got {len(balls)}"
        )
    if not np.all(np.isfinite(balls)):
        raise RegistrationError("ball centres have a non-finite value")
    sv = np.linalg.svd(balls - balls.mean(axis=0), compute_uv=False)
    if sv[0] == 0 or sv[1] / sv[0] < COLLINEAR_RATIO:
        ratio = 0.0 if sv[0] == 0 else sv[1] / sv[0]
        raise RegistrationError(
            "the balls are collinear (or nearly): a frame cannot be registered to them "
            f"(spread ratio {ratio:.1e})"
        )
    return balls


def register(
    centres_mm: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    weights: npt.ArrayLike | None = None,
) -> Registration:
    """Rigid transforms ``platform2cmm`` that best map the balls onto measured centres.

    Parameters
    ----------
    centres_mm : array_like, shape (N, k, 3) or (k, 3)
        Measured centres of the k balls at each of N steps, CMM frame.
    balls_mm : array_like, shape (k, 3)
        The same balls in the platform frame (balls file).
    weights : array_like, shape (N, k) or (k,), optional
        Non-negative weight of each ball (1 by default).

    Returns
    -------
    Registration
        Always with a leading N axis.
    """
    centres, balls, rot, transforms = _fit(centres_mm, balls_mm, weights)
    residuals = centres - (balls @ np.swapaxes(rot, 1, 2) + transforms[:, None, :3, 3])
    rms = np.sqrt((residuals**2).sum(axis=-1).mean(axis=-1)) * 1e3
    return Registration(platform2cmm=transforms, residuals_mm=residuals, rms_um=rms)


def platform_frames(
    centres_mm: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    weights: npt.ArrayLike | None = None,
) -> FloatArray:
    """:func:`register`'s ``platform2cmm`` (N, 4, 4) alone, without the residuals (the
    uncertainty's central differences register each step 6k times and use only these).

    Checked as a whole (an error names the step as :func:`register` does), then fitted
    :data:`FRAME_BLOCK` rows at a time: each row's fit is its own arithmetic, so the
    transforms are the same, and the temporaries of a block stay in the cache (the
    central differences of 10,000 targets, 360,036 registrations: 2.2 -> 1.3 s)."""
    centres, balls, w = _checked(centres_mm, balls_mm, weights)
    out = np.empty((centres.shape[0], 4, 4))
    for start in range(0, centres.shape[0], FRAME_BLOCK):
        rows = slice(start, start + FRAME_BLOCK)
        out[rows] = _solve(centres[rows], balls, w[rows])[1]
    return out


#: rows that :func:`platform_frames` fits at once
FRAME_BLOCK = 8192


def frame_derivatives(
    centres_mm: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    weights: npt.ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`platform_frames` and their derivatives by the centres, analytic.

    The fitted rotation ``R`` maximises ``sum w_k c_k . R b_k`` (centred, weights
    normalized): its gradient by a small rotation ``R -> (I + [omega]x) R`` vanishes,
    ``g = sum w_k a_k x c_k = 0`` with ``a_k = R b_k``. Moving the centres by ``dc``
    moves the optimum by ``omega = (tr(M) I - M)^-1 sum w_k [a_k]x dc_k``, where
    ``M = sum w_k a_k c_k^T`` (the implicit function theorem on ``g``; the weighted
    mean of the ``a_k`` is zero, so the centres' own mean drops out), and the translation
    ``t = c_mean - R b_mean`` by ``dt = dc_mean + (R b_mean) x omega``. The same
    minimiser whichever way :func:`register` computed it (Horn or SVD).

    Returns
    -------
    transforms : ndarray, shape (N, 4, 4)
        As :func:`platform_frames`.
    d_rotation : ndarray, shape (N, 3, k, 3)
        ``omega`` (rad) per mm of each centre coordinate: ``dR = [omega]x R``.
    d_translation : ndarray, shape (N, 3, k, 3)
        ``dt`` (mm/mm) per mm of each centre coordinate.
    """
    centres, balls, w = _checked(centres_mm, balls_mm, weights)
    out = np.empty((centres.shape[0], 4, 4))
    for start in range(0, centres.shape[0], FRAME_BLOCK):
        rows = slice(start, start + FRAME_BLOCK)
        out[rows] = _solve(centres[rows], balls, w[rows])[1]
    rot = out[:, :3, :3]
    w_norm = w / w.sum(axis=1, keepdims=True)  # (N, k)
    balls_mean = w_norm @ balls  # (N, 3)
    a = (balls[None] - balls_mean[:, None]) @ np.swapaxes(rot, 1, 2)  # a_k = R b_k
    c = centres - (w_norm[:, None, :] @ centres)
    m = np.einsum("nk,nki,nkj->nij", w_norm, a, c)
    hessian = np.trace(m, axis1=1, axis2=2)[:, None, None] * np.eye(3) - m
    # [a_k]x, (N, k, 3, 3), weighted: column i is w_k a_k x e_i
    cross = np.zeros(a.shape + (3,))
    cross[..., 0, 1], cross[..., 0, 2] = -a[..., 2], a[..., 1]
    cross[..., 1, 0], cross[..., 1, 2] = a[..., 2], -a[..., 0]
    cross[..., 2, 0], cross[..., 2, 1] = -a[..., 1], a[..., 0]
    cross *= w_norm[..., None, None]
    n, k = w.shape
    rhs = np.moveaxis(cross, 1, 2).reshape(n, 3, 3 * k)
    d_rot = inverse3(hessian) @ rhs  # (N, 3, k*3)
    lever = (rot @ balls_mean[..., None])[..., 0]  # R b_mean, (N, 3)
    d_trans = cross_columns(lever, d_rot)
    d_trans += (w_norm[:, None, :, None] * np.eye(3)[None, :, None, :]).reshape(n, 3, 3 * k)
    return out, d_rot.reshape(n, 3, k, 3), d_trans.reshape(n, 3, k, 3)


def _fit(
    centres_mm: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    weights: npt.ArrayLike | None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`register`'s checks and fit: centres (N, k, 3), balls, rotations, transforms."""
    centres, balls, w = _checked(centres_mm, balls_mm, weights)
    return (centres, balls, *_solve(centres, balls, w))


def _checked(
    centres_mm: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    weights: npt.ArrayLike | None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`register`'s checks: centres (N, k, 3), balls (k, 3), weights (N, k)."""
    balls = check_ball_layout(balls_mm)
    centres = np.asarray(centres_mm, dtype=float)
    if centres.ndim == 2:
        centres = centres[None]
    if centres.ndim != 3 or centres.shape[1:] != balls.shape:
        raise RegistrationError(
            f"centres must have shape (N, {balls.shape[0]}, 3) to match the balls, "
            f"got {centres.shape}"
        )
    if not np.all(np.isfinite(centres)):
        step = int(np.argwhere(~np.isfinite(centres))[0][0])
        raise RegistrationError(f"measured centres of step index {step} have a non-finite value")
    w = (
        np.ones(centres.shape[:2])
        if weights is None
        else np.broadcast_to(np.asarray(weights, dtype=float), centres.shape[:2])
    )
    if np.any(w < 0) or not np.all(np.isfinite(w)) or np.any(w.sum(axis=1) <= 0):
        raise RegistrationError("registration weights must be finite, non-negative, not all 0")
    return centres, balls, w


def _solve(centres: FloatArray, balls: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The rotations (N, 3, 3) and transforms (N, 4, 4) of checked rows."""
    w_norm = w / w.sum(axis=1, keepdims=True)
    balls_mean = w_norm @ balls
    centres_mean = (w_norm[:, None, :] @ centres)[:, 0]
    b = balls[None] - balls_mean[:, None]
    c = centres - centres_mean[:, None]
    cov = np.swapaxes(c * w_norm[..., None], 1, 2) @ b  # sum_k w_k c_k b_k^T
    scale = 0.5 * (
        np.einsum("nk,nki,nki->n", w_norm, b, b) + np.einsum("nk,nki,nki->n", w_norm, c, c)
    )
    rot = _rotations(cov, scale)
    return rot, _transforms(rot, centres_mean, balls_mean)


def rigid_rows(centres_mm: FloatArray, balls_mm: FloatArray, weights: FloatArray) -> FloatArray:
    """Rigid transforms (M, 4, 4) taking each row's balls onto its centres, weighted.

    What :func:`register` computes (the same minimiser, Horn's rotation) for rows
    that each have their own balls: ``centres_mm`` and ``balls_mm`` are (M, n, 3) (or
    (1, n, 3), the same for every row), ``weights`` (n,) the points' weights, shared.
    For the diagnosis, which places a twin's centres of many steps on the measured
    ones for many parameter sets at once: it trusts its caller for the checks
    ``register`` makes (finite numbers, non-negative weights, balls not collinear).
    """
    w = np.asarray(weights, dtype=float)
    w_norm = w / w.sum()
    centres = np.asarray(centres_mm, dtype=float)
    balls = np.asarray(balls_mm, dtype=float)
    balls_mean = w_norm @ balls
    centres_mean = w_norm @ centres
    b = balls - balls_mean[:, None]
    c = centres - centres_mean[:, None]
    cov = np.swapaxes(c * w_norm[:, None], 1, 2) @ b  # sum_k w_k c_k b_k^T
    scale = 0.5 * (
        np.einsum("k,nki,nki->n", w_norm, b, b) + np.einsum("k,nki,nki->n", w_norm, c, c)
    )
    return _transforms(_rotations(cov, scale), centres_mean, balls_mean)


def _transforms(rot: FloatArray, centres_mean: FloatArray, balls_mean: FloatArray) -> FloatArray:
    """The (M, 4, 4) transforms of rotations ``rot`` taking the balls' weighted mean onto
    the centres' (each (M, 3))."""
    transforms = np.zeros((rot.shape[0], 4, 4))
    transforms[:, :3, :3] = rot
    transforms[:, :3, 3] = centres_mean - (rot @ balls_mean[..., None])[..., 0]
    transforms[:, 3, 3] = 1.0
    return transforms


def _kabsch(cov: FloatArray) -> FloatArray:
    """Proper rotations maximising ``trace(R^T cov)``, by SVD (Kabsch/Umeyama)."""
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    d[d == 0] = 1.0
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    return (u * fix[:, None, :]) @ vt


#: relative gap between the two largest eigenvalues of Horn's matrix below which the
#: rotation is computed by SVD instead (where Horn's eigenvector loses digits)
_SEPARATION = 0.05


def _det3(
    a: FloatArray,
    b: FloatArray,
    c: FloatArray,
    d: FloatArray,
    e: FloatArray,
    f: FloatArray,
    g: FloatArray,
    h: FloatArray,
    i: FloatArray,
) -> FloatArray:
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


#: the first row's and the upper triangle's (row, column) pairs of a 4x4 matrix, and the
#: signs of the upper triangle's cofactors
_FIRST_ROW = ((0, 0), (0, 1), (0, 2), (0, 3))
_UPPER = tuple((i, j) for i in range(4) for j in range(i, 4))
#: flat indices of the upper triangle's entries of a 4x4 matrix, and of their mirrors
_UPPER_AT = np.array([4 * i + j for i, j in _UPPER])
_LOWER_AT = np.array([4 * j + i for i, j in _UPPER])
_UPPER_SIGNS = np.array([(-1.0) ** (i + j) for i, j in _UPPER])


def _minor_entries(pairs: tuple[tuple[int, int], ...]) -> npt.NDArray[np.intp]:
    """Where (flat index of a 4x4 matrix) each entry of the 3x3 minors at (row, column)
    ``pairs`` (P) is, shape (P * 9,)."""
    rows = np.array([[r for r in range(4) if r != i] for i, _ in pairs])
    cols = np.array([[c for c in range(4) if c != j] for _, j in pairs])
    return (4 * rows[:, :, None] + cols[:, None, :]).reshape(-1)


_FIRST_ROW_ENTRIES = _minor_entries(_FIRST_ROW)
_UPPER_ENTRIES = _minor_entries(_UPPER)


#: matrices up to which :func:`_minors` gathers every minor's entries into one array (the
#: operations are then few, on small arrays); beyond, it takes each minor's entries as
#: they lie (no copy). The same products either way.
_GATHER_UP_TO = 32


def _minors(entries: FloatArray, where: npt.NDArray[np.intp]) -> FloatArray:
    """The 3x3 minors (P, N) of matrices given by their entries (4, 4, N), each the
    products of :func:`_det3`; ``where`` from :func:`_minor_entries`."""
    flat = entries.reshape(16, -1)
    if flat.shape[1] <= _GATHER_UP_TO:
        sub = flat[where].reshape(-1, 3, 3, flat.shape[1])  # (P, 3, 3, N)
        return _det3(*(sub[:, r, c] for r in range(3) for c in range(3)))
    return np.stack([_det3(*(flat[i] for i in minor)) for minor in where.reshape(-1, 9)])


def _rotations(cov: FloatArray, scale: FloatArray) -> FloatArray:
    """Proper rotations ``R`` (N, 3, 3) maximising ``trace(R^T cov)``, as :func:`_kabsch`.

    Horn's quaternion method, written out so that it runs as array operations over
    all N instead of one LAPACK call per 3x3 matrix: the rotation's unit quaternion
    is the eigenvector of the largest eigenvalue of a symmetric, traceless 4x4 matrix
    ``K`` built from ``cov``. That eigenvalue is found by Newton's method on the
    characteristic polynomial ``l^4 + c2 l^2 + c1 l + c0`` from ``scale`` (half the
    sum of the weighted squared spreads of the two point sets, an upper bound: the
    iteration decreases monotonically onto the largest root, as in Theobald's QCP
    method), the eigenvector is the largest column of the adjugate of ``K - l I``.
    Where that is not sure to be accurate (the largest eigenvalue nearly repeated:
    a rotation the data hardly determine, or no convergence) the rows are done by SVD.
    """
    # s[i, j] = sum_k w_k b_i c_j (the source b onto c), as contiguous arrays
    sxx, syx, szx, sxy, syy, szy, sxz, syz, szz = np.ascontiguousarray(cov.reshape(-1, 9).T)
    diagonal = [sxx + syy + szz, sxx - syy - szz, -sxx + syy - szz, -sxx - syy + szz]
    upper = {
        (0, 1): syz - szy,
        (0, 2): szx - sxz,
        (0, 3): sxy - syx,
        (1, 2): sxy + syx,
        (1, 3): szx + sxz,
        (2, 3): syz + szy,
    }
    k = np.empty((cov.shape[0], 4, 4))
    for i in range(4):
        k[:, i, i] = diagonal[i]
    for (i, j), value in upper.items():
        k[:, i, j] = k[:, j, i] = value
    c2 = -2.0 * np.einsum("nij,nij->n", cov, cov)
    c1 = -8.0 * _det3(sxx, sxy, sxz, syx, syy, syz, szx, szy, szz)
    entries = k.transpose(1, 2, 0).copy()  # (4, 4, N), its own (K is kept)
    first = _minors(entries, _FIRST_ROW_ENTRIES)
    c0 = (
        entries[0, 0] * first[0]
        - entries[0, 1] * first[1]
        + entries[0, 2] * first[2]
        - entries[0, 3] * first[3]
    )
    lam = scale.astype(float, copy=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        converged = np.zeros(lam.size, dtype=bool)
        for _ in range(60):
            step = (((lam * lam + c2) * lam + c1) * lam + c0) / (
                (4.0 * lam * lam + 2.0 * c2) * lam + c1
            )
            lam = np.where(converged, lam, lam - step)
            converged |= np.abs(step) <= 4 * np.finfo(float).eps * np.abs(lam)
            if converged.all():
                break
        for refine in range(2):
            for i in range(4):
                entries[i, i] = diagonal[i] - lam
            # the adjugate of K - l I is (product of the other eigenvalue gaps) q q^T
            cofactors = _minors(entries, _UPPER_ENTRIES) * _UPPER_SIGNS[:, None]
            adj_entries = np.empty((16, lam.size))
            adj_entries[_UPPER_AT] = cofactors
            adj_entries[_LOWER_AT] = cofactors
            adj = adj_entries.reshape(4, 4, -1).transpose(2, 0, 1)  # (N, 4, 4), symmetric
            best = np.argmax(np.abs(np.einsum("nii->ni", adj)), axis=1)
            q = adj[np.arange(lam.size), best]
            size = np.sqrt(np.einsum("ni,ni->n", q, q))
            q = q / size[:, None]
            if refine == 0:
                # The root's rounding error grows with the square of 1 / (relative gap to
                # the next eigenvalue); the Rayleigh quotient of its eigenvector does not.
                lam = np.einsum("ni,nij,nj->n", q, k, q)
        # size ~ gap * l^2: keep the rows whose largest eigenvalue is well separated
        sure = converged & (size > _SEPARATION * np.abs(lam) ** 3) & np.isfinite(size)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    rot = np.empty((lam.size, 3, 3))
    rot[:, 0, 0] = w * w + x * x - y * y - z * z
    rot[:, 0, 1] = 2.0 * (x * y - w * z)
    rot[:, 0, 2] = 2.0 * (x * z + w * y)
    rot[:, 1, 0] = 2.0 * (y * x + w * z)
    rot[:, 1, 1] = w * w - x * x + y * y - z * z
    rot[:, 1, 2] = 2.0 * (y * z - w * x)
    rot[:, 2, 0] = 2.0 * (z * x - w * y)
    rot[:, 2, 1] = 2.0 * (z * y + w * x)
    rot[:, 2, 2] = w * w - x * x - y * y + z * z
    if not sure.all():
        rot[~sure] = _kabsch(cov[~sure])
    return rot


#: millimetres per inch, for telling an inch/mm mix-up from other errors
MM_PER_INCH = 25.4


@dataclass(frozen=True)
class DistanceCheck:
    """Measured inter-ball distances compared with the balls file, for N steps.

    Attributes
    ----------
    deviation_mm : ndarray, shape (N, P)
        Measured minus nominal distance of each ball pair.
    pairs : list of (int, int)
        The ball pairs, in the order of the last axis.
    worst_mm : ndarray, shape (N,)
        Largest absolute deviation of each step.
    diagnosis : list of str
        For each step, "" when within tolerance, else what looks wrong.
    """

    deviation_mm: FloatArray
    pairs: list[tuple[int, int]]
    worst_mm: FloatArray
    diagnosis: list[str]


def _pair_distances(points: FloatArray, pairs: list[tuple[int, int]]) -> FloatArray:
    i, j = np.array(pairs).T
    return np.linalg.norm(points[..., i, :] - points[..., j, :], axis=-1)


def check_distances(
    centres_mm: npt.ArrayLike,
    balls_mm: npt.ArrayLike,
    names: tuple[str, ...] | list[str],
    tolerance_mm: float = 0.05,
) -> DistanceCheck:
    """Compare every step's inter-ball distances with the balls file and say what is wrong.

    A step whose distances are all within ``tolerance_mm`` passes. Otherwise the
    diagnosis names the likeliest cause: distances off by a factor 25.4 (inch/mm
    mix-up), a relabelling of the balls that matches (swapped or mislabelled
    balls), or the ball whose pairs deviate most.

    >>> import numpy as np
    >>> balls = np.array([[0.0, 90, 30], [-73.6, -42.5, 30], [82.3, -47.5, 30]])
    >>> check = check_distances(balls[[1, 0, 2]][None], balls, ["B1", "B2", "B3"])
    >>> check.diagnosis[0]
    'balls B1 and B2 look swapped (their distances match the balls file when exchanged)'
    """
    balls = np.asarray(balls_mm, dtype=float)
    centres = np.asarray(centres_mm, dtype=float)
    if centres.ndim == 2:
        centres = centres[None]
    k = balls.shape[0]
    pairs = [(a, b) for a in range(k) for b in range(a + 1, k)]
    nominal = _pair_distances(balls, pairs)
    measured = _pair_distances(centres, pairs)
    deviation = measured - nominal
    worst = np.abs(deviation).max(axis=1)
    text = [""] * centres.shape[0]
    for step in np.flatnonzero(worst > tolerance_mm):
        text[step] = _diagnose(
            measured[step], nominal, centres[step], pairs, list(names), tolerance_mm
        )
    return DistanceCheck(deviation, pairs, worst, text)


def _diagnose(
    measured: FloatArray,
    nominal: FloatArray,
    centres: FloatArray,
    pairs: list[tuple[int, int]],
    names: list[str],
    tolerance_mm: float,
) -> str:
    for factor, what in (
        (1.0 / MM_PER_INCH, "millimetre values read as inches"),
        (MM_PER_INCH, "inch values read as millimetres"),
    ):
        if np.abs(measured * factor - nominal).max() <= tolerance_mm * max(factor, 1.0):
            return (
                f"inter-ball distances are {1 / factor:g} times the balls file: "
                f"{what}? (check UNITS of the measurement file)"
            )
    k = len(names)
    if k <= 6:
        for perm in permutations(range(k)):
            if perm == tuple(range(k)):
                continue
            relabelled = _pair_distances(centres[list(perm)], pairs)
            # measured ball perm[a] is really ball a
            if np.abs(relabelled - nominal).max() <= tolerance_mm:
                moved = [a for a in range(k) if perm[a] != a]
                if len(moved) == 2:
                    return (
                        f"balls {names[moved[0]]} and {names[moved[1]]} look swapped "
                        "(their distances match the balls file when exchanged)"
                    )
                mapping = ", ".join(f"{names[perm[a]]} is {names[a]}" for a in moved)
                return f"balls look mislabelled ({mapping} would match the balls file)"
    per_ball = np.zeros(k)
    for (a, b), dev in zip(pairs, np.abs(measured - nominal), strict=True):
        per_ball[a] += dev
        per_ball[b] += dev
    worst = int(np.argmax(per_ball))
    off = np.abs(measured - nominal).max()
    return (
        f"inter-ball distances deviate by up to {off * 1e3:.1f} um from the balls file; "
        f"ball {names[worst]} is the likeliest culprit (wrong ball probed, bad fit, or "
        "a balls file that does not match this platform)"
    )
