"""The report's tables, as data the templates print (escaped) on A4.

Numbers have the fixed decimals of their unit (:mod:`~hexatherm.workflows.report.text`),
right-aligned in tabular figures so a column lines up on its decimal point; nominal
values are exact. A step that failed a quality check is marked in every table it
appears in (its row highlighted, its label followed by :data:`FAIL_MARK`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Literal

import numpy as np

from hexatherm.core.geometry import to_um_urad
from hexatherm.core.residuals import rms
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.views import Processed, Uncertain
from hexatherm.workflows.report.figures import (
    DEVIATION_UNITS,
    POSE_NAMES,
    POSE_UNITS,
    hours_since_start,
    pose_deviations,
    reference_growth_um,
    target_labels,
)
from hexatherm.workflows.report.page import Cell, table
from hexatherm.workflows.report.render import Table, render_macro
from hexatherm.workflows.report.text import exact, fixed, unit_text

if TYPE_CHECKING:
    import pandas as pd

    from hexatherm.workflows.process.quality import QualityReport

#: what follows the label of a step that failed a quality check, in every table
FAIL_MARK = " \u2717"

#: the quality checks' columns as the report heads them, with their unit
QUALITY_HEADS = {
    "form_um": ("form", "um"),
    "diameter_dev_um": ("diameter deviation", "um"),
    "distance_dev_um": ("distance deviation", "um"),
    "registration_rms_um": ("registration RMS", "um"),
    "time_gap_s": ("time gap", "s"),
    "temperature_change_C": ("temperature change", "degC"),
    "jacobian_rcond": ("Jacobian rcond", ""),
    "growth_excess_C": ("growth beyond the log", "degC"),
    "growth_warming_C": ("warming for the growth", "degC"),
}


def head(name: str, unit: str) -> str:
    """A column head with its unit as the report writes it: ``Tx (µm)``."""
    return f"{name} ({unit_text(unit)})" if unit else name


def marked(label: str, failing: Mapping[str, str]) -> str:
    """``label``, followed by :data:`FAIL_MARK` when it failed a check."""
    return label + FAIL_MARK if label in failing else label


def commanded_columns(result: Processed) -> list[int]:
    """The pose parameters whose commanded value is not zero at every target."""
    commanded = result.session.plan.poses[result.correction.target_index]
    return [j for j in range(6) if np.any(commanded[:, j] != 0.0)]


def poses_table_html(
    result: Processed,
    uncertainty: Uncertain | None,
    which: Literal["conventional", "corrected"],
    coverage_factor: float = 2.0,
    failing: Mapping[str, str] | None = None,
) -> str:
    """:func:`poses_table` as HTML."""
    return render_macro("table", poses_table(result, uncertainty, which, coverage_factor, failing))


def poses_table(
    result: Processed,
    uncertainty: Uncertain | None,
    which: Literal["conventional", "corrected"],
    coverage_factor: float = 2.0,
    failing: Mapping[str, str] | None = None,
) -> Table:
    """Every target: commanded pose (its non-zero columns, exact) and the ``which`` pose's
    deviation from it (µm, µrad), each with its expanded uncertainty ``U = k u``.

    Parameters
    ----------
    result : ProcessResult
    uncertainty : PoseUncertainty, optional
    which : {"conventional", "corrected"}
    coverage_factor : float
        ``k`` of the expanded uncertainties (stated in the table's caption).
    failing : mapping of str to str, optional
        ``{label: failed checks}``: those rows are marked.
    """
    failing = failing or {}
    conventional, corrected = pose_deviations(result)
    deviation = corrected if which == "corrected" else conventional
    idx = result.correction.target_index
    commanded = result.session.plan.poses[idx]
    columns = commanded_columns(result)
    hours = hours_since_start(result, result.centres.times_s[idx])
    expanded: FloatArray | None = None
    if uncertainty is not None:
        u = uncertainty.corrected_u if which == "corrected" else uncertainty.conventional_u
        expanded = coverage_factor * to_um_urad(u)
    labels = target_labels(result)
    rows: list[list[Cell]] = []
    classes = []
    for i, label in enumerate(labels):
        devs: list[Cell] = [
            (
                fixed(deviation[i, j], DEVIATION_UNITS[j]),
                "" if expanded is None else fixed(expanded[i, j], DEVIATION_UNITS[j]),
            )
            for j in range(6)
        ]
        rows.append(
            [
                marked(label, failing),
                fixed(hours[i], "h"),
                *(exact(commanded[i, j]) for j in columns),
                *devs,
            ]
        )
        classes.append("fail" if label in failing else "")
    if len(rows) > 1:
        spread = np.ptp(deviation, axis=0)
        rows.append(
            [
                "spread",
                "",
                *([""] * len(columns)),
                *(fixed(spread[j], DEVIATION_UNITS[j]) for j in range(6)),
            ]
        )
        classes.append("total")
    k_text = f"k = {exact(coverage_factor)}"
    header: list[list[tuple[str, int]]] = [
        [("", 2)]
        + ([("commanded", len(columns))] if columns else [])
        + [(f"{which} \u2212 commanded", 6)],
        [
            ("step", 1),
            ("t (h)", 1),
            *[(head(POSE_NAMES[j], POSE_UNITS[j]), 1) for j in columns],
            *[(head(POSE_NAMES[j], DEVIATION_UNITS[j]), 1) for j in range(6)],
        ],
    ]
    dropped = [POSE_NAMES[j] for j in range(6) if j not in columns]
    caption = f"{which.capitalize()} pose of every target, deviation from the commanded pose"
    if expanded is not None:
        caption += f"; under each value its expanded uncertainty U ({k_text})"
    if dropped:
        caption += f"; commanded {', '.join(dropped)} = 0 at every target"
    caption += "; spread: max \u2212 min over the targets."
    return table(header, rows, numeric_from=1, row_classes=classes, caption=caption)


def growth_table(result: Processed, failing: Mapping[str, str] | None = None) -> Table:
    """Every reference step: its time and the growth of each leg since R0 (µm)."""
    failing = failing or {}
    refs, growth = reference_growth_um(result)
    hours = hours_since_start(result, result.centres.times_s[refs])
    labels = [result.session.plan.labels[r] for r in refs]
    rows = [
        [marked(label, failing), fixed(h, "h"), *(fixed(g, "um") for g in growth[k])]
        for k, (label, h) in enumerate(zip(labels, hours, strict=True))
    ]
    classes = ["fail" if label in failing else "" for label in labels]
    header = [[("reference", 1), ("t (h)", 1), *[(head(f"leg {i}", "um"), 1) for i in range(1, 7)]]]
    return table(header, rows, row_classes=classes)


def failing_rows(frame: pd.DataFrame) -> list[bool]:
    """Whether each row of a quality table failed a check (its ``failed`` column is not empty)."""
    return [bool(text) for text in frame["failed"].fillna("").astype(str)]


def quality_table(quality: QualityReport) -> Table:
    """The quality checks, one row per step: failing rows highlighted, failing values marked.

    Columns: step, kind, the value of every check (fixed decimals per column, its
    unit in the head; empty when it does not apply) and the failed checks.
    """
    from hexatherm.workflows.process.quality import CHECKS

    frame = quality.frame
    checks = [(column, f"ok_{check}") for check, (column, _, _) in CHECKS.items()]
    failed = failing_rows(frame)
    heads = [head(*QUALITY_HEADS.get(column, (column, ""))) for column, _ in checks]
    units = [QUALITY_HEADS.get(column, (column, ""))[1] for column, _ in checks]
    rows: list[list[Cell]] = []
    cell_classes = []
    for i, row in enumerate(frame.to_dict("records")):
        label = str(row["label"]) + (FAIL_MARK if failed[i] else "")
        cells: list[Cell] = [label, str(row["kind"])]
        classes = ["", ""]
        for (column, ok), unit in zip(checks, units, strict=True):
            classes.append("num" if row[ok] else "num bad")  # "na" (could not run): no failure
            cells.append(fixed(float(row[column]), unit))
        cells.append(str(row["failed"]).replace(";", ", "))
        classes.append("")
        rows.append(cells)
        cell_classes.append(classes)
    out = table(
        [[("step", 1), ("kind", 1), *[(h, 1) for h in heads], ("failed", 1)]],
        rows,
        row_classes=["fail" if f else "" for f in failed],
        css="quality",
    )
    out.cell_classes = cell_classes
    return out


def quality_summary(quality: QualityReport) -> Table:
    """One row per check: its worst value over the steps, its limit, and which steps failed
    it (or that it could not run at any step)."""
    from hexatherm.workflows.process.quality import CHECKS

    frame = quality.frame
    rows = []
    for check, (column, field, at_least) in CHECKS.items():
        name, unit = QUALITY_HEADS.get(column, (column, ""))
        values = frame[column].to_numpy(dtype=float)
        shown = values if at_least else np.abs(values)
        worst = (
            float("nan")
            if np.all(np.isnan(shown))
            else float(np.nanmin(shown) if at_least else np.nanmax(shown))
        )
        failing = frame.loc[quality.failing(check), "label"].astype(str).tolist()
        if not quality.ran_anywhere(check):
            status = "could not run"
        elif failing:
            status = f"failed at {len(failing)} step(s): " + ", ".join(failing)
        else:
            status = "ok"
        sign = "\u2265" if at_least else "\u2264"
        rows.append(
            [
                head(name, unit),
                fixed(worst, unit) if np.isfinite(worst) else "n/a",
                f"{sign} {exact(getattr(quality.thresholds, field))}",
                status,
            ]
        )
    classes = ["fail" if row[3].startswith("failed") else "" for row in rows]
    header = [[("check", 1), ("worst value", 1), ("limit", 1), ("status", 1)]]
    out = table(header, rows, numeric_from=1, row_classes=classes)
    out.cell_classes = [["", "num", "num", "wrap"]] * len(rows)  # the status: text, wrapping
    return out


def shared_parts_table(uncertainty: Uncertain, coverage_factor: float = 2.0) -> Table | None:
    """The expanded uncertainty of the corrected poses split into the part common to every
    target and the part of its own (RMS over the targets, µm and µrad), with what each
    means: the table every reader of the pose tables needs once."""
    if uncertainty.common_u is None or uncertainty.own_u is None:
        return None
    common = coverage_factor * to_um_urad(uncertainty.common_u[:, 6:])
    own = coverage_factor * to_um_urad(uncertainty.own_u[:, 6:])
    total = coverage_factor * to_um_urad(uncertainty.corrected_u)

    rows: list[list[Cell]] = [
        [name, *(fixed(v, DEVIATION_UNITS[j]) for j, v in enumerate(rms(values, axis=0)))]
        for name, values in (
            ("common to all targets (O, R0)", common),
            ("own (the target, its references)", own),
            ("total", total),
        )
    ]
    header = [
        [
            ("part of U", 1),
            *[(head(n, u), 1) for n, u in zip(POSE_NAMES, DEVIATION_UNITS, strict=True)],
        ]
    ]
    caption = (
        f"Expanded uncertainty (k = {exact(coverage_factor)}) of the corrected poses, RMS over "
        "the targets. Every corrected pose rests on the one measurement of frame O and of "
        "R0: their error moves all targets together (a common offset that reads as a bias "
        "shared by every target, not scatter between them; poses.csv u_common_*, and "
        "covariance.csv between targets). The own part is what differences between "
        "targets carry (neighbours share a reference, and two targets between the same "
        "references their interpolation error: covariance.csv). Total = "
        "sqrt(common\u00b2 + own\u00b2)."
    )
    return table(header, rows, caption=caption)
