"""The thermal deflection decoupled pose measurement method (Kalas et al.).

Given the platform frames measured at every step of a plan (O, R0, then targets
S_i with references R next to them), compute for every target:

* the **conventional** pose ``T(O, S_i)``: the measured frame of S_i relative to
  the measured frame O;
* the **corrected** pose: the pose S_i would have had with the legs in the
  thermal state of the first reference R0.

Steps of the correction, all vectorized over targets:

1. Poses of every step relative to O, then leg lengths ``q`` by the IGM.
2. Thermal growth at R: ``dq_R(t) = q_R(t) - q_R0`` for every reference step.
3. Growth at R at S_i's time: the neighbouring reference(s); with a reference on
   both sides, interpolated linearly in time (``interpolation="linear"``), or
   one neighbour as in the paper (``"before"``, ``"after"``, ``"nearest"``).
4. Scaled to S_i's leg lengths with the leg model: ``dT = dq_R / s(q_R0)``,
   ``dq_S = dT * s(q_S0)`` where ``s`` is the leg's sensitivity (mm/K) and
   ``q_S0 = q_S - dq_S`` (one fixed-point refinement; the difference is far below
   a nanometre but costs nothing).
5. ``q_S0 = q_S - dq_S``, corrected pose ``= FGM(q_S0)``.

Signs: a leg that grew (``dq > 0``) made the measured pose longer in that leg; the
corrected pose takes the growth off.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from hexatherm.core.carry import shifted_poses
from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.thermal import LegThermalModel
from hexatherm.errors import PlanError
from hexatherm.typing import FloatArray

IntArray = npt.NDArray[np.intp]
Interpolation = Literal["linear", "before", "after", "nearest", "smooth"]
INTERPOLATIONS: tuple[Interpolation, ...] = ("linear", "before", "after", "nearest", "smooth")


@dataclass(frozen=True)
class StepPoses:
    """Every step's measured pose relative to O and its IGM leg lengths.

    Attributes
    ----------
    platform2origin : ndarray, shape (N, 4, 4)
    pose : ndarray, shape (N, 6)
        ``[Tx, Ty, Tz, Rx, Ry, Rz]`` relative to O, mm and deg.
    q_mm : ndarray, shape (N, 6)
        Leg lengths of each step by the IGM.
    """

    platform2origin: FloatArray
    pose: FloatArray
    q_mm: FloatArray


@dataclass(frozen=True)
class Correction:
    """Conventional and corrected poses of the M targets of a plan.

    Attributes
    ----------
    target_index : ndarray of int, shape (M,)
        Step index of each target.
    conventional : ndarray, shape (M, 6)
        ``T(O, S_i)`` as measured, mm and deg.
    corrected : ndarray, shape (M, 6)
        The pose at the thermal state of R0, mm and deg, relative to O carried to that
        state when ``correct`` was given its shift.
    growth_mm : ndarray, shape (M, 6)
        Thermal growth of each leg at S_i, subtracted from its leg lengths.
    reference_growth_mm : ndarray, shape (M, 6)
        Growth at R (relative to R0) at S_i's time, before scaling to S_i.
    before_index, after_index : ndarray of int, shape (M,)
        Step index of the reference used before / after S_i (-1: not used).
    weight_after : ndarray, shape (M,)
        Weight of the reference after S_i in the interpolation (0 to 1).
    dt_before_s, dt_after_s : ndarray, shape (M,)
        ``t_S - t_Rbefore`` and ``t_Rafter - t_S`` of the references used (NaN: not used).
    q_corrected_mm : ndarray, shape (M, 6)
        Leg lengths given to the FGM.
    growth_weights : ndarray, shape (M, 6, N), optional
        With ``interpolation="smooth"`` when the smooth fit is used: growth at R at each
        target's time per leg = ``sum_n growth_weights[m, leg, n] * q[n, leg] - q_R0``
        (zero but at references); None otherwise (the two neighbours).
    smooth : SmoothGrowth, optional
        The smooth fit and its cross-validation (``interpolation="smooth"``).
    """

    target_index: IntArray
    conventional: FloatArray
    corrected: FloatArray
    growth_mm: FloatArray
    reference_growth_mm: FloatArray
    before_index: IntArray
    after_index: IntArray
    weight_after: FloatArray
    dt_before_s: FloatArray
    dt_after_s: FloatArray
    q_corrected_mm: FloatArray
    growth_weights: FloatArray | None = None
    smooth: SmoothGrowth | None = None


def step_poses(hexapod: Hexapod, platform2cmm: npt.ArrayLike, origin_index: int = 0) -> StepPoses:
    """Poses relative to the origin step and IGM leg lengths of every measured step.

    Parameters
    ----------
    hexapod : Hexapod
    platform2cmm : array_like, shape (N, 4, 4)
        Measured platform frame of every step in the CMM frame.
    origin_index : int
        Which step is the origin O.
    """
    frames = np.asarray(platform2cmm, dtype=float)
    origin2cmm = frames[origin_index]
    platform2origin = invert_transform(origin2cmm) @ frames
    pose = pose_from_transform(platform2origin, hexapod.convention)
    return StepPoses(platform2origin=platform2origin, pose=pose, q_mm=hexapod.igm(pose))


def choose_references(
    plan: Plan, times_s: npt.ArrayLike, interpolation: Interpolation = "linear"
) -> tuple[IntArray, IntArray, FloatArray]:
    """Which references each target uses, and the interpolation weight of the later one.

    Returns ``(before_index, after_index, weight_after)`` with -1 for an unused side.
    With ``"linear"`` and references on both sides the weight is
    ``(t_S - t_b) / (t_a - t_b)``; with one side only, that side is used. References
    measured at the same time (a burst of data stamped on arrival) get the weight 1/2:
    the target lies between them in the plan's order, and the times say no more.
    References in reverse time order are an error. ``"smooth"`` gives the neighbours as
    ``"linear"`` does (the smooth fit replaces them in :func:`correct` when it is used).
    """
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {interpolation!r}")
    t = np.asarray(times_s, dtype=float)
    adjacent = np.array(plan.adjacent_references(), dtype=np.intp).reshape(-1, 2)
    before, after = adjacent[:, 0].copy(), adjacent[:, 1].copy()
    targets = plan.target_indices
    both = (before >= 0) & (after >= 0)
    if interpolation == "before":
        after[both] = -1
    elif interpolation == "after":
        before[both] = -1
    elif interpolation == "nearest":
        closer_after = both & ((t[after] - t[targets]) < (t[targets] - t[before]))
        before[closer_after] = -1
        after[both & ~closer_after] = -1
    weight = np.where(after >= 0, 1.0, 0.0)
    both = (before >= 0) & (after >= 0)
    if np.any(both):
        tb, ta, ts = t[before[both]], t[after[both]], t[targets[both]]
        span = ta - tb
        if np.any(span < 0):
            bad = targets[both][np.argmax(span < 0)]
            raise PlanError(
                f"step {plan.labels[bad]}: its references are not in time order "
                "(the reference after it was measured before the one before it)"
            )
        # equal times (points stamped on arrival, a burst of data in one read): the data
        # hold no time distances, only the plan's order, in which the target lies between
        # its references; the symmetric weight is the one the order supports
        timed = span > 0
        weight_both = np.full(span.shape, 0.5)
        weight_both[timed] = (ts[timed] - tb[timed]) / span[timed]
        weight[both] = weight_both
    return before, after, weight


def correct(
    hexapod: Hexapod,
    plan: Plan,
    times_s: npt.ArrayLike,
    platform2cmm: npt.ArrayLike,
    interpolation: Interpolation = "linear",
    measurements: npt.ArrayLike | None = None,
    origin_shift: npt.ArrayLike | None = None,
) -> tuple[StepPoses, Correction]:
    """Run the thermal deflection decoupled method on one session.

    Parameters
    ----------
    hexapod : Hexapod
        Geometry and leg thermal model (``hexapod.legs`` is required).
    plan : Plan
        The steps, validated.
    times_s : array_like, shape (N,)
        Time of every step, seconds.
    platform2cmm : array_like, shape (N, 4, 4)
        Measured platform frame of every step in the CMM frame.
    interpolation : {"linear", "before", "after", "nearest", "smooth"}
        How a target with references on both sides uses them; ``"smooth"``: the growth
        at R over the whole session fitted per leg by a smoothing spline
        (:func:`smooth_growth`), unless its cross-validation prefers the neighbours.
    measurements : array_like of int, shape (N,), optional
        How many measurements each step averages (weights of the smooth fit).
    origin_shift : array_like, shape (4, 4), optional
        The frame O in R0's thermal state relative to O as measured
        (:mod:`hexatherm.core.carry`): the corrected poses are expressed in it; the
        conventional ones stay relative to O as measured. None: O as measured.

    Returns
    -------
    (StepPoses, Correction)
    """
    if hexapod.legs is None:
        raise PlanError("the hexapod file has no leg model (legs:): cannot scale thermal growth")
    t = np.asarray(times_s, dtype=float)
    frames = np.asarray(platform2cmm, dtype=float)
    if t.shape != (len(plan.labels),) or frames.shape != (len(plan.labels), 4, 4):
        raise ValueError("times and frames must have one entry per plan step")
    steps = step_poses(hexapod, frames, plan.origin_index)
    targets = plan.target_indices
    refs = plan.reference_indices
    before, after, w_after = choose_references(plan, t, interpolation)

    q = steps.q_mm
    q_r0 = q[refs[0]] if refs.size else np.full(6, np.nan)
    reference_growth = interpolated_growth(q, q_r0, before, after, w_after)
    smooth, growth_weights = None, None
    if interpolation == "smooth" and targets.size:
        counts = np.ones(len(t)) if measurements is None else np.asarray(measurements, float)
        smooth = smooth_growth(t[refs], q[refs] - q_r0, t[targets], counts[refs])
        if smooth.used:
            growth_weights = np.zeros((targets.size, 6, len(t)))
            growth_weights[:, :, refs] = smooth.weights
            reference_growth = np.einsum("mln,nl->ml", growth_weights, q) - q_r0
    q_s = q[targets]
    growth_s = target_growth(hexapod.legs, reference_growth, q_r0, q_s)
    q_corr = q_s - growth_s
    corrected = hexapod.fgm(q_corr, initial_poses=steps.pose[targets])
    if origin_shift is not None:
        corrected = shifted_poses(origin_shift, corrected, hexapod.convention)

    dt_before = np.where(before >= 0, t[targets] - t[np.maximum(before, 0)], np.nan)
    dt_after = np.where(after >= 0, t[np.maximum(after, 0)] - t[targets], np.nan)
    correction = Correction(
        target_index=targets,
        conventional=steps.pose[targets],
        corrected=corrected,
        growth_mm=growth_s,
        reference_growth_mm=reference_growth,
        before_index=before,
        after_index=after,
        weight_after=w_after,
        dt_before_s=dt_before,
        dt_after_s=dt_after,
        q_corrected_mm=q_corr,
        growth_weights=growth_weights,
        smooth=smooth,
    )
    return steps, correction


def interpolated_growth(
    q_mm: npt.ArrayLike,
    q_r0_mm: npt.ArrayLike,
    before_index: npt.ArrayLike,
    after_index: npt.ArrayLike,
    weight_after: npt.ArrayLike,
) -> FloatArray:
    """Growth since R0 at the references, interpolated to each target (steps 2 and 3).

    Parameters
    ----------
    q_mm : array_like, shape (..., N, 6)
        Leg lengths of every step.
    q_r0_mm : array_like, shape (..., 6)
        Leg lengths of R0.
    before_index, after_index : array_like of int, shape (M,)
        The references each target uses (-1: none), as in :class:`Correction`.
    weight_after : array_like, shape (M,)
        Weight of the later reference.

    Returns
    -------
    ndarray, shape (..., M, 6)
    """
    q = np.asarray(q_mm, dtype=float)
    before = np.asarray(before_index, dtype=np.intp)
    after = np.asarray(after_index, dtype=np.intp)
    w_after = np.asarray(weight_after, dtype=float)
    growth_r = q - np.asarray(q_r0_mm, dtype=float)[..., None, :]  # meaningful at references
    g_before = np.where((before >= 0)[:, None], growth_r[..., np.maximum(before, 0), :], 0.0)
    g_after = np.where((after >= 0)[:, None], growth_r[..., np.maximum(after, 0), :], 0.0)
    return (1.0 - w_after)[:, None] * g_before + w_after[:, None] * g_after


def target_growth(
    legs: LegThermalModel,
    reference_growth_mm: npt.ArrayLike,
    q_r0_mm: npt.ArrayLike,
    q_s_mm: npt.ArrayLike,
) -> FloatArray:
    """Growth of the targets' legs (step 4): the growth at the references scaled by the
    leg model from R0's leg lengths to the target's less its growth (one fixed-point
    pass from the measured ones).

    Parameters
    ----------
    legs : LegThermalModel
    reference_growth_mm : array_like, shape (..., M, 6)
    q_r0_mm : array_like, shape (..., 6) or (..., 1, 6)
    q_s_mm : array_like, shape (..., M, 6)
        Measured leg lengths of the targets.

    Returns
    -------
    ndarray, shape (..., M, 6)
    """
    q_s = np.asarray(q_s_mm, dtype=float)
    growth_s = legs.scale_growth(reference_growth_mm, q_r0_mm, q_s)
    return legs.scale_growth(reference_growth_mm, q_r0_mm, q_s - growth_s)


# ------------------------------------------------------------------ smooth growth
#: smoothing parameters tried by the cross-validation (times scaled to [0, 1])
SMOOTHING_GRID = np.logspace(-12, 2, 57)
#: fewest references a smooth fit needs (fewer: the two neighbours)
MIN_SMOOTH_REFERENCES = 5
#: the smooth fit is used when its leave-one-out error is below this share of the
#: neighbours': a tie keeps the linear default
SMOOTH_MARGIN = 0.95


@dataclass(frozen=True)
class SmoothGrowth:
    """The growth at R as a smooth function of time, and whether it was used.

    Attributes
    ----------
    used : bool
        True: the smooth fit replaces the two neighbours; False: it fell back to the
        linear two-neighbour interpolation (``reason`` says why).
    weights : ndarray, shape (M, 6, n_refs)
        Growth at each target's time per leg = ``weights @ (q_refs - q_R0)``: the
        smoother's hat matrix evaluated at the targets (linear in the data for the
        chosen smoothing; rows sum to 1).
    lam : ndarray, shape (6,)
        Smoothing parameter of each leg (times scaled to [0, 1]).
    cv_smooth_um, cv_linear_um : float
        Leave-one-out RMS prediction error of the references' growth (um, all legs):
        by the smooth fit, and by linear interpolation between the two neighbours.
    reason : str
        One line: the decision and its numbers.
    """

    used: bool
    weights: FloatArray
    lam: FloatArray
    cv_smooth_um: float
    cv_linear_um: float
    reason: str


def natural_spline_operators(t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``Q`` (n, n-2) and ``R`` (n-2, n-2) of the natural cubic spline through knots ``t``.

    Green & Silverman's form: the roughness ``int g''^2 = g^T Q R^-1 Q^T g`` and the
    second derivatives at the interior knots ``gamma = R^-1 Q^T g``.
    """
    n = len(t)
    h = np.diff(t)
    q = np.zeros((n, n - 2))
    r = np.zeros((n - 2, n - 2))
    for j in range(1, n - 1):
        c = j - 1
        q[j - 1, c] = 1 / h[j - 1]
        q[j, c] = -1 / h[j - 1] - 1 / h[j]
        q[j + 1, c] = 1 / h[j]
        r[c, c] = (h[j - 1] + h[j]) / 3
        if c + 1 < n - 2:
            r[c, c + 1] = r[c + 1, c] = h[j] / 6
    return q, r


