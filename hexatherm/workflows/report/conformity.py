"""The report's conformity statement: the verdict's item and the table of every target's
decision, with the guard band (ISO 14253-1, :mod:`hexatherm.core.conformity`)."""

from __future__ import annotations

import numpy as np

from hexatherm.core.conformity import DECISION_RULE, WORDS
from hexatherm.workflows.process.conformity import Conformity, tolerance_text
from hexatherm.workflows.report.page import Cell, table
from hexatherm.workflows.report.render import Table
from hexatherm.workflows.report.text import exact, fixed, unit_text


def conformity_item(judged: Conformity) -> tuple[str, str]:
    """The verdict's item: the overall decision, the counts, the tolerances and the rule."""
    counts = {d: int(np.sum(judged.per_target == d)) for d in WORDS}
    words = ", ".join(f"{n} {WORDS[d]}" for d, n in counts.items() if n)
    return (
        "Conformity",
        f"{WORDS[judged.overall].upper()} to |corrected \u2212 commanded| \u2264 "
        f"{tolerance_text(judged.keys, judged.tolerances)} ({len(judged.labels)} targets: "
        f"{words}); decision rule {DECISION_RULE}, U = k\u00b7u with k = "
        f"{exact(judged.coverage_factor)}.",
    )


def conformity_table(judged: Conformity) -> Table:
    """One row per target: per toleranced component the deviation, its U (the guard band)
    and the decision; then the target's decision. The header gives each tolerance."""
    head: list[tuple[str, int]] = [("target", 1)]
    sub: list[tuple[str, int]] = [("", 1)]
    for key, limit in zip(judged.keys, judged.tolerances, strict=True):
        name, unit = key.split("_")
        head.append((f"{name}: T = {exact(float(limit))} {unit_text(unit)}", 3))
        sub += [(f"d ({unit_text(unit)})", 1), ("U = guard band", 1), ("decision", 1)]
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
                fixed(judged.deviation[i, j], unit),
                fixed(u, unit) if np.isfinite(u) else "n/a",
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
        caption=f"Conformity of the corrected deviations from the commanded pose: "
        f"{DECISION_RULE}. The acceptance zone is |d| \u2264 T \u2212 U. Highlighted: "
        "targets that do not conform or are not decidable.",
    )
