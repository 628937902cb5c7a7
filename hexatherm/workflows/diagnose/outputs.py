"""The files of ``hexatherm diagnose``: ``diagnosis.json``, ``hexapod.yaml`` and the story.

``diagnosis.json`` holds the spec's keys ("Results of hexatherm diagnose"):
``baseline_rms_um``, ``added`` (each with ``effect``, ``parameters``,
``std_errors``, ``delta_bic``, ``rms_before_um``, ``rms_after_um``,
``heldout_rms_before_um``, ``heldout_rms_after_um``) and ``final_rms_um``, and
these extensions, documented in docs/diagnose.md:

* ``parameters`` and ``std_errors`` of an ``added`` entry are those of the final
  joint fit of every added effect (the values written to ``hexapod.yaml``);
  ``parameters_when_added`` are the values of the round that added it;
* in each ``added`` entry: ``alternatives``, the other passing candidates that
  explain the same residual (``effect``, ``delta_bic``, ``similarity``: the cosine
  of their fitted residual changes), and ``note`` (e.g. a parameter at a bound, or
  one these data do not see: not identifiable, kept at its start value);
* ``baseline_heldout_rms_um``, ``final_heldout_rms_um``;
* ``rounds``: every candidate of every round (``effect``, ``parameters``,
  ``std_errors``, ``delta_bic``, ``rms_um``, ``heldout_rms_um``, ``passes``,
  ``note``);
* ``skipped``: candidates not tried, and why;
* ``rms``: what the RMS figures are; ``session``, ``hexapod``, ``model``
  (the effects the model had before), ``centre_uncertainty``, ``hexatherm``.

* ``adequate`` (bool), ``noise_floor_um`` and ``unexplained_rms_um`` (issue 14):
  the verdict on the final model (:func:`hexatherm.core.diagnosis.adequacy`); the
  floor is the RMS expected from noise alone with the definition of ``rms``
  (from the centres' uncertainties, or, without them, from consecutive
  references), the unexplained part ``sqrt(max(0, final_rms^2 - floor^2))``;
  ``adequacy`` holds the details (chi2/dof with its spread and limit, the
  reasons, the failed structure tests, where the residual shows);
* in each ``added`` entry: ``explains`` (``"all"``, or ``"part"`` when the model
  with it still disagrees), ``flags`` (parameters of the final fit at a bound of
  their range or outside it) and ``runner_up`` (the round's runner-up fitted
  with it: the effect's parameters and standard errors without and with it).

* ``written_model`` (``"diagnosed"``, or ``"session"`` when the diagnosed model corrects
  the held-out targets worse than the session's own: then ``hexapod.yaml`` is the
  session's model and a caution says why) and ``twin_check`` (issue 35: the held-out
  twin correction of the targets, :mod:`hexatherm.core.diagnosis.guard`);
* ``cautions`` (issue 24): the sentences saying that an added effect may stand in
  for a cause outside the registry, or that two added effects trade off
  (:mod:`hexatherm.core.diagnosis.standin`); in each ``added`` entry, ``folds``:
  its parameters of the final joint fit refitted on the even and on the odd blocks
  of time, with standard errors and ``z``, their difference in combined SE.

Numbers that are not defined are written as ``null``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from typing import Any

from hexatherm import __version__
from hexatherm.core.diagnosis import Adequacy, Candidate, Folds, RunnerUp
from hexatherm.core.diagnosis.guard import TwinCheck
from hexatherm.io.config import hexapod_to_yaml
from hexatherm.workflows.diagnose.nextsteps import next_steps
from hexatherm.workflows.diagnose.run import DiagnosisResult

RMS_DEFINITION = (
    "root mean square over all steps, balls and axes of the measured minus the "
    "predicted ball centre, um; frame O fitted to all steps (held out: fitted on "
    "every other block of time, evaluated on the others)"
)


def _number(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _values(mapping: dict[str, float]) -> dict[str, float | None]:
    return {k: _number(v) for k, v in mapping.items()}


def _candidate(candidate: Candidate) -> dict[str, Any]:
    entry: dict[str, Any] = {"effect": candidate.name}
    if candidate.fit is not None and candidate.fit.effects:
        entry["parameters"] = _values(candidate.fit.effects[-1].values)
        entry["std_errors"] = _values(candidate.fit.std_errors[-1])
    entry.update(
        {
            "delta_bic": _number(candidate.delta_bic),
            "rms_um": _number(candidate.rms_um),
            "heldout_rms_um": _number(candidate.heldout_rms_um),
            "passes": candidate.passes,
            "note": candidate.note,
        }
    )
    return entry


def _adequacy(verdict: Adequacy) -> dict[str, Any]:
    return {
        "chi2_per_dof": _number(verdict.chi2_per_dof),
        "chi2_spread": _number(verdict.chi2_spread),
        "chi2_limit": _number(verdict.chi2_limit),
        "dof": verdict.dof,
        "noise_floor_source": verdict.noise_floor_source,
        "reference_floor_um": _number(verdict.reference_floor_um),
        "reasons": list(verdict.reasons),
        "where": verdict.where() if not verdict.adequate else [],
        "failed_tests": [
            {
                "series": f.series,
                "test": f.test,
                "statistic": _number(f.statistic),
                "p_value": _number(f.p_value),
            }
            for f in verdict.findings
        ],
        "n_tests": verdict.n_tests,
    }


def _runner_up(runner: RunnerUp | None) -> dict[str, Any] | None:
    if runner is None:
        return None
    return {
        "effect": runner.name,
        "delta_bic": _number(runner.delta_bic),
        "parameters_alone": _values(runner.values),
        "std_errors_alone": _values(runner.std_errors),
        "parameters_with": _values(runner.values_with),
        "std_errors_with": _values(runner.std_errors_with),
        "shift_in_se": _values(runner.shift_in_se()),
        "runner_up_parameters": _values(runner.runner_values),
        "runner_up_std_errors": _values(runner.runner_std_errors),
    }


def _folds(folds: Folds | None) -> dict[str, Any] | None:
    if folds is None:
        return None
    return {
        "parameters_even": _values(folds.values[0]),
        "parameters_odd": _values(folds.values[1]),
        "std_errors_even": _values(folds.std_errors[0]),
        "std_errors_odd": _values(folds.std_errors[1]),
        "z": _values(folds.z()),
    }


def _twin_check(check: TwinCheck | None) -> dict[str, Any] | None:
    if check is None:
        return None
    return {
        "own_heldout_um": _number(check.own_um),
        "diagnosed_heldout_um": _number(check.diagnosed_um),
        "n_targets": check.n_targets,
        "diagnosed_worse": check.worse,
    }


def diagnosis_document(result: DiagnosisResult) -> dict[str, Any]:
    """The content of ``diagnosis.json`` (spec keys first, then the extensions)."""
    diagnosis = result.diagnosis
    added = []
    final = zip(diagnosis.final.effects, diagnosis.final.std_errors, strict=True)
    for round_, addition, (effect, errors) in zip(
        diagnosis.rounds, diagnosis.added, final, strict=False
    ):
        chosen = next(c for c in round_ if c.name == addition.effect.name)
        added.append(
            {
                "effect": addition.effect.name,
                "parameters": _values(effect.values),
                "std_errors": _values(errors),
                "delta_bic": _number(addition.delta_bic),
                "rms_before_um": _number(addition.rms_before_um),
                "rms_after_um": _number(addition.rms_after_um),
                "heldout_rms_before_um": _number(addition.heldout_rms_before_um),
                "heldout_rms_after_um": _number(addition.heldout_rms_after_um),
                "alternatives": [
                    {"effect": name, "delta_bic": _number(delta), "similarity": _number(cos)}
                    for name, delta, cos in addition.alternatives
                ],
                "note": chosen.note,
                "parameters_when_added": _values(addition.effect.values),
                "explains": addition.explains,
                "flags": list(addition.flags),
                "runner_up": _runner_up(addition.runner_up),
                "folds": _folds(addition.folds),
            }
        )
    data = result.data
    verdict = diagnosis.adequacy
    doc: dict[str, Any] = {
        "baseline_rms_um": _number(diagnosis.baseline_rms_um),
        "added": added,
        "final_rms_um": _number(diagnosis.final_rms_um),
        "adequate": None if verdict is None else verdict.adequate,
        "noise_floor_um": None if verdict is None else _number(verdict.noise_floor_um),
        "unexplained_rms_um": None if verdict is None else _number(verdict.unexplained_rms_um),
        "adequacy": None if verdict is None else _adequacy(verdict),
        "cautions": diagnosis.cautions(),
        "written_model": "diagnosed" if diagnosis.writes_diagnosed else "session",
        "twin_check": _twin_check(diagnosis.twin_check),
        "baseline_heldout_rms_um": _number(diagnosis.baseline_heldout_rms_um),
        "final_heldout_rms_um": _number(diagnosis.final_heldout_rms_um),
        "rounds": [[_candidate(c) for c in round_] for round_ in diagnosis.rounds],
        "skipped": dict(diagnosis.skipped),
        "rms": RMS_DEFINITION,
        "session": data.session.name,
        "hexapod": data.hexapod_source,
        "model": [e.as_dict() for e in data.current],
        "centre_uncertainty": data.uncertainty_source,
    }
    if data.frames_said is not None:  # what the commanded poses went through
        doc["controller_frames"] = data.frames_said
    doc["hexatherm"] = __version__
    return doc


def diagnosis_json(result: DiagnosisResult) -> str:
    """``diagnosis.json`` as text."""
    return json.dumps(diagnosis_document(result), indent=2, allow_nan=False) + "\n"


def diagnosed_hexapod_yaml(result: DiagnosisResult) -> str:
    """The hexapod file with the added effects (their joint fit) appended to ``thermal_model``;
    the session's own model when the diagnosed one corrects the held-out targets worse
    (:attr:`~hexatherm.core.diagnosis.Diagnosis.writes_diagnosed`: a caution says so)."""
    hexapod = result.data.written_hexapod
    if not result.diagnosis.writes_diagnosed:
        return hexapod_to_yaml(hexapod)
    added = tuple(e.as_dict() for e in result.diagnosis.final.effects)
    effects = tuple(hexapod.effects) + added
    return hexapod_to_yaml(dataclasses.replace(hexapod, effects=effects))


def _format_effect(
    effect_values: dict[str, float], errors: dict[str, float], units: tuple[str, ...]
) -> str:
    parts = []
    for (name, value), unit in zip(effect_values.items(), units, strict=True):
        parts.append(f"{name} = {value:.4g} ± {errors.get(name, float('nan')):.2g} {unit}")
    return ", ".join(parts) + " (± standard uncertainty, k = 1)"


def candidates_table(round_: tuple[Candidate, ...]) -> str:
    """One round's candidates as a fixed-width table (as wide as its longest name)."""
    w = max([len("effect"), *(len(c.name) for c in round_)])
    lines = [f"  {'effect':<{w}} {'dBIC':>9} {'RMS_um':>8} {'heldout_um':>10}  passes  note"]
    for c in sorted(round_, key=lambda c: -c.delta_bic if math.isfinite(c.delta_bic) else 0):
        lines.append(
            f"  {c.name:<{w}} {c.delta_bic:9.1f} {c.rms_um:8.3f} "
            f"{c.heldout_rms_um:10.3f}  {'yes' if c.passes else 'no ':<6}  {c.note}"
        )
    return "\n".join(lines)


