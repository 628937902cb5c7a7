"""An independent heating generator: leg temperature histories the twin does not make.

The twin's own heatings (:mod:`hexatherm.core.heating`) are first-order responses of the
legs to mats switched on or off, one time constant each: the same model O's carry without
a log reads its error with (a curvature equal to the slope over a time constant), so a
check on them is circular (issue 35). These histories are other shapes, written here
without that module, each a :class:`~hexatherm.core.heating.HeatingModel` (``legs(t)``,
``air(t)``) that the twin's sessions take in place of its own (``TwinSessionSpec.heating``):

* :class:`TwoTimeConstants`: a fast and a slow response summed (a leg's body and its
  screw lagging differently): its curvature is not proportional to its slope;
* :class:`RampPlateau`: a linear warming, then flat (two kinks, no curvature between);
* :class:`SmoothStep`: a step of a few tens of seconds mid-session (a logistic);
* :class:`AirWave`: the room's air drifting periodically, every leg following it with
  its own lag and amplitude (the legs' histories differ: not one shape);
* :class:`Uneven`: legs heated unevenly, each with its own onset and time constant.

The legs' growth is the leg model's of these temperatures (the twin's ``growth_mm``:
linear in each segment's temperature), so the correction's scaling of the growth from R
to a target is exact and what is measured is the no-log terms' reading of the growth's
shape in time. The truth of the corrected poses is the twin's kinematic one (the pose
with the legs in R0's thermal state relative to O in that state, from the temperatures at
R0's time): it does not depend on the heating's shape, and
``tests/workflows/test_heatgen.py`` checks it against a solve of this module's own
(:func:`corrected_truth`: leg lengths from the IGM plus the leg model's growth at R0's
temperatures, the pose found by least squares on the IGM, not by hexatherm's FGM).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import invert_transform, pose_from_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.typing import FloatArray

#: the legs' gains, K (six unequal legs, as the workflow tests' twins)
GAIN_C = np.array([3.0, 7.0, 2.0, 3.0, 9.0, 3.5])
AIR_C = 20.0


def _t(t_s: npt.ArrayLike) -> FloatArray:
    return np.asarray(t_s, dtype=float).reshape(-1)


class _Together:
    """Every leg the same history ``rise(t)`` (0 to 1) times its gain, in still air."""

    scale: float

    def rise(self, t: FloatArray) -> FloatArray:
        raise NotImplementedError

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        return np.full(_t(t_s).size, AIR_C)

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        return AIR_C + np.outer(self.rise(_t(t_s)), self.scale * GAIN_C)


@dataclass(frozen=True)
class TwoTimeConstants(_Together):
    """From ``on_s``: a share ``fast`` of the gain with ``tau_fast_s``, the rest with
    ``tau_slow_s``."""

    on_s: float = 1000.0
    tau_fast_s: float = 150.0
    tau_slow_s: float = 3000.0
    fast: float = 0.5
    scale: float = 1.0

    def rise(self, t: FloatArray) -> FloatArray:
        dt = np.clip(t - self.on_s, 0.0, None)
        fast = self.fast * -np.expm1(-dt / self.tau_fast_s)
        return fast + (1 - self.fast) * -np.expm1(-dt / self.tau_slow_s)


@dataclass(frozen=True)
class RampPlateau(_Together):
    """A straight warming from ``start_s`` to ``end_s``, then flat."""

    start_s: float = 700.0
    end_s: float = 1700.0
    scale: float = 1.0

    def rise(self, t: FloatArray) -> FloatArray:
        return np.clip((t - self.start_s) / (self.end_s - self.start_s), 0.0, 1.0)


@dataclass(frozen=True)
class SmoothStep(_Together):
    """A logistic step of width ``width_s`` centred at ``at_s``."""

    at_s: float = 1500.0
    width_s: float = 20.0
    scale: float = 1.0

    def rise(self, t: FloatArray) -> FloatArray:
        return 0.5 * (1 + np.tanh((t - self.at_s) / (2 * self.width_s)))


@dataclass(frozen=True)
class AirWave:
    """The air ``amplitude_C sin(2 pi t / period_s)``; leg i follows it with its own lag
    (``lag_s[i]``) and amplitude (``share[i]``), plus a slow warming ``drift_C`` over the
    session (linear)."""

    amplitude_C: float = 1.0
    period_s: float = 2400.0
    lag_s: tuple[float, ...] = (0.0, 60.0, 120.0, 200.0, 300.0, 400.0)
    share: tuple[float, ...] = (1.0, 0.9, 0.8, 0.7, 0.6, 0.5)
    drift_C: float = 0.5
    span_s: float = 3000.0

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        t = _t(t_s)
        return AIR_C + self.amplitude_C * np.sin(2 * np.pi * t / self.period_s)

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        t = _t(t_s)[:, None]
        phase = 2 * np.pi * (t - np.asarray(self.lag_s)) / self.period_s
        wave = self.amplitude_C * np.asarray(self.share) * np.sin(phase)
        return AIR_C + wave + self.drift_C * t / self.span_s


@dataclass(frozen=True)
class Uneven:
    """Leg i heated from ``on_s[i]`` towards ``GAIN_C[i] scale`` as
    ``(1 - exp(-dt / tau_s[i]))^2`` (a sigmoid start: the heat reaching the leg through
    its mount), each leg its own onset and time constant."""

    on_s: tuple[float, ...] = (600.0, 700.0, 900.0, 1200.0, 1500.0, 1800.0)
    tau_s: tuple[float, ...] = (300.0, 500.0, 800.0, 400.0, 1200.0, 600.0)
    scale: float = 1.0

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        return np.full(_t(t_s).size, AIR_C)

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        dt = np.clip(_t(t_s)[:, None] - np.asarray(self.on_s), 0.0, None)
        rise = (-np.expm1(-dt / np.asarray(self.tau_s))) ** 2
        return AIR_C + rise * self.scale * GAIN_C


def _solve_pose(hexapod: Hexapod, q_mm: FloatArray, start: FloatArray) -> FloatArray:
    """The pose whose IGM gives ``q_mm`` (least squares, from ``start``)."""
    from scipy.optimize import least_squares

    fit = least_squares(
        lambda x: hexapod.igm(x[None])[0] - q_mm, start, xtol=1e-15, ftol=1e-15, gtol=1e-15
    )
    return np.asarray(fit.x, dtype=float)


def corrected_truth(
    hexapod: Hexapod,
    commanded: FloatArray,
    origin_index: int,
    state_C: FloatArray,
) -> FloatArray:
    """The true corrected poses (N, 6) of steps commanded at ``commanded`` (N, 6): each
    step's legs in the thermal state ``state_C`` (6,: R0's leg temperatures, every
    segment of a leg at its leg's), relative to O's in that state; solved on the IGM
    (least squares), not with the FGM."""
    legs = hexapod.legs
    assert legs is not None
    q_cmd = hexapod.igm(commanded)
    segments = np.broadcast_to(state_C[None, :, None], (len(commanded), 6, legs.variable.shape[1]))
    growth = legs.growth_mm(q_cmd, segments, per_segment=True)
    q = q_cmd + growth
    poses = np.array([_solve_pose(hexapod, q[i], commanded[i]) for i in range(len(q))])
    conv = hexapod.convention
    origin = transform_from_pose(poses[origin_index], conv)
    frames = transform_from_pose(poses, conv)
    return np.asarray(pose_from_transform(invert_transform(origin) @ frames, conv))
