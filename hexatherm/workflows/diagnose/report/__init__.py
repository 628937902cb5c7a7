"""Tables, figures and ``report.md`` of ``hexatherm diagnose``: where twin and data disagree.

From a :class:`~hexatherm.workflows.diagnose.run.DiagnosisResult`:

* :func:`summaries` sums up the residuals before (the current model) and after
  (with the added effects) with :func:`hexatherm.core.residuals.summarize`;
* :func:`summary_tables` and :func:`candidate_tables` lay them out as
  :class:`Table` objects, rendered fixed-width for the terminal
  (:func:`render_text`, :func:`terminal_tables`) or as Markdown
  (:func:`render_markdown`);
* the figure functions (:func:`pose_time_figure`, :func:`legs_time_figure`,
  :func:`centre_rms_figure`, :func:`temperature_figure`) return
  :class:`matplotlib.figure.Figure` objects on the Agg canvas (headless, no
  pyplot, nothing global); every residual line is labelled ``"before"`` or
  ``"after"`` and drawn in time order, so its data can be read back;
* :func:`report_markdown` writes ``report.md`` (the story, the candidates of
  every round, the tables before and after, the tests, links to the figures),
  :func:`report_html` the same story as one page in the style of ``report``
  (figures embedded, provenance; :mod:`hexatherm.workflows.report.page`), and
  :func:`write_report_files` writes both with the PNGs into a folder.

diagnose always draws its figures: matplotlib's Figure and Agg canvas load with these
modules (never with another command's).
"""

from __future__ import annotations

from hexatherm.workflows.diagnose.report.figures import (
    centre_rms_figure,
    legs_time_figure,
    pose_time_figure,
    report_figures,
    temperature_figure,
)
from hexatherm.workflows.diagnose.report.html import (
    REPORT_HTML,
    markdown_html,
    report_html,
    write_report_files,
)
from hexatherm.workflows.diagnose.report.markdown import (
    adequacy_section,
    headline,
    report_markdown,
)
from hexatherm.workflows.diagnose.report.tables import (
    AFTER_COLOUR,
    BEFORE_COLOUR,
    FIGURE_CAPTIONS,
    FIGURE_DPI,
    FIGURE_FILES,
    REPORT_FILE,
    TEMPERATURE_COLOUR,
    Table,
    candidate_tables,
    changed,
    format_value,
    render_markdown,
    render_text,
    start_time_s,
    structure_table,
    structure_tables,
    summaries,
    summary_tables,
    terminal_tables,
    worst_table,
)

__all__ = [
    "REPORT_HTML",
    "markdown_html",
    "report_html",
    "AFTER_COLOUR",
    "BEFORE_COLOUR",
    "FIGURE_CAPTIONS",
    "FIGURE_DPI",
    "FIGURE_FILES",
    "REPORT_FILE",
    "TEMPERATURE_COLOUR",
    "Table",
    "adequacy_section",
    "candidate_tables",
    "centre_rms_figure",
    "changed",
    "format_value",
    "headline",
    "legs_time_figure",
    "pose_time_figure",
    "render_markdown",
    "render_text",
    "report_figures",
    "report_markdown",
    "start_time_s",
    "structure_table",
    "structure_tables",
    "summaries",
    "summary_tables",
    "temperature_figure",
    "terminal_tables",
    "worst_table",
    "write_report_files",
]
