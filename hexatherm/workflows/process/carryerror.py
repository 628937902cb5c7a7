"""The error of carrying O and R0 to R0's thermal state, in the poses' u (issue 35).

:mod:`~hexatherm.workflows.process.carrying` carries every measurement of O and R0 by the
growth the leg model gives from the thermocouple log, ``s(q) (T(t) - T(t_state))``. Two
things make that growth wrong, and both go into the common part of every corrected pose's
u (they move all targets together):

* the thermocouples' noise: each logged temperature scatters by ``sigma_T``, a Type A
  evaluation from the log itself (each sample against the straight line through its two
  neighbours, :func:`~hexatherm.core.propagation.reference_scatter`, pooled over the legs;
  the heating's curvature between neighbours adds to it, on the safe side); the carry of
  a measurement reads two temperatures, its own and the state's;
* the leg model's own error (lag behind the thermocouples, gradients along a leg): how far
  the same model misses the growth the references measured since R0, relative to the
  growth it predicts (:func:`~hexatherm.core.carry.model_misfit`, the references' noise
  included), times the carried growth, fully correlated over the measurements.

Each is a growth error per leg; it moves O's carried frame (the corrected poses' frame)
and R0's carried centres (the growth at every reference), carried to the outputs through
the shift's derivative and the propagation's Jacobian of R0's centres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexatherm.core.carry import (
    carry_centres,
    carry_motion,
    leg_growth,
    model_misfit,
    shift_jacobian,
)
from hexatherm.core.geometry import pose_from_transform
from hexatherm.core.propagation import PoseChain, TargetJacobian, reference_scatter
from hexatherm.core.registration import register
from hexatherm.core.smoothbias import own_leg_covariance
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.carrying import extrapolation_weights, line_at_end
from hexatherm.workflows.process.pipeline import ProcessResult

__all__ = ["CarryError", "carry_error"]

#: growth step of the carry's derivatives, mm
STEP_MM = 1e-4


@dataclass(frozen=True)
class CarryError:
    """The carry's error and its effect on the outputs.

    Attributes
    ----------
    factor : ndarray, shape (M, 12, 12)
        ``F`` with the outputs' added covariance ``F_a F_b^T`` between targets a and b
        (common to all targets): mm and deg.
    sigma_C : float
        The thermocouples' noise from the log (Type A), K (NaN: no log).
    misfit : float
        The leg model's relative misfit of the references' growth (NaN: no log).
    source : str
        How O was carried (:class:`~hexatherm.workflows.process.carrying.OriginCarry`).
    basis : str
        Without a log: what the extrapolation's error rests on (one line).
    """

    factor: FloatArray
    sigma_C: float
    misfit: float
    source: str = "log"
    basis: str = ""

    def covariance(self) -> FloatArray:
        """Added covariance (M, 12, 12) of every target's outputs."""
        return np.asarray(np.einsum("myp,mzp->myz", self.factor, self.factor))


def _leg_sd(
    sensitivity: FloatArray, growth: FloatArray, sigma_c: float, misfit: float
) -> FloatArray:
    """Standard deviation (6,) of the mean carried growth of n measurements: the
    thermocouples' noise of their own times averaged (``1/n``), the state's reading
    shared by every moved one, the model's error fully correlated."""
    n = max(len(growth), 1)
    moved = np.any(growth != 0, axis=1)
    own = sensitivity**2 * sigma_c**2 * moved.sum() / n**2
    state = (sensitivity * sigma_c * moved.sum() / n) ** 2
    model = (misfit * np.sqrt(np.mean(growth**2, axis=0))) ** 2
    return np.asarray(np.sqrt(own + state + model), dtype=float)