def spline_evaluation(t_knots: FloatArray, t_eval: FloatArray) -> FloatArray:
    """Matrix (m, n): values at ``t_eval`` of the natural cubic spline whose knot values are
    the data (linear beyond the end knots, with the end slopes)."""
    n = len(t_knots)
    q, r = natural_spline_operators(t_knots)
    gamma_of = np.zeros((n, n))  # second derivatives at every knot from the knot values
    gamma_of[1:-1] = np.linalg.solve(r, q.T)
    h = np.diff(t_knots)
    out = np.zeros((len(t_eval), n))
    for e, te in enumerate(t_eval):
        if te <= t_knots[0]:
            slope = (np.eye(n)[1] - np.eye(n)[0]) / h[0] - h[0] * gamma_of[1] / 6
            out[e] = np.eye(n)[0] + (te - t_knots[0]) * slope
            continue
        if te >= t_knots[-1]:
            slope = (np.eye(n)[-1] - np.eye(n)[-2]) / h[-1] + h[-1] * gamma_of[-2] / 6
            out[e] = np.eye(n)[-1] + (te - t_knots[-1]) * slope
            continue
        i = int(np.searchsorted(t_knots, te, side="right") - 1)
        a, b = te - t_knots[i], t_knots[i + 1] - te
        row = np.zeros(n)
        row[i + 1] += a / h[i]
        row[i] += b / h[i]
        row -= a * b / 6 * ((1 + a / h[i]) * gamma_of[i + 1] + (1 + b / h[i]) * gamma_of[i])
        out[e] = row
    return out


