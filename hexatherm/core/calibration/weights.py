"""The poses' covariance and its whitening: per-pose blocks, all poses at once, or all
poses at once with their structure (:class:`BandedCovariance`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import sparse
from scipy.linalg import block_diag, cholesky_banded, solve_triangular
from scipy.linalg.lapack import dtbtrs

from hexatherm.errors import CalibrationError
from hexatherm.typing import FloatArray


@dataclass(frozen=True)
class BandedCovariance:
    """A covariance ``B + U U^T`` (n, n): ``B`` banded, ``U`` of a few columns.

    The joint covariance of a session's poses has this form: each pose's own step and
    its neighbouring references make ``B`` (a band a few poses wide), the frame O and
    the first reference R0, measured once and carried by every pose, make ``U``. Its
    whitening costs O(n) instead of the O(n^3) of a dense Cholesky factor.

    Several sessions together are independent: ``groups`` gives the sizes of the runs
    of rows that are (their ``B`` and ``U`` blocks do not meet), and the whitening's
    low-rank part is factored group by group, each with its own columns of ``U``
    (O and R0 of each session: O(n r / g) instead of O(n r) per use).

    Attributes
    ----------
    band : ndarray, shape (w + 1, n)
        The lower band of ``B``: ``band[d, j] = B[j + d, j]`` (zero past the end).
    common : ndarray, shape (n, r)
        ``U``.
    groups : tuple of int
        Sizes of consecutive independent groups of rows (sum ``n``); empty: one group.
    """

    band: FloatArray
    common: FloatArray
    groups: tuple[int, ...] = ()

    @property
    def size(self) -> int:
        return int(self.band.shape[1])

    def dense(self) -> FloatArray:
        """The covariance as a dense (n, n) matrix."""
        n, w = self.size, self.band.shape[0] - 1
        out = self.common @ self.common.T
        for d in range(w + 1):
            j = np.arange(n - d)
            out[j + d, j] += self.band[d, : n - d]
            if d:
                out[j, j + d] += self.band[d, : n - d]
        return np.asarray(out, dtype=float)

    @classmethod
    def from_factor(
        cls, factor: sparse.spmatrix, common_columns: npt.ArrayLike, block: int = 6
    ) -> BandedCovariance | None:
        """``A A^T`` with ``A`` (n, m) sparse, the ``common_columns`` of ``A`` as ``U``;
        None when the rest is not banded within a quarter of ``n`` (then a dense
        factor is as cheap). The band is widened to whole blocks of ``block`` rows."""
        a = sparse.csc_matrix(factor)
        n = a.shape[0]
        common = np.zeros(a.shape[1], dtype=bool)
        common[np.asarray(common_columns, dtype=np.intp)] = True
        rest = a[:, np.flatnonzero(~common)]
        # the band's width from the pattern first (O(nnz)): rows i and j meet in B only
        # through a column both touch; a dense product of a factor whose columns touch
        # every row (the smooth growth) is not worth forming to learn that
        rows_of = sparse.csc_matrix(rest, copy=True)
        rows_of.eliminate_zeros()
        rows_of.sort_indices()
        touched = np.flatnonzero(np.diff(rows_of.indptr))
        if touched.size:
            first = rows_of.indices[rows_of.indptr[touched]]
            last = rows_of.indices[rows_of.indptr[touched + 1] - 1]
            if block * (int((last - first).max()) // block + 1) > max(n // 4, block):
                return None
        u = np.asarray(a[:, np.flatnonzero(common)].toarray(), dtype=float)
        b = sparse.coo_matrix(rest @ rest.T)
        lower = b.row >= b.col
        rows, cols, values = b.row[lower], b.col[lower], b.data[lower]
        width = int((rows - cols).max(initial=0))
        width = block * (width // block + 1) - 1
        if width + 1 > max(n // 4, block):
            return None
        band = np.zeros((width + 1, n))
        np.add.at(band, (rows - cols, cols), values)
        return cls(band, u)

    def plus(
        self,
        common: FloatArray | None = None,
        banded: FloatArray | sparse.spmatrix | None = None,
    ) -> BandedCovariance | None:
        """This covariance plus ``C C^T`` (more columns of ``U``: ``common`` (n, r')) and
        ``D D^T`` (into the band: ``banded`` (n, s), dense or sparse, each column's rows
        within the band's width of each other, else the band widened; None beyond a
        quarter of ``n``).

        >>> b = BandedCovariance(np.ones((6, 48)), np.zeros((48, 1)))
        >>> d = np.zeros((48, 1)); d[[0, 7]] = 1.0
        >>> wider = b.plus(np.ones((48, 1)), d)
        >>> bool(np.allclose(wider.dense(), b.dense() + 1.0 + d @ d.T)), wider.band.shape
        (True, (12, 48))
        """
        u = self.common if common is None else np.hstack([self.common, common])
        band = self.band
        if banded is not None and banded.shape[1]:
            n = self.size
            d = sparse.csr_matrix(banded)
            b = sparse.coo_matrix(d @ d.T)
            lower = b.row >= b.col
            rows, cols, values = b.row[lower], b.col[lower], b.data[lower]
            width = int((rows - cols).max(initial=0))
            if width >= band.shape[0]:
                width = 6 * (width // 6 + 1) - 1  # whole poses, as :meth:`from_factor`
                if width + 1 > max(n // 4, 6):
                    return None
                band = np.pad(band, ((0, width + 1 - band.shape[0]), (0, 0)))
            else:
                band = band.copy()
            np.add.at(band, (rows - cols, cols), values)
        return BandedCovariance(band, u, self.groups)

    @classmethod
    def stacked(cls, parts: list[BandedCovariance]) -> BandedCovariance:
        """Independent groups (sessions): the covariance block-diagonal in them."""
        width = max(p.band.shape[0] for p in parts)
        band = np.concatenate(
            [np.pad(p.band, ((0, width - p.band.shape[0]), (0, 0))) for p in parts], axis=1
        )
        groups = tuple(g for p in parts for g in (p.groups or (p.size,)))
        return cls(band, np.asarray(block_diag(*[p.common for p in parts]), dtype=float), groups)

    def group_rows(self) -> list[tuple[int, int, npt.NDArray[np.intp]]]:
        """Each independent group's first and past-the-end rows and its columns of ``U``
        (those not zero on its rows); one group of every row and column when
        :attr:`groups` is empty or the groups meet (a band entry or a column of ``U``
        across two of them)."""
        whole = [(0, self.size, np.arange(self.common.shape[1]))]
        if len(self.groups) < 2:
            return whole
        ends = np.cumsum(self.groups)
        starts = ends - np.asarray(self.groups)
        out = []
        used = np.zeros(self.common.shape[1], dtype=int)
        for start, end in zip(starts.tolist(), ends.tolist(), strict=True):
            cols = np.flatnonzero(np.any(self.common[start:end] != 0.0, axis=0))
            used[cols] += 1
            out.append((start, end, cols))
            # band entries from this group's columns into a later row: none
            d, j = np.nonzero(self.band[:, start:end])
            if np.any(start + j + d >= end):
                return whole
        return whole if np.any(used > 1) else out

    def subset(self, rows: npt.NDArray[np.intp]) -> BandedCovariance:
        """The marginal covariance of some rows (increasing)."""
        w = self.band.shape[0] - 1
        band = np.zeros((w + 1, rows.size))
        for d in range(min(w + 1, rows.size)):
            apart = rows[d:] - rows[: rows.size - d]
            inside = apart <= w
            band[d, : rows.size - d][inside] = self.band[
                apart[inside], rows[: rows.size - d][inside]
            ]
        groups: tuple[int, ...] = ()
        if self.groups:
            counts = np.diff(np.searchsorted(rows, np.cumsum((0,) + self.groups)))
            groups = tuple(int(c) for c in counts if c > 0)
        return BandedCovariance(band, self.common[rows], groups)

    def mapped(self, by: FloatArray) -> BandedCovariance:
        """The covariance of ``A_k X_k`` (poses of 6 rows, A (N, 6, 6)): ``P C P^T`` with
        ``P`` block-diagonal; the band keeps its width (whole blocks)."""
        n = self.size
        d, j = np.nonzero(self.band)
        rows = np.concatenate([j + d, j[d > 0]])
        cols = np.concatenate([j, (j + d)[d > 0]])
        values = np.concatenate([self.band[d, j], self.band[d, j][d > 0]])
        b = sparse.csr_matrix((values, (rows, cols)), shape=(n, n))
        p = sparse.bsr_matrix((by, np.arange(by.shape[0]), np.arange(by.shape[0] + 1)), (n, n))
        mapped = sparse.coo_matrix(p @ b @ p.T)
        lower = mapped.row >= mapped.col
        band = np.zeros_like(self.band)
        np.add.at(
            band,
            (mapped.row[lower] - mapped.col[lower], mapped.col[lower]),
            mapped.data[lower],
        )
        common = np.einsum("kab,kbr->kar", by, self.common.reshape(by.shape[0], 6, -1))
        return BandedCovariance(band, common.reshape(n, -1), self.groups)


class PoseWeights:
    """The poses' covariance and its whitening (Cholesky) factor.

    Parameters
    ----------
    covariance : array_like, shape (N, 6, 6) or (6N, 6N), or BandedCovariance
        Per pose (blocks, poses independent) or for all poses at once (the
        between-target covariance included; rows ``6k .. 6k+5`` are pose k's
        ``Tx .. Rz``), dense or with its structure (:class:`BandedCovariance`, whitened
        with the same inner products in O(N): see :meth:`whiten`). Units mm and deg
        (mm^2, mm deg, deg^2).
    n_poses : int
    """

    def __init__(self, covariance: npt.ArrayLike | BandedCovariance, n_poses: int):
        self._subsets: dict[bytes, PoseWeights] = {}
        self.structure: BandedCovariance | None = None
        if isinstance(covariance, BandedCovariance):
            if covariance.size != 6 * n_poses:
                raise CalibrationError(
                    f"pose covariance must have shape ({6 * n_poses}, {6 * n_poses}), "
                    f"got ({covariance.size}, {covariance.size})"
                )
            if self._factor_structure(covariance, n_poses):
                return
            covariance = covariance.dense()  # not positive definite as given: say where
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
        self._covariance: FloatArray | None = cov
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

    def _factor_structure(self, cov: BandedCovariance, n_poses: int) -> bool:
        """Factor ``B + U U^T`` as ``F F^T``, ``F = L_B M``: ``L_B`` the banded Cholesky
        factor of ``B``, ``M = I + Q (G - I) Q^T`` with ``V = L_B^-1 U = Q R`` and ``G``
        the Cholesky factor of ``I + R R^T`` (then ``M M^T = I + V V^T``), ``M``
        block-diagonal over independent groups (:meth:`BandedCovariance.group_rows`).
        False when ``B`` is not positive definite."""
        if not (np.all(np.isfinite(cov.band)) and np.all(np.isfinite(cov.common))):
            raise CalibrationError("pose covariance has a non-finite value")
        try:
            lower = cholesky_banded(cov.band, lower=True)
        except np.linalg.LinAlgError:
            return False
        # per independent group (a session): its rows, Q and G^-1 - I of its columns of U
        self._low_rank: list[tuple[int, int, FloatArray, FloatArray]] = []
        for start, end, cols in cov.group_rows():
            # a group's band factor is its slice (nothing crosses to the next group)
            v = _solve_band(lower[:, start:end], cov.common[start:end, cols])
            q, r = np.linalg.qr(v)
            g = np.linalg.cholesky(np.eye(r.shape[0]) + r @ r.T)
            eye = np.eye(g.shape[0])
            less_eye = np.asarray(solve_triangular(g, eye, lower=True), float) - eye
            self._low_rank.append((start, end, q, less_eye))
        self.blocks = False
        self._covariance = None  # dense on request only
        self.n_poses = n_poses
        self.structure = cov
        self._band_factor = lower
        self._inverse = None
        return True

    @property
    def covariance(self) -> FloatArray:
        """The covariance as given, (N, 6, 6) or (6N, 6N) (dense, also with a structure)."""
        if self._covariance is None:
            assert self.structure is not None
            self._covariance = self.structure.dense()
        return self._covariance

    def whiten(self, x: FloatArray) -> FloatArray:
        """``F^-1 x`` for x (N, 6) or (N, 6, p), flattened to (6N,) or (6N, p), ``F F^T``
        the covariance: ``F = L`` its Cholesky factor, or, with its structure,
        ``F = L_B M`` (see :meth:`_factor_structure`): the whitened vectors differ
        from ``L^-1 x`` by an orthogonal map, their inner products
        ``x^T C^-1 y`` (sums of squares, least squares solutions) are the same."""
        if self.structure is not None:
            flat = x.reshape((6 * self.n_poses, -1))
            y = _solve_band(self._band_factor, flat)
            if len(self._low_rank) == 1:
                _, _, q, less_eye = self._low_rank[0]
                y = y + q @ (less_eye @ (q.T @ y))
            else:
                for start, end, q, less_eye in self._low_rank:
                    y[start:end] += q @ (less_eye @ (q.T @ y[start:end]))
            return y.reshape((6 * self.n_poses,) + x.shape[2:])
        if self.blocks:
            flat = solve_triangular_blocks(self.cholesky, x)
            return flat.reshape((6 * self.n_poses,) + x.shape[2:])
        assert self._inverse is not None
        return np.asarray(self._inverse @ x.reshape((6 * self.n_poses,) + x.shape[2:]), float)

    def subset(self, index: npt.ArrayLike) -> PoseWeights:
        """The weights of some poses (their marginal covariance), factored once per
        subset (the held-out folds are the same for every level)."""
        idx = np.asarray(index, dtype=np.intp)
        key = idx.tobytes()
        if key not in self._subsets:
            self._subsets[key] = self._subset(idx)
        return self._subsets[key]

    def _subset(self, idx: npt.NDArray[np.intp]) -> PoseWeights:
        if self.blocks:
            return PoseWeights(self.covariance[idx], idx.size)
        rows = (6 * idx[:, None] + np.arange(6)).ravel()
        if self.structure is not None:
            if np.all(np.diff(idx) > 0):
                return PoseWeights(self.structure.subset(rows), idx.size)
            return PoseWeights(self.structure.dense()[np.ix_(rows, rows)], idx.size)
        return PoseWeights(self.covariance[np.ix_(rows, rows)], idx.size)

    def mapped(self, by: FloatArray) -> PoseWeights:
        """The weights of ``A_k X_k`` for matrices A (N, 6, 6): covariance ``A C A^T``."""
        if self.structure is not None:
            return PoseWeights(self.structure.mapped(by), self.n_poses)
        if self.blocks:
            cov = by @ self.covariance @ np.swapaxes(by, 1, 2)
        else:
            c = self.covariance.reshape(self.n_poses, 6, self.n_poses, 6)
            cov = np.einsum("kab,kbmc,mdc->kamd", by, c, by).reshape(c.shape[0] * 6, -1)
        return PoseWeights(0.5 * (cov + np.swapaxes(cov, -1, -2)), self.n_poses)


def _solve_band(lower: FloatArray, x: FloatArray) -> FloatArray:
    """``L^-1 x`` for a lower triangular band ``L`` (storage of ``cholesky_banded``)."""
    out, info = dtbtrs(lower, x, uplo="L")
    if info != 0:  # pragma: no cover - a Cholesky factor has a positive diagonal
        raise CalibrationError(f"banded triangular solve failed (LAPACK info {info})")
    return np.asarray(out, dtype=float)


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
