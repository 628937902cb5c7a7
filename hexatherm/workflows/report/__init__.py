"""The HTML report of a processed session: figures and tables in one self-contained page.

:func:`build_report` turns a :class:`~hexatherm.workflows.process.pipeline.ProcessResult` into one
HTML file (no external resource: the figures are PNGs embedded as base64 data
URIs, the style sheet is inline, every text is escaped), with the poses'
uncertainty of :func:`hexatherm.workflows.process.uncertainty.pose_uncertainty` and the checks of
:func:`hexatherm.workflows.process.quality.quality_checks`; :func:`report_html` takes them as
given (either may be left out, and the page says so). It holds:

* the verdict first (:mod:`~hexatherm.workflows.report.verdict`): targets, the ones
  that failed a check, the largest corrected deviation with its expanded uncertainty
  ``U = k u``, the size of the thermal correction, the uncertainty's basis;
* the paper's Figure 6: the six pose parameters of every target, conventional and
  corrected, as deviations from the commanded pose (µm, µrad), with expanded
  uncertainty bars (``k`` stated) when an uncertainty is given; and their tables, one
  for the conventional and one for the corrected pose;
* the paper's Figure 7: leg (and air, ...) temperatures over time;
* the legs' thermal growth measured at the references over time, and its table;
* the registration residual of every step;
* the quality flags of every step, failing rows highlighted;
* the session's metadata (files, hexapod, steps, time span, interpolation, version)
  and the provenance: generation time, command line and options, quality limits,
  input files with size and SHA-256.

Numbers have fixed decimals per unit and nominal values are exact
(:mod:`~hexatherm.workflows.report.text`); a step that failed a check is marked in
every table (:mod:`~hexatherm.workflows.report.tables`) and shaded in the pose
figure. The page prints on A4 (a print style sheet; the widest table fits 180 mm). It is
written from the template ``process.html.j2`` (:mod:`~hexatherm.workflows.report.render`),
which a lab may override with its own.

The figure functions return :class:`matplotlib.figure.Figure` objects drawn with
the Agg canvas (no pyplot, no global state), so tests can read their axes' data.
matplotlib is imported inside them only.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from hexatherm.workflows.report.figures import (
    CONVENTIONAL_COLOUR,
    CORRECTED_COLOUR,
    DEVIATION_UNITS,
    FIGURE_DPI,
    KIND_STYLES,
    LEG_COLOURS,
    LEG_STYLES,
    POSE_NAMES,
    POSE_UNITS,
    TRIAL_OFFSET,
    figure_png,
    growth_figure,
    hours_since_start,
    pose_deviations,
    pose_figure,
    reference_growth_um,
    registration_figure,
    start_time_s,
    target_labels,
    temperature_figure,
)
from hexatherm.workflows.report.page import (
    STYLE,
    Cell,
    figure,
    provenance,
    signature_table,
    table,
)
from hexatherm.workflows.report.render import Figure, Table, render_page
from hexatherm.workflows.report.text import exact, fixed, unit_text
from hexatherm.workflows.report.verdict import Extreme, Verdict, verdict

#: the page of ``report`` and its tables, loaded on first use (PEP 562): ``diagnose``
#: builds its own page from the figures, ``page`` and ``render``, and would otherwise load
#: ``process``'s pipeline and tables with them
LAZY = {
    "build_report": "html",
    "metadata_rows": "html",
    "provenance_block": "html",
    "report_html": "html",
    "verdict_failed": "html",
    "verdict_items": "html",
    "FAIL_MARK": "tables",
    "commanded_columns": "tables",
    "failing_rows": "tables",
    "growth_table": "tables",
    "poses_table": "tables",
    "poses_table_html": "tables",
    "quality_summary": "tables",
    "quality_table": "tables",
}

if TYPE_CHECKING:
    from hexatherm.workflows.report.html import (
        build_report,
        metadata_rows,
        provenance_block,
        report_html,
        verdict_failed,
        verdict_items,
    )
    from hexatherm.workflows.report.tables import (
        FAIL_MARK,
        commanded_columns,
        failing_rows,
        growth_table,
        poses_table,
        poses_table_html,
        quality_summary,
        quality_table,
    )


def __getattr__(name: str) -> Any:
    """The names of :data:`LAZY`, imported from their module when first asked for."""
    if name not in LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{LAZY[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *LAZY})


__all__ = [
    "FAIL_MARK",
    "Cell",
    "LEG_STYLES",
    "Extreme",
    "Verdict",
    "commanded_columns",
    "exact",
    "fixed",
    "figure",
    "render_page",
    "provenance_block",
    "provenance",
    "unit_text",
    "verdict",
    "verdict_failed",
    "verdict_items",
    "CONVENTIONAL_COLOUR",
    "CORRECTED_COLOUR",
    "DEVIATION_UNITS",
    "FIGURE_DPI",
    "KIND_STYLES",
    "LEG_COLOURS",
    "POSE_NAMES",
    "POSE_UNITS",
    "STYLE",
    "TRIAL_OFFSET",
    "build_report",
    "failing_rows",
    "figure_png",
    "growth_figure",
    "growth_table",
    "hours_since_start",
    "table",
    "metadata_rows",
    "pose_deviations",
    "pose_figure",
    "poses_table",
    "poses_table_html",
    "signature_table",
    "Figure",
    "Table",
    "quality_summary",
    "quality_table",
    "reference_growth_um",
    "registration_figure",
    "report_html",
    "start_time_s",
    "target_labels",
    "temperature_figure",
]
