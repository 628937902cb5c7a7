"""The diagnosis's observations and model.

What the twin predicts, the candidates and their parameters.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hexatherm.core.diagnosis.twins import TwinRuns
from hexatherm.core.effects import Effect, ThermocoupleLog
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.registration import rigid_rows
from hexatherm.core.twin import cmm_readings, predict
from hexatherm.typing import FloatArray

BoolArray = npt.NDArray[np.bool_]


#: ΔBIC a candidate must exceed to be added
DELTA_BIC_THRESHOLD = 10.0


#: |cosine| between two candidates' fitted residual changes above which they are
#: "explaining the same residual"
SIMILARITY_THRESHOLD = 0.9


#: relative step (in units of a parameter's scale) of the finite differences
_FD_STEP = 1e-3


@dataclass(frozen=True)
class Observations:
    """What a session measured, as the diagnosis needs it.

    Attributes
    ----------
    plan : Plan
    times_s : ndarray, shape (N,)
        Time of each step, in the log's time base (seconds).
    centres_mm : ndarray, shape (N, k, 3)
        Measured ball centres, CMM frame.
    balls_mm : ndarray, shape (k, 3)
        Ball centres in the platform frame.
    log : ThermocoupleLog
    u_mm : ndarray, shape (N, k)
        Standard uncertainty of each centre (per axis); all ones when unknown.
    ball_times_s : ndarray, shape (N, k), optional
        When each ball was measured (default: the step's time).
    u_given : bool
        Whether ``u_mm`` are the centres' uncertainties (True) or mere equal
        weights (False: the noise floor is then estimated from the references,
        see :func:`noise_floor`).
    """

    plan: Plan
    times_s: FloatArray
    centres_mm: FloatArray
    balls_mm: FloatArray
    log: ThermocoupleLog
    u_mm: FloatArray
    ball_times_s: FloatArray | None = None
    u_given: bool = True

    def __post_init__(self) -> None:
        n = len(self.plan.labels)
        centres = np.asarray(self.centres_mm, dtype=float)
        k = np.asarray(self.balls_mm).shape[0]
        if centres.shape != (n, k, 3):
            raise ValueError(f"centres must have shape ({n}, {k}, 3), got {centres.shape}")
        u = np.broadcast_to(np.asarray(self.u_mm, dtype=float), (n, k))
        if not (np.all(np.isfinite(u)) and np.all(u > 0)):
            raise ValueError("centre uncertainties must be finite and positive")
        object.__setattr__(self, "centres_mm", centres)
        object.__setattr__(self, "u_mm", np.array(u))
        t = np.asarray(self.times_s, dtype=float).reshape(-1)
        if t.shape != (n,):
            raise ValueError(f"need one time per step ({n}), got {t.shape}")
        object.__setattr__(self, "times_s", t)
        bt = self.ball_times_s
        bt = np.broadcast_to(t[:, None], (n, k)) if bt is None else np.asarray(bt, dtype=float)
        object.__setattr__(self, "ball_times_s", np.array(bt))

    @property
    def times_per_ball_s(self) -> FloatArray:
        """The time of every ball of every step (N, k), s: ``ball_times_s``, or the step's time."""
        if self.ball_times_s is None:  # never after __post_init__; kept for the type checker
            return np.broadcast_to(self.times_s[:, None], self.centres_mm.shape[:2]).copy()
        return self.ball_times_s

    @property
    def n_steps(self) -> int:
        return len(self.plan.labels)


@dataclass(frozen=True)
class Fit:
    """One model fitted to (part of) the steps.

    Attributes
    ----------
    effects : tuple of Effect
        The fitted effects (the hexapod's own effects are not in it).
    std_errors : tuple of dict
        Standard error of each fitted parameter, per effect.
    origin2cmm : ndarray, shape (4, 4)
        The fitted placement of frame O on the CMM (the nuisance).
    residual_mm : ndarray, shape (N, k, 3)
        Measured minus predicted centres of every step (held-out steps included).
    predicted_mm : ndarray, shape (N, k, 3)
        Predicted centres (CMM frame).
    rss_w : float
        Weighted sum of squares over the fitted steps.
    n : int
        Number of residual values fitted.
    p : int
        Number of parameters (6 for the nuisance plus the effects').
    covariance : ndarray, shape (P, P)
        Covariance of the fitted effects' parameters, in their units, in the
        order of ``effects`` and their ``parameters`` (NaN rows and columns for the
        ``unseen`` ones, whose standard errors are NaN too).
    unseen : tuple of tuple of str
        Per fitted effect (aligned with ``effects``; empty: none), its parameters
        that move no prediction on the fitted steps (a zero column of the Jacobian,
        e.g. an air-driven effect when the air is constant): not identifiable from
        these data, kept at their start value.
    """

    effects: tuple[Effect, ...]
    std_errors: tuple[dict[str, float], ...]
    origin2cmm: FloatArray
    residual_mm: FloatArray
    predicted_mm: FloatArray
    rss_w: float
    n: int
    p: int
    covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    unseen: tuple[tuple[str, ...], ...] = ()

    def unseen_of(self, index: int) -> tuple[str, ...]:
        """The ``unseen`` parameters of ``effects[index]`` (see above)."""
        return self.unseen[index] if self.unseen else ()

    @property
    def bic(self) -> float:
        return float(self.n * np.log(self.rss_w / self.n) + self.p * np.log(self.n))


@dataclass(frozen=True)
class Candidate:
    """One candidate effect tried in one round of the selection.

    Attributes
    ----------
    name : str
    fit : Fit or None
        The joint fit (added effects and this one) on all steps; None when skipped.
    delta_bic : float
        BIC of the current model minus this one's (positive: better).
    rms_um, heldout_rms_um : float
        RMS of the centre residuals, fitted and held out.
    passes : bool
        ΔBIC above the threshold and held-out RMS lower than the current model's.
    note : str
        Why it was skipped, or what is noteworthy (a parameter at its bound, or one
        these data do not see).
    """

    name: str
    fit: Fit | None
    delta_bic: float = float("nan")
    rms_um: float = float("nan")
    heldout_rms_um: float = float("nan")
    passes: bool = False
    note: str = ""


@dataclass(frozen=True)
class Addition:
    """An effect added to the model, with the scores that earned it its place."""

    effect: Effect
    std_errors: dict[str, float]
    delta_bic: float
    rms_before_um: float
    rms_after_um: float
    heldout_rms_before_um: float
    heldout_rms_after_um: float
    alternatives: tuple[tuple[str, float, float], ...] = ()
    """Other passing candidates explaining the same residual: (name, ΔBIC, cosine)."""
    adequate_after: bool | None = None
    """Whether the model with this effect (and those before it) is adequate
    (:func:`adequacy`); False: the effect *explains part* of the disagreement."""
    flags: tuple[str, ...] = ()
    """Parameters of the final joint fit at a bound of their range or outside it."""
    runner_up: RunnerUp | None = None
    """How this effect's parameters move when the round's runner-up is fitted with it."""
    folds: Folds | None = None
    """This effect's parameters of the final joint fit refitted on each held-out fold."""

    @property
    def explains(self) -> str:
        """``"part"`` when the model still disagrees after adding it, ``"all"`` when the
        residual left is noise, ``"unknown"`` when not assessed."""
        if self.adequate_after is None:
            return "unknown"
        return "all" if self.adequate_after else "part"


@dataclass(frozen=True)
class RunnerUp:
    """An added effect refitted together with its round's runner-up.

    Attributes
    ----------
    name : str
        The runner-up (the other candidate of the round with the largest ΔBIC).
    delta_bic : float
        The runner-up's ΔBIC in that round.
    values, std_errors : dict of str to float
        The added effect's parameters and standard errors without the runner-up
        (the round's fit).
    values_with, std_errors_with : dict of str to float
        The same, fitted jointly with the runner-up.
    runner_values, runner_std_errors : dict of str to float
        The runner-up's own parameters in the joint fit.
    """

    name: str
    delta_bic: float
    values: dict[str, float]
    std_errors: dict[str, float]
    values_with: dict[str, float]
    std_errors_with: dict[str, float]
    runner_values: dict[str, float]
    runner_std_errors: dict[str, float]

    def shift_in_se(self) -> dict[str, float]:
        """``(value_with - value) / std_error`` per parameter (nan when the SE is 0)."""
        return {
            p: (self.values_with[p] - v) / self.std_errors[p]
            if self.std_errors[p] > 0
            else float("nan")
            for p, v in self.values.items()
        }

    def se_ratio(self) -> dict[str, float]:
        """``std_error_with / std_error`` per parameter (how much looser the bars get)."""
        return {
            p: self.std_errors_with[p] / se if se > 0 else float("nan")
            for p, se in self.std_errors.items()
        }


#: the two held-out folds' values of a parameter differing by more than this many of
#: their combined standard errors: the parameter is not stable across the session
FOLD_SIGMAS = 3.0


@dataclass(frozen=True)
class Folds:
    """An added effect's parameters fitted separately on the two held-out folds.

    The final joint fit refitted on the even blocks of time, then on the odd ones
    (the folds of the held-out check). A physical effect has one value all session
    long: the two halves agree within their standard errors. A stand-in for a cause
    outside the registry takes whatever values bend it to the disagreement of each
    half, which need not agree.

    Attributes
    ----------
    values, std_errors : tuple of two dicts of str to float
        The parameters and their standard errors (clustered by step) on the even
        and on the odd blocks.
    """

    values: tuple[dict[str, float], dict[str, float]]
    std_errors: tuple[dict[str, float], dict[str, float]]

    def z(self) -> dict[str, float]:
        """``(even - odd) / sqrt(se_even^2 + se_odd^2)`` per parameter (nan: no SE)."""
        (a, b), (sa, sb) = self.values, self.std_errors
        out = {}
        for p in a:
            se = float(np.hypot(sa[p], sb[p]))
            out[p] = (a[p] - b[p]) / se if np.isfinite(se) and se > 0 else float("nan")
        return out

    def unstable(self) -> dict[str, float]:
        """The parameters whose folds differ by more than ``FOLD_SIGMAS``: name -> z."""
        return {p: z for p, z in self.z().items() if np.isfinite(z) and abs(z) > FOLD_SIGMAS}


def rms_um(residual_mm: npt.ArrayLike) -> float:
    """RMS of centre residuals (any shape ending in 3), micrometres."""
    r = np.asarray(residual_mm, dtype=float)
    return float(np.sqrt(np.mean(r**2)) * 1e3) if r.size else float("nan")


def twin_centres(
    hexapod: Hexapod,
    obs: Observations,
    effects: Sequence[Effect],
    runs: TwinRuns | None = None,
) -> FloatArray:
    """The twin's ball centres (N, k, 3) of every step in the nominal frame O.

    ``runs`` (:class:`~hexatherm.core.diagnosis.twins.TwinRuns` of the same hexapod and
    observations) computes them with what does not depend on the effects kept; the
    same centres, bit for bit.
    """
    if runs is not None:
        return runs.centres([effects])[0]
    steps = predict(
        hexapod,
        obs.plan,
        obs.times_s,
        obs.log,
        obs.balls_mm,
        np.eye(4),
        effects,
        reference_state=False,
    )
    return steps.centres_cmm_mm


def place(
    y_mm: FloatArray, obs: Observations, effects: Sequence[Effect], mask: BoolArray
) -> tuple[FloatArray, FloatArray]:
    """Fit the placement ``C`` of frame O on the CMM; return ``C`` and the predicted centres.

    ``C`` is the weighted rigid registration of the twin's centres ``y`` (frame O)
    of the steps in ``mask`` onto the measured ones, less what the CMM-side
    effects add (recomputed once with the first ``C``: exact for additive ones).
    """
    return place_many([y_mm], obs, [effects], mask)[0]


def place_many(
    y_mm: Sequence[FloatArray],
    obs: Observations,
    effects: Sequence[Sequence[Effect]],
    mask: BoolArray,
) -> list[tuple[FloatArray, FloatArray]]:
    """:func:`place` for several twins' centres (each with its effects) at once: the
    registrations of all of them in one :func:`~hexatherm.core.registration.rigid_rows`."""
    w = (1.0 / obs.u_mm**2)[mask].reshape(-1)
    x_fit = obs.centres_mm[mask].reshape(1, -1, 3)
    y_fit = np.stack([y[mask].reshape(-1, 3) for y in y_mm])
    first = rigid_rows(x_fit, y_fit, w)
    out = []
    for origin2cmm, y, y_row, row_effects in zip(first, y_mm, y_fit, effects, strict=True):
        cmm_side = [
            e for e in row_effects if type(e).cmm_coordinates_mm is not Effect.cmm_coordinates_mm
        ]
        if cmm_side:
            t = obs.times_per_ball_s
            placed = _apply(origin2cmm, y)
            shift = cmm_readings(placed, t, obs.log, cmm_side) - placed
            x_shifted = x_fit - shift[mask].reshape(1, -1, 3)
            origin2cmm = rigid_rows(x_shifted, y_row[None], w)[0]
            placed = _apply(origin2cmm, y)
            out.append((origin2cmm, cmm_readings(placed, t, obs.log, cmm_side)))
        else:
            out.append((origin2cmm, _apply(origin2cmm, y)))
    return out


def _change(before: Fit, after: Fit, obs: Observations) -> FloatArray:
    """Weighted change of the residuals from one model to another (a direction)."""
    return ((before.residual_mm - after.residual_mm) / obs.u_mm[..., None]).ravel()


def _cosine(a: FloatArray, b: FloatArray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return float(a @ b / (na * nb)) if na > 0 and nb > 0 else 0.0


def _apply(transform: FloatArray, points: FloatArray) -> FloatArray:
    return points @ transform[:3, :3].T + transform[:3, 3]
