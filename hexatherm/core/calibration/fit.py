"""Identification: weighted least squares, covariance, observability and rank diagnosis.

See :mod:`hexatherm.core.calibration` for the model, the weighting and the indices.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Literal, TypeVar

import numpy as np
import numpy.typing as npt
from scipy import special
from scipy.optimize import least_squares

from hexatherm.core.calibration.identified import diverged, refuse_unidentified
from hexatherm.core.calibration.model import (
    BASE,
    GAINS,
    N_PARAMETERS,
    OFFSETS,
    PARAMETER_NAMES,
    PLATFORM,
    CalibrationModel,
    Level,
    angle_axes,
    check_level,
)
from hexatherm.core.calibration.weights import BandedCovariance, PoseWeights
from hexatherm.core.geometry import check_poses, rotation_from_angles, to_um_urad
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError, ConvergenceError, RankDeficientError
from hexatherm.typing import FloatArray, IntArray

ResidualKind = Literal["pose", "leg"]
#: residual spaces: ``pose`` (the default) or ``leg``
RESIDUAL_KINDS: tuple[ResidualKind, ...] = ("pose", "leg")
#: singular values below this fraction of the largest count as zero (rank)
RANK_RTOL = 1e-8
#: |correlation| above which two parameters are flagged
HIGH_CORRELATION = 0.9
#: pose components spanning less than this (mm or deg) count as not varied
_FLAT = 1e-9
#: most rounds of the leg-space fit's reweighting
_LEG_ROUNDS = 5
_COMPONENTS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
#: significance of the chi-square test of a calibration: a chi-square that chance alone
#: exceeds less often than this says the model does not explain the poses
EXPLAINED_P = 1e-3


# ---------------------------------------------------------------------- observability
@dataclass(frozen=True)
class Observability:
    """Singular values of the whitened Jacobian and what they say (see the package text).

    Attributes
    ----------
    singular_values : ndarray, shape (n_free,)
        Of the whitened Jacobian in the free coordinates, largest first (per mm of a
        joint or offset, per unit of a gain).
    n_poses : int
    n_free, n_gauge, n_parameters : int
        Free coordinates, gauge freedoms fixed, the level's parameters.
    rank : int
        Rank counted over the level's parameters: free directions the poses see plus
        the gauge's fixed ones (full: ``n_parameters``).
    directions : ndarray, shape (k, 48)
        Orthonormal parameter directions the poses do not see (gauge excluded).
    reason : str
        Why the rank is deficient and what to add ("" when full).
    """

    singular_values: FloatArray
    n_poses: int
    n_free: int
    n_gauge: int
    n_parameters: int
    rank: int
    directions: FloatArray
    reason: str

    @property
    def full_rank(self) -> bool:
        return self.rank == self.n_parameters

    @property
    def condition_number(self) -> float:
        """``sigma_max / sigma_min`` (inf when rank deficient)."""
        s = self.singular_values
        return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")

    @property
    def o1(self) -> float:
        """``(sigma_1 ... sigma_L)^(1/L) / sqrt(m)``, m poses (D-optimality)."""
        s = self.singular_values
        if s[-1] <= 0:
            return 0.0
        return float(np.exp(np.mean(np.log(s))) / np.sqrt(self.n_poses))

    @property
    def o2(self) -> float:
        """``sigma_min / sigma_max``, the inverse condition number."""
        return float(self.singular_values[-1] / self.singular_values[0])

    @property
    def o3(self) -> float:
        """``sigma_min`` (E-optimality)."""
        return float(self.singular_values[-1])

    @property
    def o4(self) -> float:
        """``sigma_min^2 / sigma_max``, the noise amplification index."""
        return float(self.singular_values[-1] ** 2 / self.singular_values[0])

    @property
    def o5(self) -> float:
        """``1 / sum(1 / sigma_i)`` (0 when rank deficient)."""
        s = self.singular_values
        return float(1.0 / np.sum(1.0 / s)) if s[-1] > 0 else 0.0

    def indices(self) -> dict[str, float]:
        """O1 .. O5 and the condition number by name."""
        return {
            "O1": self.o1,
            "O2": self.o2,
            "O3": self.o3,
            "O4": self.o4,
            "O5": self.o5,
            "condition_number": self.condition_number,
        }


def observability(
    model: CalibrationModel,
    jacobian_w: FloatArray,
    commanded_poses: FloatArray,
    svd: tuple[FloatArray, FloatArray] | None = None,
) -> Observability:
    """Observability of whitened Jacobian rows (6N, n_free) of the commanded poses
    (``svd``: their singular values and right singular vectors ``vt``, when known)."""
    n_poses = commanded_poses.shape[0]
    if svd is None:
        svd = _singular(jacobian_w, model.n_free)
    s, vt = svd
    values = np.zeros(model.n_free)
    values[: s.size] = s
    rank = int(np.sum(values > RANK_RTOL * values[0])) if values[0] > 0 else 0
    null = vt[rank:]  # (k, n_free), orthonormal
    directions = null @ model.basis.T
    reason = "" if rank == model.n_free else _why_deficient(model, commanded_poses, directions)
    return Observability(
        singular_values=values,
        n_poses=n_poses,
        n_free=model.n_free,
        n_gauge=model.n_gauge,
        n_parameters=model.n_parameters,
        rank=rank + model.n_gauge,
        directions=directions,
        reason=reason,
    )


def _why_deficient(model: CalibrationModel, poses: FloatArray, directions: FloatArray) -> str:
    """Words for the parameter directions (k, 48) the poses do not see, and what to add."""
    k = directions.shape[0]
    n_poses = poses.shape[0]
    parts = [
        f"rank {model.n_free - k + model.n_gauge} of {model.n_parameters} "
        f"({model.n_gauge} fixed by the gauge): {k} parameter direction(s) not identifiable"
    ]
    if _unseen_joint_pairs(model, directions) == 18:
        parts.append(
            "moving a leg's base joint and platform joint by the same vector changes no pose "
            "(each leg's joints enter only as their difference)"
        )
    else:
        weight = np.sum(directions**2, axis=0)
        top = [int(i) for i in np.argsort(-weight)[: min(6, k + 3)] if weight[i] > 1e-6]
        parts.append("they involve mostly " + ", ".join(PARAMETER_NAMES[i] for i in top))
    flat = [_COMPONENTS[c] for c in range(6) if np.ptp(poses[:, c]) < _FLAT]
    if flat:
        example = " (e.g. rotations of a few degrees about X, Y and Z)" if "Rx" in flat else ""
        parts.append(f"the poses never vary {', '.join(flat)}: add poses that do{example}")
    elif 6 * n_poses <= model.n_free:
        need = model.n_free // 6 + 1 - n_poses
        parts.append(
            f"{n_poses} poses give {6 * n_poses} residuals for {model.n_free} free "
            f"coordinates: add at least {need} pose(s)"
        )
    else:
        parts.append("add poses spread over the whole stroke, rotations included")
    return "; ".join(parts)


def _unseen_joint_pairs(model: CalibrationModel, directions: FloatArray) -> int:
    """How many of the 18 moves 'base joint and platform joint of a leg by the same unit
    vector' the poses cannot see (their free part lies in the unseen directions)."""
    pair = np.zeros((18, N_PARAMETERS))
    pair[np.arange(18), BASE + np.arange(18)] = 1.0
    pair[np.arange(18), PLATFORM + np.arange(18)] = 1.0
    free = pair @ model.basis  # the gauge's part of a move is unseen anyway
    norms = np.linalg.norm(free, axis=1)
    if directions.shape[0] == 0 or not np.all(norms > 0):
        return 0
    inside = np.linalg.norm(free @ (directions @ model.basis).T, axis=1) / norms
    return int(np.sum(inside > 1.0 - 1e-6))