def carry_error(
    result: ProcessResult, chain: PoseChain, jacobian: TargetJacobian, centre_cov_mm2: FloatArray
) -> CarryError | None:
    """The carry's error (module docstring); None when nothing was carried."""
    carry = result.carry
    session = result.session
    legs, hexapod = session.hexapod.legs, session.hexapod
    if carry is None or legs is None:
        return None
    plan = session.plan
    refs = plan.reference_indices
    q = result.steps.q_mm
    origin = plan.origin_index
    g_o = carry.origin_growth_mm
    sigma_c, misfit, basis = np.nan, np.nan, ""
    model_o = np.zeros(6)
    if carry.source == "references":
        sd_o, model_o, basis = _extrapolation_error(result, chain, centre_cov_mm2)
    else:
        if result.temperatures is None:
            return None
        log = result.temperatures
        sigma2, _ = reference_scatter(log.time_s, log.legs_C)
        sigma_c = float(np.sqrt(sigma2)) if np.isfinite(sigma2) else 0.0
        predicted = leg_growth(
            legs, hexapod.igm(plan.poses[refs]), carry.leg_C[refs], carry.state_leg_C
        )
        misfit = 1.0
        if refs.size > 1:
            # the references' growth is measured with their noise and R0's: not the model's
            legs_cov = own_leg_covariance(chain, result.centres.centres_mm, centre_cov_mm2, refs)
            noise = np.trace(legs_cov[1:], axis1=1, axis2=2).sum() + (refs.size - 1) * np.trace(
                legs_cov[0]
            )
            misfit = model_misfit(q[refs[1:]] - q[refs[0]], predicted[1:], float(noise))
        misfit = min(misfit, 1.0) if np.isfinite(misfit) else 1.0
        sd_o = _leg_sd(
            legs.sensitivity_mm_per_K(hexapod.igm(plan.poses[origin])), g_o, sigma_c, misfit
        )
    m = len(result.correction.target_index)
    factor = np.zeros((m, 12, 12))
    # O: its carried frame, the corrected poses' frame
    zero = np.zeros((1, 6))
    g_mean = g_o.mean(axis=0)
    by_growth = np.stack(
        [
            (
                pose_from_transform(carry_motion(hexapod, zero, g_mean + STEP_MM * e)[0])
                - pose_from_transform(carry_motion(hexapod, zero, g_mean - STEP_MM * e)[0])
            )
            / (2 * STEP_MM)
            for e in np.eye(6)
        ],
        axis=1,
    )  # (6 pose, 6 legs)
    unshifted = result.correction.corrected  # the shift's derivative at ~ the same poses
    _, by_shift = shift_jacobian(carry.shift, unshifted, hexapod.convention)
    factor[:, 6:, :6] = by_shift @ (by_growth * sd_o)
    if carry.source == "references":
        # the extrapolation's model error: every leg's together (R0's columns are free)
        factor[:, 6:, 6] = by_shift @ (by_growth @ model_o)
    # R0: its carried centres (all but the last measurement moved)
    g_r = carry.reference_growth_mm
    if carry.source == "log" and np.any(g_r != 0):
        r0 = int(refs[0])
        sd_r = _leg_sd(
            legs.sensitivity_mm_per_K(hexapod.igm(plan.poses[r0])),
            g_r,
            sigma_c,
            misfit,
        )
        c = result.centres.centres_mm[r0]
        frame = register(c[None], session.balls.centres_mm).platform2cmm
        pose = plan.poses[r0][None]
        by_c = np.stack(
            [
                (
                    carry_centres(frame, carry_motion(hexapod, pose, STEP_MM * e[None]), c[None])
                    - carry_centres(frame, carry_motion(hexapod, pose, -STEP_MM * e[None]), c[None])
                )[0].reshape(-1)
                / (2 * STEP_MM)
                for e in np.eye(6)
            ],
            axis=1,
        )  # (3k, 6 legs): a growth error of R0's state moves its centres
        k = c.shape[0]
        on_r0 = np.where((jacobian.steps == r0)[..., None, None, None], jacobian.jac, 0.0).sum(
            axis=1
        )  # (M, 12, k, 3)
        factor[:, :, 6:] = on_r0.reshape(m, 12, 3 * k) @ (by_c * sd_r)
    return CarryError(factor, sigma_c, misfit, carry.source, basis)


def _divided(times: FloatArray, values: FloatArray, order: int) -> FloatArray:
    """Divided differences (n - order, 6) of ``order`` over consecutive times."""
    dd = values
    for k in range(1, order + 1):
        dd = np.diff(dd, axis=0) / (times[k:] - times[:-k])[:, None]
    return dd


