"""The poses' covariance and its whitening: per-pose blocks or all poses at once."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.linalg import solve_triangular

from hexatherm.errors import CalibrationError
from hexatherm.typing import FloatArray


class PoseWeights:
    """The poses' covariance and its whitening (Cholesky) factor.

    Parameters
    ----------
    covariance : array_like, shape (N, 6, 6) or (6N, 6N)
        Per pose (blocks, poses independent) or for all poses at once (the
        between-target covariance included; rows ``6k .. 6k+5`` are pose k's
        ``Tx .. Rz``). Units mm and deg (mm^2, mm deg, deg^2).
    n_poses : int
    """

    def __init__(self, covariance: npt.ArrayLike, n_poses: int):
        cov = np.asarray(covariance, dtype=float)
        if cov.shape == (n_poses, 6, 6):
            self.blocks = True
        elif cov.shape == (6 * n_poses, 6 * n_poses):
            self.blocks = False
        else:
            raise CalibrationError(
                f"pose covariance must have shape ({n_poses}, 6, 6) or "
                f"({6 * n_poses}, {6 * n_poses}), got {cov.shape}"
            )
        if not np.all(np.isfinite(cov)):
            raise CalibrationError("pose covariance has a non-finite value")
        asym = np.abs(cov - np.swapaxes(cov, -1, -2)).max(initial=0.0)
        if asym > 1e-9 * np.abs(cov).max(initial=0.0):
            raise CalibrationError("pose covariance is not symmetric")
        self.covariance = cov
        self.n_poses = n_poses
        try:
            self.cholesky = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            where = ""
            if self.blocks:
                bad = [k for k in range(n_poses) if np.any(np.linalg.eigvalsh(cov[k]) <= 0)]
                where = f" (pose index {bad[0]})" if bad else ""
            raise CalibrationError(
                f"pose covariance is not positive definite{where}: every pose needs an "
                "uncertainty in all six components (frame O itself carries no information: "
                "leave it out)"
            ) from None
        # the full form's inverse factor, once: a product per use is much faster than
        # a triangular solve on a machine whose BLAS threads compete
        self._inverse: FloatArray | None = None
        if not self.blocks:
            self._inverse = np.asarray(
                solve_triangular(self.cholesky, np.eye(6 * n_poses), lower=True), float
            )

    def whiten(self, x: FloatArray) -> FloatArray:
        """``L^-1 x`` for x (N, 6) or (N, 6, p), flattened to (6N,) or (6N, p)."""
        if self.blocks:
            flat = solve_triangular_blocks(self.cholesky, x)
            return flat.reshape((6 * self.n_poses,) + x.shape[2:])
        assert self._inverse is not None
        return np.asarray(self._inverse @ x.reshape((6 * self.n_poses,) + x.shape[2:]), float)

    def subset(self, index: npt.ArrayLike) -> PoseWeights:
        """The weights of some poses (their marginal covariance)."""
        idx = np.asarray(index, dtype=np.intp)
        if self.blocks:
            return PoseWeights(self.covariance[idx], idx.size)
        rows = (6 * idx[:, None] + np.arange(6)).ravel()
        return PoseWeights(self.covariance[np.ix_(rows, rows)], idx.size)

    def mapped(self, by: FloatArray) -> PoseWeights:
        """The weights of ``A_k X_k`` for matrices A (N, 6, 6): covariance ``A C A^T``."""
        if self.blocks:
            cov = by @ self.covariance @ np.swapaxes(by, 1, 2)
        else:
            c = self.covariance.reshape(self.n_poses, 6, self.n_poses, 6)
            cov = np.einsum("kab,kbmc,mdc->kamd", by, c, by).reshape(c.shape[0] * 6, -1)
        return PoseWeights(0.5 * (cov + np.swapaxes(cov, -1, -2)), self.n_poses)


def solve_triangular_blocks(lower: FloatArray, x: FloatArray) -> FloatArray:
    """``L_k^-1 x_k`` for lower triangular blocks (N, 6, 6) and x (N, 6) or (N, 6, p)."""
    rhs = x if x.ndim == 3 else x[..., None]
    out = np.empty_like(rhs, dtype=float)
    for i in range(6):  # forward substitution, vectorized over poses and columns
        acc = rhs[:, i] - np.einsum("nj,njp->np", lower[:, i, :i], out[:, :i])
        out[:, i] = acc / lower[:, i, i, None]
    return out if x.ndim == 3 else out[..., 0]


def pose_covariance_from_sigma(
    n_poses: int, sigma_translation_um: float, sigma_rotation_urad: float
) -> FloatArray:
    """Independent poses with one standard uncertainty per kind: (N, 6, 6), mm and deg.

    >>> c = pose_covariance_from_sigma(2, 1.0, 5.0)
    >>> c.shape, float(np.sqrt(c[0, 0, 0]) * 1e3)
    ((2, 6, 6), 1.0)
    >>> round(float(np.deg2rad(np.sqrt(c[1, 5, 5])) * 1e6), 9)
    5.0
    """
    if not (sigma_translation_um > 0 and sigma_rotation_urad > 0):
        raise CalibrationError("pose standard uncertainties must be positive")
    sd = np.array([sigma_translation_um * 1e-3] * 3 + [np.rad2deg(sigma_rotation_urad * 1e-6)] * 3)
    return np.broadcast_to(np.diag(sd**2), (n_poses, 6, 6)).copy()