def _singular(jacobian_w: FloatArray, n_free: int) -> tuple[FloatArray, FloatArray]:
    """Singular values and ``vt`` of whitened Jacobian rows (padded with zero rows to
    ``n_free`` when fewer); of their QR factor R when they are many (the same values and
    vectors, without the 6N left singular vectors: a third of the time)."""
    rows = jacobian_w
    if rows.shape[0] < n_free:  # fewer residuals than coordinates: pad with zeros
        rows = np.concatenate([rows, np.zeros((n_free - rows.shape[0], n_free))])
    elif rows.shape[0] > 2 * n_free:
        rows = np.asarray(np.linalg.qr(rows, mode="r"), float)
    _, s, vt = np.linalg.svd(rows, full_matrices=False)
    return s, vt


def refuse_rank_deficient(obs: Observability, level: str) -> None:
    """RankDeficientError when the poses do not identify the level's parameters."""
    if not obs.full_rank:
        raise RankDeficientError(
            f"the poses do not identify level {level!r}: {obs.reason}",
            rank=obs.rank,
            n_parameters=obs.n_parameters,
            directions=obs.directions,
        )


# ---------------------------------------------------------------------- the fit
@dataclass(frozen=True)
class CalibrationFit:
    """Parameters of one level fitted to measured poses.

    Attributes
    ----------
    model : CalibrationModel
    parameters : ndarray, shape (48,)
        Fitted parameters in the gauge (base Kabsch-aligned onto the nominal base);
        the level's fixed parameters nominal.
    covariance : ndarray, shape (48, 48)
        Their covariance (zero for fixed parameters; rank ``n_free``).
    covariance_free : ndarray, shape (n_free, n_free)
        The covariance of the free coordinates.
    residual_kind : {"pose", "leg"}
        The residuals fitted.
    residuals : ndarray, shape (N, 6)
        Measured minus predicted poses, mm and deg (pose space, whatever was fitted).
    chi_square : float
        Sum of squares of the whitened residuals fitted.
    dof : int
        ``6 N - n_free``.
    observability : Observability
        At the fitted parameters.
    n_evaluations : int
        Model evaluations of the optimizer (all rounds).
    """

    model: CalibrationModel
    parameters: FloatArray
    covariance: FloatArray
    covariance_free: FloatArray
    residual_kind: ResidualKind
    residuals: FloatArray
    chi_square: float
    dof: int
    observability: Observability
    n_evaluations: int

    @property
    def level(self) -> Level:
        return self.model.level

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the level's parameters."""
        return tuple(n for n, m in zip(PARAMETER_NAMES, self.model.mask, strict=True) if m)

    @property
    def std_errors(self) -> FloatArray:
        """Standard uncertainties (48,) of the parameters (0 for fixed ones), their units."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @property
    def correlation(self) -> FloatArray:
        """Correlation matrix (48, 48) (NaN rows and columns for fixed parameters)."""
        sd = self.std_errors
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self.covariance / np.outer(sd, sd)
        out[~self.model.mask] = np.nan
        out[:, ~self.model.mask] = np.nan
        return out

    def high_correlations(
        self, threshold: float = HIGH_CORRELATION
    ) -> list[tuple[str, str, float]]:
        """Pairs of fitted parameters with ``|rho| > threshold``, largest first."""
        rho = self.correlation
        i, j = np.nonzero(np.triu(np.abs(np.nan_to_num(rho)) > threshold, k=1))
        pairs = [
            (PARAMETER_NAMES[a], PARAMETER_NAMES[b], float(rho[a, b]))
            for a, b in zip(i, j, strict=True)
        ]
        return sorted(pairs, key=lambda p: -abs(p[2]))

    @property
    def chi_square_per_dof(self) -> float:
        return self.chi_square / self.dof

    @property
    def chi_square_p(self) -> float:
        """Probability that the chi-square is this large or larger by chance alone, the
        model right and the poses' covariance honest (chi-square with ``dof``): the
        arithmetic of ``scipy.stats.chi2.sf``, without importing scipy.stats (0.3 s)."""
        return float(special.chdtrc(self.dof, self.chi_square)) if self.dof > 0 else 1.0

    @property
    def explains_poses(self) -> bool:
        """Whether the fitted model explains the poses within their covariance: the
        chi-square test passes at :data:`EXPLAINED_P` (with no degree of freedom left,
        nothing can be told, and it is taken to)."""
        return self.chi_square_p >= EXPLAINED_P

    def chi_square_limit_per_dof(self) -> float:
        """The chi2/dof above which :attr:`explains_poses` fails."""
        return float(special.chdtri(self.dof, EXPLAINED_P)) / self.dof if self.dof > 0 else np.inf

    @property
    def leg_offsets_mm(self) -> FloatArray:
        return self.parameters[OFFSETS:GAINS].copy()

    @property
    def leg_gains(self) -> FloatArray:
        return self.parameters[GAINS:].copy()

    def predict(self, commanded_poses: npt.ArrayLike) -> FloatArray:
        """Poses (N, 6) relative to O the calibrated model predicts for commanded poses."""
        return self.model.predict(self.parameters, commanded_poses)[0]

    def predicted_covariance(self, commanded_poses: npt.ArrayLike) -> FloatArray:
        """Covariance (N, 6, 6) of the predicted poses from the parameters' (mm, deg)."""
        _, jac = self.model.predict(self.parameters, commanded_poses)
        g = jac @ self.model.basis
        return np.asarray(g @ self.covariance_free @ np.swapaxes(g, 1, 2), float)

    def predicted_sigma_um_urad(self, commanded_poses: npt.ArrayLike) -> FloatArray:
        """Standard uncertainties (N, 6) of the predicted poses, um and urad."""
        cov = self.predicted_covariance(commanded_poses)
        return to_um_urad(np.sqrt(np.einsum("nii->ni", cov)))

    def hexapod(self) -> Hexapod:
        """The calibrated hexapod, base joints in frame O (see ``calibrated_hexapod``)."""
        return self.model.calibrated_hexapod(self.parameters)

    def origin_parameters(self) -> tuple[FloatArray, FloatArray]:
        """Parameters (48,) with the base in frame O, and their covariance (48, 48).

        The base joints of :meth:`hexapod` (the gauge-free form: frame O is measured)
        with the platform joints, offsets and gains; the covariance carries the
        uncertainty of frame O's place in the fit's gauge.
        """
        theta = self.parameters
        origin, d_origin = self.model.origin(theta)
        conv = self.model.nominal.convention
        rot = rotation_from_angles(origin[3:], conv)
        w = angle_axes(origin[3:], conv)[0]
        base = theta[BASE:PLATFORM].reshape(6, 3)
        rel = base - origin[:3]
        out = theta.copy()
        out[BASE:PLATFORM] = (rel @ rot).ravel()
        # d b_O = R^T (db - dt_O + [b - t_O]x W da_O)
        jac = np.eye(N_PARAMETERS)
        d_t = d_origin[:3]  # (3, 48)
        d_phi = w @ d_origin[3:]  # (3, 48)
        for i in range(6):
            rows = slice(BASE + 3 * i, BASE + 3 * i + 3)
            skew = np.array(
                [
                    [0.0, -rel[i, 2], rel[i, 1]],
                    [rel[i, 2], 0.0, -rel[i, 0]],
                    [-rel[i, 1], rel[i, 0], 0.0],
                ]
            )
            jac[rows] = rot.T @ (np.eye(N_PARAMETERS)[rows] - d_t + skew @ d_phi)
        return out, jac @ self.covariance @ jac.T