def smoothing_hat(t: FloatArray, w: FloatArray, lam: float) -> FloatArray:
    """Hat matrix (n, n) of the weighted cubic smoothing spline: ``(W + lam K)^-1 W``."""
    q, r = natural_spline_operators(t)
    k = q @ np.linalg.solve(r, q.T)
    return np.asarray(np.linalg.solve(np.diag(w) + lam * k, np.diag(w)))


def smooth_growth(
    ref_times_s: npt.ArrayLike,
    ref_growth_mm: npt.ArrayLike,
    target_times_s: npt.ArrayLike,
    ref_weights: npt.ArrayLike | None = None,
) -> SmoothGrowth:
    """The growth at R fitted over the session per leg by a cubic smoothing spline.

    The smoothing of each leg is chosen by generalized cross-validation (GCV) over
    :data:`SMOOTHING_GRID`; the references are weighted by ``ref_weights`` (the inverse of
    their relative variance: a reference averaged over n measurements weighs n). The fit
    is used only when its leave-one-out error of the references' growth (all legs) is
    below :data:`SMOOTH_MARGIN` times that of linear interpolation between each
    reference's two neighbours, the linear method's way of predicting: on heating that
    is not smooth (a step) the neighbours predict as well or better, and the linear
    default stays.

    Parameters
    ----------
    ref_times_s : array_like, shape (n,)
        Times of the references, strictly increasing.
    ref_growth_mm : array_like, shape (n, 6)
        Growth of each leg at the references, ``q_R - q_R0``.
    target_times_s : array_like, shape (M,)
    ref_weights : array_like, shape (n,), optional

    Returns
    -------
    SmoothGrowth
    """
    t = np.asarray(ref_times_s, dtype=float)
    g = np.asarray(ref_growth_mm, dtype=float)
    ts = np.asarray(target_times_s, dtype=float)
    n = len(t)
    w = np.ones(n) if ref_weights is None else np.asarray(ref_weights, dtype=float)
    nan6 = np.full(6, np.nan)
    empty = np.zeros((len(ts), 6, n))
    if n < MIN_SMOOTH_REFERENCES:
        return SmoothGrowth(
            False,
            empty,
            nan6,
            np.nan,
            np.nan,
            f"{n} references, too few for a smooth fit (at least {MIN_SMOOTH_REFERENCES}): "
            "the two neighbours kept",
        )
    if np.any(np.diff(t) <= 0):
        return SmoothGrowth(
            False,
            empty,
            nan6,
            np.nan,
            np.nan,
            "references without distinct times in order: the two neighbours kept",
        )
    scale = t[-1] - t[0]
    x, xs = (t - t[0]) / scale, (ts - t[0]) / scale
    hats = np.array([smoothing_hat(x, w, lam) for lam in SMOOTHING_GRID])  # (L, n, n)
    fitted = np.einsum("aij,jl->ail", hats, g)  # (L, n, 6)
    trace = np.einsum("aii->a", hats)
    rss = np.einsum("i,ail->al", w, (g - fitted) ** 2)
    gcv = n * rss / np.maximum(n - trace, 1e-9)[:, None] ** 2  # (L, 6)
    # one smoothing for all legs: they warm up with one history, and the noise of a
    # reference's frame reaches every leg; per leg the choice is noisier (measured)
    best = np.full(6, np.argmin(gcv.sum(axis=1)))
    evaluation = spline_evaluation(x, xs)  # (M, n)
    weights = np.stack([evaluation @ hats[b] for b in best], axis=1)  # (M, 6, n)
    # leave-one-out: smooth e_i / (1 - H_ii); linear: each inner reference from its neighbours
    loo = np.stack(
        [(g[:, leg] - fitted[b, :, leg]) / (1 - np.diag(hats[b])) for leg, b in enumerate(best)],
        axis=1,
    )[1:-1]
    frac = (t[1:-1] - t[:-2]) / (t[2:] - t[:-2])
    linear = g[1:-1] - ((1 - frac)[:, None] * g[:-2] + frac[:, None] * g[2:])
    cv_smooth = float(np.sqrt(np.mean(loo**2))) * 1e3
    cv_linear = float(np.sqrt(np.mean(linear**2))) * 1e3
    used = cv_smooth < SMOOTH_MARGIN * cv_linear
    verdict = (
        "smooth fit used"
        if used
        else f"the two neighbours kept (the smooth fit is not below {SMOOTH_MARGIN:g}x: "
        "the heating is not smooth enough for it)"
    )
    reason = (
        f"leave-one-out error of the references' growth {cv_smooth:.3g} um smooth, "
        f"{cv_linear:.3g} um linear between neighbours: {verdict}"
    )
    return SmoothGrowth(used, weights, SMOOTHING_GRID[best], cv_smooth, cv_linear, reason)
