"""Where the twin and the measurements disagree, and which missing effect explains it.

The twin (:mod:`hexatherm.core.twin`) predicts, from the commanded poses and the
thermocouple log, where every ball of every step of a session should be. The
diagnosis compares that with the measured ball centres and, one effect of the
registry (:mod:`hexatherm.core.effects`) at a time, asks whether adding it to the
model explains the difference.

**The comparison.** Residuals are in ball-centre space, the space the CMM
measures in: for step k and ball b, ``x_kb - cmm(C y_kb(theta), t_kb)`` where
``x`` is the measured centre (CMM frame), ``y(theta)`` the twin's ball centre in
the nominal frame O with the effects' parameters ``theta``, ``cmm`` the CMM-side
effects (a drift) and ``C`` the placement of frame O on the CMM. ``C`` is the
nuisance of every model, the baseline included: six parameters fitted to all
steps (a weighted rigid registration of every predicted centre onto every
measured one, exact for each ``theta``). So the one measurement of O is one step
among the others and its error does not sit in every residual. Residuals are
weighted by each centre's standard uncertainty.

**The scores.** For a model with ``p`` parameters (6 for ``C`` plus the
effects') fitted to ``n`` residual values, ``BIC = n ln(RSS_w / n) + p ln n``
with ``RSS_w`` the weighted sum of squares (the noise level is estimated, so a
misestimated uncertainty scales all models alike). The held-out check splits
the steps, in time order, into blocks; the model (``C`` included) is fitted on
every other block and evaluated on the rest, then the other way round. A
candidate is added when ``BIC`` drops by more than 10 *and* the held-out RMS
goes down; the best (largest drop) is added, all added parameters are refitted
together, and the search repeats until no candidate passes.

**Reported RMS** (``*_rms_um``): root mean square, over all steps, balls and the
three axes, of the measured minus the predicted centre, micrometres.

Candidates that explain the same residual are flagged: when another passing
candidate's fitted change of the residuals is nearly parallel to the chosen
one's (cosine above 0.9), both are named and the choice is the smaller BIC.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy import stats
from scipy.optimize import least_squares

from hexatherm.core.effects import EFFECTS, Effect, ThermocoupleLog
from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.registration import register
from hexatherm.core.residuals import (
    LEG_NAMES,
    POSE_COMPONENTS,
    TIME_PARTS,
    PoseResiduals,
    spearman,
    summarize,
    time_blocks,
)
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
        order of ``effects`` and their ``parameters``.
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
        Why it was skipped, or what is noteworthy (a parameter at its bound).
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


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of :func:`diagnose`.

    Attributes
    ----------
    baseline : Fit
        The current model (the hexapod's own effects), only ``C`` fitted.
    final : Fit
        The model with every added effect, fitted jointly.
    added : tuple of Addition
        In the order they were added.
    rounds : tuple of tuple of Candidate
        Every candidate of every round.
    baseline_heldout_rms_um, final_heldout_rms_um : float
    skipped : dict of str to str
        Candidates not tried at all, and why (e.g. no air temperature).
    adequacy : Adequacy or None
        The verdict on the final model (None when not assessed).
    """

    baseline: Fit
    final: Fit
    added: tuple[Addition, ...]
    rounds: tuple[tuple[Candidate, ...], ...]
    baseline_heldout_rms_um: float
    final_heldout_rms_um: float
    skipped: dict[str, str] = field(default_factory=dict)
    adequacy: Adequacy | None = None

    @property
    def baseline_rms_um(self) -> float:
        return rms_um(self.baseline.residual_mm)

    @property
    def final_rms_um(self) -> float:
        return rms_um(self.final.residual_mm)


# --------------------------------------------------------------------- the model
def rms_um(residual_mm: npt.ArrayLike) -> float:
    """RMS of centre residuals (any shape ending in 3), micrometres."""
    r = np.asarray(residual_mm, dtype=float)
    return float(np.sqrt(np.mean(r**2)) * 1e3) if r.size else float("nan")


def twin_centres(hexapod: Hexapod, obs: Observations, effects: Sequence[Effect]) -> FloatArray:
    """The twin's ball centres (N, k, 3) of every step in the nominal frame O."""
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
    w = (1.0 / obs.u_mm**2)[mask].reshape(1, -1)
    y_fit = y_mm[mask].reshape(1, -1, 3)[0]
    x_fit = obs.centres_mm[mask].reshape(1, -1, 3)
    t = obs.times_per_ball_s
    origin2cmm = register(x_fit, y_fit, w).platform2cmm[0]
    cmm_side = [e for e in effects if type(e).cmm_coordinates_mm is not Effect.cmm_coordinates_mm]
    if cmm_side:
        placed = _apply(origin2cmm, y_mm)
        shift = cmm_readings(placed, t, obs.log, cmm_side) - placed
        origin2cmm = register(x_fit - shift[mask].reshape(1, -1, 3), y_fit, w).platform2cmm[0]
        placed = _apply(origin2cmm, y_mm)
        return origin2cmm, cmm_readings(placed, t, obs.log, cmm_side)
    return origin2cmm, _apply(origin2cmm, y_mm)


