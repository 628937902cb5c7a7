"""The smooth growth's own error: what the spline's bias and its smoothing's choice add.

The linear propagation of ``--interpolation smooth`` holds the chosen smoothing fixed and
the spline exact: it carries the references' noise, not the error of the smooth function
itself (a spline that cannot follow the heating, a smoothing chosen from noisy data). The
references' residuals from the fit see both: ``e = D^-1/2 (I - H) g`` (``H`` the hat matrix
of the chosen smoothing, ``D`` its ``1 - H_ii``), the standardized residuals, halfway (in
the log) between the in-sample residual ``(I - H) g`` (the fit's error where it saw the
reference) and the leave-one-out error ``D^-1 (I - H) g`` (where it did not, across twice
the references' spacing); a target lies between two references, not on one. Noise alone
gives them the covariance ``sum_j A_ij^2 S_j`` (``A = D^-1/2 (I - H)``, ``S_j`` the 6x6
covariance of reference j's leg lengths from its own centres; O's and R0's noise is common
to every reference and the spline reproduces constants, so it cancels). What the observed
residuals hold beyond that is the smooth fit's own error (:func:`growth_excess`, a Type A
evaluation). Which of the three residuals carries the error to the targets was chosen
against a simulated twin's truth (docs/uncertainty.md): the in-sample residuals claimed
0.73x of the error on heating switched on mid-session, the leave-one-out ones 1.47x, the
standardized ones 0.95x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.correction import smoothing_hat, target_growth
from hexatherm.core.propagation import PoseChain
from hexatherm.typing import FloatArray

__all__ = [
    "GrowthExcess",
    "corrected_excess",
    "growth_excess",
    "growth_to_pose",
    "leg_derivatives",
    "log_growth",
    "log_shape_error",
    "neighbour_shape_error",
    "own_leg_covariance",
]

#: central-difference step on a leg's growth, mm
STEP_MM = 1e-4


@dataclass(frozen=True)
class GrowthExcess:
    """The smooth fit's own error of the growth at R, beyond the references' noise.

    Attributes
    ----------
    cov_mm2 : ndarray, shape (6, 6)
        Covariance of the growth at R per leg that the noise does not explain (positive
        semi-definite; zero when the errors are no larger than noise).
    observed_um, noise_um : float
        RMS standardized residual of the inner references' growth (all legs): observed,
        and expected from the propagated noise alone.
    shape_um : ndarray, shape (M,), optional
        RMS over the legs of the fit's error at each target on a growth shaped as the
        thermocouple log (:func:`log_shape_error`); None without a log.
    widest_gap : float
        The longest interval between consecutive references over their median one.
    past_um : ndarray, shape (M,), optional
        RMS over the legs of the fit's error past the last reference without a log, at
        each target (0 for those before it); None with a log.
    """

    cov_mm2: FloatArray
    observed_um: float
    noise_um: float
    shape_um: FloatArray | None = None
    widest_gap: float = 1.0
    past_um: FloatArray | None = None

    @property
    def excess_um(self) -> float:
        """RMS over the legs of the added standard uncertainty of the growth, um."""
        return float(np.sqrt(np.trace(self.cov_mm2) / 6)) * 1e3


def growth_excess(
    ref_times_s: npt.ArrayLike,
    ref_growth_mm: npt.ArrayLike,
    ref_weights: npt.ArrayLike,
    lam: float,
    ref_leg_cov_mm2: npt.ArrayLike,
    ref_model_mm: npt.ArrayLike | None = None,
) -> GrowthExcess:
    """Covariance of the smooth growth's error beyond noise, from the inner references'
    standardized residuals (module docstring).

    Parameters
    ----------
    ref_times_s : array_like, shape (n,)
        Times of the references, increasing (n >= 3).
    ref_growth_mm : array_like, shape (n, 6)
        ``q_R - q_R0`` of every reference.
    ref_weights : array_like, shape (n,)
        The smooth fit's weights (measurements each reference averages).
    lam : float
        The chosen smoothing (times scaled to [0, 1]).
    ref_leg_cov_mm2 : array_like, shape (n, 6, 6)
        Covariance of each reference's leg lengths from its own centres.
    ref_model_mm : array_like, shape (n, 6), optional
        A growth shaped as the thermocouple log at the references: its residuals from the
        same fit are the share of the observed ones that the log explains, taken off as the
        noise's is (the log's shape is then carried to each target on its own,
        :func:`log_shape_error`).

    Returns
    -------
    GrowthExcess

    Examples
    --------
    Noise-free growth that a straight line follows: nothing to add.

    >>> t = np.linspace(0.0, 600.0, 7)
    >>> g = np.outer(t, np.ones(6)) * 1e-6
    >>> ex = growth_excess(t, g, np.ones(7), 1e-3, np.zeros((7, 6, 6)))
    >>> float(np.abs(ex.cov_mm2).max()) < 1e-20
    True
    """
    t = np.asarray(ref_times_s, dtype=float)
    g = np.asarray(ref_growth_mm, dtype=float)
    s = np.asarray(ref_leg_cov_mm2, dtype=float)
    x = (t - t[0]) / (t[-1] - t[0])
    hat = smoothing_hat(x, np.asarray(ref_weights, dtype=float), lam)
    # standardized residuals (a fit that interpolates a reference leaves it none: 0)
    d = np.maximum(1.0 - np.diag(hat), 1e-12)
    a = (np.eye(len(t)) - hat) / np.sqrt(d)[:, None]
    a = a[1:-1]  # inner references: the targets lie between references
    e = a @ g  # (n-2, 6)
    observed = np.einsum("il,im->lm", e, e) / len(e)
    noise = np.einsum("ij,jlm->lm", a**2, s) / len(e)
    # the observed covariance less the noise's share of it (one scalar over the legs: the
    # legs share one heating history; per leg pair, 6x6 from a few references, the
    # difference is too noisy and its positive part too large)
    explained = float(np.trace(noise))
    if ref_model_mm is not None:
        m = a @ np.asarray(ref_model_mm, dtype=float)
        explained += float(np.sum(m**2)) / len(m)
    total = float(np.trace(observed))
    share = max(0.0, 1.0 - explained / total) if total > 0 else 0.0
    cov = share * observed
    spacing = np.diff(t)
    return GrowthExcess(
        cov_mm2=cov,
        observed_um=float(np.sqrt(np.trace(observed) / 6)) * 1e3,
        noise_um=float(np.sqrt(np.trace(noise) / 6)) * 1e3,
        widest_gap=float(spacing.max() / np.median(spacing)),
    )


def log_shape_error(
    weights: npt.ArrayLike,
    ref_times_s: npt.ArrayLike,
    target_times_s: npt.ArrayLike,
    log_times_s: npt.ArrayLike,
    log_legs_C: npt.ArrayLike,
    sensitivity_mm_per_K: npt.ArrayLike,
) -> FloatArray:
    """The smooth fit's error at each target on a growth shaped as the thermocouple log,
    (M, 6) mm: ``s * (W T(t_refs) - T(t_target))`` per leg.

    The residuals at the references (:func:`growth_excess`) see the fit's error where the
    fit has data, pooled over the session; between references far apart (a gap, times
    irregular) or across a heating switched on or off, the error at a target is larger
    than at any reference, and only the heating's history shows it. The log gives that
    history: the fit's weights ``W`` (M, 6, n; rows summing to 1) applied to the legs'
    logged temperatures at the references, against their temperature at the target, times
    each leg's growth per kelvin ``s``, is the error the fit makes on a growth that follows
    the log (a Type B evaluation: the log's shape, the leg model's gain).

    >>> t = np.array([0.0, 600.0, 1200.0])
    >>> w = np.broadcast_to([0.5, 0.5, 0.0], (1, 6, 3))  # halfway between the first two
    >>> logged = np.outer([20.0, 20.0, 21.0, 22.0], np.ones(6))   # a kink at 600 s
    >>> err = log_shape_error(w, t, [300.0], [0.0, 600.0, 900.0, 1200.0], logged, 1e-2)
    >>> float(abs(err).max())
    0.0
    >>> err = log_shape_error(w, t, [900.0], [0.0, 600.0, 900.0, 1200.0], logged, 1e-2)
    >>> round(float(err[0, 0]), 6)   # 20 logged at the references' mean, 21 at 900 s
    -0.01
    """
    log = (log_times_s, log_legs_C, sensitivity_mm_per_K)
    fitted = np.einsum(
        "mln,nl->ml", np.asarray(weights, dtype=float), log_growth(ref_times_s, *log)
    )
    return fitted - log_growth(target_times_s, *log)


def neighbour_shape_error(
    columns: npt.ArrayLike,
    weights: npt.ArrayLike,
    ref_times_s: npt.ArrayLike,
    target_times_s: npt.ArrayLike,
    log_times_s: npt.ArrayLike,
    log_legs_C: npt.ArrayLike,
    sensitivity_mm_per_K: npt.ArrayLike,
) -> FloatArray:
    """:func:`log_shape_error` of weights that are zero but on a few references, the same
    on every leg (a straight line between two neighbours): each target's references
    ``columns`` (M, k; indices into ``ref_times_s``, distinct within a row) and their
    ``weights`` (M, k; 0 for a side not used), (M, 6) mm. The same numbers without the
    dense weights: at 10,000 targets and as many references those are 800 MB and
    6 x 10^8 products, nearly all of zeros; here k products a target and leg.

    >>> t = np.array([0.0, 600.0, 1200.0])
    >>> logged = np.outer([20.0, 20.0, 21.0, 22.0], np.ones(6))   # a kink at 600 s
    >>> err = neighbour_shape_error([[0, 1]], [[0.5, 0.5]], t, [900.0],
    ...                             [0.0, 600.0, 900.0, 1200.0], logged, 1e-2)
    >>> round(float(err[0, 0]), 6)   # as log_shape_error's halfway weights
    -0.01
    """
    log = (log_times_s, log_legs_C, sensitivity_mm_per_K)
    growth = log_growth(ref_times_s, *log)  # (n, 6)
    cols = np.asarray(columns, dtype=np.intp)
    w = np.asarray(weights, dtype=float)
    fitted = np.zeros((cols.shape[0], growth.shape[1]))
    # the sum over the references of log_shape_error, of its terms that are not zero
    # (adding a zero changes no sum)
    for j in range(cols.shape[1]):
        fitted += w[:, j, None] * growth[cols[:, j]]
    return fitted - log_growth(target_times_s, *log)


def log_growth(
    times_s: npt.ArrayLike,
    log_times_s: npt.ArrayLike,
    log_legs_C: npt.ArrayLike,
    sensitivity_mm_per_K: npt.ArrayLike,
) -> FloatArray:
    """Growth (n, 6) mm shaped as the log: each leg's logged temperature at ``times_s``
    (linear between samples, held beyond) times its growth per kelvin."""
    t = np.asarray(times_s, dtype=float)
    lt = np.asarray(log_times_s, dtype=float)
    legs = np.asarray(log_legs_C, dtype=float)
    logged = np.column_stack([np.interp(t, lt, legs[:, i]) for i in range(6)])
    return np.asarray(np.asarray(sensitivity_mm_per_K, dtype=float) * logged)


def leg_derivatives(
    chain: PoseChain, centres_mm: npt.ArrayLike, steps: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Derivatives (S, 6, k, 3) of the leg lengths of ``steps`` (relative to O) by their
    own centres and by O's: the poses' analytic derivatives
    (:meth:`~hexatherm.core.propagation.PoseChain.pose_derivatives`) through the IGM's
    Jacobian."""
    c = np.asarray(centres_mm, dtype=float)
    idx = np.asarray(steps, dtype=np.intp)
    pose, own, by_o = chain.pose_derivatives(c, idx)
    jac = chain.hexapod.jacobian(pose)  # (S, 6 legs, 6 pose)
    shape = (idx.size, 6, c.shape[1], 3)
    return (jac @ own).reshape(shape), (jac @ by_o).reshape(shape)


