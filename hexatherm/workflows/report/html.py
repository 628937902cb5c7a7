"""The report's HTML: tables, embedded figures, the page, and build_report."""

from __future__ import annotations

import base64
import html
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from hexatherm import __version__
from hexatherm.core.geometry import to_um_urad
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.pipeline import ProcessResult
from hexatherm.workflows.report.figures import (
    DEVIATION_UNITS,
    POSE_NAMES,
    POSE_UNITS,
    _time_text,
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

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from hexatherm.session import QualityLimits
    from hexatherm.workflows.process.quality import QualityReport
    from hexatherm.workflows.process.uncertainty import PoseUncertainty

# --------------------------------------------------------------------- HTML
STYLE = """
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1150px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.8em; margin: 0.5em 0; }
th, td { border: 1px solid #ccc; padding: 2px 6px; }
td.num { text-align: right; font-family: monospace; white-space: nowrap; }
th { background: #f0f0f0; }
tr.fail td { background: #fdd; }
td.bad { color: #b00; font-weight: bold; }
figure { margin: 0.5em 0; } figure img { max-width: 100%; }
figcaption, p.note { font-size: 0.85em; color: #555; }
pre { font-size: 0.8em; background: #f7f7f7; padding: 4px 8px; overflow-x: auto; }
p.missing { background: #fff3cd; border: 1px solid #e0c060; padding: 4px 8px; }
""".strip()


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _num(value: float, fmt: str = ".3f") -> str:
    return "" if not np.isfinite(value) else format(value, fmt)


def html_table(
    header_rows: Sequence[Sequence[tuple[str, int]]],
    rows: Iterable[Sequence[str]],
    numeric_from: int = 1,
    row_classes: Sequence[str] | None = None,
) -> str:
    """An escaped HTML table.

    Parameters
    ----------
    header_rows : sequence of sequence of (text, colspan)
    rows : iterable of sequence of str
        Cell texts (escaped here).
    numeric_from : int
        Cells from this column on are right-aligned numbers.
    row_classes : sequence of str, optional
        CSS class of each body row (``"fail"`` highlights it).
    """
    out = ["<table>", "<thead>"]
    for header in header_rows:
        cells = "".join(
            f'<th colspan="{span}">{_e(text)}</th>' if span > 1 else f"<th>{_e(text)}</th>"
            for text, span in header
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("</thead><tbody>")
    for i, row in enumerate(rows):
        cls = row_classes[i] if row_classes is not None else ""
        cells = "".join(
            f'<td class="num">{_e(c)}</td>' if k >= numeric_from else f"<td>{_e(c)}</td>"
            for k, c in enumerate(row)
        )
        out.append(f'<tr class="{_e(cls)}">{cells}</tr>' if cls else f"<tr>{cells}</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def _figure_html(fig: Figure | None, alt: str, caption: str) -> str:
    if fig is None:
        return ""
    data = base64.b64encode(figure_png(fig)).decode("ascii")
    return (
        f'<figure><img src="data:image/png;base64,{data}" alt="{_e(alt)}">'
        f"<figcaption>{_e(caption)}</figcaption></figure>"
    )


def _session_files(result: ProcessResult) -> dict[str, str]:
    """The hexapod, balls and plan file names as the session file gives them."""
    from hexatherm.io.yamlfile import YamlDoc

    data = YamlDoc.load(result.session.path).data
    return {key: str(data.get(key, "")) for key in ("hexapod", "balls", "plan")}


def metadata_rows(result: ProcessResult) -> list[tuple[str, str]]:
    """``(field, value)`` rows describing the session and how it was processed."""
    session, plan = result.session, result.session.plan
    files = _session_files(result)
    times = result.centres.times_s
    start = start_time_s(result)
    end = float(np.max(times))
    if result.temperatures is not None:
        end = max(end, float(result.temperatures.time_s[-1]))
    temps = result.temperatures
    columns = "none"
    if temps is not None:
        columns = ", ".join([f"leg{i}" for i in range(1, 7)] + list(temps.others_C))
    n_refs = len(plan.reference_indices)
    return [
        ("session", session.name),
        ("session file", str(session.path)),
        ("hexapod file", files["hexapod"]),
        ("balls file", files["balls"]),
        ("plan file", files["plan"]),
        ("measurements", ", ".join(p.name for p in session.measurements)),
        ("temperatures", "none" if session.temperatures is None else session.temperatures.name),
        ("temperature columns", columns),
        ("hexapod", f"{session.hexapod.name} (convention {session.hexapod.convention})"),
        ("balls", f"{len(session.balls.names)}: {', '.join(session.balls.names)}"),
        (
            "steps",
            f"{len(plan.labels)}: 1 origin, {n_refs} references, "
            f"{len(result.correction.target_index)} targets",
        ),
        ("reference pose (mm, deg)", ", ".join(f"{v:g}" for v in plan.reference_pose)),
        (
            "time span",
            f"{_time_text(result, start)} to {_time_text(result, end)} "
            f"({(end - start) / 3600:.2f} h)",
        ),
        ("interpolation", result.interpolation),
        ("hexatherm", __version__),
    ]


def poses_table_html(result: ProcessResult, uncertainty: PoseUncertainty | None) -> str:
    """Every target: commanded pose, conventional and corrected deviations (+- u, k = 1)."""
    conventional, corrected = pose_deviations(result)
    idx = result.correction.target_index
    commanded = result.session.plan.poses[idx]
    hours = hours_since_start(result, result.centres.times_s[idx])
    u_conv = u_corr = None
    if uncertainty is not None:
        u_conv = to_um_urad(uncertainty.conventional_u)
        u_corr = to_um_urad(uncertainty.corrected_u)

    def cells(values: FloatArray, u: FloatArray | None) -> list[str]:
        if u is None:
            return [_num(v) for v in values]
        return [f"{_num(v)} ± {_num(s)}" for v, s in zip(values, u, strict=True)]

    rows = []
    for i, label in enumerate(target_labels(result)):
        rows.append(
            [
                label,
                _time_text(result, float(result.centres.times_s[idx[i]])),
                _num(hours[i]),
                *(_num(v, ".4g") for v in commanded[i]),
                *cells(conventional[i], None if u_conv is None else u_conv[i]),
                *cells(corrected[i], None if u_corr is None else u_corr[i]),
            ]
        )
    if len(rows) > 1:
        rows.append(
            [
                "spread (max - min)",
                "",
                "",
                *[""] * 6,
                *(_num(v) for v in np.ptp(conventional, axis=0)),
                *(_num(v) for v in np.ptp(corrected, axis=0)),
            ]
        )
    units = [f"{n} ({u})" for n, u in zip(POSE_NAMES, POSE_UNITS, strict=True)]
    devs = [f"{n} ({u})" for n, u in zip(POSE_NAMES, DEVIATION_UNITS, strict=True)]
    header = [
        [("", 3), ("commanded", 6), ("conventional - commanded", 6), ("corrected - commanded", 6)],
        [("step", 1), ("time", 1), ("t (h)", 1), *[(c, 1) for c in units + devs + devs]],
    ]
    return html_table(header, rows, numeric_from=2)


def growth_table_html(result: ProcessResult) -> str:
    """Every reference step: its time and the growth of each leg since R0 (um)."""
    refs, growth = reference_growth_um(result)
    hours = hours_since_start(result, result.centres.times_s[refs])
    rows = [
        [result.session.plan.labels[r], _num(h), *(_num(g) for g in growth[k])]
        for k, (r, h) in enumerate(zip(refs, hours, strict=True))
    ]
    header = [[("reference", 1), ("t (h)", 1), *[(f"leg {i} (um)", 1) for i in range(1, 7)]]]
    return html_table(header, rows)


def failing_rows(frame: pd.DataFrame) -> list[bool]:
    """Whether each row of a quality table failed a check (its ``failed`` column is not empty)."""
    return [bool(text) for text in frame["failed"].fillna("").astype(str)]


def quality_table_html(quality: QualityReport) -> str:
    """The quality checks, one row per step: failing rows highlighted, failing values marked.

    Columns: ``label``, ``kind``, the value of every check (units in the name; empty
    when it does not apply) and ``failed`` (the failed checks).
    """
    from hexatherm.workflows.process.quality import CHECKS

    frame = quality.frame
    checks = [(column, f"ok_{check}") for check, (column, _, _) in CHECKS.items()]
    failed = failing_rows(frame)
    out = [
        "<table>",
        "<thead><tr><th>step</th><th>kind</th>"
        + "".join(f"<th>{_e(column)}</th>" for column, _ in checks)
        + "<th>failed</th></tr></thead><tbody>",
    ]
    for i, row in enumerate(frame.to_dict("records")):
        cells = [f"<td>{_e(row['label'])}</td>", f"<td>{_e(row['kind'])}</td>"]
        for column, ok in checks:
            cls = "num" if row[ok] else "num bad"
            cells.append(f'<td class="{cls}">{_e(_num(float(row[column]), ".4g"))}</td>')
        cells.append(f"<td>{_e(row['failed'])}</td>")
        out.append(('<tr class="fail">' if failed[i] else "<tr>") + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def report_html(
    result: ProcessResult,
    uncertainty: PoseUncertainty | None = None,
    quality: QualityReport | None = None,
) -> str:
    """The report page of a processed session (see the module's docstring).

    Parameters
    ----------
    result : ProcessResult
    uncertainty : PoseUncertainty, optional
        Standard uncertainties of the poses; without it the figure has no error
        bars and the page says "uncertainty not available".
    quality : QualityReport, optional
        Quality checks; without it the page says "quality checks not available".

    Returns
    -------
    str
        One self-contained HTML document.
    """
    name = result.session.name
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>hexatherm report: {_e(name)}</title>",
        f"<style>\n{STYLE}\n</style></head><body>",
        f"<h1>hexatherm report: {_e(name)}</h1>",
        "<h2>Session</h2>",
        html_table(
            [[("field", 1), ("value", 1)]],
            [[k, v] for k, v in metadata_rows(result)],
            numeric_from=99,
        ),
    ]
    if result.warnings:
        parts.append(
            "<h2>Warnings</h2><ul>"
            + "".join(f"<li>{_e(w)}</li>" for w in result.warnings)
            + "</ul>"
        )

    parts.append("<h2>Pose parameters per trial (the paper's Figure 6)</h2>")
    if uncertainty is None:
        parts.append(
            '<p class="missing">uncertainty not available: the poses are shown '
            "without uncertainty bars.</p>"
        )
    parts += [
        _figure_html(
            pose_figure(result, uncertainty),
            "pose parameters per trial",
            "Deviations of the conventional (measured) and corrected (thermal state "
            "of R0) poses from the commanded pose: translations in um, rotations in "
            "urad."
            + (
                " Error bars and \u00b1 values in the table: standard uncertainty (k = 1)."
                if uncertainty is not None
                else ""
            ),
        ),
        poses_table_html(result, uncertainty),
    ]
    if uncertainty is not None:
        method = (
            "linear propagation (GUM)"
            if uncertainty.method == "linear"
            else f"Monte Carlo, {uncertainty.draws} draws, seed {uncertainty.seed}"
        )
        parts.append(
            f'<p class="note">Uncertainty: {_e(method)}; ball centres: '
            f"{_e(uncertainty.centres.description)}.</p>"
        )

    parts.append("<h2>Temperatures (the paper's Figure 7)</h2>")
    temperature = temperature_figure(result)
    if temperature is None:
        parts.append('<p class="missing">no temperature log in this session.</p>')
    else:
        parts.append(
            _figure_html(
                temperature,
                "measured temperatures",
                "Thermocouple temperatures over time; ticks at the bottom: the targets' times.",
            )
        )

    parts += [
        "<h2>Leg growth at the references</h2>",
        _figure_html(
            growth_figure(result),
            "leg growth at the references",
            "Growth of each leg since R0 (um), from the IGM of the measured reference "
            "poses; ticks at the bottom: the targets' times.",
        ),
        growth_table_html(result),
        "<h2>Registration residuals</h2>",
        _figure_html(
            registration_figure(result),
            "registration residuals",
            "RMS distance between the measured ball centres and the registered "
            "balls file, per step (um).",
        ),
        "<h2>Quality flags</h2>",
    ]
    if quality is None:
        parts.append('<p class="missing">quality checks not available.</p>')
    else:
        failed = sum(failing_rows(quality.frame))
        parts.append(
            f'<p class="note">{failed} step(s) failing a check (highlighted, the '
            "failing values in bold). Worst value of every check and its limit:</p>"
        )
        parts.append(f"<pre>{_e(chr(10).join(quality.summary()))}</pre>")
        parts.append(quality_table_html(quality))
    parts.append(f'<p class="note">Made by hexatherm {_e(__version__)}.</p>')
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def build_report(
    result: ProcessResult,
    mc: int = 0,
    seed: int = 0,
    thresholds: QualityLimits | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> str:
    """The report page of ``result`` with its pose uncertainty and quality checks.

    Parameters
    ----------
    result : ProcessResult
    mc : int
        0: linear propagation of the uncertainty; else Monte Carlo draws.
    seed : int
        Seed of the Monte Carlo draws.
    thresholds : QualityLimits, optional
        Limits of the quality checks (default: :class:`QualityLimits`'s).
    progress : callable, optional
        ``progress(draws_done, draws)`` during Monte Carlo draws.
    """
    from hexatherm.workflows.process.quality import quality_checks
    from hexatherm.workflows.process.uncertainty import pose_uncertainty

    return report_html(
        result,
        uncertainty=pose_uncertainty(result, mc=mc, seed=seed, progress=progress),
        quality=quality_checks(result, thresholds),
    )
