"""Choosing the model level (BIC and held-out folds) and the poses to measure (greedy design).

See :mod:`hexatherm.core.calibration` for the rules written out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hexatherm.core.calibration.fit import (
    CalibrationFit,
    Observability,
    check_campaign,
    fit_calibration,
    fold_of_poses,
    observability,
    refuse_rank_deficient,
)
from hexatherm.core.calibration.heldout import heldout_residuals
from hexatherm.core.calibration.model import LEVELS, CalibrationModel, Level, check_level
from hexatherm.core.calibration.weights import (
    BandedCovariance,
    PoseWeights,
    pose_covariance_from_sigma,
)
from hexatherm.core.geometry import check_poses, to_um_urad
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError
from hexatherm.typing import BoolArray, FloatArray, IntArray

#: BIC drop a larger level must exceed to be chosen (as ``diagnose``'s effects)
DELTA_BIC_THRESHOLD = 10.0
#: default reciprocal condition number of ``dq/dX`` below which a candidate is refused
DEFAULT_MIN_RCOND = 0.01
#: design criteria of :func:`select_poses` (``sigma``: the earlier name of ``g-optimal``)
CRITERIA = ("d-optimal", "g-optimal", "i-optimal", "sigma")
#: the prior information of the greedy design, relative to one pose's mean
_PRIOR = 1e-8


# ---------------------------------------------------------------------- level
@dataclass(frozen=True)
class LevelScore:
    """One level fitted to all poses and checked on held-out folds.

    Attributes
    ----------
    level : str
    fit : CalibrationFit or None
        The fit to all poses (None when the level could not be fitted: ``note``).
    bic : float
        ``n ln(RSS_w / n) + p ln n``: n whitened residuals, p free coordinates
        (NaN when not fitted).
    heldout_residuals : ndarray, shape (N, 6)
        Each pose's measured minus predicted pose, predicted by the fit to the
        folds it is not in (mm, deg; NaN when not fitted).
    heldout_rms_w : float
        RMS of the held-out residuals whitened by their covariance (1: as noisy as
        the measurements say).
    note : str
        Why the level was not fitted, or what is worth knowing.
    """

    level: Level
    fit: CalibrationFit | None
    bic: float
    heldout_residuals: FloatArray
    heldout_rms_w: float
    note: str = ""

    @property
    def heldout_rms_um_urad(self) -> FloatArray:
        """RMS (6,) of the held-out residuals per component, um and urad."""
        return np.asarray(np.sqrt(np.mean(to_um_urad(self.heldout_residuals) ** 2, axis=0)), float)


@dataclass(frozen=True)
class LevelChoice:
    """The level chosen and the figures of every level tried."""

    level: Level
    scores: tuple[LevelScore, ...]

    @property
    def fit(self) -> CalibrationFit:
        """The chosen level's fit to all poses."""
        for score in self.scores:
            if score.level == self.level and score.fit is not None:
                return score.fit
        raise AssertionError("the chosen level has a fit")  # pragma: no cover


def select_level(
    nominal: Hexapod,
    commanded_poses: npt.ArrayLike,
    measured_poses: npt.ArrayLike,
    covariance: npt.ArrayLike | BandedCovariance,
    *,
    levels: tuple[str, ...] = LEVELS,
    n_folds: int = 5,
    residuals: str = "pose",
) -> LevelChoice:
    """Choose the model level as ``diagnose`` chooses effects: BIC and held-out folds.

    Every level is fitted to all poses. The poses are split into ``n_folds``
    interleaved folds (:func:`~hexatherm.core.calibration.fit.fold_of_poses`); each
    fold is predicted by the level refitted to the others. Starting from the smallest
    level that can be fitted, the next larger one is chosen when its BIC is lower by
    more than :data:`DELTA_BIC_THRESHOLD` *and* its whitened held-out RMS is lower.

    Parameters
    ----------
    nominal, commanded_poses, measured_poses, covariance, residuals
        As :func:`~hexatherm.core.calibration.fit.fit_calibration`.
    levels : tuple of str
        Levels to try, smallest first.
    n_folds : int

    Returns
    -------
    LevelChoice

    Raises
    ------
    CalibrationError
        No level can be fitted, or none on every fold (the reasons of each): a level
        whose held-out residuals are incomplete is not chosen.
    """
    x_cmd, x_meas = check_campaign(commanded_poses, measured_poses)
    n = x_cmd.shape[0]
    weights = PoseWeights(covariance, n)
    folds = fold_of_poses(n, n_folds)
    scores = [
        _score(nominal, check_level(level), x_cmd, x_meas, weights, folds, residuals)
        for level in levels
    ]
    fitted = [s for s in scores if s.fit is not None]
    if not fitted:
        raise CalibrationError(
            "no calibration level can be fitted: "
            + "; ".join(f"{s.level}: {s.note}" for s in scores)
        )
    checked = [s for s in fitted if np.isfinite(s.heldout_rms_w)]  # every fold fitted
    if not checked:
        raise CalibrationError(
            "no calibration level can be checked on held-out folds of the poses (--level "
            "fits one without them): " + "; ".join(f"{s.level}: {s.note}" for s in scores)
        )
    current = checked[0]
    for score in checked[1:]:
        if (
            current.bic - score.bic > DELTA_BIC_THRESHOLD
            and score.heldout_rms_w < current.heldout_rms_w
        ):
            current = score
    return LevelChoice(current.level, tuple(scores))