def own_leg_covariance(
    chain: PoseChain,
    centres_mm: npt.ArrayLike,
    centre_cov_mm2: npt.ArrayLike,
    steps: npt.ArrayLike,
    own: FloatArray | None = None,
) -> FloatArray:
    """Covariance (len(steps), 6, 6) of the leg lengths of ``steps`` from their own centres
    (O held fixed), by their derivatives ``own`` (S, 6, k, 3) (:func:`leg_derivatives`,
    made here when not given)."""
    cov = np.asarray(centre_cov_mm2, dtype=float)
    idx = np.asarray(steps, dtype=np.intp)
    if own is None:
        own = leg_derivatives(chain, centres_mm, idx)[0]
    k = own.shape[2]
    dq = np.moveaxis(own, 1, -1)  # (R, k, 3, 6)
    weighted = (cov[idx] @ dq).reshape(idx.size, 3 * k, 6)  # U dq, ball by ball
    return np.asarray(np.swapaxes(dq.reshape(idx.size, 3 * k, 6), 1, 2) @ weighted)


def corrected_excess(
    chain: PoseChain,
    growth_mm: npt.ArrayLike,
    q_r0_mm: npt.ArrayLike,
    q_s_mm: npt.ArrayLike,
    corrected: npt.ArrayLike,
    growth_cov_mm2: npt.ArrayLike,
) -> FloatArray:
    """Covariance (M, 6, 6) of the corrected poses (mm, deg) from an error of the growth at
    R of covariance ``growth_cov_mm2`` (6, 6), or one per target (M, 6, 6): through the
    growth scaling to each target's legs and the FGM (:func:`growth_to_pose`)."""
    jd = growth_to_pose(chain, growth_mm, q_r0_mm, q_s_mm, corrected)
    return np.asarray(jd @ np.asarray(growth_cov_mm2, dtype=float) @ np.swapaxes(jd, 1, 2))


