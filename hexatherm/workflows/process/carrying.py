"""O and R0 in one thermal state: each measurement carried there, repeats averaged.

The corrected poses refer to R0's thermal state and are expressed relative to O. O is
measured before R0, in the legs' own state then, and repeated measurements of O and R0
(``plan --origin-repeats N --reference0-repeats N``) each in theirs, while the legs may
heat. With a thermocouple log, every measurement of O and R0 is carried to the thermal
state of R0's last measurement (the one nearest the first target, which interpolates from
it) by the leg model (:mod:`hexatherm.core.carry`); R0's measurements are then averaged
(its time that of the last), and O's carried average gives the frame the corrected poses
are expressed in (``OriginCarry.shift``), while the conventional poses keep O as measured.
Without a log nothing is carried: each step's measurements are averaged at their mean time,
and the screen says so.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from hexatherm.core.carry import carry_centres, carry_motion, leg_growth
from hexatherm.core.geometry import invert_transform
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
    """

    label: str
    labels: tuple[str, ...]
    times_s: FloatArray
    deviations_mm: FloatArray
    dof: int
    cov_mm2: FloatArray
    motions: FloatArray | None = None


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
        The logged leg temperatures at every step of the (reduced) plan.
    state_leg_C : ndarray, shape (6,)
        The leg temperatures of R0's state.
    """

    shift: FloatArray
    origin_growth_mm: FloatArray
    reference_growth_mm: FloatArray
    state_time_s: float
    leg_C: FloatArray
    state_leg_C: FloatArray

    @property
    def warming_K(self) -> float:
        """The legs' mean warming from O's (first) measurement to R0's state, K."""
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


def carry_and_average(
    session: Session, centres: StepCentres, temperatures: Temperatures | None
) -> tuple[Session, StepCentres, tuple[RepeatGroup, ...], OriginCarry | None]:
    """Carry O and R0 to R0's (last) thermal state and average the repeats.

    Each ball's centre of an averaged step is the mean of its (carried) centres, its
    covariance the sum of theirs over ``n^2`` (fits), its ``u_um`` ``sqrt(sum u^2) / n``
    (files); R0's time is its last measurement's when carried (the mean of the times
    otherwise), O's the mean of its times. O's centres stay the mean of the measured ones
    (the conventional poses' frame); its carry is ``OriginCarry.shift``. The session's
    plan loses the repeats (:func:`hexatherm.core.plan.without_repeats`). Returns the
    session and centres unchanged, no group and no carry when nothing is repeated and
    there is no log (or no reference).
    """
    plan = session.plan
    repeats = find_repeats(plan)
    legs = session.hexapod.legs
    carry = temperatures is not None and legs is not None and bool(repeats.reference0)
    if not repeats.any and not carry:
        return session, centres, (), None
    c, t, u = centres.centres_mm.copy(), centres.times_s.copy(), centres.u_um.copy()
    cov = None if centres.cov_mm2 is None else centres.cov_mm2.copy()
    count = np.ones(len(plan.labels), dtype=np.intp)
    weights = registration_weights(centres.u_um)
    growth: dict[int, FloatArray] = {}
    motions: dict[int, FloatArray] = {}
    state_time = float(centres.times_s[repeats.reference0[-1]]) if repeats.reference0 else np.nan
    if carry:
        assert temperatures is not None and legs is not None
        idx = np.array(repeats.origin + repeats.reference0, dtype=np.intp)
        temps = logged_legs(temperatures, centres.times_s[idx])
        state = logged_legs(temperatures, np.array([state_time]))[0]
        g = leg_growth(legs, session.hexapod.igm(plan.poses[idx]), temps, state)
        frames = register(
            centres.centres_mm[idx],
            session.balls.centres_mm,
            None if weights is None else weights[idx],
        ).platform2cmm
        motion = carry_motion(session.hexapod, plan.poses[idx], g)
        world = frames @ motion @ invert_transform(frames)
        world[~np.any(g != 0, axis=1)] = np.eye(4)  # R0's last: exactly where it is
        for j, i in enumerate(idx):
            growth[int(i)], motions[int(i)] = g[j], world[j]
    groups = []
    shift = np.eye(4)
    for steps in (repeats.origin, repeats.reference0):
        idx = np.asarray(steps, dtype=np.intp)
        if not idx.size:
            continue
        n, first = len(idx), int(idx[0])
        times = centres.times_s[idx]
        measured = centres.centres_mm[idx]  # (n, k, 3)
        world = np.stack([motions.get(int(i), np.eye(4)) for i in idx])
        carried = carry_centres(np.eye(4), world, measured) if carry else measured
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
                    world if carry and first != plan.origin_index else None,
                )
            )
        is_origin = first == plan.origin_index
        c[first] = (measured if is_origin or not carry else carried).mean(axis=0)
        t[first] = times.mean() if is_origin or not carry else state_time
        u[first] = np.sqrt((centres.u_um[idx] ** 2).sum(axis=0)) / n
        if cov is not None and centres.cov_mm2 is not None:
            cov[first] = centres.cov_mm2[idx].sum(axis=0) / n**2
        count[first] = n
        if is_origin and carry:
            w = None if weights is None else weights[first][None]
            pair = register(
                np.stack([measured.mean(axis=0), carried.mean(axis=0)]),
                session.balls.centres_mm,
                w,
            ).platform2cmm
            shift = invert_transform(pair[0]) @ pair[1]
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
    )
    origin_carry = None
    if carry:
        assert temperatures is not None
        origin_carry = OriginCarry(
            shift,
            np.array([growth[i] for i in repeats.origin]),
            np.array([growth[i] for i in repeats.reference0]),
            state_time,
            logged_legs(temperatures, averaged.times_s),
            logged_legs(temperatures, np.array([state_time]))[0],
        )
    return dataclasses.replace(session, plan=reduced), averaged, tuple(groups), origin_carry
