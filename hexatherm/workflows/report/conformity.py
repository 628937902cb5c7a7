"""The report's conformity statement: the verdict's item, the decision rule with the risk
it carries, and the table of every target's decision (:mod:`hexatherm.core.conformity`:
ILAC-G8:09/2019, JCGM 106:2012, ISO 14253-1)."""

from __future__ import annotations

import numpy as np

from hexatherm.core.conformity import CONFORMS, NOT_DECIDABLE, WORDS
from hexatherm.workflows.process.conformity import Conformity, tolerance_text
from hexatherm.workflows.report.page import Cell, table
from hexatherm.workflows.report.render import Table
from hexatherm.workflows.report.text import exact, fixed, unit_text


def _percent(p: float) -> str:
    return "n/a" if not np.isfinite(p) else f"{100 * p:.3g} %"


def rule_text(judged: Conformity) -> str:
    """The decision rule, as agreed with the customer, and the risk it carries at the
    acceptance limit; for the targets not decidable, what accepting them would risk."""
    rule = judged.rule
    text = (
        f"Decision rule: {rule.describe()}; U = k\u00b7u with k = "
        f"{exact(judged.coverage_factor)}. Risk: {rule.risk_text(judged.coverage_factor)}."
    )
    undecided = judged.per_target == NOT_DECIDABLE
    if undecided.any():
        risk = judged.risk_if_accepted()[undecided]
        text += (
            f" The {int(undecided.sum())} target(s) not decidable would be accepted with a "
            f"probability of being outside a tolerance of {_percent(float(risk.min()))} to "
            f"{_percent(float(risk.max()))} (at most, per target: the sum over its "
            "components of 1 \u2212 p, p the probability of conformity below)."
        )
    accepted = judged.per_target == CONFORMS
    if accepted.any():
        worst = float(judged.risk_if_accepted()[accepted].max())
        text += (
            f" Of the {int(accepted.sum())} target(s) that conform, the largest probability of "
            f"being outside a tolerance is {_percent(worst)}."
        )
    return text


def conformity_item(
    judged: Conformity, what: str = "corrected \u2212 commanded"
) -> tuple[str, str]:
    """The verdict's item: the overall decision, the counts, the tolerances and the rule
    (``what``: the deviation judged)."""
    counts = {d: int(np.sum(judged.per_target == d)) for d in WORDS}
    words = ", ".join(f"{n} {WORDS[d]}" for d, n in counts.items() if n)
    return (
        "Conformity",
        f"{WORDS[judged.overall].upper()}: {what} within "
        f"{tolerance_text(judged.keys, judged.lower, judged.upper)} ({len(judged.labels)} "
        f"targets: {words}). {rule_text(judged)}",
    )


def _zone(lower: float, upper: float, unit: str) -> str:
    if lower == -upper:
        return f"T = \u00b1{exact(upper)} {unit_text(unit)}"
    return f"T = [{exact(lower)}, {exact(upper)}] {unit_text(unit)}"


def conformity_table(
    judged: Conformity, what: str = "the corrected deviations d from the commanded pose"
) -> Table:
    """One row per target: per toleranced component the deviation with its U, the
    probability of conformity and the decision; then the target's decision. The header
    gives each tolerance zone."""
    head: list[tuple[str, int]] = [("target", 1)]
    sub: list[tuple[str, int]] = [("", 1)]
    for key, lo, hi in zip(judged.keys, judged.lower, judged.upper, strict=True):
        name, unit = key.split("_")
        head.append((f"{name}: {_zone(float(lo), float(hi), unit)}", 3))
        sub += [(f"d ({unit_text(unit)}), U", 1), ("p", 1), ("decision", 1)]
    head.append(("target", 1))
    sub.append(("decision", 1))
    rows: list[list[Cell]] = []
    classes = []
    for i, label in enumerate(judged.labels):
        row: list[Cell] = [label]
        for j, key in enumerate(judged.keys):
            unit = key.split("_")[1]
            u = judged.expanded_u[i, j]
            row += [
                (fixed(judged.deviation[i, j], unit), fixed(u, unit) if np.isfinite(u) else "n/a"),
                _percent(float(judged.p_conform[i, j])),
                WORDS[judged.decisions[i, j]],
            ]
        row.append(WORDS[judged.per_target[i]])
        rows.append(row)
        classes.append("fail" if judged.per_target[i] != "conforms" else "")
    align = "l" + "rrl" * len(judged.keys) + "l"
    return table(
        [head, sub],
        rows,
        row_classes=classes,
        align=align,
        caption=f"Conformity of {what}, U = "
        f"k\u00b7u under each (k = {exact(judged.coverage_factor)}); p: the probability that "
        "the true deviation lies in the tolerance zone (normal pdf, JCGM 106:2012). "
        f"Decision rule: {judged.rule.describe()}. Highlighted: targets that do not "
        "conform or are not decidable.",
    )
