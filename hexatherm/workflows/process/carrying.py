"""O and R0 in one thermal state: each measurement carried there, repeats averaged.

The corrected poses refer to R0's thermal state and are expressed relative to O. O is
measured before R0, in the legs' own state then, and repeated measurements of O and R0
(``plan --origin-repeats N --reference0-repeats N``) each in theirs, while the legs may
heat. With a thermocouple log, every measurement of O and R0 is carried to the thermal
state of R0's last measurement (the one nearest the first target, which interpolates from
it) by the leg model (:mod:`hexatherm.core.carry`); R0's measurements are then averaged
(its time that of the last), and O's carried average gives the frame the corrected poses
are expressed in (``OriginCarry.shift``), while the conventional poses keep O as measured.
Without a log, the references' growth stands in for the leg model's (the same correction
the targets get): O is carried by the growth R1 (and R2) measured since R0, on the
straight line (the parabola) through them back to O's time, scaled to O's legs, and R0's
repeats give their straight line in time at the last one's time (their drift is the legs'
growth); with no reference after R0
nothing is carried, and the screen says so. Either way the corrected poses mean one
thing, the pose in R0's (last) thermal state relative to O in that state, as the twin's
truth defines it (:class:`hexatherm.core.twin.TwinSteps`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.carry import carry_centres, carry_motion, leg_growth
from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.plan import find_repeats, without_repeats
from hexatherm.core.registration import register
from hexatherm.io.temperatures import Temperatures
from hexatherm.session import Session
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.measured import StepCentres, registration_weights

__all__ = ["OriginCarry", "RepeatGroup", "carry_and_average"]


@dataclass(frozen=True)
class RepeatGroup:
    """The measurements of one step repeated (O or R0), before they were averaged.

    Attributes
    ----------
    label : str
        The step kept (``O``, ``R0``).
    labels : tuple of str
        Every measurement's step, in plan order (``O``, ``O-2``, ...).
    times_s : ndarray, shape (n,)
    deviations_mm : ndarray, shape (n, k, 3)
        Each measurement's centres (carried to R0's last thermal state when the session
        has a thermocouple log) less their mean (n = 2) or less a straight line in time
        fitted per coordinate (n >= 3: a slow drift of the platform is not noise).
    dof : int
        Degrees of freedom of the deviations, ``3 k (n - 1)`` or ``3 k (n - 2)``.
    cov_mm2 : ndarray, shape (n, k, 3, 3)
        Each measurement's centre covariance from its sphere fit (NaN: none).
    motions : ndarray, shape (n, 4, 4), optional
        The rigid motion (CMM frame) applied to each measurement's centres before they
        are averaged (R0's carry to its last thermal state); None: none (identity).
    weights : ndarray, shape (n,), optional
        Each measurement's weight in the step's centres (``1/n``: the mean; R0's line at
        its last time without a log, :func:`line_at_end`); None: the mean.
    """

    label: str
    labels: tuple[str, ...]
    times_s: FloatArray
    deviations_mm: FloatArray
    dof: int
    cov_mm2: FloatArray
    motions: FloatArray | None = None
    weights: FloatArray | None = None


@dataclass(frozen=True)
class OriginCarry:
    """O carried to R0's thermal state (and R0's measurements to their last one's).

    Attributes
    ----------
    shift : ndarray, shape (4, 4)
        The frame O in R0's thermal state relative to O as measured (its mean): the
        corrected poses are expressed in it.
    origin_growth_mm : ndarray, shape (n_O, 6)
        Each measurement of O: its legs' growth since R0's state (negative: shorter).
    reference_growth_mm : ndarray, shape (n_R0, 6)
        Each measurement of R0: its legs' growth since R0's last measurement.
    state_time_s : float
        Time of R0's thermal state (its last measurement).
    leg_C : ndarray, shape (N, 6)
        The logged leg temperatures at every step of the (reduced) plan (NaN: no log).
    state_leg_C : ndarray, shape (6,)
        The leg temperatures of R0's state (NaN: no log).
    source : str
        ``log``: the growth from the leg model and the thermocouple log; ``references``:
        from the growth the references measured since R0, extrapolated in time
        (:func:`growth_from_references`).
    origin_times_s : ndarray, shape (n_O,)
        Each measurement of O's time.
    series : ReferenceSeries, optional
        Without a log: the references' growth O's growth was read from.
    """

    shift: FloatArray
    origin_growth_mm: FloatArray
    reference_growth_mm: FloatArray
    state_time_s: float
    leg_C: FloatArray
    state_leg_C: FloatArray
    source: str = "log"
    origin_times_s: FloatArray = dataclasses.field(default_factory=lambda: np.zeros(0))
    series: ReferenceSeries | None = None

    @property
    def warming_K(self) -> float:
        """The legs' mean warming from O's (first) measurement to R0's state, K (NaN
        without a log)."""
        return float(np.mean(self.state_leg_C - self.leg_C[0]))


def logged_legs(temperatures: Temperatures, times_s: FloatArray) -> FloatArray:
    """Leg temperatures (n, 6) at ``times_s`` from the log, joined by straight lines."""
    t = np.asarray(times_s, dtype=float)
    return np.column_stack(
        [np.interp(t, temperatures.time_s, temperatures.legs_C[:, i]) for i in range(6)]
    )


def _deviations(times: FloatArray, values: FloatArray) -> tuple[FloatArray, int]:
    """Each value less the mean (n = 2) or a straight line in time (n >= 3)."""
    n = len(times)
    if n >= 3 and np.ptp(times) > 0:
        design = np.column_stack([np.ones(n), times - times.mean()])
        coef, *_ = np.linalg.lstsq(design, values.reshape(n, -1), rcond=None)
        return (values.reshape(n, -1) - design @ coef).reshape(values.shape), values[0].size * (
            n - 2
        )
    return values - values.mean(axis=0), values[0].size * (n - 1)


def line_at_end(times_s: FloatArray) -> FloatArray:
    """Weights (n,) giving the straight line fitted in time through n values at the last
    time: ``1/n + (t_n - mean) (t_i - mean) / Sxx`` (the mean's when the times coincide).

    >>> line_at_end(np.array([0.0, 1.0])).tolist()
    [0.0, 1.0]
    >>> line_at_end(np.array([0.0, 1.0, 2.0])).round(3).tolist()
    [-0.167, 0.333, 0.833]
    """
    t = np.asarray(times_s, dtype=float)
    d = t - t.mean()
    sxx = float(np.sum(d**2))
    if not sxx > 0:
        return np.full(t.size, 1.0 / t.size)
    return np.asarray(1.0 / t.size + d[-1] * d / sxx, dtype=float)


def extrapolation_weights(ref_times_s: FloatArray, at_s: FloatArray) -> FloatArray:
    """Weights (n_at, n) of the polynomial through n references' values (Lagrange: a
    straight line through two, a parabola through three) at times ``at_s``.

    >>> extrapolation_weights(np.array([1.0, 2.0]), np.array([0.0])).tolist()
    [[2.0, -1.0]]
    >>> extrapolation_weights(np.array([1.0, 2.0, 3.0]), np.array([0.0])).tolist()
    [[3.0, -3.0, 1.0]]
    """
    tr = np.asarray(ref_times_s, dtype=float)
    at = np.asarray(at_s, dtype=float)[:, None]
    out = np.ones((at.shape[0], tr.size))
    for j in range(tr.size):
        for m in range(tr.size):
            if m != j:
                out[:, j] *= (at[:, 0] - tr[m]) / (tr[j] - tr[m])
    return out


def extrapolation_degree(ref_times_s: FloatArray, growth_mm: FloatArray) -> int:
    """The polynomial's degree to take the references' growth back to O's time: 1 (the
    line through R0 and R1) with two references, 2 (the parabola through R0, R1, R2) with
    three; with four or more, the one that predicts each reference from the next two
    (three), backwards as O is reached, with the smaller RMS error over the references.

    >>> t = np.arange(6.0)
    >>> int(extrapolation_degree(t, np.outer(1 - np.exp(-t / 3), np.ones(6))))  # a curve
    2
    >>> int(extrapolation_degree(t, np.outer(t + [0, 1, -1, 1, -1, 1], np.ones(6))))  # noise
    1
    """
    t = np.asarray(ref_times_s, dtype=float)
    g = np.asarray(growth_mm, dtype=float)
    if t.size < 4:
        return min(t.size - 1, 2)
    miss: dict[int, list[FloatArray]] = {1: [], 2: []}
    for j in range(t.size - 3):
        for degree in (1, 2):
            nxt = slice(j + 1, j + 2 + degree)
            predicted = extrapolation_weights(t[nxt], t[j : j + 1]) @ g[nxt]
            miss[degree].append(predicted[0] - g[j])
    rms = {d: float(np.sqrt(np.mean(np.square(m)))) for d, m in miss.items()}
    return 2 if rms[2] < rms[1] else 1


def series_weights(series_s: FloatArray, at_s: FloatArray, degree: int) -> FloatArray:
    """Weights (n_at, n) of the references' growth series (times ``series_s``) at times
    ``at_s``: between two references the straight line through them (as a target's
    growth), before the first the polynomial of ``degree`` through the first ``degree +
    1`` (after the last, the line through the last two).

    >>> series_weights(np.array([1.0, 2.0, 3.0]), np.array([0.0, 1.5]), 1).tolist()
    [[2.0, -1.0, 0.0], [0.5, 0.5, 0.0]]
    """
    ts = np.asarray(series_s, dtype=float)
    at = np.asarray(at_s, dtype=float)
    out = np.zeros((at.size, ts.size))
    for e, t in enumerate(at):
        if t < ts[0]:
            out[e, : degree + 1] = extrapolation_weights(ts[: degree + 1], np.array([t]))[0]
        elif t >= ts[-1]:
            out[e, -2:] = extrapolation_weights(ts[-2:], np.array([t]))[0]
        else:
            i = int(np.searchsorted(ts, t, side="right") - 1)
            out[e, i : i + 2] = extrapolation_weights(ts[i : i + 2], np.array([t]))[0]
    return out


@dataclass(frozen=True)
class ReferenceSeries:
    """The references' growth series O's growth is read from without a log.

    Attributes
    ----------
    times_s : ndarray, shape (n,)
        Every measurement of R0, then the references after it.
    growth_mm : ndarray, shape (n, 6)
        Their legs' growth since R0's state (``q - q_R0``, R0 its line at its last time).
    weights : ndarray, shape (n_O, n)
        O's measurements' growth (at R's legs) is ``weights @ growth_mm``.
    r0_count : int
        How many of the series are measurements of R0.
    degree : int
        The polynomial's degree before the first (:func:`extrapolation_degree`).
    """

    times_s: FloatArray
    growth_mm: FloatArray
    weights: FloatArray
    r0_count: int
    degree: int


def growth_from_references(
    session: Session,
    centres: StepCentres,
    weights: FloatArray | None,
    origin: tuple[int, ...],
    r0: tuple[int, ...],
    r0_state_mm: FloatArray,
    later: tuple[int, ...],
) -> tuple[FloatArray, ReferenceSeries]:
    """Growth (n_O, 6) of O's legs at O's measurements since R0's state, from the
    references alone (no thermocouple log), and the series it rests on: the growth since
    R0's state (``r0_state_mm``, R0's centres in it) of every measurement of R0 and of
    the references after it (poses relative to O, its measurements' mean), read at each
    O's time (:func:`series_weights`: between neighbours a straight line, before the
    first the line or parabola of :func:`extrapolation_degree`), scaled to O's commanded
    legs by the leg model (:meth:`~hexatherm.core.thermal.LegThermalModel.scale_growth`).
    """
    hexapod, legs, plan = session.hexapod, session.hexapod.legs, session.plan
    assert legs is not None
    steps = np.array(r0 + later, dtype=np.intp)
    c = np.concatenate(
        [
            centres.centres_mm[list(origin)].mean(axis=0)[None],
            r0_state_mm[None],
            centres.centres_mm[steps],
        ]
    )
    w = None
    if weights is not None:
        w = np.concatenate([weights[[origin[0], r0[0]]], weights[steps]])
    frames = register(c, session.balls.centres_mm, w).platform2cmm
    poses = pose_from_transform(invert_transform(frames[0]) @ frames[1:], hexapod.convention)
    q = hexapod.igm(poses)  # R0's state, then the series
    ts = centres.times_s[steps]
    growth = q[1:] - q[0]
    if len(r0) == 1:
        growth[0] = 0.0  # R0 is its state
    degree = extrapolation_degree(ts, growth)
    at = centres.times_s[list(origin)]
    wts = series_weights(ts, at, degree)
    q_o = hexapod.igm(plan.poses[origin[0]][None])[0]
    g_o = legs.scale_growth(wts @ growth, q[0], q_o)
    return np.asarray(g_o, dtype=float), ReferenceSeries(ts, growth, wts, len(r0), degree)


def carry_and_average(
    session: Session, centres: StepCentres, temperatures: Temperatures | None
) -> tuple[Session, StepCentres, tuple[RepeatGroup, ...], OriginCarry | None]:
    """Carry O and R0 to R0's (last) thermal state and average the repeats.

    With a thermocouple log, each measurement of O and R0 is carried by the leg model's
    growth; R0's centres are the mean of its carried ones. Without a log, R0's repeats are
    a straight line in time per centre coordinate taken at the last one's time
    (:func:`line_at_end`: its drift is the legs' growth), and O is carried by the
    references' growth (:func:`growth_from_references`) when there is a reference after
    R0. Each ball's centre of an averaged step is a weighted sum of its centres, its
    covariance the sum of theirs times the squared weights (fits), its ``u_um`` likewise
    (files); R0's time is its last measurement's when carried (the mean of the times
    otherwise), O's the mean of its times. O's centres stay the mean of the measured ones
    (the conventional poses' frame); its carry is ``OriginCarry.shift``. The session's
    plan loses the repeats (:func:`hexatherm.core.plan.without_repeats`). Returns the
    session and centres unchanged, no group and no carry when nothing is repeated and
    nothing can be carried.
    """
    plan = session.plan
    repeats = find_repeats(plan)
    legs = session.hexapod.legs
    logged = temperatures is not None and legs is not None and bool(repeats.reference0)
    later = [int(i) for i in plan.reference_indices if int(i) not in repeats.reference0]
    series_t = centres.times_s[list(repeats.reference0) + later]
    by_references = (
        not logged
        and legs is not None
        and bool(repeats.reference0)
        and bool(later)
        and bool(np.all(np.isfinite(series_t)))
        and bool(np.all(np.diff(series_t) > 0))  # a burst (one time): nothing to read
    )
    carry = logged or by_references
    if not repeats.any and not carry:
        return session, centres, (), None
    c, t, u = centres.centres_mm.copy(), centres.times_s.copy(), centres.u_um.copy()
    cov = None if centres.cov_mm2 is None else centres.cov_mm2.copy()
    count = np.ones(len(plan.labels), dtype=np.intp)
    spread = np.ones(len(plan.labels))
    weights = registration_weights(centres.u_um)
    growth: dict[int, FloatArray] = {}
    motions: dict[int, FloatArray] = {}
    state_time = float(centres.times_s[repeats.reference0[-1]]) if repeats.reference0 else np.nan
    if logged:
        assert temperatures is not None and legs is not None
        idx = np.array(repeats.origin + repeats.reference0, dtype=np.intp)
        temps = logged_legs(temperatures, centres.times_s[idx])
        state = logged_legs(temperatures, np.array([state_time]))[0]
        growth.update(
            zip(
                idx.tolist(),
                leg_growth(legs, session.hexapod.igm(plan.poses[idx]), temps, state),
                strict=True,
            )
        )
        motions.update(_world_motions(session, centres, weights, idx, growth))
    groups = []
    for steps in (repeats.origin, repeats.reference0):
        idx = np.asarray(steps, dtype=np.intp)
        if not idx.size:
            continue
        n, first = len(idx), int(idx[0])
        is_origin = first == plan.origin_index
        times = centres.times_s[idx]
        measured = centres.centres_mm[idx]  # (n, k, 3)
        world = np.stack([motions.get(int(i), np.eye(4)) for i in idx])
        carried = carry_centres(np.eye(4), world, measured) if logged else measured
        # R0 without a log: its line in time at its last measurement (its state)
        w = line_at_end(times) if by_references and not is_origin else np.full(n, 1.0 / n)
        if n > 1:
            deviations, dof = _deviations(times, carried)
            one_cov = (
                np.full(measured.shape + (3,), np.nan)
                if centres.cov_mm2 is None
                else centres.cov_mm2[idx]
            )
            groups.append(
                RepeatGroup(
                    plan.labels[first],
                    tuple(plan.labels[i] for i in idx),
                    times,
                    deviations,
                    int(dof),
                    one_cov,
                    world if logged and not is_origin else None,
                    w,
                )
            )
        c[first] = np.einsum("i,ikj->kj", w, measured if is_origin else carried)
        t[first] = state_time if carry and not is_origin else times.mean()
        u[first] = np.sqrt(np.einsum("i,ik->k", w**2, centres.u_um[idx] ** 2))
        if cov is not None and centres.cov_mm2 is not None:
            cov[first] = np.einsum("i,ikab->kab", w**2, centres.cov_mm2[idx])
        count[first] = n
        spread[first] = float(np.sum(w**2))
    origin_carry = None
    if carry:
        o_idx = np.asarray(repeats.origin, dtype=np.intp)
        if by_references:
            g_o, series = growth_from_references(
                session,
                centres,
                weights,
                repeats.origin,
                repeats.reference0,
                c[repeats.reference0[0]],
                tuple(later),
            )
            growth.update(zip(o_idx.tolist(), g_o, strict=True))
            growth.update((int(i), np.zeros(6)) for i in repeats.reference0)
            motions.update(_world_motions(session, centres, weights, o_idx, growth))
        measured = centres.centres_mm[o_idx]
        world = np.stack([motions[int(i)] for i in o_idx])
        pair = register(
            np.stack([measured.mean(axis=0), carry_centres(np.eye(4), world, measured).mean(0)]),
            session.balls.centres_mm,
            None if weights is None else weights[plan.origin_index][None],
        ).platform2cmm
        shift = invert_transform(pair[0]) @ pair[1]
        if logged:
            assert temperatures is not None
            leg_c = logged_legs(temperatures, t)
            state_c = logged_legs(temperatures, np.array([state_time]))[0]
        else:
            leg_c, state_c = np.full((len(t), 6), np.nan), np.full(6, np.nan)
        origin_carry = OriginCarry(
            shift,
            np.array([growth[i] for i in repeats.origin]),
            np.array([growth[i] for i in repeats.reference0]),
            state_time,
            leg_c,
            state_c,
            "log" if logged else "references",
            centres.times_s[o_idx],
            series if by_references else None,
        )
    reduced, keep = without_repeats(plan, repeats) if repeats.any else (plan, np.arange(len(t)))
    averaged = StepCentres(
        c[keep],
        t[keep],
        centres.time_kind,
        u[keep],
        None if cov is None else cov[keep],
        count[keep],
        centres.time_aware,
        None if centres.cov_from_file is None else centres.cov_from_file[keep],
        spread[keep],
    )
    if origin_carry is not None:
        origin_carry = dataclasses.replace(origin_carry, leg_C=origin_carry.leg_C[keep])
    return dataclasses.replace(session, plan=reduced), averaged, tuple(groups), origin_carry


def _world_motions(
    session: Session,
    centres: StepCentres,
    weights: FloatArray | None,
    idx: npt.NDArray[np.intp],
    growth: dict[int, FloatArray],
) -> dict[int, FloatArray]:
    """The rigid motions (CMM frame) carrying the measurements ``idx`` by their growth:
    ``F M F^-1`` (:func:`~hexatherm.core.carry.carry_motion`), identity where none."""
    plan = session.plan
    g = np.array([growth[int(i)] for i in idx])
    frames = register(
        centres.centres_mm[idx],
        session.balls.centres_mm,
        None if weights is None else weights[idx],
    ).platform2cmm
    motion = carry_motion(session.hexapod, plan.poses[idx], g)
    world = frames @ motion @ invert_transform(frames)
    world[~np.any(g != 0, axis=1)] = np.eye(4)  # R0's last: exactly where it is
    return dict(zip(idx.tolist(), world, strict=True))
