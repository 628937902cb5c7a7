"""The interpolation's own error carried to the corrected poses: the smooth growth's
(``--interpolation smooth``) and the straight line's between references (linear, one
neighbour, smooth's fallback).

The glue between :class:`~hexatherm.workflows.process.pipeline.ProcessResult` and
:mod:`hexatherm.core.smoothbias` / :mod:`hexatherm.core.curvature`;
:func:`~hexatherm.workflows.process.uncertainty.pose_uncertainty` adds the results to the
corrected poses' own part.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from hexatherm.core.correction import Correction
from hexatherm.core.curvature import CurvatureError, curvature_error
from hexatherm.core.propagation import PoseChain, reference_scatter
from hexatherm.core.smoothbias import (
    GrowthExcess,
    growth_excess,
    growth_to_pose,
    log_growth,
    log_shape_error,
    neighbour_shape_error,
    own_leg_covariance,
)
from hexatherm.typing import FloatArray, IntArray
from hexatherm.workflows.process.pipeline import ProcessResult

__all__ = ["SmoothExcess", "curvature_excess", "neighbour_weights", "smooth_excess"]


class SmoothExcess(NamedTuple):
    """The smooth growth's own error on the corrected poses (:func:`smooth_excess`).

    Attributes
    ----------
    cov : ndarray, shape (M, 6, 6)
        Each target's own (mm, deg).
    evaluation : GrowthExcess
        Its evaluation at the references.
    vectors : ndarray, shape (M, 6, K)
        Its part shared by the targets of one interval, as error vectors of each
        corrected pose: ``V_a V_b^T`` the covariance between two of them (``V V^T`` is in
        ``cov``).
    interval : ndarray of int, shape (M,)
        The interval of each target: the reference before it (the last one for a target
        past it; -1 before the first: its own).
    """

    cov: FloatArray
    evaluation: GrowthExcess
    vectors: FloatArray
    interval: IntArray


def smooth_excess(
    result: ProcessResult,
    chain: PoseChain,
    centre_cov_mm2: FloatArray,
    legs_cov_mm2: FloatArray | None = None,
) -> SmoothExcess | None:
    """The smooth growth's own error carried to the corrected poses, (M, 6, 6), and its
    evaluation at the references; None unless the smooth fit was used.

    The inner references' standardized residuals beyond what their noise predicts
    (:func:`~hexatherm.core.smoothbias.growth_excess`) give the covariance of the growth
    at R that the fixed-smoothing propagation leaves out (the spline's bias, the smoothing's
    choice); it is carried to every target's legs by the growth scaling and through the
    FGM. With a thermocouple log, each target also gets the fit's error on a growth
    shaped as the log (:func:`~hexatherm.core.smoothbias.log_shape_error`): what the
    residuals at the references cannot see at a target far from them (a gap, irregular
    times) or across a heating switched on or off. Without one, a target past the last
    reference gets the fit's error there (:func:`past_last_error`).

    Two targets of one interval (between the same two references, or both past the last)
    share: with a log, both terms (the fit's error is a smooth function of time, nearly
    the same at two targets of one interval once the log's shape is taken off; measured
    against the twin's truth, docs/uncertainty.md); without one, the error past the last
    reference (the Type A part is then each target's own: measured, shared it claimed
    0.58 of the difference of two targets' errors where the fit bends across the
    interval, own 0.82).

    ``legs_cov_mm2`` (R, 6, 6): the references' leg lengths' covariance from their own
    centres (:func:`~hexatherm.core.smoothbias.own_leg_covariance`), made here when not
    given (only when the smooth fit was used).
    """
    corr = result.correction
    smooth = corr.smooth
    if smooth is None or not smooth.used:
        return None
    refs = result.session.plan.reference_indices
    q = result.steps.q_mm
    times = result.centres.times_s
    legs_cov = legs_cov_mm2
    if legs_cov is None:
        legs_cov = own_leg_covariance(chain, result.centres.centres_mm, centre_cov_mm2, refs)
    temperatures, legs = result.temperatures, chain.hexapod.legs
    shape, ref_model = None, None
    if temperatures is not None and legs is not None:
        # the log's shape: at the targets against the fit of it, and at the references
        # (its residuals there are not the fit's unexplained error)
        sensitivity = legs.sensitivity_mm_per_K(q[refs[0]])
        log = (temperatures.time_s, temperatures.legs_C, sensitivity)
        shape = log_shape_error(smooth.weights, times[refs], times[corr.target_index], *log)
        ref_model = log_growth(times[refs], *log)
    excess = growth_excess(
        times[refs],
        q[refs] - q[refs[0]],
        result.centres.measurements[refs].astype(float),
        float(smooth.lam[0]),
        legs_cov,
        ref_model,
    )
    m = corr.target_index.size
    growth_cov = np.broadcast_to(excess.cov_mm2, (m, 6, 6))
    if shape is not None:
        growth_cov = growth_cov + shape[:, :, None] * shape[:, None, :]
        excess = dataclasses.replace(excess, shape_um=np.sqrt(np.mean(shape**2, axis=1)) * 1e3)
        # shared within an interval: the excess as vectors (its eigenvectors times the
        # square roots of their values; with the log's shape taken off, what is left
        # varies slowly across an interval), and the log's shape
        values, axes = np.linalg.eigh(excess.cov_mm2)
        root = np.broadcast_to(axes * np.sqrt(np.clip(values, 0.0, None)), (m, 6, 6))
        shared = np.concatenate([root, shape[:, :, None]], axis=2)
    else:
        # without a log the excess is each target's own; past the last reference, the
        # fit's straight continuation
        shared = past_last_error(result, legs_cov)
        growth_cov = growth_cov + shared @ np.swapaxes(shared, 1, 2)
        past_um = np.sqrt(np.sum(shared**2, axis=(1, 2)) / 6) * 1e3
        excess = dataclasses.replace(excess, past_um=past_um)
    by_growth = to_pose_factor(result, chain)
    cov = np.asarray(by_growth @ growth_cov @ np.swapaxes(by_growth, 1, 2))
    interval = np.searchsorted(times[refs], times[corr.target_index], side="right") - 1
    return SmoothExcess(cov, excess, by_growth @ shared, interval.astype(np.intp))


def past_last_error(result: ProcessResult, legs_cov_mm2: FloatArray) -> FloatArray:
    """The smooth fit's own error of the growth at R at each target past the last
    reference, without a log, as two vectors (M, 6, 2; zero for the other targets).

    The references' residuals see the fit between references, not its straight
    continuation past the last one (a natural spline's). With the fit's weights ``W``
    there (the same on every leg: one smoothing) and ``L`` the line through the last two
    references carried on, the error is ``(W - L) G`` (the fit against that line) plus
    the line's own extrapolation error, ``f g''`` with ``f = (t - t0)(t1 - t) / 2``
    (negative) and ``g''`` read by the last inner reference's stencil
    (:func:`~hexatherm.core.curvature.curvature_error`). That stencil reads the curvature
    before the last reference, not past it (a heating switched on settles: its curvature
    turns), so the second is a vector of unknown sign, independent of the first. Each
    with its noise's share off (``max(0, 1 - tr N / |v|^2)``, ``N = sum_j c_j^2 S_j``).
    """
    corr = result.correction
    assert corr.smooth is not None
    refs = result.session.plan.reference_indices
    t, ts = result.centres.times_s[refs], result.centres.times_s[corr.target_index]
    out = np.zeros((ts.size, 6, 2))
    past = np.flatnonzero(ts > t[-1])
    if past.size == 0:
        return out
    q = result.steps.q_mm
    growth = q[refs] - q[refs[0]]
    w = (ts[past] - t[-2]) / (t[-1] - t[-2])
    line = np.zeros((past.size, t.size))
    line[:, -2], line[:, -1] = 1.0 - w, w
    c = corr.smooth.weights[past, 0, :] - line
    first = c @ growth
    noise = (c**2) @ np.trace(legs_cov_mm2, axis1=1, axis2=2)
    total = np.sum(first**2, axis=1)
    share = np.where(total > 0, np.maximum(0.0, 1.0 - noise / np.where(total > 0, total, 1.0)), 0.0)
    out[past, :, 0] = np.sqrt(share)[:, None] * first
    curved = curvature_error(t, growth, legs_cov_mm2, ts[past], line, by_leg=False)
    assert curved.vector_mm is not None
    out[past, :, 1] = curved.vector_mm
    return out


def curvature_excess(
    result: ProcessResult, chain: PoseChain, legs_cov_mm2: FloatArray
) -> tuple[FloatArray, CurvatureError] | None:
    """The interpolation's own error between references carried to the corrected poses,
    each target's error vectors (M, 6, K: mm, deg; its covariance ``F F^T``, and ``F_a F_b^T``
    between two targets of one interval, :attr:`CurvatureError.interval`), and its
    evaluation (:mod:`hexatherm.core.curvature`); None when no target has it.

    Every target interpolated from its neighbouring references (``--interpolation
    linear``, the smooth fit's fallback to it, or one reference: ``before``, ``after``,
    ``nearest``, two targets between two references) gets the interpolation's error of the
    growth at its time, carried by the growth scaling and the FGM to its corrected pose,
    as its own part. With a thermocouple log, the error on a growth shaped as the log
    (:func:`~hexatherm.core.smoothbias.log_shape_error` with the neighbours' weights: the
    log shows a heating switched on between two references, which no curvature of the
    references' growth resolves). Without one, the references' growth around the target
    (:func:`~hexatherm.core.curvature.curvature_error`, with ``legs_cov_mm2`` (R, 6, 6),
    the references' leg lengths' covariance from their own centres:
    :func:`~hexatherm.core.smoothbias.own_leg_covariance`). Where the smooth fit is used
    without a log, its residuals see its error at the references' median spacing: a
    target gets the curvature term only for the part of its interval beyond it (a gap
    between references). With a log the smooth fit's error on the log's shape holds the
    gap (:func:`smooth_excess`): nothing here.
    """
    corr = result.correction
    smooth = corr.smooth
    refs = result.session.plan.reference_indices
    times = result.centres.times_s
    temperatures, legs = result.temperatures, chain.hexapod.legs
    m = corr.target_index.size
    if legs is None or refs.size < 2 or m == 0:
        return None
    q = result.steps.q_mm
    # the references each target's straight line uses, two a target (columns, weights)
    columns, weights = neighbour_weights(corr, refs, q.shape[0])
    seen = 0.0
    if smooth is not None and smooth.used:
        if temperatures is not None:
            return None
        # its residuals see the first-order part and the error at the median spacing:
        # the straight line's curvature term beyond that spacing only
        seen = float(np.median(np.diff(times[refs])))
        line_columns, line_weights = _line_weights(times[refs], times[corr.target_index])
    else:
        line_columns, line_weights = columns, weights
    if temperatures is not None:
        sensitivity = legs.sensitivity_mm_per_K(q[refs[0]])
        log = (temperatures.time_s, temperatures.legs_C, sensitivity)
        e = neighbour_shape_error(columns, weights, times[refs], times[corr.target_index], *log)
        evaluated = np.asarray((weights != 0.0).any(axis=1), dtype=bool)
        e[~evaluated] = 0.0
        # the thermocouples' own noise (Type A, the log's second differences) is in e at
        # the references' times and the target's: not the legs' growth, its share off
        sigma2, _ = reference_scatter(temperatures.time_s, temperatures.legs_C)
        sigma2 = float(sigma2) if np.isfinite(sigma2) else 0.0
        noise = sigma2 * np.sum(np.square(sensitivity)) * (np.sum(weights**2, axis=1) + 1.0)
        total = np.sum(e**2, axis=1)
        share = np.where(total > 0, np.clip(1.0 - noise / np.where(total > 0, total, 1.0), 0, 1), 0)
        # the interval: the reference before the target (the last one past it)
        around = np.searchsorted(times[refs], times[corr.target_index], side="right") - 1
        error = CurvatureError.from_vectors(
            np.sqrt(share)[:, None] * e, np.where(evaluated, around, -1), "log"
        )
    else:
        error = curvature_error(
            times[refs],
            q[refs] - q[refs[0]],
            legs_cov_mm2,
            times[corr.target_index],
            line_weights,
            seen,
            line_columns,
        )
    if not error.evaluated.any():
        return None
    assert error.vector_mm is not None
    factor = to_pose_factor(result, chain)
    f = np.einsum("mpl,ml->mp", factor, error.vector_mm)[:, :, None]
    if error.spread_mm is not None:  # each leg's own part: a column a leg
        f = np.concatenate([f, factor * error.spread_mm[:, None, :]], axis=2)
    return f, error


def to_pose_factor(result: ProcessResult, chain: PoseChain) -> FloatArray:
    """Derivatives (M, 6 pose, 6 legs) of each target's corrected pose (mm, deg) by an
    error of the growth at R at its time (:func:`~hexatherm.core.smoothbias.growth_to_pose`)."""
    corr = result.correction
    q, r0 = result.steps.q_mm, result.session.plan.reference_indices[0]
    return growth_to_pose(
        chain, corr.reference_growth_mm, q[r0], q[corr.target_index], corr.corrected
    )


def neighbour_weights(
    correction: Correction, refs: IntArray, n_steps: int
) -> tuple[IntArray, FloatArray]:
    """The references each target's straight line uses: their columns (M, 2; into
    ``refs``, the one before first) and weights (M, 2; ``1 - w`` and ``w``, 0 for a side not
    used, whose column is then 0)."""
    position = np.zeros(n_steps, dtype=np.intp)
    position[refs] = np.arange(refs.size)
    before, after = correction.before_index, correction.after_index
    w = np.asarray(correction.weight_after, dtype=float)
    columns = np.stack(
        [np.where(before >= 0, position[before], 0), np.where(after >= 0, position[after], 0)],
        axis=1,
    )
    weights = np.stack([np.where(before >= 0, 1.0 - w, 0.0), np.where(after >= 0, w, 0.0)], axis=1)
    # one reference on both sides (never from choose_references): one column, its weights
    # added as the dense weights add them
    same = columns[:, 0] == columns[:, 1]
    weights[same, 0] += weights[same, 1]
    weights[same, 1] = 0.0
    return columns, weights


def _line_weights(
    ref_times_s: FloatArray, target_times_s: FloatArray
) -> tuple[IntArray, FloatArray]:
    """The straight line through the two references around each target in time: their
    columns (M, 2) and weights (M, 2), :func:`neighbour_weights`' form (both 0 outside
    them)."""
    n = ref_times_s.size
    p = np.searchsorted(ref_times_s, target_times_s, side="right") - 1
    pc = np.clip(p, 0, max(n - 2, 0))
    inside = (p >= 0) & (p < n - 1)
    if n >= 2:
        t0, t1 = ref_times_s[pc], ref_times_s[pc + 1]
        inside &= t1 > t0
        with np.errstate(divide="ignore", invalid="ignore"):
            w = (target_times_s - t0) / (t1 - t0)
    else:
        w = np.zeros(target_times_s.size)
    columns = np.where(inside[:, None], np.stack([pc, pc + 1], axis=1), 0)
    weights = np.where(inside[:, None], np.stack([1.0 - w, w], axis=1), 0.0)
    return columns.astype(np.intp), weights
