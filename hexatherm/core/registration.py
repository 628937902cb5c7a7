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