def _beyond_noise(times: FloatArray, values: FloatArray, var: FloatArray, order: int) -> FloatArray:
    """The divided differences' RMS of ``order`` (6,) beyond what the values' noise (their
    variances ``var`` (n, 6), independent) gives them: ``sqrt(max(0, mean dd^2 - mean
    var dd))``, signed as their mean."""
    dd = _divided(times, values, order)
    operator = _divided(times, np.eye(times.size), order)  # (n - order, n)
    noise = np.mean(operator**2 @ var, axis=0)
    rms2 = np.maximum(np.mean(dd**2, axis=0) - noise, 0.0)
    return np.asarray(np.sqrt(rms2) * np.sign(np.mean(dd, axis=0)), dtype=float)


def _extrapolation_error(
    result: ProcessResult, chain: PoseChain, centre_cov_mm2: FloatArray
) -> tuple[FloatArray, FloatArray, str]:
    """O's mean growth read from the references' series (no log, :class:`ReferenceSeries`):
    its noise's standard deviation per leg (6,), its model error (6,: one error of every
    leg together, the heating's history being the legs' one), and one line on what the
    model error rests on.

    O's growth is ``sum_j W_j (q_j - q_R0)`` over the series (O's measurements' weights
    averaged), scaled to O's legs, R0's state being the line ``sum_i l_i q_i`` of R0's
    measurements: its noise ``sum_i (W_i - l_i sum W)^2 var q_i`` over R0's measurements
    plus ``sum_j W_j^2 var q_j`` over the later references (their own centres, O held
    fixed; one measurement of R0 has R0's state's variance over ``sum l^2``). Its model
    error is the term the line or polynomial misses: the RMS divided difference of the
    next order over consecutive members of the series, beyond what their noise gives it
    (in squares), times ``prod_j (t_O - t_j)`` over the members used; with too few
    members to read it, the whole last term (the parabola's departure from the line; with
    two, the whole carry). Added to the outputs as independent of the correction's own
    noise (R0's state is in both: left out, on the safe side).
    """
    session, carry = result.session, result.carry
    assert carry is not None and carry.series is not None
    assert session.hexapod.legs is not None
    series = carry.series
    hexapod, legs, plan = session.hexapod, session.hexapod.legs, session.plan
    refs = plan.reference_indices
    ts, g, n0 = series.times_s, series.growth_mm, series.r0_count
    n = ts.size
    legs_cov = own_leg_covariance(chain, result.centres.centres_mm, centre_cov_mm2, refs)
    var = np.diagonal(legs_cov, axis1=1, axis2=2)  # (R, 6): R0's state, then the later
    line = line_at_end(ts[:n0])  # R0's state from its measurements
    var_single = var[0] / float(np.sum(line**2))
    var_series = np.concatenate([np.repeat(var_single[None], n0, axis=0), var[1:]])
    w = series.weights.mean(axis=0)
    # on R0's measurements: their own weight less their share of R0's state
    on = np.concatenate([w[:n0] - w.sum() * line, w[n0:]])
    noise = (on[:, None] ** 2 * var_series).sum(axis=0)
    models = []
    for t, row in zip(carry.origin_times_s, series.weights, strict=True):
        used = np.flatnonzero(row)
        if t < ts[0]:
            order = used.size  # degree + 1
            if n > order:
                rms = _beyond_noise(ts, g, var_series, order)
                models.append(rms * float(np.prod(t - ts[:order])))
            elif order == 3:
                line2 = extrapolation_weights(ts[:2], np.array([t]))[0]
                models.append(row[:3] @ g[:3] - line2 @ g[:2])
            else:
                models.append(row @ g)
        elif n >= 3:
            rms = _beyond_noise(ts, g, var_series, 2)
            models.append(rms * float(np.prod(t - ts[used])))
        else:
            models.append(np.zeros(6))
    model = np.mean(models, axis=0)
    q_r0 = result.steps.q_mm[refs[0]]
    ratio = legs.sensitivity_mm_per_K(hexapod.igm(plan.poses[plan.origin_index][None])[0]) / (
        legs.sensitivity_mm_per_K(q_r0)
    )
    shape = {1: "line", 2: "parabola"}[series.degree]
    basis = f"the references' noise and what the {shape} through them misses ({n} in the " + (
        f"series, the next divided differences' RMS beyond their noise over "
        f"{n - series.degree - 1} sets)"
        if n > series.degree + 1
        else "series: the whole last term)"
    )
    return (
        np.asarray(ratio * np.sqrt(noise), dtype=float),
        np.asarray(ratio * model, dtype=float),
        basis,
    )