def check_campaign(
    commanded_poses: npt.ArrayLike, measured_poses: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Commanded and measured poses (N, 6) checked: finite, same shape."""
    x_cmd = np.atleast_2d(check_poses(commanded_poses, "commanded pose"))
    x_meas = np.atleast_2d(check_poses(measured_poses, "measured pose"))
    if x_cmd.shape != x_meas.shape:
        raise CalibrationError(
            f"{x_meas.shape[0]} measured poses for {x_cmd.shape[0]} commanded ones"
        )
    return x_cmd, x_meas


def fit_calibration(
    nominal: Hexapod,
    commanded_poses: npt.ArrayLike,
    measured_poses: npt.ArrayLike,
    covariance: npt.ArrayLike | BandedCovariance | PoseWeights,
    *,
    level: str = "joints",
    residuals: str = "pose",
    start: npt.ArrayLike | None = None,
) -> CalibrationFit:
    """Fit a level's parameters to measured poses by weighted least squares.

    Parameters
    ----------
    nominal : Hexapod
        The hexapod file the controller used (its IGM made the commanded legs).
    commanded_poses : array_like, shape (N, 6)
        Commanded poses relative to O, mm and deg (frame O itself left out).
    measured_poses : array_like, shape (N, 6)
        Measured poses relative to the measured O (conventional, corrected or twin),
        mm and deg.
    covariance : array_like, shape (N, 6, 6) or (6N, 6N), or PoseWeights
        The measured poses' covariance (mm, deg), between-target terms included in
        the (6N, 6N) form.
    level : {"offsets", "joints", "joints+gains"}
    residuals : {"pose", "leg"}
        Residual space (see the package text); ``pose`` by default.
    start : array_like, shape (48,), optional
        Start parameters (default nominal); moved into the gauge first.

    Returns
    -------
    CalibrationFit

    Raises
    ------
    CalibrationError
        Bad input: shapes, a covariance that is not positive definite, too few poses;
        poses that identify the level only in name, or a fit that diverged
        (:mod:`~hexatherm.core.calibration.identified`).
    RankDeficientError
        The poses do not identify the level's parameters (why, and what to add).
    """
    model = CalibrationModel(nominal, check_level(level))
    if residuals not in RESIDUAL_KINDS:
        raise CalibrationError(
            f"unknown residual space {residuals!r}; expected one of {RESIDUAL_KINDS}"
        )
    kind: ResidualKind = "pose" if residuals == "pose" else "leg"
    x_cmd, x_meas = check_campaign(commanded_poses, measured_poses)
    n = x_cmd.shape[0]
    if 6 * n <= model.n_free:
        raise CalibrationError(
            f"{n} poses give {6 * n} residuals for the {model.n_free} free coordinates of "
            f"level {model.level!r}: at least {model.n_free // 6 + 1} poses are needed"
        )
    weights = covariance if isinstance(covariance, PoseWeights) else PoseWeights(covariance, n)
    if weights.n_poses != n:
        raise CalibrationError(f"pose weights for {weights.n_poses} poses, {n} poses given")
    z = np.zeros(model.n_free) if start is None else model.coordinates(start)
    evaluations = 0
    try:
        if kind == "pose":
            problem = partial(_pose_problem, model, x_cmd, x_meas, weights)
            first = problem(z)  # the optimizer's first evaluation too
            # structural check at the start (rank deficiency is exact there)
            refuse_rank_deficient(observability(model, -first[1], x_cmd), model.level)
            z, evaluations, (r_w, j_w, pred) = _solve(model, problem, z, first)
        else:
            # structural check at the start (rank deficiency is exact there)
            _, jac0 = model.predict(model.parameters(z), x_cmd)
            refuse_rank_deficient(
                observability(model, weights.whiten(jac0 @ model.basis), x_cmd), model.level
            )
            for _ in range(_LEG_ROUNDS):  # weights at the previous estimate
                theta = model.parameters(z)
                _, _, by_meas = model.leg_residuals(theta, x_cmd, x_meas)
                leg_weights = weights.mapped(by_meas)
                z_new, nfev, (r_w, j_w) = _solve(
                    model, partial(_leg_problem, model, x_cmd, x_meas, leg_weights), z
                )
                evaluations += nfev
                step = z_new - z
                z = z_new
                if np.sum((j_w @ step) ** 2) < 1e-6:  # the step in units of its uncertainty
                    break
            r_w, j_w = _leg_problem(model, x_cmd, x_meas, leg_weights, z)
            pred, _ = model.predict(model.parameters(z), x_cmd)
    except ConvergenceError as error:  # a trial geometry the model cannot stand
        raise diverged(model, error, x_cmd) from None
    theta = model.parameters(z)
    svd = _singular(j_w, model.n_free)
    obs = observability(model, j_w, x_cmd, svd)
    refuse_rank_deficient(obs, model.level)
    cov_z = _inverse_normal(*svd)
    refuse_unidentified(model, model.basis @ cov_z @ model.basis.T, x_cmd)
    return CalibrationFit(
        model=model,
        parameters=theta,
        covariance=model.basis @ cov_z @ model.basis.T,
        covariance_free=cov_z,
        residual_kind=kind,
        residuals=x_meas - pred,
        chi_square=float(r_w @ r_w),
        dof=6 * n - model.n_free,
        observability=obs,
        n_evaluations=evaluations,
    )


def _inverse_normal(s: FloatArray, vt: FloatArray) -> FloatArray:
    """``(J^T J)^-1`` from the SVD (singular values, ``vt``) of the whitened Jacobian
    (full rank assumed)."""
    return np.asarray((vt.T / s**2) @ vt, float)


def _pose_problem(
    model: CalibrationModel, x_cmd: FloatArray, x_meas: FloatArray, w: PoseWeights, z: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Whitened pose residuals (6N,), their Jacobian (6N, n_free), and the predicted
    poses (N, 6)."""
    pred, jac = model.predict(model.parameters(z), x_cmd)
    return w.whiten(x_meas - pred), -w.whiten(jac @ model.basis), pred


def _leg_problem(
    model: CalibrationModel, x_cmd: FloatArray, x_meas: FloatArray, w: PoseWeights, z: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Whitened leg residuals (6N,) and their Jacobian (6N, n_free)."""
    res, jac, _ = model.leg_residuals(model.parameters(z), x_cmd, x_meas)
    return w.whiten(res), w.whiten(jac @ model.basis)


_Evaluation = TypeVar("_Evaluation", bound=tuple[FloatArray, ...])
#: evaluations :func:`_solve` keeps (the solution is one of the last few points tried)
_KEPT_EVALUATIONS = 4


def _solve(
    model: CalibrationModel,
    problem: Callable[[FloatArray], _Evaluation],
    z0: FloatArray,
    first: _Evaluation | None = None,
) -> tuple[FloatArray, int, _Evaluation]:
    """Levenberg-Marquardt (MINPACK) on a problem returning whitened residuals and
    Jacobian first (and whatever else it computes); ``first`` is its value at ``z0``
    when known. Returns the solution, the evaluations, and the problem's value there
    (each point is evaluated once: the last few values are kept)."""
    cache: dict[bytes, _Evaluation] = {}
    if first is not None:
        cache[np.asarray(z0, float).tobytes()] = first

    def evaluate(z: FloatArray) -> _Evaluation:
        key = z.tobytes()
        if key not in cache:
            if len(cache) >= _KEPT_EVALUATIONS:
                del cache[next(iter(cache))]  # the oldest
            cache[key] = problem(z)
        return cache[key]

    result = least_squares(
        lambda z: evaluate(z)[0],
        z0,
        jac=lambda z: evaluate(z)[1],
        method="lm",
        x_scale="jac",
        xtol=1e-10,
        ftol=1e-10,
        gtol=1e-10,
        max_nfev=100 * (model.n_free + 1),
    )
    z = np.asarray(result.x, float)
    return z, int(result.nfev), evaluate(z)


def fold_of_poses(n_poses: int, n_folds: int) -> IntArray:
    """Fold (0 .. n_folds-1) of each pose, interleaved in the given order: ``k % n_folds``.

    >>> fold_of_poses(7, 3).tolist()
    [0, 1, 2, 0, 1, 2, 0]
    """
    if n_folds < 2:
        raise CalibrationError(f"held-out checks need at least 2 folds, got {n_folds}")
    return np.asarray(np.arange(n_poses) % n_folds, dtype=np.int64)