def growth_to_pose(
    chain: PoseChain,
    growth_mm: npt.ArrayLike,
    q_r0_mm: npt.ArrayLike,
    q_s_mm: npt.ArrayLike,
    corrected: npt.ArrayLike,
) -> FloatArray:
    """Derivatives (M, 6, 6) of the corrected poses (mm, deg) by the growth at R of each
    target (mm): the growth scaling to its legs (leg by leg) and the FGM (the inverse of
    the IGM's Jacobian at the corrected pose)."""
    legs = chain.hexapod.legs
    if legs is None:
        raise ValueError("the hexapod has no leg model")
    g = np.asarray(growth_mm, dtype=float)
    q_s = np.asarray(q_s_mm, dtype=float)
    q_r0 = np.broadcast_to(np.asarray(q_r0_mm, dtype=float), q_s.shape)
    # the scaling is leg by leg: d q_corr / d G is diagonal, (M, 6)
    d_growth = -(
        target_growth(legs, g + STEP_MM, q_r0, q_s) - target_growth(legs, g - STEP_MM, q_r0, q_s)
    ) / (2 * STEP_MM)
    jac = np.linalg.inv(chain.hexapod.jacobian(np.asarray(corrected, dtype=float)))  # (M, 6, 6)
    return np.asarray(jac * d_growth[:, None, :])