def _score(
    nominal: Hexapod,
    level: Level,
    x_cmd: FloatArray,
    x_meas: FloatArray,
    weights: PoseWeights,
    folds: IntArray,
    residuals: str,
) -> LevelScore:
    nan = np.full(x_cmd.shape, np.nan)
    try:
        fit = fit_calibration(nominal, x_cmd, x_meas, weights, level=level, residuals=residuals)
    except CalibrationError as error:
        return LevelScore(level, None, float("nan"), nan, float("nan"), str(error))
    n_res = 6 * x_cmd.shape[0]
    rss = max(fit.chi_square, n_res * 1e-30)  # an exact fit: the BIC's floor
    bic = float(n_res * np.log(rss / n_res) + fit.model.n_free * np.log(n_res))
    held, squares, notes = heldout_residuals(nominal, fit, x_cmd, x_meas, weights, folds, residuals)
    rms_w = float(np.sqrt(squares / n_res))
    return LevelScore(level, fit, bic, held, rms_w, "; ".join(notes))


# ---------------------------------------------------------------------- poses
@dataclass(frozen=True)
class PoseSelection:
    """Poses chosen for a calibration campaign.

    Attributes
    ----------
    indices : ndarray of int, shape (n,)
        Into the candidates given, in the order chosen.
    poses : ndarray, shape (n, 6)
        The chosen commanded poses (mm, deg).
    criterion : {"d-optimal", "g-optimal", "i-optimal"}
    worst_sigma_um : float
        Largest standard uncertainty of Tx, Ty, Tz predicted by a calibration from
        these poses, over the evaluation poses (um).
    worst_sigma_urad : float
        The same for Rx, Ry, Rz (urad).
    mean_sigma_um : float
        Root mean square of the predicted standard uncertainties of Tx, Ty, Tz over the
        evaluation poses (um): what ``i-optimal`` lowers.
    random_sigma_um : (float, float)
        The worst and RMS figures of as many poses drawn at random from the feasible
        candidates (the medians over ``random_draws`` draws; NaN when none asked): what
        the design gains, at the design stage.
    observability : Observability
        Of the chosen poses.
    refused : dict of str to int
        Candidates left out, by reason (``stroke``, ``box``, ``singular``).
    """

    indices: IntArray
    poses: FloatArray
    criterion: str
    worst_sigma_um: float
    worst_sigma_urad: float
    observability: Observability
    refused: dict[str, int] = field(default_factory=dict)
    mean_sigma_um: float = float("nan")
    random_sigma_um: tuple[float, float] = (float("nan"), float("nan"))


def _translation_figures(eval_plain: FloatArray, rows: FloatArray) -> tuple[float, float]:
    """Worst and RMS predicted sigma of Tx, Ty, Tz (um) at the evaluation Jacobians
    ``eval_plain`` (E, 6, p) of a design whose whitened rows are ``rows``."""
    cov_z = np.linalg.inv(rows.T @ rows)
    t = eval_plain[:, :3]
    sigma = np.sqrt(np.einsum("eip,pq,eiq->ei", t, cov_z, t)) * 1e3
    return float(sigma.max()), float(np.sqrt(np.mean(sigma**2)))