def add_common(
    error: CarryError | None,
    covariance: FloatArray,
    linear: FloatArray,
    common_u: FloatArray,
    own_u: FloatArray,
    pairs: FloatArray | None,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray | None]:
    """The carry's error added to the outputs' covariance (reported and linear), to the
    covariance between targets (12, M, M), if any, and to the common part: the common
    share of the linear variance, with the carry's, applied to the reported u (as
    :func:`~hexatherm.workflows.process.uncertainty.shared_parts` applies it)."""
    if error is None:
        return covariance, linear, common_u, own_u, pairs
    added = error.covariance()
    extra = np.diagonal(added, axis1=1, axis2=2)  # (M, 12)
    before = common_u**2 + own_u**2
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(before > 0, common_u**2 / np.where(before > 0, before, 1.0), 0.0)
    lin = np.diagonal(linear, axis1=1, axis2=2)
    new_lin = lin + extra
    with np.errstate(invalid="ignore", divide="ignore"):
        new_share = np.where(
            new_lin > 0, (share * lin + extra) / np.where(new_lin > 0, new_lin, 1.0), 0.0
        )
    covariance = covariance + added
    u = np.sqrt(np.clip(np.diagonal(covariance, axis1=1, axis2=2), 0.0, None))
    if pairs is not None:
        pairs = pairs + np.einsum("ayp,byp->yab", error.factor, error.factor)
    common = u * np.sqrt(np.clip(new_share, 0.0, 1.0))
    own = u * np.sqrt(np.clip(1.0 - new_share, 0.0, 1.0))
    return covariance, linear + added, common, own, pairs


def carry_line(result: ProcessResult, error: CarryError | None) -> str:
    """One screen line: how O (and R0's repeats) were carried to R0's state, and the
    carry's error in u; or why nothing was carried."""
    carry = result.carry
    plan = result.session.plan
    if carry is None:
        if plan.reference_indices.size and result.session.hexapod.legs is not None:
            return (
                "warning: O not carried to R0's thermal state (no thermocouple log and no "
                "reference after R0): the corrected poses refer to O in its own state"
            )
        return ""
    g = carry.origin_growth_mm * 1e3
    repeats = {group.label: len(group.labels) for group in result.repeats}
    r0 = repeats.get(plan.labels[plan.reference_indices[0]], 1)
    if carry.source == "references":
        text = (
            "O carried to R0's thermal state by the references' growth (no thermocouple "
            "log: the growth since R0 of R0's measurements and the references after it, "
            "read at O's time, between two of them on the line through them, before the "
            f"first on a line or parabola; scaled to O's legs; O's growth {g.min():+.3g} to "
            f"{g.max():+.3g} um)"
        )
        if r0 > 1:
            text += (
                f"; R0's {r0} measurements fitted by a straight line in time, taken at the "
                "last one's"
            )
    else:
        text = (
            f"O carried to R0's thermal state by the leg model and the thermocouple log (R0's "
            f"legs {carry.warming_K:+.3f} K warmer than O's on average; O's growth "
            f"{g.min():+.3g} to {g.max():+.3g} um)"
        )
        if r0 > 1:
            text += f"; R0's {r0} measurements carried to the last one's state and averaged"
    if error is not None:
        u = np.sqrt(np.diagonal(error.covariance(), axis1=1, axis2=2)).max(axis=0)
        if error.source == "references":
            basis = error.basis
        else:
            basis = (
                f"thermocouple noise {error.sigma_C * 1e3:.3g} mK (Type A from the log), "
                f"leg model gain error {error.misfit:.0%} beyond the references' noise"
            )
        text += (
            f"; its error in u (common): {basis}: up to {u[6:9].max() * 1e3:.3g} um, "
            f"{np.deg2rad(u[9:]).max() * 1e6:.3g} urad"
        )
    return text