def _apply(transform: FloatArray, points: FloatArray) -> FloatArray:
    return points @ transform[:3, :3].T + transform[:3, 3]


# ------------------------------------------------------------------- the fitting
class _Problem:
    """The twin's centres as a function of the free effects' parameters, memoized.

    The twin (a forward model per step) is the expensive part; placing frame O
    for a set of steps is cheap. So one evaluation of the twin serves the fit on
    all steps and the fits on the held-out folds alike.
    """

    def __init__(
        self,
        hexapod: Hexapod,
        obs: Observations,
        fixed: Sequence[Effect],
        free: Sequence[type[Effect]],
    ) -> None:
        self.hexapod, self.obs = hexapod, obs
        self.fixed, self.free = tuple(fixed), tuple(free)
        self.sizes = [len(cls.parameters) for cls in self.free]

        def cat(parts: list[FloatArray]) -> FloatArray:
            return np.concatenate(parts) if parts else np.zeros(0)

        self.scale = cat([cls.scales() for cls in self.free])
        self.lo = cat([np.array([r[0] for r in cls.ranges]) for cls in self.free])
        self.hi = cat([np.array([r[1] for r in cls.ranges]) for cls in self.free])
        self.sqrt_w = 1.0 / obs.u_mm[..., None]
        self._cache: dict[bytes, FloatArray] = {}

    def effects(self, theta: FloatArray) -> tuple[Effect, ...]:
        out, i = [], 0
        for cls, size in zip(self.free, self.sizes, strict=True):
            out.append(cls.from_vector(theta[i : i + size].tolist()))
            i += size
        return self.fixed + tuple(out)

    def centres(self, theta: FloatArray) -> FloatArray:
        key = np.asarray(theta, dtype=float).tobytes()
        if key not in self._cache:
            self._cache[key] = twin_centres(self.hexapod, self.obs, self.effects(theta))
        return self._cache[key]

    def evaluate(
        self, theta: FloatArray, mask: BoolArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Placement of O, predicted centres and residuals (all steps) fitted on ``mask``."""
        origin2cmm, predicted = place(self.centres(theta), self.obs, self.effects(theta), mask)
        return origin2cmm, predicted, self.obs.centres_mm - predicted

    def weighted(self, theta: FloatArray, mask: BoolArray) -> FloatArray:
        return (self.evaluate(theta, mask)[2] * self.sqrt_w)[mask].ravel()

    def jacobian(self, theta: FloatArray, mask: BoolArray) -> FloatArray:
        """Forward differences of the weighted residuals in units of each parameter's scale."""
        r0 = self.weighted(theta, mask)
        cols = []
        for j in range(theta.size):
            h = _FD_STEP * self.scale[j]
            if theta[j] + h > self.hi[j]:
                h = -h
            step = theta.copy()
            step[j] += h
            cols.append((self.weighted(step, mask) - r0) / (h / self.scale[j]))
        return np.column_stack(cols) if cols else np.zeros((r0.size, 0))

    def start(self, starts: Sequence[FloatArray | None], mask: BoolArray) -> FloatArray:
        """The best combination of start values (given ones, or each effect's own)."""
        options = [
            [s] if s is not None else cls.start_values()
            for cls, s in zip(self.free, starts, strict=True)
        ]
        combos = [np.zeros(0)]
        for opts in options:
            combos = [np.concatenate([c, o]) for c in combos for o in opts]
        combos = [np.clip(c, self.lo, self.hi) for c in combos]
        costs = [float(np.sum(self.weighted(c, mask) ** 2)) for c in combos]
        return combos[int(np.argmin(costs))]

    def solve(self, theta0: FloatArray, mask: BoolArray) -> FloatArray:
        """Least squares from ``theta0`` within the ranges (trust region, scaled)."""
        if theta0.size == 0:
            return theta0
        # z = 1 + (theta - theta0) / scale: starting at z = 1 gives the trust region
        # a unit first radius (least_squares sizes it by |z0|, tiny near zero)
        z_lo, z_hi = 1 + (self.lo - theta0) / self.scale, 1 + (self.hi - theta0) / self.scale
        inside = 1e-9 * (z_hi - z_lo)
        z0 = np.clip(np.ones(theta0.size), z_lo + inside, z_hi - inside)

        def theta_of(z: FloatArray) -> FloatArray:
            return theta0 + (z - 1) * self.scale

        solution = least_squares(
            lambda z: self.weighted(theta_of(z), mask),
            z0,
            jac=lambda z: self.jacobian(theta_of(z), mask),
            bounds=(z_lo, z_hi),
            method="trf",
            x_scale=1.0,
            max_nfev=30,
            xtol=1e-8,
            ftol=1e-8,
            gtol=None,
        )
        return np.clip(theta_of(solution.x), self.lo, self.hi)

    def refit(self, theta_hat: FloatArray, mask: BoolArray, iterations: int = 3) -> FloatArray:
        """Refit from a nearby solution with its Jacobian kept (chord iterations).

        The held-out folds start from the fit on all steps; the twin at the
        Jacobian's points is already memoized, so each iteration costs one twin.
        """
        if theta_hat.size == 0:
            return theta_hat
        jac = self.jacobian(theta_hat, mask)
        theta = theta_hat
        for _ in range(iterations):
            r = self.weighted(theta, mask)
            dz = np.linalg.lstsq(jac, -r, rcond=None)[0]
            theta = np.clip(theta + dz * self.scale, self.lo, self.hi)
        return theta

    def fit(self, theta: FloatArray, mask: BoolArray) -> Fit:
        """The :class:`Fit` at ``theta`` (standard errors from the Jacobian there)."""
        origin2cmm, predicted, residual = self.evaluate(theta, mask)
        rss = float(np.sum((residual * self.sqrt_w)[mask] ** 2))
        n = int(residual[mask].size)
        p = 6 + int(theta.size)
        errors: list[dict[str, float]] = []
        covariance = np.zeros((theta.size, theta.size))
        if theta.size:
            covariance = self.covariance(theta, mask)
            se = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
            i = 0
            for cls, size in zip(self.free, self.sizes, strict=True):
                errors.append(
                    dict(zip(cls.parameters, (float(v) for v in se[i : i + size]), strict=True))
                )
                i += size
        return Fit(
            self.effects(theta)[len(self.fixed) :],
            tuple(errors),
            origin2cmm,
            residual,
            predicted,
            rss,
            n,
            p,
            covariance,
        )

    def covariance(self, theta: FloatArray, mask: BoolArray) -> FloatArray:
        """Covariance of the fitted parameters: the sandwich, clustered by step.

        ``A^-1 (sum_s J_s^T r_s r_s^T J_s) A^-1 G/(G-1)`` with ``A = J^T J`` and ``G``
        the number of steps: it holds when the noise differs between axes (a
        sphere fit's centre is looser along the cap's axis) and when a step's
        residuals move together (the hexapod's positioning noise), where the
        textbook ``s^2 A^-1`` would be too optimistic.
        """
        jac = self.jacobian(theta, mask)
        r = self.weighted(theta, mask)
        groups = int(mask.sum())
        per_step = r.size // groups
        scores = (jac * r[:, None]).reshape(groups, per_step, -1).sum(axis=1)
        bread = np.linalg.pinv(jac.T @ jac)
        meat = scores.T @ scores * groups / max(groups - 1, 1)
        cov_z = bread @ meat @ bread
        return cov_z * np.outer(self.scale, self.scale)


def fit_model(
    hexapod: Hexapod,
    obs: Observations,
    fixed: Sequence[Effect],
    free: Sequence[type[Effect]],
    start: Sequence[FloatArray | None] = (),
    mask: BoolArray | None = None,
) -> Fit:
    """Fit the parameters of the ``free`` effects (and ``C``) to the steps in ``mask``.

    Parameters
    ----------
    hexapod : Hexapod
    obs : Observations
    fixed : sequence of Effect
        The current model's effects, kept as they are.
    free : sequence of Effect classes
        The effects whose parameters are fitted, jointly, within their ranges.
    start : sequence of (ndarray or None)
        A starting value per free effect (None: try the effect's start values).
    mask : ndarray of bool, shape (N,), optional
        The steps fitted (default all); residuals are returned for every step.

    Returns
    -------
    Fit
    """
    problem = _Problem(hexapod, obs, fixed, free)
    mask = np.ones(obs.n_steps, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    starts = list(start) + [None] * (len(problem.free) - len(start))
    theta = problem.solve(problem.start(starts, mask), mask)
    return problem.fit(theta, mask)


def heldout_rms_um(problem: _Problem, theta_hat: FloatArray, blocks: npt.NDArray[np.intp]) -> float:
    """RMS (um) of the residuals of steps the model was not fitted to.

    Two folds: fitted on the even blocks of time, evaluated on the odd ones, and
    the other way round (each fold refitted from ``theta_hat``, the fit on all
    steps); the RMS is over both held-out halves.
    """
    squares, count = 0.0, 0
    for parity in (0, 1):
        train = blocks % 2 == parity
        theta = problem.refit(theta_hat, train)
        held = problem.evaluate(theta, train)[2][~train]
        squares += float(np.sum(held**2))
        count += held.size
    return float(np.sqrt(squares / count) * 1e3)


def _fit_and_hold_out(
    hexapod: Hexapod,
    obs: Observations,
    fixed: Sequence[Effect],
    free: Sequence[type[Effect]],
    start: Sequence[FloatArray | None],
    blocks: npt.NDArray[np.intp],
) -> tuple[Fit, float]:
    problem = _Problem(hexapod, obs, fixed, free)
    everything = np.ones(obs.n_steps, dtype=bool)
    starts = list(start) + [None] * (len(problem.free) - len(start))
    theta = problem.solve(problem.start(starts, everything), everything)
    return problem.fit(theta, everything), heldout_rms_um(problem, theta, blocks)


def _change(before: Fit, after: Fit, obs: Observations) -> FloatArray:
    """Weighted change of the residuals from one model to another (a direction)."""
    return ((before.residual_mm - after.residual_mm) / obs.u_mm[..., None]).ravel()


def _cosine(a: FloatArray, b: FloatArray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return float(a @ b / (na * nb)) if na > 0 and nb > 0 else 0.0


def diagnose(
    hexapod: Hexapod,
    obs: Observations,
    current: Sequence[Effect] = (),
    candidates: Sequence[str] | None = None,
    *,
    n_blocks: int = 6,
    max_additions: int = 3,
    progress: Callable[[int, int, int], None] | None = None,
) -> Diagnosis:
    """Find the effects missing from the model, one by one (see the module's text).

    Parameters
    ----------
    hexapod : Hexapod
        Nominal geometry and leg model.
    obs : Observations
    current : sequence of Effect
        The model's effects (the hexapod file's ``thermal_model``), kept fixed.
    candidates : sequence of str, optional
        Names of the effects to try (default: every registered one not in ``current``).
    n_blocks : int
        Blocks of time for the held-out check.
    max_additions : int
        Stop after adding this many effects.
    progress : callable, optional
        Called as ``progress(round, done, total)`` after every candidate fitted.

    Returns
    -------
    Diagnosis
    """
    current = tuple(current)
    in_model = {e.name for e in current}
    names = [n for n in (candidates if candidates is not None else EFFECTS) if n not in in_model]
    skipped: dict[str, str] = {}
    for name in list(names):
        if EFFECTS[name].needs_air and obs.log.air_C is None:
            skipped[name] = "needs the air temperature (an 'air' column in temperatures.csv)"
            names.remove(name)
    blocks = time_blocks(obs.times_s, n_blocks)
    baseline, heldout = _fit_and_hold_out(hexapod, obs, current, (), (), blocks)
    baseline_heldout = heldout
    model = baseline
    added: list[Addition] = []
    rounds: list[tuple[Candidate, ...]] = []
    added_classes: list[type[Effect]] = []
    while names and len(added) < max_additions:
        starts: list[FloatArray | None] = [e.vector() for e in model.effects]
        tried: list[Candidate] = []
        for name in names:
            cls = EFFECTS[name]
            free = [*added_classes, cls]
            fit, held = _fit_and_hold_out(hexapod, obs, current, free, starts, blocks)
            delta = model.bic - fit.bic
            note = _bound_note(fit.effects[-1])
            tried.append(
                Candidate(
                    name,
                    fit,
                    delta,
                    rms_um(fit.residual_mm),
                    held,
                    bool(delta > DELTA_BIC_THRESHOLD and held < heldout),
                    note,
                )
            )
            if progress is not None:
                progress(len(rounds) + 1, len(tried), len(names))
        rounds.append(tuple(tried))
        passing = sorted((c for c in tried if c.passes), key=lambda c: -c.delta_bic)
        if not passing:
            break
        best = passing[0]
        assert best.fit is not None
        direction = _change(model, best.fit, obs)
        alternatives = []
        for other in passing[1:]:
            assert other.fit is not None
            cos = _cosine(direction, _change(model, other.fit, obs))
            if abs(cos) > SIMILARITY_THRESHOLD:
                alternatives.append((other.name, other.delta_bic, cos))
        others = sorted(
            (c for c in tried if c is not best and c.fit is not None and np.isfinite(c.delta_bic)),
            key=lambda c: -c.delta_bic,
        )
        runner = (
            _runner_up(hexapod, obs, current, added_classes, best, others[0]) if others else None
        )
        added.append(
            Addition(
                best.fit.effects[-1],
                best.fit.std_errors[-1],
                best.delta_bic,
                rms_um(model.residual_mm),
                best.rms_um,
                heldout,
                best.heldout_rms_um,
                tuple(alternatives),
                adequacy(hexapod, obs, best.fit).adequate,
                (),
                runner,
            )
        )
        added_classes.append(EFFECTS[best.name])
        names.remove(best.name)
        model, heldout = best.fit, best.heldout_rms_um
        # the joint refit of everything added so far is ``best.fit`` itself
    # the flags are those of the final joint fit (the values written to hexapod.yaml)
    added = [
        replace(a, flags=bound_flags(effect))
        for a, effect in zip(added, model.effects, strict=True)
    ]
    return Diagnosis(
        baseline,
        model,
        tuple(added),
        tuple(rounds),
        baseline_heldout,
        heldout,
        skipped,
        adequacy(hexapod, obs, model),
    )


def _runner_up(
    hexapod: Hexapod,
    obs: Observations,
    current: Sequence[Effect],
    before: Sequence[type[Effect]],
    best: Candidate,
    runner: Candidate,
) -> RunnerUp:
    """Refit the round's chosen effect together with its runner-up (see :class:`RunnerUp`)."""
    assert best.fit is not None and runner.fit is not None
    chosen = best.fit.effects[-1]
    free = [*before, type(chosen), EFFECTS[runner.name]]
    starts: list[FloatArray | None] = [e.vector() for e in best.fit.effects]
    both = fit_model(hexapod, obs, current, free, [*starts, runner.fit.effects[-1].vector()])
    return RunnerUp(
        runner.name,
        runner.delta_bic,
        dict(chosen.values),
        dict(best.fit.std_errors[-1]),
        dict(both.effects[-2].values),
        dict(both.std_errors[-2]),
        dict(both.effects[-1].values),
        dict(both.std_errors[-1]),
    )


def _bound_note(effect: Effect) -> str:
    notes = []
    for p, (lo, hi) in zip(effect.parameters, effect.ranges, strict=True):
        value = effect.values[p]
        span = hi - lo
        if value <= lo + 1e-6 * span or value >= hi - 1e-6 * span:
            notes.append(f"{p} at the bound of its range [{lo:g}, {hi:g}]")
    return "; ".join(notes)


# ------------------------------------------------------------------ pose space
def pose_residuals(hexapod: Hexapod, obs: Observations, fit: Fit) -> PoseResiduals:
    """Residuals of ``fit`` in pose space (6 components) and leg space (through the IGM).

    Both the measured and the predicted centres of a step are registered to the
    balls, and the frames are expressed relative to the fitted frame O.
    """
    cmm2origin = invert_transform(fit.origin2cmm)
    measured = cmm2origin @ register(obs.centres_mm, obs.balls_mm).platform2cmm
    predicted = cmm2origin @ register(fit.predicted_mm, obs.balls_mm).platform2cmm
    pm = pose_from_transform(measured, hexapod.convention)
    pp = pose_from_transform(predicted, hexapod.convention)
    pose = pm - pp
    pose[:, 3:] = (pose[:, 3:] + 180.0) % 360.0 - 180.0
    pose = pose * np.array([1e3] * 3 + [np.pi / 180 * 1e6] * 3)
    legs = (hexapod.igm(pm) - hexapod.igm(pp)) * 1e3
    step_rms = np.sqrt(np.mean(fit.residual_mm**2, axis=(1, 2))) * 1e3
    return PoseResiduals(pose, legs, step_rms)


# ------------------------------------------------------------------ adequacy
#: the final RMS may exceed the noise floor by this factor before the model is inadequate
RMS_RATIO_LIMIT = 1.3
#: chi2/dof must exceed 1 by this many of its spreads (and by the RMS limit) to fail
CHI2_SIGMAS = 5.0
#: family-wise level of the structure tests (Bonferroni over all of them); strict because
#: their p-values assume independent residuals and the series overlap (pose and legs are
#: one residual seen twice): at 0.01, 1 of 20 null campaigns of 8 targets failed
STRUCTURE_ALPHA = 0.001


@dataclass(frozen=True)
class Finding:
    """A structure test of the residuals that fails (Bonferroni, family level 0.001).

    Attributes
    ----------
    series : str
        What was tested: a pose component (``"Rx"``), a leg (``"leg3"``), or
        ``"steps"`` (every step's mean square centre residual).
    test : str
        ``"autocorrelated"`` (Ljung-Box), ``"trend with time"`` (slope),
        ``"correlates with time"``, ``"correlates with temperature"`` (Spearman),
        ``"differs by step kind"`` (Kruskal-Wallis).
    statistic : float
        Q, t, rho or H.
    p_value : float
    """

    series: str
    test: str
    statistic: float
    p_value: float

    def text(self) -> str:
        symbol = {"autocorrelated": "Q", "trend with time": "t", "differs by step kind": "H"}
        name = symbol.get(self.test, "rho")
        return f"{self.series} {self.test} ({name} = {self.statistic:.3g}, p = {self.p_value:.1e})"


@dataclass(frozen=True)
class Adequacy:
    """Whether a fitted model explains the measurements down to their noise.

    Attributes
    ----------
    adequate : bool
        False when ``chi2_per_dof`` is beyond its limit, or ``final_rms_um`` above
        ``RMS_RATIO_LIMIT`` times the floor, or a structure test fails.
    chi2_per_dof, chi2_spread : float
        ``sum(r^2 / sigma^2) / dof`` over every centre residual value and its
        spread ``sqrt(2 / dof)`` (``sqrt(2/dof + 2/m)`` when sigma is estimated
        from ``m`` reference differences); ``dof = n - p``.
    chi2_limit : float
        ``max(RMS_RATIO_LIMIT^2, 1 + CHI2_SIGMAS chi2_spread)``.
    dof : int
    noise_floor_um : float
        RMS expected from noise alone (per centre and axis, um), the definition of
        the reported RMS: ``sqrt(mean(u^2))`` of the centre uncertainties when
        given, else estimated from consecutive references (:func:`noise_floor`).
    noise_floor_source : str
        ``"centre uncertainties"`` or ``"references"``.
    reference_floor_um : float
        The estimate from consecutive references (a cross-check; nan without two).
    final_rms_um : float
    unexplained_rms_um : float
        ``sqrt(max(0, final_rms^2 - floor^2))``.
    reasons : tuple of str
        Why inadequate, in words (empty when adequate).
    findings : tuple of Finding
        The failed structure tests, smallest p first.
    n_tests : int
        How many structure tests were made (the Bonferroni divisor).
    component_rms : ndarray, shape (6,)
        RMS of the pose residuals Tx, Ty, Tz (um), Rx, Ry, Rz (urad).
    kind_rms_um, kind_floor_um : dict of str to float
        RMS of the centre residuals, and its noise floor, by step kind.
    kind_count : dict of str to int
        Steps of each kind.
    part_rms_um, part_floor_um : ndarray, shape (TIME_PARTS,)
        The same by quarter of the session in time order.
    part_span_s : ndarray, shape (TIME_PARTS, 2)
    temperature_rho : float
        Spearman's rho of each step's mean square residual with the mean leg
        temperature.
    notes : tuple of str
        What the verdict rests on, when it is weaker than usual (no floor; centre
        uncertainties smaller than the references' scatter).
    """

    adequate: bool
    chi2_per_dof: float
    chi2_spread: float
    chi2_limit: float
    dof: int
    noise_floor_um: float
    noise_floor_source: str
    reference_floor_um: float
    final_rms_um: float
    unexplained_rms_um: float
    reasons: tuple[str, ...]
    findings: tuple[Finding, ...]
    n_tests: int
    component_rms: FloatArray
    kind_rms_um: dict[str, float]
    kind_floor_um: dict[str, float]
    kind_count: dict[str, int]
    part_rms_um: FloatArray
    part_floor_um: FloatArray
    part_span_s: FloatArray
    temperature_rho: float
    notes: tuple[str, ...] = ()

    def where(self) -> list[str]:
        """Where the unexplained part shows, in words: components, step kinds, time,
        temperature (the failed tests first)."""
        out = []
        comps = sorted({f.series for f in self.findings if f.series in POSE_COMPONENTS})
        legs = sorted({f.series for f in self.findings if f.series in LEG_NAMES})
        if comps:
            out.append(f"components {', '.join(comps)}")
        if legs:
            out.append(f"legs {', '.join(legs)}")
        # a kind of one or two steps (the origin) is too noisy to point at
        ratio = {
            k: v / self.kind_floor_um[k]
            for k, v in self.kind_rms_um.items()
            if self.kind_floor_um.get(k, 0) > 0 and self.kind_count.get(k, 0) >= 3
        }
        if ratio:
            kind = max(ratio, key=lambda k: ratio[k])
            out.append(
                f"{kind} steps ({self.kind_rms_um[kind]:.2f} um vs floor "
                f"{self.kind_floor_um[kind]:.2f} um)"
            )
        with np.errstate(invalid="ignore", divide="ignore"):
            part_ratio = self.part_rms_um / self.part_floor_um
        if np.any(np.isfinite(part_ratio)):
            q = int(np.nanargmax(part_ratio))
            t0 = float(np.nanmin(self.part_span_s))
            a, b = (self.part_span_s[q] - t0) / 3600.0
            out.append(
                f"quarter {q + 1} of the session ({a:.1f}-{b:.1f} h: "
                f"{self.part_rms_um[q]:.2f} um vs floor {self.part_floor_um[q]:.2f} um)"
            )
        temp = [f for f in self.findings if "temperature" in f.test]
        if temp:
            out.append("with temperature: " + ", ".join(f.series for f in temp))
        elif np.isfinite(self.temperature_rho):
            out.append(f"vs temperature rho = {self.temperature_rho:.2f} (steps' mean square)")
        return out

    def summary(self) -> str:
        """One line: the verdict with its numbers (and where, when inadequate)."""
        numbers = (
            f"final RMS {self.final_rms_um:.3f} um, noise floor {self.noise_floor_um:.3f} um "
            f"({self.noise_floor_source}), chi2/dof {self.chi2_per_dof:.2f} "
            f"(1 ± {self.chi2_spread:.2f}, limit {self.chi2_limit:.2f})"
        )
        notes = "".join(f"; note: {n}" for n in self.notes)
        if self.adequate:
            return f"ADEQUATE: the residual left is noise: {numbers}{notes}"
        size = (
            f"{self.unexplained_rms_um:.3f} um RMS is left unexplained"
            if np.isfinite(self.unexplained_rms_um)
            else "the residual is structured"
        )
        return (
            f"NOT ADEQUATE: {size} ({numbers}); because {'; '.join(self.reasons)}; "
            f"it shows in: {'; '.join(self.where())}{notes}"
        )


def noise_floor(obs: Observations, fit: Fit) -> tuple[float, int]:
    """Noise per centre and axis (um) from consecutive references, and the values used.

    The references are measured at one commanded pose a few minutes apart: the
    difference of the residuals of two consecutive ones (in time order) is noise
    (the CMM's and the hexapod's positioning) times sqrt(2), plus what an
    unexplained effect changes between them (little for slow thermal effects,
    nothing for pose-dependent ones; an approach-direction effect adds). Returns
    ``(sqrt(mean(d^2) / 2) * 1e3, d.size)``, nan and 0 with fewer than two
    references.
    """
    refs = np.flatnonzero(np.array([k == "reference" for k in obs.plan.kinds], dtype=bool))
    if refs.size < 2:
        return float("nan"), 0
    refs = refs[np.argsort(obs.times_s[refs], kind="stable")]
    d = np.diff(fit.residual_mm[refs], axis=0)
    return float(np.sqrt(np.mean(d**2) / 2.0) * 1e3), int(d.size)


def adequacy(hexapod: Hexapod, obs: Observations, fit: Fit) -> Adequacy:
    """The verdict on a fitted model: is what it leaves the measurements' noise?

    Three checks, each of which can fail it:

    1. **chi-square**: ``chi2/dof`` of the weighted centre residuals, expected
       ``1 ± sqrt(2/dof)``. It fails above ``max(1.3^2, 1 + 5 sqrt(2/dof))``: the
       centres' uncertainties of sphere fits leave out the hexapod's positioning
       noise and part of a cap fit's out-of-plane noise (issue 14, part 1), so an
       adequate model on simulated campaigns reads 1.3-1.4, far beyond the
       spread; the limit is the RMS limit below in weighted form.
    2. **RMS**: the final RMS above ``RMS_RATIO_LIMIT`` (1.3) times the noise floor.
    3. **structure**: any of the tests of the pose and leg residuals (whiteness,
       trend, correlation with time and with temperature, per series), of every
       step's mean square residual against time and temperature, and across
       step kinds (Kruskal-Wallis) below ``STRUCTURE_ALPHA / n_tests``.

    Without the centres' uncertainties (``obs.u_given`` False) sigma is the
    floor estimated from consecutive references (:func:`noise_floor`).
    """
    if fit.residual_mm.shape != obs.centres_mm.shape:
        raise ValueError("the fit's residuals must have the observations' shape")
    residual = fit.residual_mm
    dof = max(fit.n - fit.p, 1)
    ref_floor, m = noise_floor(obs, fit)
    final = rms_um(residual)
    if obs.u_given:
        floor, source = float(np.sqrt(np.mean(obs.u_mm**2)) * 1e3), "centre uncertainties"
        sigma_mm = obs.u_mm
        chi2 = float(np.sum((residual / sigma_mm[..., None]) ** 2)) / dof
        spread = float(np.sqrt(2.0 / dof))
    else:
        floor, source = ref_floor, "references"
        sigma_mm = np.full(obs.u_mm.shape, floor * 1e-3)
        chi2 = float(np.sum(residual**2) / (floor * 1e-3) ** 2) / dof if m else float("nan")
        spread = float(np.sqrt(2.0 / dof + 2.0 / m)) if m else float("nan")
    limit = max(RMS_RATIO_LIMIT**2, 1.0 + CHI2_SIGMAS * spread)
    unexplained = (
        float(np.sqrt(max(0.0, final**2 - floor**2))) if np.isfinite(floor) else float("nan")
    )
    notes = []
    if not np.isfinite(floor):
        notes.append(
            "the noise floor is unknown (no centre uncertainties and fewer than two "
            "references): only the structure tests are made"
        )
    elif obs.u_given and np.isfinite(ref_floor) and ref_floor > RMS_RATIO_LIMIT * floor:
        notes.append(
            f"consecutive references scatter by {ref_floor:.3f} um, more than the centres' "
            f"uncertainties ({floor:.3f} um): they may leave out noise (the hexapod's "
            "positioning, form errors), which the verdict then counts as unexplained"
        )

    res = pose_residuals(hexapod, obs, fit)
    kinds = list(obs.plan.kinds)
    temperature = obs.log.legs_at(obs.times_s)
    summary = summarize(res, obs.plan.labels, kinds, obs.times_s, temperature, n_worst=0)
    tests: list[Finding] = []
    for st in summary.tests:
        tests += [
            Finding(st.name, "autocorrelated", st.whiteness.q, st.whiteness.p_value),
            Finding(st.name, "trend with time", st.trend.t, st.trend.p_value),
            Finding(st.name, "correlates with time", st.vs_time.rho, st.vs_time.p_value),
            Finding(
                st.name,
                "correlates with temperature",
                st.vs_temperature.rho,
                st.vs_temperature.p_value,
            ),
        ]
    step_ms = np.mean((residual / sigma_mm[..., None]) ** 2, axis=(1, 2))
    vs_time = spearman(obs.times_s, step_ms)
    vs_temp = spearman(temperature.mean(axis=1), step_ms)
    tests += [
        Finding("steps", "correlates with time", vs_time.rho, vs_time.p_value),
        Finding("steps", "correlates with temperature", vs_temp.rho, vs_temp.p_value),
    ]
    groups = [step_ms[[k == kind for k in kinds]] for kind in sorted(set(kinds))]
    groups = [g for g in groups if g.size >= 2]
    if len(groups) >= 2 and np.ptp(step_ms) > 0:
        h = stats.kruskal(*groups)
        tests.append(Finding("steps", "differs by step kind", float(h.statistic), float(h.pvalue)))
    n_tests = len(tests)
    cut = STRUCTURE_ALPHA / max(n_tests, 1)
    findings = tuple(
        sorted(
            (f for f in tests if np.isfinite(f.p_value) and f.p_value < cut),
            key=lambda f: f.p_value,
        )
    )

    reasons = []
    if np.isfinite(chi2) and chi2 > limit:
        reasons.append(f"chi2/dof {chi2:.2f} is above {limit:.2f}")
    if np.isfinite(floor) and final > RMS_RATIO_LIMIT * floor:
        reasons.append(
            f"the final RMS is {final / floor:.2f}x the noise floor (limit {RMS_RATIO_LIMIT:g}x)"
        )
    if findings:
        reasons.append(f"{len(findings)} of {n_tests} structure tests fail")

    u2 = np.mean(sigma_mm**2, axis=1) * 1e6  # per step, um^2
    step_ms_um2 = np.mean(residual**2, axis=(1, 2)) * 1e6
    kind_floor = {}
    for kind in summary.kind_rms_um:
        sel = np.array([k == kind for k in kinds], dtype=bool)
        kind_floor[kind] = float(np.sqrt(np.mean(u2[sel])))
    blocks = time_blocks(obs.times_s, TIME_PARTS)
    part_rms = np.full(TIME_PARTS, np.nan)
    part_floor = np.full(TIME_PARTS, np.nan)
    for b in range(TIME_PARTS):
        sel = blocks == b
        if sel.any():
            part_rms[b] = np.sqrt(np.mean(step_ms_um2[sel]))
            part_floor[b] = np.sqrt(np.mean(u2[sel]))
    return Adequacy(
        adequate=not reasons,
        chi2_per_dof=chi2,
        chi2_spread=spread,
        chi2_limit=limit,
        dof=dof,
        noise_floor_um=floor,
        noise_floor_source=source,
        reference_floor_um=ref_floor,
        final_rms_um=final,
        unexplained_rms_um=unexplained,
        reasons=tuple(reasons),
        findings=findings,
        n_tests=n_tests,
        component_rms=summary.component_rms,
        kind_rms_um=dict(summary.kind_rms_um),
        kind_floor_um=kind_floor,
        kind_count=dict(summary.kind_count),
        part_rms_um=part_rms,
        part_floor_um=part_floor,
        part_span_s=summary.part_span_s,
        temperature_rho=vs_temp.rho,
        notes=tuple(notes),
    )


def bound_flags(effect: Effect) -> tuple[str, ...]:
    """Parameters of a fitted effect at a bound of their range, or outside it."""
    flags = [f"{p}: {why}" for p, why in effect.out_of_range().items()]
    note = _bound_note(effect)
    return tuple(flags + ([note] if note else []))
