"""The search: which effects the model misses, candidate by candidate, round by round.

:func:`diagnose` (see :mod:`hexatherm.core.diagnosis`); the fitting itself is
:mod:`hexatherm.core.diagnosis.fitting`'s.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from hexatherm.core.diagnosis.adequacy import _bound_note, adequacy, bound_flags
from hexatherm.core.diagnosis.fitting import (
    _prepare_across,
    _prepare_jacobians_across,
    _Problem,
    _runs,
    fit_model,
    heldout_rms_many,
    heldout_rms_um,
)
from hexatherm.core.diagnosis.guard import twin_check
from hexatherm.core.diagnosis.model import (
    DELTA_BIC_THRESHOLD,
    SIMILARITY_THRESHOLD,
    Addition,
    Candidate,
    Fit,
    Folds,
    Observations,
    RunnerUp,
    _change,
    _cosine,
    rms_um,
)
from hexatherm.core.diagnosis.outcome import Diagnosis
from hexatherm.core.diagnosis.twins import TwinRuns
from hexatherm.core.effects import EFFECTS, Effect
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.residuals import time_blocks
from hexatherm.typing import FloatArray

#: blocks of time of the held-out check (steps in time order, even blocks against odd)
HELDOUT_BLOCKS = 6
#: the fewest steps a diagnosis is made from: two in every block of the held-out check.
#: Sessions of a twin with no hidden effect (``plan --random N``, ``simulate --plan``,
#: 8 seeds each): 4 steps, an effect added once and NOT ADEQUATE six times, of noise
#: alone; 6 steps, an effect added once; 12 and 18 steps, nothing added, all adequate
MIN_STEPS = 2 * HELDOUT_BLOCKS


def _starts(problem: _Problem, start: Sequence[FloatArray | None]) -> list[FloatArray | None]:
    return list(start) + [None] * (len(problem.free) - len(start))


def _fit(problem: _Problem, start: Sequence[FloatArray | None]) -> tuple[FloatArray, Fit]:
    """A model fitted on all steps: its solution and :class:`Fit`."""
    everything = np.ones(problem.obs.n_steps, dtype=bool)
    theta, seen = problem.solve(problem.start(_starts(problem, start), everything), everything)
    return theta, problem.fit(theta, everything, seen)


def _prepare_starts(problems: Sequence[_Problem], start: Sequence[FloatArray | None]) -> None:
    """What every candidate's fit asks first, stacked across the candidates: the start
    values, then the Jacobian at each one's best (:meth:`_Problem.solve`'s first)."""
    everything = np.ones(problems[0].obs.n_steps, dtype=bool)
    _prepare_across(
        [
            (problem, combo, everything)
            for problem in problems
            for combo in problem.start_combinations(_starts(problem, start))
        ]
    )
    best = [(problem, problem.start(_starts(problem, start), everything)) for problem in problems]
    _prepare_jacobians_across(
        [(problem, theta, everything) for problem, theta in best if theta.size]
    )


def diagnose(
    hexapod: Hexapod,
    obs: Observations,
    current: Sequence[Effect] = (),
    candidates: Sequence[str] | None = None,
    *,
    n_blocks: int = HELDOUT_BLOCKS,
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
    runs = _runs(hexapod, obs)  # shared by every fit
    problem = _Problem(hexapod, obs, current, (), runs)
    theta, baseline = _fit(problem, ())
    heldout = heldout_rms_um(problem, theta, blocks)
    baseline_heldout = heldout
    model = baseline
    added: list[Addition] = []
    rounds: list[tuple[Candidate, ...]] = []
    added_classes: list[type[Effect]] = []
    while names and len(added) < max_additions:
        starts: list[FloatArray | None] = [e.vector() for e in model.effects]
        problems = [
            _Problem(hexapod, obs, current, [*added_classes, EFFECTS[name]], runs) for name in names
        ]
        _prepare_starts(problems, starts)
        fitted: list[tuple[_Problem, FloatArray, Fit]] = []
        for problem in problems:
            theta, fit = _fit(problem, starts)
            problem.keep_only(theta)
            fitted.append((problem, theta, fit))
            if progress is not None:
                progress(len(rounds) + 1, len(fitted), len(names))
        # every candidate's held-out refits side by side (their twins run stacked)
        helds = heldout_rms_many([(problem, theta) for problem, theta, _ in fitted], blocks)
        tried: list[Candidate] = []
        for name, (_, _, fit), held in zip(names, fitted, helds, strict=True):
            delta = model.bic - fit.bic
            note = _bound_note(fit.effects[-1], fit.unseen_of(len(fit.effects) - 1))
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
            _runner_up(hexapod, obs, current, added_classes, best, others[0], runs)
            if others
            else None
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
    folds = _folds(hexapod, obs, current, model, blocks, runs)
    added = [
        replace(a, flags=bound_flags(effect, model.unseen_of(k)), folds=folds[k])
        for k, (a, effect) in enumerate(zip(added, model.effects, strict=True))
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
        twin_check(hexapod, obs, current, model, folds, blocks, runs),
    )


def _folds(
    hexapod: Hexapod,
    obs: Observations,
    current: Sequence[Effect],
    final: Fit,
    blocks: npt.NDArray[np.intp],
    runs: TwinRuns,
) -> list[Folds]:
    """The final fit's added effects refitted on each held-out fold (see :class:`Folds`)."""
    if not final.effects:
        return []
    problem = _Problem(hexapod, obs, current, [type(e) for e in final.effects], runs)
    theta = np.concatenate([e.vector() for e in final.effects])
    values: list[list[dict[str, float]]] = [[] for _ in final.effects]
    errors: list[list[dict[str, float]]] = [[] for _ in final.effects]
    trains = [blocks % 2 == parity for parity in (0, 1)]
    thetas = problem.refit(theta, trains)
    problem.prepare_jacobians(list(zip(thetas, trains, strict=True)))  # the folds' covariances
    for refitted, train in zip(thetas, trains, strict=True):
        fold = problem.fit(refitted, train)
        for k, (effect, se) in enumerate(zip(fold.effects, fold.std_errors, strict=True)):
            unseen = final.unseen_of(k)
            values[k].append(dict(effect.values))
            errors[k].append({p: float("nan") if p in unseen else v for p, v in se.items()})
    return [Folds((v[0], v[1]), (e[0], e[1])) for v, e in zip(values, errors, strict=True)]


def _runner_up(
    hexapod: Hexapod,
    obs: Observations,
    current: Sequence[Effect],
    before: Sequence[type[Effect]],
    best: Candidate,
    runner: Candidate,
    runs: TwinRuns,
) -> RunnerUp:
    """Refit the round's chosen effect together with its runner-up (see :class:`RunnerUp`)."""
    assert best.fit is not None and runner.fit is not None
    chosen = best.fit.effects[-1]
    free = [*before, type(chosen), EFFECTS[runner.name]]
    starts: list[FloatArray | None] = [e.vector() for e in best.fit.effects]
    runner_start = runner.fit.effects[-1].vector()
    both = fit_model(hexapod, obs, current, free, [*starts, runner_start], runs=runs)
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
