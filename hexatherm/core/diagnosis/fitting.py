"""Fitting candidate effects.

Weighted least squares with frame O as a nuisance, BIC and held-out folds, clustered
standard errors.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from hexatherm.core.diagnosis.model import (
    _FD_STEP,
    BoolArray,
    Fit,
    Observations,
    place,
    place_many,
    twin_centres,
)
from hexatherm.core.diagnosis.twins import TwinRuns
from hexatherm.core.effects import Effect
from hexatherm.core.hexapod import Hexapod
from hexatherm.typing import FloatArray

# --------------------------------------------------------------------- the model


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
        runs: TwinRuns | None = None,
    ) -> None:
        self.hexapod, self.obs = hexapod, obs
        self.runs = _runs(hexapod, obs) if runs is None else runs
        self.fixed, self.free = tuple(fixed), tuple(free)
        self.sizes = [len(cls.parameters) for cls in self.free]

        def cat(parts: list[FloatArray]) -> FloatArray:
            return np.concatenate(parts) if parts else np.zeros(0)

        self.scale = cat([cls.scales() for cls in self.free])
        self.lo = cat([np.array([r[0] for r in cls.ranges]) for cls in self.free])
        self.hi = cat([np.array([r[1] for r in cls.ranges]) for cls in self.free])
        self.sqrt_w = 1.0 / obs.u_mm[..., None]
        # the parameters the twin's centres depend on: a CMM-side effect (a drift, a
        # scale) acts after the twin, in ``place``, so its parameters share one twin
        self._twin_sees = np.concatenate(
            [
                np.full(size, _moves_twin(cls))
                for cls, size in zip(self.free, self.sizes, strict=True)
            ]
            or [np.zeros(0, dtype=bool)]
        )
        self._cache: dict[bytes, FloatArray] = {}
        # placements and weighted residuals by (theta, mask): a Jacobian's columns, the
        # covariance's Jacobian and the held-out refits ask for the same ones again
        self._placed: dict[tuple[bytes, bytes], tuple[FloatArray, FloatArray, FloatArray]] = {}
        self._weighted: dict[tuple[bytes, bytes], FloatArray] = {}

    def effects(self, theta: FloatArray) -> tuple[Effect, ...]:
        out, i = [], 0
        for cls, size in zip(self.free, self.sizes, strict=True):
            out.append(cls.from_vector(theta[i : i + size].tolist()))
            i += size
        return self.fixed + tuple(out)

    def _twin_key(self, theta: FloatArray) -> bytes:
        return np.asarray(theta, dtype=float)[self._twin_sees].tobytes()

    def centres(self, theta: FloatArray) -> FloatArray:
        key = self._twin_key(theta)
        if key not in self._cache:
            self._cache[key] = twin_centres(self.hexapod, self.obs, self.effects(theta), self.runs)
        return self._cache[key]

    def prepare(self, thetas: Sequence[FloatArray], mask: BoolArray) -> None:
        """Evaluate several parameter sets on ``mask`` at once (:meth:`prepare_pairs`)."""
        self.prepare_pairs([(theta, mask) for theta in thetas])

    def prepare_pairs(self, pairs: Sequence[tuple[FloatArray, BoolArray]]) -> None:
        """Evaluate (parameters, mask) pairs at once (:func:`_prepare_across`)."""
        _prepare_across([(self, theta, mask) for theta, mask in pairs])

    def evaluate(
        self, theta: FloatArray, mask: BoolArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Placement of O, predicted centres and residuals (all steps) fitted on ``mask``
        (memoized: the arrays returned are shared, never to be modified)."""
        key = (np.asarray(theta, dtype=float).tobytes(), np.asarray(mask).tobytes())
        if key not in self._placed:
            self.prepare([theta], mask)
        return self._placed[key]

    def weighted(self, theta: FloatArray, mask: BoolArray) -> FloatArray:
        key = (np.asarray(theta, dtype=float).tobytes(), np.asarray(mask).tobytes())
        if key not in self._weighted:
            self._weighted[key] = (self.evaluate(theta, mask)[2] * self.sqrt_w)[mask].ravel()
        return self._weighted[key].copy()  # the optimizer's own array

    def jacobian(self, theta: FloatArray, mask: BoolArray) -> FloatArray:
        """Forward differences of the weighted residuals in units of each parameter's scale
        (the columns' twins run together, :meth:`prepare`)."""
        steps, sizes = self._differences(theta)
        self.prepare([theta, *steps], mask)
        r0 = self.weighted(theta, mask)
        cols = [
            (self.weighted(step, mask) - r0) / size for step, size in zip(steps, sizes, strict=True)
        ]
        return np.column_stack(cols) if cols else np.zeros((r0.size, 0))

    def keep_only(self, theta: FloatArray) -> None:
        """Forget what was memoized but the twins at ``theta`` and its Jacobian's points
        (what the held-out refits from ``theta`` start with): a round keeps every
        candidate's problem until its held-out refits."""
        keep = {self._twin_key(t) for t in [theta, *self._differences(theta)[0]]}
        self._cache = {k: v for k, v in self._cache.items() if k in keep}
        self._placed.clear()
        self._weighted.clear()

    def _differences(self, theta: FloatArray) -> tuple[list[FloatArray], list[float]]:
        """The points of :meth:`jacobian`'s forward differences and their steps in scales."""
        steps, sizes = [], []
        for j in range(theta.size):
            h = _FD_STEP * self.scale[j]
            if theta[j] + h > self.hi[j]:
                h = -h
            step = theta.copy()
            step[j] += h
            steps.append(step)
            sizes.append(h / self.scale[j])
        return steps, sizes

    def prepare_jacobians(self, pairs: Sequence[tuple[FloatArray, BoolArray]]) -> None:
        """Evaluate what the Jacobians at (parameters, mask) pairs need, all at once."""
        _prepare_jacobians_across([(self, theta, mask) for theta, mask in pairs])

    def start_combinations(self, starts: Sequence[FloatArray | None]) -> list[FloatArray]:
        """The combinations of start values :meth:`start` chooses from."""
        options = [
            [s] if s is not None else cls.start_values()
            for cls, s in zip(self.free, starts, strict=True)
        ]
        combos = [np.zeros(0)]
        for opts in options:
            combos = [np.concatenate([c, o]) for c in combos for o in opts]
        return [np.clip(c, self.lo, self.hi) for c in combos]

    def start(self, starts: Sequence[FloatArray | None], mask: BoolArray) -> FloatArray:
        """The best combination of start values (given ones, or each effect's own)."""
        combos = self.start_combinations(starts)
        self.prepare(combos, mask)
        costs = [float(np.sum(self.weighted(c, mask) ** 2)) for c in combos]
        return combos[int(np.argmin(costs))]

    def solve(self, theta0: FloatArray, mask: BoolArray) -> tuple[FloatArray, BoolArray]:
        """Least squares from ``theta0`` within the ranges (trust region, scaled); the
        solution, and which parameters move a prediction on these steps (the others,
        zero columns of the Jacobian, keep their start)."""
        if theta0.size == 0:
            return theta0, np.zeros(0, dtype=bool)
        # z = 1 + (theta - theta0) / scale: starting at z = 1 gives the trust region
        # a unit first radius (least_squares sizes it by |z0|, tiny near zero)
        z_lo, z_hi = 1 + (self.lo - theta0) / self.scale, 1 + (self.hi - theta0) / self.scale
        inside = 1e-9 * (z_hi - z_lo)
        z0 = np.clip(np.ones(theta0.size), z_lo + inside, z_hi - inside)

        # a parameter that moves no prediction on these data (an air-driven effect when
        # the air is constant) stays where it starts: the trust region cannot scale a
        # zero column (NaN steps)
        seen = np.linalg.norm(self.jacobian(theta0, mask), axis=0) > 0
        if not seen.any():
            return np.clip(theta0, self.lo, self.hi), seen

        def theta_of(z: FloatArray) -> FloatArray:
            full = np.ones(theta0.size)
            full[seen] = z
            return theta0 + (full - 1) * self.scale

        solution = least_squares(
            lambda z: self.weighted(theta_of(z), mask),
            z0[seen],
            jac=lambda z: self.jacobian(theta_of(z), mask)[:, seen],
            bounds=(z_lo[seen], z_hi[seen]),
            method="trf",
            x_scale=1.0,
            max_nfev=30,
            xtol=1e-8,
            ftol=1e-8,
            gtol=None,
        )
        return np.clip(theta_of(solution.x), self.lo, self.hi), seen

    def refit(
        self, theta_hat: FloatArray, masks: Sequence[BoolArray], iterations: int = 3
    ) -> list[FloatArray]:
        """Refit on each mask from a nearby solution (:func:`_refit_across`)."""
        return _refit_across([(self, theta_hat)], masks, iterations)[0]

    def fit(self, theta: FloatArray, mask: BoolArray, seen: BoolArray | None = None) -> Fit:
        """The :class:`Fit` at ``theta`` (standard errors from the Jacobian there);
        ``seen`` (from :meth:`solve`, default all) marks the parameters the data see:
        the others are the fit's ``unseen``, their standard errors NaN."""
        origin2cmm, predicted, residual = self.evaluate(theta, mask)
        rss = float(np.sum((residual * self.sqrt_w)[mask] ** 2))
        n = int(residual[mask].size)
        p = 6 + int(theta.size)
        errors: list[dict[str, float]] = []
        unseen: list[tuple[str, ...]] = []
        covariance = np.zeros((theta.size, theta.size))
        if theta.size:
            blind = np.zeros(theta.size, dtype=bool) if seen is None else ~np.asarray(seen)
            covariance = self.covariance(theta, mask)
            covariance[blind, :] = np.nan
            covariance[:, blind] = np.nan
            se = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
            i = 0
            for cls, size in zip(self.free, self.sizes, strict=True):
                errors.append(
                    dict(zip(cls.parameters, (float(v) for v in se[i : i + size]), strict=True))
                )
                unseen.append(
                    tuple(q for q, b in zip(cls.parameters, blind[i : i + size], strict=True) if b)
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
            tuple(unseen) if any(unseen) else (),
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


def _runs(hexapod: Hexapod, obs: Observations) -> TwinRuns:
    return TwinRuns(hexapod, obs.plan, obs.times_s, obs.log, obs.balls_mm)


#: the stages of :class:`~hexatherm.core.effects.Effect` the twin's centres go through
#: (all but the CMM's reading, ``cmm_coordinates_mm``)
_TWIN_STAGES = (
    "leg_temperature_C",
    "segment_temperature_C",
    "growth_mm",
    "leg_growth_mm",
    "leg_length_mm",
    "commanded_leg_length_mm",
    "ball_positions_mm",
    "base_joints_mm",
)


def _moves_twin(cls: type[Effect]) -> bool:
    """Whether an effect changes :func:`twin_centres` (overrides a stage before the CMM's)."""
    return any(getattr(cls, stage) is not getattr(Effect, stage) for stage in _TWIN_STAGES)


def fit_model(
    hexapod: Hexapod,
    obs: Observations,
    fixed: Sequence[Effect],
    free: Sequence[type[Effect]],
    start: Sequence[FloatArray | None] = (),
    mask: BoolArray | None = None,
    runs: TwinRuns | None = None,
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
    runs : TwinRuns, optional
        The twin runs of ``hexapod`` and ``obs``, to share between fits (default: new).

    Returns
    -------
    Fit
    """
    problem = _Problem(hexapod, obs, fixed, free, runs)
    mask = np.ones(obs.n_steps, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    starts = list(start) + [None] * (len(problem.free) - len(start))
    theta, seen = problem.solve(problem.start(starts, mask), mask)
    return problem.fit(theta, mask, seen)


def _prepare_across(requests: Sequence[tuple[_Problem, FloatArray, BoolArray]]) -> None:
    """Evaluate (problem, parameters, mask) requests at once, memoized in each problem as
    one by one: the twins not yet run in one stacked run (the problems share their
    :class:`TwinRuns`), the placements of a mask in one registration."""
    Todo = dict[tuple[int, bytes], tuple[_Problem, FloatArray]]
    twins: dict[int, tuple[TwinRuns, Todo]] = {}
    for problem, theta, _ in requests:
        twin_key = problem._twin_key(theta)
        if twin_key not in problem._cache:
            todo = twins.setdefault(id(problem.runs), (problem.runs, {}))[1]
            todo.setdefault((id(problem), twin_key), (problem, theta))
    for runs, todo in twins.values():
        if len(todo) == 1:
            problem, theta = next(iter(todo.values()))
            problem.centres(theta)
            continue
        sets = [problem.effects(theta) for problem, theta in todo.values()]
        for (_, twin_key), (problem, _), centres in zip(
            todo, todo.values(), runs.centres(sets), strict=True
        ):
            problem._cache[twin_key] = centres
    by_mask: dict[tuple[int, bytes], tuple[Observations, BoolArray, Todo]] = {}
    for problem, theta, mask in requests:
        mask_key = np.asarray(mask).tobytes()
        key = (np.asarray(theta, dtype=float).tobytes(), mask_key)
        if key not in problem._placed:
            group = (id(problem.obs), mask_key)
            todo = by_mask.setdefault(group, (problem.obs, mask, {}))[2]
            todo.setdefault((id(problem), key[0]), (problem, theta))
    for (_, mask_key), (obs, mask, todo) in by_mask.items():
        ys = [problem.centres(theta) for problem, theta in todo.values()]
        effects = [problem.effects(theta) for problem, theta in todo.values()]
        placed = (
            [place(ys[0], obs, effects[0], mask)]
            if len(todo) == 1
            else place_many(ys, obs, effects, mask)
        )
        for (_, theta_key), (problem, _), (origin2cmm, predicted) in zip(
            todo, todo.values(), placed, strict=True
        ):
            residual = problem.obs.centres_mm - predicted
            problem._placed[(theta_key, mask_key)] = (origin2cmm, predicted, residual)


def _prepare_jacobians_across(requests: Sequence[tuple[_Problem, FloatArray, BoolArray]]) -> None:
    """Evaluate what the Jacobians of (problem, parameters, mask) requests need, at once."""
    _prepare_across(
        [
            (problem, point, mask)
            for problem, theta, mask in requests
            for point in [theta, *problem._differences(theta)[0]]
        ]
    )


def _refit_across(
    items: Sequence[tuple[_Problem, FloatArray]], masks: Sequence[BoolArray], iterations: int = 3
) -> list[list[FloatArray]]:
    """Refit each (problem, solution) on each mask from the solution with its Jacobian
    kept (chord iterations), all side by side: each iteration's twins in one stacked run.

    The held-out folds start from the fit on all steps; the twin at the
    Jacobian's points is already memoized, so each iteration costs one twin.
    """
    free = [(problem, theta) for problem, theta in items if theta.size]
    _prepare_jacobians_across([(problem, theta, mask) for problem, theta in free for mask in masks])
    jacs = [
        [problem.jacobian(theta, mask) for mask in masks] if theta.size else []
        for problem, theta in items
    ]
    thetas = [[theta for _ in masks] for _, theta in items]
    for _ in range(iterations if free else 0):
        _prepare_across(
            [
                (problem, thetas[i][k], mask)
                for i, (problem, theta) in enumerate(items)
                if theta.size
                for k, mask in enumerate(masks)
            ]
        )
        for i, (problem, theta) in enumerate(items):
            if not theta.size:
                continue
            for k, (jac, mask) in enumerate(zip(jacs[i], masks, strict=True)):
                r = problem.weighted(thetas[i][k], mask)
                dz = np.linalg.lstsq(jac, -r, rcond=None)[0]
                thetas[i][k] = np.clip(thetas[i][k] + dz * problem.scale, problem.lo, problem.hi)
    return thetas


def heldout_rms_many(
    items: Sequence[tuple[_Problem, FloatArray]], blocks: npt.NDArray[np.intp]
) -> list[float]:
    """:func:`heldout_rms_um` of several (problem, fit on all steps), side by side."""
    trains = [blocks % 2 == parity for parity in (0, 1)]
    refitted = _refit_across(items, trains)
    _prepare_across(
        [
            (problem, theta, train)
            for (problem, _), thetas in zip(items, refitted, strict=True)
            for theta, train in zip(thetas, trains, strict=True)
        ]
    )
    out = []
    for (problem, _), thetas in zip(items, refitted, strict=True):
        squares, count = 0.0, 0
        for theta, train in zip(thetas, trains, strict=True):
            held = problem.evaluate(theta, train)[2][~train]
            squares += float(np.sum(held**2))
            count += held.size
        out.append(float(np.sqrt(squares / count) * 1e3))
    return out


def heldout_rms_um(problem: _Problem, theta_hat: FloatArray, blocks: npt.NDArray[np.intp]) -> float:
    """RMS (um) of the residuals of steps the model was not fitted to.

    Two folds: fitted on the even blocks of time, evaluated on the odd ones, and
    the other way round (each fold refitted from ``theta_hat``, the fit on all
    steps); the RMS is over both held-out halves.
    """
    return heldout_rms_many([(problem, theta_hat)], blocks)[0]