def verdict_line(summary: str, cautions: list[str]) -> str:
    """The adequacy verdict's line with the cautions that the named effects may stand
    in for a cause outside the registry (:meth:`Diagnosis.cautions`) after it."""
    return summary + "".join(f"; caution: {c}" for c in cautions)


def story(result: DiagnosisResult) -> str:
    """What the diagnosis found, in words and numbers (the command prints it)."""
    d = result.diagnosis
    data = result.data
    obs = data.observations
    model = ", ".join(e.name for e in data.current) or "no effect"
    cautions = d.cautions()
    lines = [] if d.adequacy is None else [verdict_line(d.adequacy.summary(), cautions)]
    lines += [
        f"session {data.session.name}: {obs.n_steps} steps, {obs.balls_mm.shape[0]} balls, "
        f"{obs.log.times_s.size} thermocouple samples"
        f"{' with air' if obs.log.air_C is not None else ' (no air column)'}",
        f"model: {data.hexapod_source} hexapod, thermal model: {model}",
        f"centre uncertainties: {data.uncertainty_source}",
        *([] if data.frames_said is None else [f"controller frames: {data.frames_said}"]),
        f"gap between measurements and twin: {d.baseline_rms_um:.3f} um RMS "
        f"({d.baseline_heldout_rms_um:.3f} um held out)",
    ]
    for name, why in d.skipped.items():
        lines.append(f"not tried: {name}: {why}")
    for i, round_ in enumerate(d.rounds):
        lines.append(
            f"round {i + 1}: each candidate fitted with the model "
            f"(ΔBIC > 10 and a lower held-out RMS to pass)"
        )
        lines.append(candidates_table(round_))
        if i < len(d.added):
            a = d.added[i]
            units = type(a.effect).units
            lines.append(
                f"-> added {a.effect.name} ({type(a.effect).summary}): "
                f"{_format_effect(a.effect.values, a.std_errors, units)}; ΔBIC {a.delta_bic:.1f}; "
                f"RMS {a.rms_before_um:.3f} -> {a.rms_after_um:.3f} um, held out "
                f"{a.heldout_rms_before_um:.3f} -> {a.heldout_rms_after_um:.3f} um"
            )
            if a.explains == "part":
                lines.append(
                    f"   {a.effect.name} explains part of the disagreement: the model with it "
                    "still leaves more than noise"
                )
            for flag in a.flags:
                lines.append(f"   flag: {a.effect.name}: {flag}")
            if a.runner_up is not None:
                r = a.runner_up
                moves = ", ".join(
                    f"{p} {r.values[p]:.4g} -> {r.values_with[p]:.4g} ({shift:+.1f} SE), "
                    f"SE {r.std_errors[p]:.2g} -> {r.std_errors_with[p]:.2g}"
                    for p, shift in r.shift_in_se().items()
                )
                lines.append(f"   with the runner-up {r.name} fitted too: {moves}")
            for name, delta, cos in a.alternatives:
                lines.append(
                    f"   note: {name} explains much the same residual (ΔBIC {delta:.1f}, "
                    f"similarity {cos:.2f}); {a.effect.name} fits better"
                )
        else:
            lines.append("-> nothing passes: the model is kept as it is")
    if len(d.added) > 1:
        lines.append("all added effects refitted together:")
        for effect, errors in zip(d.final.effects, d.final.std_errors, strict=True):
            lines.append(
                f"   {effect.name}: {_format_effect(effect.values, errors, type(effect).units)}"
            )
    lines += [f"caution: {c}" for c in cautions]
    if d.adequacy is not None and not d.adequacy.adequate:
        lines.append(
            f"verdict: NOT ADEQUATE: {d.adequacy.unexplained_rms_um:.3f} um RMS unexplained; "
            "the effects named explain part of it at most"
        )
        lines += [f"next: {step}" for step in next_steps(d.adequacy)]
    names = ", ".join(a.effect.name for a in d.added) or "nothing"
    lines.append(
        f"result: added {names}; gap {d.baseline_rms_um:.3f} -> {d.final_rms_um:.3f} um "
        f"RMS, held out {d.baseline_heldout_rms_um:.3f} -> "
        f"{d.final_heldout_rms_um:.3f} um"
    )
    return "\n".join(lines)