def feasible_candidates(
    nominal: Hexapod,
    candidates: npt.ArrayLike,
    *,
    box_lower: npt.ArrayLike | None = None,
    box_upper: npt.ArrayLike | None = None,
    min_rcond: float = DEFAULT_MIN_RCOND,
) -> tuple[BoolArray, dict[str, int]]:
    """Which candidate poses (M, 6) may be commanded, and how many were refused why.

    A candidate is refused when a leg ``IGM_nominal(pose)`` is outside the stroke (if
    the hexapod has one), when it is outside the box ``[box_lower, box_upper]`` (mm,
    deg, per component), or when the reciprocal condition number of ``dq/dX`` (mm per
    mm, mm per degree) is below ``min_rcond``.
    """
    x = np.atleast_2d(check_poses(candidates, "candidate pose"))
    if not min_rcond >= 0:
        raise CalibrationError(f"min_rcond must be >= 0, got {min_rcond}")
    stroke = nominal.check_stroke(nominal.igm(x)).any(axis=1)
    box = np.zeros(x.shape[0], dtype=bool)
    if box_lower is not None:
        box |= np.any(x < np.broadcast_to(np.asarray(box_lower, float), (6,)), axis=1)
    if box_upper is not None:
        box |= np.any(x > np.broadcast_to(np.asarray(box_upper, float), (6,)), axis=1)
    sv = np.linalg.svd(nominal.jacobian(x), compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        singular = ~(sv[:, -1] / sv[:, 0] >= min_rcond)
    refused = {
        "stroke": int(stroke.sum()),
        "box": int((box & ~stroke).sum()),
        "singular": int((singular & ~stroke & ~box).sum()),
    }
    return ~(stroke | box | singular), refused


def design_jacobians(
    model: CalibrationModel, theta: FloatArray, poses: FloatArray, covariance: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Whitened and plain Jacobians (M, 6, n_free) of the poses predicted at ``poses``."""
    plain = prediction_jacobian(model, theta, poses)
    white = PoseWeights(covariance, poses.shape[0]).whiten(plain)
    return white.reshape(plain.shape), plain


def prediction_jacobian(
    model: CalibrationModel, theta: FloatArray, poses: FloatArray
) -> FloatArray:
    """Jacobian (M, 6, n_free) of the predicted poses by the free coordinates."""
    _, jac = model.predict(theta, poses)
    return np.asarray(jac @ model.basis, float)


def predicted_sigma(
    nominal: Hexapod,
    design_poses: npt.ArrayLike,
    evaluation_poses: npt.ArrayLike,
    *,
    level: str = "joints",
    sigma_translation_um: float = 1.0,
    sigma_rotation_urad: float = 5.0,
    parameters: npt.ArrayLike | None = None,
) -> FloatArray:
    """Standard uncertainties (E, 6) (um, urad) of the poses a calibration from
    ``design_poses`` would predict at ``evaluation_poses`` (linear, before measuring).

    Raises RankDeficientError when the design does not identify the level.
    """
    model = CalibrationModel(nominal, check_level(level))
    theta = model.theta0 if parameters is None else np.asarray(parameters, float)
    design = np.atleast_2d(check_poses(design_poses, "design pose"))
    cov = pose_covariance_from_sigma(design.shape[0], sigma_translation_um, sigma_rotation_urad)
    white, _ = design_jacobians(model, theta, design, cov)
    rows = white.reshape(-1, model.n_free)
    refuse_rank_deficient(observability(model, rows, design), model.level)
    cov_z = np.linalg.inv(rows.T @ rows)
    evaluation = np.atleast_2d(check_poses(evaluation_poses, "evaluation pose"))
    plain = prediction_jacobian(model, theta, evaluation)
    return to_um_urad(np.sqrt(np.einsum("eip,pq,eiq->ei", plain, cov_z, plain)))


def select_poses(
    nominal: Hexapod,
    candidates: npt.ArrayLike,
    n_poses: int,
    *,
    level: str = "joints",
    criterion: str = "d-optimal",
    sigma_translation_um: float = 1.0,
    sigma_rotation_urad: float = 5.0,
    box_lower: npt.ArrayLike | None = None,
    box_upper: npt.ArrayLike | None = None,
    min_rcond: float = DEFAULT_MIN_RCOND,
    evaluation_poses: npt.ArrayLike | None = None,
    parameters: npt.ArrayLike | None = None,
    random_draws: int = 0,
) -> PoseSelection:
    """Choose ``n_poses`` commanded poses from candidates, greedily, for a calibration.

    The candidates the hexapod may not be commanded to are left out
    (:func:`feasible_candidates`). Each pose's information is ``J_k^T C_k^-1 J_k``
    (``J_k`` the Jacobian of its predicted pose by the free coordinates at the
    nominal parameters, ``C_k`` the pose covariance from the two sigmas). The greedy
    step adds the candidate that most increases ``log det`` of the summed
    information (``d-optimal``: O1). ``g-optimal`` (``sigma``, its earlier name) then
    exchanges poses (Fedorov) to lower the worst predicted standard uncertainty of Tx,
    Ty, Tz over the evaluation poses (default: the feasible candidates, the stroke the
    user asked for), ``i-optimal`` their mean predicted variance: what a user of the
    calibrated hexapod meets at a new pose. A tiny prior (1e-8 of a pose's mean
    information) keeps the first steps defined; the result is checked without it.

    Parameters
    ----------
    nominal : Hexapod
    candidates : array_like, shape (M, 6)
        Candidate commanded poses relative to O, mm and deg.
    n_poses : int
    level : {"offsets", "joints", "joints+gains"}
    criterion : {"d-optimal", "g-optimal", "i-optimal"}
    sigma_translation_um, sigma_rotation_urad : float
        Standard uncertainty of the measured poses' components.
    box_lower, box_upper : array_like, shape (6,), optional
        The user's box (mm, deg).
    min_rcond : float
    evaluation_poses : array_like, shape (E, 6), optional
    parameters : array_like, shape (48,), optional
        Where to linearize (default nominal).
    random_draws : int
        Also evaluate this many random choices of ``n_poses`` feasible candidates
        (seeded: the same figures every time; draws that do not identify the level are
        drawn again) for :attr:`PoseSelection.random_sigma_um`.

    Returns
    -------
    PoseSelection

    Raises
    ------
    CalibrationError
        Too few feasible candidates, or an unknown criterion.
    RankDeficientError
        The feasible candidates (or the chosen poses) do not identify the level,
        naming why and what to add.
    """
    if criterion not in CRITERIA:
        raise CalibrationError(
            f"unknown design criterion {criterion!r}; expected one of {CRITERIA}"
        )
    model = CalibrationModel(nominal, check_level(level))
    theta = model.theta0 if parameters is None else np.asarray(parameters, float)
    x = np.atleast_2d(check_poses(candidates, "candidate pose"))
    ok, refused = feasible_candidates(
        nominal, x, box_lower=box_lower, box_upper=box_upper, min_rcond=min_rcond
    )
    feasible = np.flatnonzero(ok)
    need = model.n_free // 6 + 1
    if n_poses < need:
        raise CalibrationError(
            f"level {model.level!r} has {model.n_free} free coordinates: at least {need} "
            f"poses are needed, {n_poses} asked"
        )
    if feasible.size < n_poses:
        raise CalibrationError(
            f"only {feasible.size} of {x.shape[0]} candidates may be commanded "
            f"(refused: {refused}), {n_poses} asked"
        )
    cov = pose_covariance_from_sigma(feasible.size, sigma_translation_um, sigma_rotation_urad)
    white, plain = design_jacobians(model, theta, x[feasible], cov)
    refuse_rank_deficient(
        observability(model, white.reshape(-1, model.n_free), x[feasible]), model.level
    )
    if evaluation_poses is None:
        eval_plain = plain
    else:
        ev = np.atleast_2d(check_poses(evaluation_poses, "evaluation pose"))
        eval_plain = prediction_jacobian(model, theta, ev)
    chosen = _greedy(white, eval_plain[:, :3], n_poses, criterion)
    rows = white[chosen].reshape(-1, model.n_free)
    obs = observability(model, rows, x[feasible[chosen]])
    refuse_rank_deficient(obs, model.level)
    cov_z = np.linalg.inv(rows.T @ rows)
    var = np.einsum("eip,pq,eiq->ei", eval_plain, cov_z, eval_plain)
    sigma = to_um_urad(np.sqrt(var))
    baseline = (float("nan"), float("nan"))
    if random_draws > 0:
        rng = np.random.default_rng(0)
        draws: list[tuple[float, float]] = []
        for _ in range(20 * random_draws):
            pick = rng.choice(feasible.size, n_poses, replace=False)
            drawn = white[pick].reshape(-1, model.n_free)
            if np.linalg.matrix_rank(drawn) == model.n_free:
                draws.append(_translation_figures(eval_plain, drawn))
            if len(draws) == random_draws:
                break
        if draws:
            worst_median, rms_median = np.median(np.array(draws), axis=0)
            baseline = (float(worst_median), float(rms_median))
    return PoseSelection(
        indices=np.asarray(feasible[chosen], dtype=np.int64),
        poses=x[feasible[chosen]],
        criterion="g-optimal" if criterion == "sigma" else criterion,
        worst_sigma_um=float(sigma[:, :3].max()),
        worst_sigma_urad=float(sigma[:, 3:].max()),
        observability=obs,
        refused=refused,
        mean_sigma_um=float(np.sqrt(np.mean(sigma[:, :3] ** 2))),
        random_sigma_um=baseline,
    )


def _greedy(white: FloatArray, targets: FloatArray, n_poses: int, criterion: str) -> IntArray:
    """Indices of the candidates chosen (see :func:`select_poses`).

    ``white`` (M, 6, p) are the candidates' whitened Jacobians, ``targets`` (E, 3, p)
    the Jacobians of the evaluation poses' translations.
    """
    m, _, p = white.shape
    info = np.einsum("kip,kiq->pq", white, white)
    prior = _PRIOR * np.trace(info) / (m * p) * np.eye(p)
    information = prior.copy()
    available = np.ones(m, dtype=bool)
    chosen: list[int] = []
    for _ in range(n_poses):
        cand = np.flatnonzero(available)
        jc = white[cand]
        inner = np.eye(6) + jc @ np.linalg.inv(information) @ np.swapaxes(jc, 1, 2)
        best = int(cand[int(np.argmax(np.linalg.slogdet(inner)[1]))])
        chosen.append(best)
        available[best] = False
        information = information + white[best].T @ white[best]
    if criterion in ("sigma", "g-optimal", "i-optimal"):
        worst = criterion != "i-optimal"
        chosen = _exchange(white, targets.reshape(-1, p), chosen, prior, worst=worst)
    return np.asarray(chosen, dtype=np.int64)


def _worst_after(
    white: FloatArray,
    rows: FloatArray,
    information: FloatArray,
    cand: IntArray,
    worst: bool = True,
) -> FloatArray:
    """Worst (or, not ``worst``, mean) predicted variance over ``rows`` once each
    candidate is added, (len(cand),).

    With ``C`` the covariance of ``information`` and ``J`` a candidate's whitened
    Jacobian, ``var_e' = var_e - b^T (I + J C J^T)^-1 b``, ``b = J C g_e``.
    """
    cov = np.linalg.inv(information)
    jc = white[cand]
    proj = jc @ cov  # J C, (M, 6, p)
    # (I + J C J^T)^-1 = K^T K with K = L^-1, L its Cholesky factor
    factor = np.linalg.inv(np.linalg.cholesky(np.eye(6) + proj @ np.swapaxes(jc, 1, 2)))
    b = (factor @ proj).reshape(-1, proj.shape[2]) @ rows.T  # (M * 6, E)
    reduced = np.sum((b * b).reshape(len(cand), 6, -1), axis=1)
    var = np.einsum("ep,pq,eq->e", rows, cov, rows)
    after = var[None, :] - reduced
    return np.asarray(np.max(after, axis=1) if worst else np.mean(after, axis=1), float)


def _exchange(
    white: FloatArray,
    rows: FloatArray,
    chosen: list[int],
    prior: FloatArray,
    passes: int = 2,
    worst: bool = True,
) -> list[int]:
    """Exchange passes on the worst (or, not ``worst``, the mean) predicted variance: each
    chosen pose in turn is replaced by the candidate (itself included) that leaves the
    smallest criterion, until a pass changes nothing (Fedorov's exchange: minimax,
    G-optimal; or average, I-optimal)."""
    chosen = list(chosen)
    for _ in range(passes):
        changed = False
        for position in range(len(chosen)):
            others = chosen[:position] + chosen[position + 1 :]
            information = prior + np.einsum("kip,kiq->pq", white[others], white[others])
            available = np.ones(white.shape[0], dtype=bool)
            available[others] = False
            cand = np.flatnonzero(available)
            after = _worst_after(white, rows, information, cand, worst)
            current = after[int(np.searchsorted(cand, chosen[position]))]
            best = int(np.argmin(after))
            if after[best] < current * (1.0 - 1e-9):
                chosen[position] = int(cand[best])
                changed = True
        if not changed:
            break
    return chosen
