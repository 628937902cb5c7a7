"""Rigid registration of measured ball centres to the balls file.

For a step, the three (or more) ball centres measured in the CMM frame M are
matched to the same balls' centres known in the platform frame P. The rigid
transform ``platform2cmm`` minimising ``sum w_k |platform2cmm(b_k) - c_k|^2`` is
found by the Kabsch/Umeyama SVD method with the reflection excluded
(determinant +1), for many steps at once.

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

from hexatherm.core.geometry import apply_transform
from hexatherm.errors import RegistrationError

FloatArray = npt.NDArray[np.float64]

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
    w = np.ones(centres.shape[:2]) if weights is None else np.broadcast_to(
        np.asarray(weights, dtype=float), centres.shape[:2]
    )
    if np.any(w < 0) or not np.all(np.isfinite(w)) or np.any(w.sum(axis=1) <= 0):
        raise RegistrationError("registration weights must be finite, non-negative, not all 0")
    w_norm = w / w.sum(axis=1, keepdims=True)
    balls_mean = np.einsum("nk,ki->ni", w_norm, balls)
    centres_mean = np.einsum("nk,nki->ni", w_norm, centres)
    b = balls[None] - balls_mean[:, None]
    c = centres - centres_mean[:, None]
    cov = np.einsum("nk,nki,nkj->nij", w_norm, c, b)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    d[d == 0] = 1.0
    fix = np.ones((len(d), 3))
    fix[:, 2] = d
    rot = (u * fix[:, None, :]) @ vt
    transforms = np.zeros((centres.shape[0], 4, 4))
    transforms[:, :3, :3] = rot
    transforms[:, :3, 3] = centres_mean - np.einsum("nij,nj->ni", rot, balls_mean)
    transforms[:, 3, 3] = 1.0
    residuals = centres - apply_transform(transforms, balls)
    rms = np.sqrt((residuals**2).sum(axis=-1).mean(axis=-1)) * 1e3
    return Registration(platform2cmm=transforms, residuals_mm=residuals, rms_um=rms)


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
        text[step] = _diagnose(measured[step], nominal, centres[step], pairs, list(names),
                               tolerance_mm)
    return DistanceCheck(deviation, pairs, worst, text)


def _diagnose(
    measured: FloatArray,
    nominal: FloatArray,
    centres: FloatArray,
    pairs: list[tuple[int, int]],
    names: list[str],
    tolerance_mm: float,
) -> str:
    for factor, what in ((1.0 / MM_PER_INCH, "millimetre values read as inches"),
                         (MM_PER_INCH, "inch values read as millimetres")):
        if np.abs(measured * factor - nominal).max() <= tolerance_mm * max(factor, 1.0):
            return (f"inter-ball distances are {1 / factor:g} times the balls file: "
                    f"{what}? (check UNITS of the measurement file)")
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
                    return (f"balls {names[moved[0]]} and {names[moved[1]]} look swapped "
                            "(their distances match the balls file when exchanged)")
                mapping = ", ".join(f"{names[perm[a]]} is {names[a]}" for a in moved)
                return f"balls look mislabelled ({mapping} would match the balls file)"
    per_ball = np.zeros(k)
    for (a, b), dev in zip(pairs, np.abs(measured - nominal), strict=True):
        per_ball[a] += dev
        per_ball[b] += dev
    worst = int(np.argmax(per_ball))
    off = np.abs(measured - nominal).max()
    return (f"inter-ball distances deviate by up to {off * 1e3:.1f} um from the balls file; "
            f"ball {names[worst]} is the likeliest culprit (wrong ball probed, bad fit, or "
            "a balls file that does not match this platform)")
