"""The HTML report of a processed session: figures and tables in one self-contained page.

:func:`build_report` turns a :class:`~hexatherm.workflows.process.pipeline.ProcessResult` into one
HTML file (no external resource: the figures are PNGs embedded as base64 data
URIs, the style sheet is inline, every text is escaped), with the poses'
uncertainty of :func:`hexatherm.workflows.process.uncertainty.pose_uncertainty` and the checks of
:func:`hexatherm.workflows.process.quality.quality_checks`; :func:`report_html` takes them as
given (either may be left out, and the page says so). It holds:

* the session's metadata (files, hexapod, steps, time span, interpolation, version);
* the paper's Figure 6: the six pose parameters of every target, conventional and
  corrected, as deviations from the commanded pose (um, urad), with standard
  uncertainty bars (k = 1) when an uncertainty is given; and their table;
* the paper's Figure 7: leg (and air, ...) temperatures over time;
* the legs' thermal growth measured at the references over time, and its table;
* the registration residual of every step;
* the quality flags of every step, failing rows highlighted.

The figure functions return :class:`matplotlib.figure.Figure` objects drawn with
the Agg canvas (no pyplot, no global state), so tests can read their axes' data.
matplotlib is imported inside them only.
"""

from __future__ import annotations

from hexatherm.workflows.report.figures import (
    CONVENTIONAL_COLOUR,
    CORRECTED_COLOUR,
    DEVIATION_UNITS,
    FIGURE_DPI,
    KIND_STYLES,
    LEG_COLOURS,
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
from hexatherm.workflows.report.html import (
    STYLE,
    build_report,
    failing_rows,
    growth_table_html,
    html_table,
    metadata_rows,
    poses_table_html,
    quality_table_html,
    report_html,
)

__all__ = [
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
    "growth_table_html",
    "hours_since_start",
    "html_table",
    "metadata_rows",
    "pose_deviations",
    "pose_figure",
    "poses_table_html",
    "quality_table_html",
    "reference_growth_um",
    "registration_figure",
    "report_html",
    "start_time_s",
    "target_labels",
    "temperature_figure",
]
