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
    shift_derivative,
)
from hexatherm.core.geometry import pose_from_transform
from hexatherm.core.propagation import (
    PoseChain,
    TargetJacobian,
    covariance_root,
    reference_scatter,
)
from hexatherm.core.registration import register
from hexatherm.core.smoothbias import leg_derivatives
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
    deceleration : float
        Without a log: how many times steeper the references' growth is over its first
        interval after R0's state than over its second at least (along the growth's
        shape, each slope at 1 standard deviation of its noise; NaN: not read). A
        heating whose response is faster than the references' spacing, switched on
        before R0, shows so; O's growth before R0 is then extrapolated over a bend no
        reference holds.
    jacobian : TargetJacobian, optional
        Without a log: the targets' Jacobian with O's carry as a function of the centres
        of the steps it reads (O, R0's state, the later references), every target's
        corrected pose moved by them through the carried O; its covariance holds the
        carry's noise with its correlation to the correction's (``factor`` holds the
        rest). None with a log (the thermocouples' noise is no centre's).
    """

    factor: FloatArray
    sigma_C: float
    misfit: float
    source: str = "log"
    basis: str = ""
    jacobian: TargetJacobian | None = None
    deceleration: float = float("nan")

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
    result: ProcessResult,
    chain: PoseChain,
    jacobian: TargetJacobian,
    centre_cov_mm2: FloatArray,
    legs_cov_mm2: FloatArray,
    derivatives: tuple[FloatArray, FloatArray] | None = None,
) -> CarryError | None:
    """The carry's error (module docstring); None when nothing was carried.

    ``legs_cov_mm2`` (R, 6, 6) is the references' leg lengths' covariance from their own
    centres (:func:`~hexatherm.core.smoothbias.own_leg_covariance`), ``derivatives`` the
    references' leg lengths' derivatives by their own centres and O's
    (:func:`~hexatherm.core.smoothbias.leg_derivatives`, (R, 6, k, 3) each), made when
    needed and not given."""
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
    derivative: dict[int, FloatArray] = {}
    deceleration = np.nan
    if carry.source == "references":
        derivative, sd_o, model_o, basis, deceleration = _extrapolation_error(
            result, chain, centre_cov_mm2, legs_cov_mm2, derivatives
        )
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
            noise = np.trace(legs_cov_mm2[1:], axis1=1, axis2=2).sum() + (refs.size - 1) * np.trace(
                legs_cov_mm2[0]
            )
            misfit = model_misfit(q[refs[1:]] - q[refs[0]], predicted[1:], float(noise))
        misfit = min(misfit, 1.0) if np.isfinite(misfit) else 1.0
        sd_o = _leg_sd(
            legs.sensitivity_mm_per_K(hexapod.igm(plan.poses[origin])), g_o, sigma_c, misfit
        )
    m = len(result.correction.target_index)
    factor = np.zeros((m, 12, 12))
    # O: its carried frame, the corrected poses' frame
    g_mean = g_o.mean(axis=0)
    steps = STEP_MM * np.concatenate([np.eye(6), -np.eye(6)])  # +- each leg, one batch
    poses = pose_from_transform(carry_motion(hexapod, np.zeros((12, 6)), g_mean + steps))
    by_growth = ((poses[:6] - poses[6:]) / (2 * STEP_MM)).T  # (6 pose, 6 legs)
    unshifted = result.correction.corrected  # the shift's derivative at ~ the same poses
    by_shift = shift_derivative(carry.shift, unshifted, hexapod.convention)
    on_outputs = by_shift @ by_growth  # (M, 6 pose, 6 legs)
    carried_jacobian = None
    if carry.source == "references":
        # the series' noise outside the steps, and the extrapolation's model error: every
        # leg's together (R0's columns are free)
        factor[:, 6:, :6] = on_outputs @ sd_o
        factor[:, 6:, 6] = on_outputs @ model_o
        # O's growth by the centres of the steps it reads: into the targets' Jacobian
        parts = np.zeros((m, len(derivative), 12) + jacobian.jac.shape[3:])
        parts[:, :, 6:] = np.einsum(
            "mpl,slbi->mspbi", on_outputs, np.stack(list(derivative.values()))
        )
        carried_jacobian = jacobian.with_parts(np.array(list(derivative)), parts)
    else:
        factor[:, 6:, :6] = on_outputs * sd_o
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
        moved = carry_centres(
            np.broadcast_to(frame, (12, 4, 4)),
            carry_motion(hexapod, np.repeat(pose, 12, axis=0), steps),
            np.broadcast_to(c, (12, *c.shape)),
        ).reshape(12, -1)
        by_c = (
            (moved[:6] - moved[6:]) / (2 * STEP_MM)
        ).T  # (3k, 6 legs): a growth error of R0's state moves its centres
        k = c.shape[0]
        on_r0 = np.where((jacobian.steps == r0)[..., None, None, None], jacobian.jac, 0.0).sum(
            axis=1
        )  # (M, 12, k, 3)
        factor[:, :, 6:] = on_r0.reshape(m, 12, 3 * k) @ (by_c * sd_r)
    return CarryError(
        factor, sigma_c, misfit, carry.source, basis, carried_jacobian, float(deceleration)
    )


def _divided(times: FloatArray, values: FloatArray, order: int) -> FloatArray:
    """Divided differences (n - order, 6) of ``order`` over consecutive times."""
    dd = values
    for k in range(1, order + 1):
        dd = np.diff(dd, axis=0) / (times[k:] - times[:-k])[:, None]
    return dd


def _divided_band(times: FloatArray, order: int) -> FloatArray:
    """The divided differences' operator as its band (n - order, order + 1): row i holds
    the coefficients of values i .. i + order in :func:`_divided`'s set i (the rows of
    ``_divided(times, np.eye(n), order)`` without their zeros, the same numbers)."""
    band = np.ones((times.size, 1))
    for k in range(1, order + 1):
        width = band.shape[1]
        padded = np.zeros((band.shape[0], width + 1))
        padded[:, :width] = band
        shifted = np.zeros((band.shape[0] - 1, width + 1))
        shifted[:, 1:] = band[1:]
        band = (shifted - padded[:-1]) / (times[k:] - times[:-k])[:, None]
    return band


def _response_term(
    times: FloatArray, values: FloatArray, var: FloatArray, order: int, at_s: float
) -> FloatArray:
    """The divided difference of ``order`` (6,; 2: half the curvature, 3: a sixth of the
    third derivative) of the series at time ``at_s``, as a first-order response of the
    legs to their heating gives it: between changes of the heating, the curvature is
    ``-g' / tau`` and the third derivative ``g' / tau^2``. One error of every leg
    together: the legs' growth has one shape (the first singular vector ``s`` of the
    series' growth, the heating's history being the legs' one), read along it.

    ``g'`` is the slope of the series' interval at ``at_s`` (its first before the first
    member), its square less its noise's; ``1 / (2 tau)`` the regression of the series'
    second divided differences ``k_i`` on its slopes ``v_i`` at the inner members
    (centred), ``r = -sum k_i v_i / sum (v_i^2 - noise)``, its square less its noise's.
    The second divided differences' RMS over the whole series (before) held the heating's
    switching anywhere in it as if it were at O: with the mats switched on after R1 it
    claimed 10x O's growth error there, with them switched on just before R0 0.19x; tied
    to the slope at O, 1.01x and 0.96x (issue 35).

    ``var`` is each value's covariance over the legs (n, 6, 6), the values independent
    of one another; or its variances alone (n, 6: the legs independent). A value's legs
    come from one pose: their errors are correlated (legs 1 and 6 at +0.94 at the
    twins' reference pose), and ``s^T S s`` is 1.27x ``sum s_l^2 S_ll`` there."""
    n = times.size
    if n < 3:
        return np.zeros(6)
    _, _, vt = np.linalg.svd(values, full_matrices=False)
    shape = vt[0] * (-1.0 if vt[0] @ values.sum(axis=0) < 0 else 1.0)  # unit, along growth
    y = values @ shape
    var = np.asarray(var, dtype=float)
    if var.ndim == 3:  # each value's variance along the shape
        on_shape = np.einsum("l,jlm,m->j", shape, var, shape)
    else:
        on_shape = var @ shape**2
    i = int(np.clip(np.searchsorted(times, at_s, side="right") - 1, 0, n - 2))
    h = times[i + 1] - times[i]
    slope = (y[i + 1] - y[i]) / h
    slope2 = max(slope**2 - (on_shape[i] + on_shape[i + 1]) / h**2, 0.0)
    curvature = _divided(times, values, 2) @ shape  # (sets,): g'' / 2 at the inner members
    span = times[2:] - times[:-2]
    centred = (y[2:] - y[:-2]) / span  # the slope there
    spread = float(np.sum(centred**2 - (on_shape[2:] + on_shape[:-2]) / span**2))
    if not spread > 0:
        return np.zeros(6)
    rate = -float(curvature @ centred) / spread  # 1 / (2 tau)
    band = _divided_band(times, 2)
    sets = band.shape[0]
    var_curvature = np.sum(band**2 * on_shape[np.arange(sets)[:, None] + np.arange(3)], axis=1)
    rate2 = max(rate**2 - float(centred**2 @ var_curvature) / spread**2, 0.0)
    if order == 2:
        k = -np.sign(rate) * np.sqrt(rate2 * slope2)
    else:
        k = 4 * rate2 / 6 * np.sqrt(slope2)
    return np.asarray(k * np.sign(slope) * shape, dtype=float)


def _extrapolation_error(
    result: ProcessResult,
    chain: PoseChain,
    centre_cov_mm2: FloatArray,
    legs_cov: FloatArray,
    derivatives: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[dict[int, FloatArray], FloatArray, FloatArray, str, float]:
    """O's mean growth read from the references' series (no log, :class:`ReferenceSeries`)
    as a function of the centres: its derivatives (6 legs, k, 3) by the centres of the
    steps it reads (O, R0's state, the later references used), the factor (6, 6) of its
    noise that no step of the propagation holds, its model error (6,: one error of every
    leg together, the heating's history being the legs' one), one line on what the
    model error rests on, and the series' deceleration over its first two intervals
    (:attr:`CarryError.deceleration`).

    O's growth is ``sum_j W_j (q_j - q_R0)`` over the series (O's measurements' weights
    averaged), scaled to O's legs, R0's state being the line ``s = sum_i l_i R0_i`` of
    R0's measurements. The later references and R0's state are steps of the propagation:
    their derivatives carry O's carry into its Jacobian, correlated with the targets'
    correction through them (R0's state is in both). R0's measurements, each ``V = U_s /
    sum l^2`` (the state's covariance over the line's weights), are ``(l_i / sum l^2) s``
    plus a part ``r_i`` independent of the state: the growth reads ``s`` through
    ``sum_i W_i l_i / sum l^2 - sum W``, and ``sum_i W_i r_i``, of covariance ``V (sum W_i^2
    - (sum W_i l_i)^2 / sum l^2)``, is the noise left outside the steps. The model error is
    the term the line or polynomial misses: the divided difference of the next order at
    O's time along the growth's shape as a first-order response of the legs gives it
    (the slope there over the series' time constant, each beyond its noise:
    :func:`_response_term`), times ``prod_j (t_O - t_j)`` over the members used; with
    too few members to read it, the whole last term (the parabola's departure from the
    line; with two, the whole carry). A heating switched on or off between O and the
    members is not held.
    """
    session, carry = result.session, result.carry
    assert carry is not None and carry.series is not None
    assert session.hexapod.legs is not None
    series = carry.series
    hexapod, legs, plan = session.hexapod, session.hexapod.legs, session.plan
    refs = plan.reference_indices
    ts, g, n0 = series.times_s, series.growth_mm, series.r0_count
    n = ts.size
    w = series.weights.mean(axis=0)
    line = line_at_end(ts[:n0])  # R0's state from its measurements
    spread = float(np.sum(line**2))
    used = np.flatnonzero(w[n0:]) + 1  # the later references read (index in refs)
    read = np.r_[0, used]
    if derivatives is None:  # the references' legs by their own centres and O's
        own, by_o = leg_derivatives(chain, result.centres.centres_mm, refs[read])
    else:
        own, by_o = derivatives[0][read], derivatives[1][read]
    q_r0 = result.steps.q_mm[refs[0]]
    ratio = legs.sensitivity_mm_per_K(hexapod.igm(plan.poses[plan.origin_index][None])[0]) / (
        legs.sensitivity_mm_per_K(q_r0)
    )
    on_state = float(w[:n0] @ line) / spread - float(w.sum())
    later = w[n0 - 1 + used]
    derivative = {
        int(refs[0]): on_state * own[0],
        plan.origin_index: np.einsum("j,jlbi->lbi", later, by_o[1:] - by_o[:1]),
    }
    for j, weight, d in zip(used, later, own[1:], strict=True):
        derivative[int(refs[j])] = weight * d
    derivative = {step: ratio[:, None, None] * d for step, d in derivative.items()}
    # R0's measurements beyond its state: sum_i W_i r_i, through R0's legs
    left = max(float(w[:n0] @ w[:n0]) - float(w[:n0] @ line) ** 2 / spread, 0.0) / spread
    flat = own[0].reshape(6, -1)
    block = np.zeros((flat.shape[1],) * 2)
    for ball, cov in enumerate(np.asarray(centre_cov_mm2, dtype=float)[refs[0]]):
        block[3 * ball : 3 * ball + 3, 3 * ball : 3 * ball + 3] = cov
    outside = ratio[:, None] * ratio[None] * (flat @ (left * block) @ flat.T)
    # each member's legs' covariance (R0's measurements: the state's over the line's
    # weights), then the later references'
    var_series = np.concatenate([np.repeat(legs_cov[:1] / spread, n0, axis=0), legs_cov[1:]])
    models = []
    for t, row in zip(carry.origin_times_s, series.weights, strict=True):
        members = np.flatnonzero(row)
        if t < ts[0]:
            order = members.size  # degree + 1
            if n > order:
                term = _response_term(ts, g, var_series, order, t)
                models.append(term * float(np.prod(t - ts[:order])))
            elif order == 3:
                line2 = extrapolation_weights(ts[:2], np.array([t]))[0]
                models.append(row[:3] @ g[:3] - line2 @ g[:2])
            else:
                models.append(row @ g)
        elif n >= 3:
            term = _response_term(ts, g, var_series, 2, t)
            models.append(term * float(np.prod(t - ts[members])))
        else:
            models.append(np.zeros(6))
    model = np.mean(models, axis=0)
    shape = {1: "line", 2: "parabola"}[series.degree]
    basis = f"the references' noise and what the {shape} through them misses ({n} in the " + (
        "series; the legs a first-order response to their heating: the curvature at O's "
        f"time its slope over the time constant, read over {n - 2} sets beyond their noise)"
        if n > series.degree + 1
        else "series: the whole last term)"
    )
    deceleration = _start_deceleration(ts[n0 - 1 :], g[n0 - 1 :], var_series[n0 - 1 :])
    return derivative, covariance_root(outside), ratio * model, basis, deceleration


#: the slopes' lower (first) and upper (second) bounds, in standard deviations
DECELERATION_Z = 1.0
#: the first interval's slope read only beyond this many of its standard deviations
DECELERATION_SEEN = 3.0
#: the first interval's slope at least this many times the second's: a warning
DECELERATION_WARNING = 1.5


def _start_deceleration(times: FloatArray, values: FloatArray, var: FloatArray) -> float:
    """How many times steeper the series' first interval is than its second at least,
    along the growth's shape: the first's slope less :data:`DECELERATION_Z` of its
    standard deviations over the second's plus as many of its own (its noise from
    ``var``, each member's legs' covariance (n, 6, 6)); NaN with fewer than three
    members or a first slope within :data:`DECELERATION_SEEN` standard deviations.

    Over 20 noise replicas (1 um point noise, steps 200 s apart): legs of two time
    constants (150 s, 3000 s) heated from the start 1.5 or more in 9, the air drifting
    periodically with the legs lagging it in 9, the twin's first-order response (2400 s)
    from the start in 1 (1.63), no heating in 1 (2.07)."""
    if times.size < 3 or not np.all(np.diff(times[:3]) > 0):
        return float("nan")
    shape = np.linalg.svd(values, full_matrices=False)[2][0]
    y = values[:3] @ shape
    noise = np.einsum("l,jlm,m->j", shape, var[:3], shape)
    h = np.diff(times[:3])
    first, second = np.diff(y) / h
    sd = np.sqrt(noise[0] + noise[1]) / h[0]
    if not abs(first) > DECELERATION_SEEN * sd:
        return float("nan")
    low = abs(first) - DECELERATION_Z * sd
    high = (abs(second) if first * second > 0 else 0.0) + DECELERATION_Z * np.sqrt(
        noise[1] + noise[2]
    ) / h[1]
    return float(low / high) if high > 0 else float("inf")


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


def carry_warning(error: CarryError | None) -> str:
    """A warning when the references' growth decelerates sharply after R0 without a log
    (:attr:`CarryError.deceleration`): O's growth is extrapolated over a bend no
    reference holds, a limit of the method; else ``""``."""
    if error is None or not error.deceleration >= DECELERATION_WARNING:
        return ""
    return (
        f"warning: the references' growth is at least {error.deceleration:.2g}x steeper over its "
        "first interval after R0 than over its second and there is no thermocouple log: "
        "a heating faster than the references' spacing was on before R0, and O's growth, "
        "extrapolated back from them, does not hold it (legs of two time constants, 150 "
        "and 3000 s, heated from the start: the corrected Tx and Tz claimed 0.23x and "
        "0.37x of their errors); measure O and R0 after the heating settles, or give the "
        "session its log"
    )


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
        beyond = ""
        if error.jacobian is not None:
            # the references' noise is in the propagation, with R0's in the correction
            basis += " (their noise propagated with the correction's: R0's state is in both)"
            beyond = "beyond the propagation "
        text += (
            f"; its error in u (common): {basis}: {beyond}up to {u[6:9].max() * 1e3:.3g} um, "
            f"{np.deg2rad(u[9:]).max() * 1e6:.3g} urad"
        )
    return text
