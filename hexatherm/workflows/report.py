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

import base64
import html
import io
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from hexatherm import __version__
from hexatherm.io.records import seconds_to_iso
from hexatherm.workflows.process.pipeline import ProcessResult

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from hexatherm.session import QualityLimits
    from hexatherm.workflows.process.quality import QualityReport
    from hexatherm.workflows.process.uncertainty import PoseUncertainty

from hexatherm.core.geometry import to_um_urad
from hexatherm.typing import FloatArray

POSE_NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
#: units of a deviation from the commanded pose, per pose parameter
DEVIATION_UNITS = ("um", "um", "um", "urad", "urad", "urad")
#: units of the pose itself, per pose parameter
POSE_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")
LEG_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
CONVENTIONAL_COLOUR = "#d62728"
CORRECTED_COLOUR = "#1f77b4"
KIND_STYLES = {
    "origin": ("#000000", "D"),
    "reference": ("#7f7f7f", "s"),
    "target": ("#1f77b4", "o"),
}
#: horizontal offset of the conventional / corrected markers around a trial's position
TRIAL_OFFSET = 0.12
FIGURE_DPI = 100


# --------------------------------------------------------------------- numbers
def target_labels(result: ProcessResult) -> list[str]:
    """Labels of the targets, in plan order."""
    return [result.session.plan.labels[i] for i in result.correction.target_index]


def pose_deviations(result: ProcessResult) -> tuple[FloatArray, FloatArray]:
    """Conventional and corrected poses minus the commanded pose, um and urad, shape (M, 6)."""
    corr = result.correction
    commanded = result.session.plan.poses[corr.target_index]
    return to_um_urad(corr.conventional - commanded), to_um_urad(corr.corrected - commanded)


def start_time_s(result: ProcessResult) -> float:
    """Start of the session: its first temperature sample or its first step, the earlier."""
    start = float(np.min(result.centres.times_s))
    if result.temperatures is not None and result.temperatures.time_s.size:
        start = min(start, float(result.temperatures.time_s[0]))
    return start


def hours_since_start(result: ProcessResult, times_s: npt.ArrayLike) -> FloatArray:
    """Times in hours since :func:`start_time_s`."""
    return (np.asarray(times_s, dtype=float) - start_time_s(result)) / 3600.0


def reference_growth_um(result: ProcessResult) -> tuple[npt.NDArray[np.intp], FloatArray]:
    """Thermal growth of every leg at every reference step since R0, um.

    Returns
    -------
    step_index : ndarray of int, shape (R,)
        The reference steps.
    growth_um : ndarray, shape (R, 6)
        ``q_R - q_R0`` of their IGM leg lengths.
    """
    refs = result.session.plan.reference_indices
    q = result.steps.q_mm
    if not refs.size:
        return refs, np.zeros((0, 6))
    return refs, (q[refs] - q[refs[0]]) * 1e3


def _time_text(result: ProcessResult, seconds: float) -> str:
    if result.centres.time_kind == "iso":
        return seconds_to_iso(seconds)[:19]
    return f"{seconds:g} s"


# --------------------------------------------------------------------- figures
def _new_figure(width_in: float, height_in: float, **margins: float) -> Figure:
    """A figure on the Agg canvas (no pyplot: nothing global, nothing to close).

    ``margins`` go to ``subplots_adjust`` (fixed margins: a layout engine would
    take half of the drawing time).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(**{"left": 0.08, "right": 0.98, "bottom": 0.12, "top": 0.92, **margins})
    return fig


def _trial_ticks(ax: Axes, labels: Sequence[str]) -> None:
    """Trial positions 1..M labelled with the targets' labels (thinned when many)."""
    every = max(1, int(np.ceil(len(labels) / 12)))
    positions = np.arange(1, len(labels) + 1)[::every]
    shown = [labels[p - 1] for p in positions]
    ax.set_xticks(positions, shown, rotation=90 if sum(map(len, shown)) > 30 else 0, fontsize=8)
    ax.set_xlim(0.4, len(labels) + 0.6)


def pose_figure(result: ProcessResult, uncertainty: PoseUncertainty | None = None) -> Figure:
    """The paper's Figure 6: pose parameters per trial, conventional and corrected.

    One panel per pose parameter; each target (trial) is at position 1..M on x,
    the conventional pose slightly left of it and the corrected one slightly
    right, as deviations from the commanded pose (um, urad). With
    ``uncertainty``, each marker has a standard uncertainty bar (k = 1).

    The lines are labelled ``"conventional"`` and ``"corrected"``.
    """
    conventional, corrected = pose_deviations(result)
    labels = target_labels(result)
    trials = np.arange(1, len(labels) + 1, dtype=float)
    bars: tuple[FloatArray | None, FloatArray | None] = (None, None)
    if uncertainty is not None:
        bars = (to_um_urad(uncertainty.conventional_u), to_um_urad(uncertainty.corrected_u))
    fig = _new_figure(11.0, 6.5, left=0.065, bottom=0.17, top=0.87, wspace=0.32, hspace=0.22)
    axes = fig.subplots(2, 3, sharex=True)
    for j, ax in enumerate(axes.flat):
        for values, u, name, colour, marker, dx in (
            (conventional, bars[0], "conventional", CONVENTIONAL_COLOUR, "o", -TRIAL_OFFSET),
            (corrected, bars[1], "corrected", CORRECTED_COLOUR, "s", TRIAL_OFFSET),
        ):
            ax.errorbar(
                trials + dx,
                values[:, j],
                yerr=None if u is None else u[:, j],
                fmt=f"{marker}-",
                color=colour,
                label=name,
                markersize=4,
                linewidth=0.8,
                elinewidth=0.8,
                capsize=2,
            )
        ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=0)
        ax.set_title(POSE_NAMES[j], fontsize=10)
        ax.set_ylabel(f"{POSE_NAMES[j]} - commanded ({DEVIATION_UNITS[j]})", fontsize=9)
        ax.grid(True, linewidth=0.3)
        _trial_ticks(ax, labels)
        if j >= 3:
            ax.set_xlabel("trial (target step)", fontsize=9)
    handles, names = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncols=2, fontsize=9)
    bar_text = (
        "error bars: standard uncertainty (k = 1)"
        if uncertainty is not None
        else "uncertainty not available: no error bars"
    )
    fig.suptitle(
        f"Measured pose parameters, deviation from the commanded pose\n{bar_text}", fontsize=11
    )
    return fig


def temperature_figure(result: ProcessResult) -> Figure | None:
    """The paper's Figure 7: leg temperatures (and air, ...) over time; None without a log.

    Lines are labelled ``"leg 1"`` .. ``"leg 6"`` and by the further columns' names
    (``"air"`` ...), x in hours since the start of the session.
    """
    temps = result.temperatures
    if temps is None:
        return None
    hours = hours_since_start(result, temps.time_s)
    fig = _new_figure(9.0, 4.5)
    ax = fig.subplots()
    for leg in range(6):
        ax.plot(
            hours,
            temps.legs_C[:, leg],
            color=LEG_COLOURS[leg],
            linewidth=1.0,
            label=f"leg {leg + 1}",
        )
    for k, (name, values) in enumerate(temps.others_C.items()):
        ax.plot(
            hours,
            values,
            color="#000000" if k == 0 else "#7f7f7f",
            linewidth=1.0,
            linestyle=("--", ":", "-.")[k % 3],
            label=name,
        )
    _mark_targets(ax, result)
    ax.set_xlabel("time since start (h)")
    ax.set_ylabel("temperature (degC)")
    ax.grid(True, linewidth=0.3)
    ax.legend(fontsize=8, ncols=2)
    ax.set_title("Measured temperatures", fontsize=11)
    return fig


def _mark_targets(ax: Axes, result: ProcessResult) -> None:
    """Ticks at the bottom of ``ax`` at the targets' times (no legend entry)."""
    hours = hours_since_start(result, result.centres.times_s[result.correction.target_index])
    ax.plot(
        hours,
        np.zeros_like(hours),
        linestyle="none",
        marker="|",
        markersize=8,
        color="#555555",
        transform=ax.get_xaxis_transform(),
        gid="targets",
        label="_targets",
    )


def growth_figure(result: ProcessResult) -> Figure:
    """Thermal growth of every leg measured at the references since R0 (um) over time.

    One line per leg (labelled ``"leg 1"`` ..), one marker per reference step; the
    straight segments between them are what the linear interpolation uses.
    """
    refs, growth = reference_growth_um(result)
    hours = hours_since_start(result, result.centres.times_s[refs])
    fig = _new_figure(9.0, 4.5)
    ax = fig.subplots()
    for leg in range(6):
        ax.plot(
            hours,
            growth[:, leg],
            marker="o",
            markersize=3,
            linewidth=1.0,
            color=LEG_COLOURS[leg],
            label=f"leg {leg + 1}",
        )
    ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=0)
    _mark_targets(ax, result)
    ax.set_xlabel("time since start (h)")
    ax.set_ylabel("growth since R0 (um)")
    ax.grid(True, linewidth=0.3)
    ax.legend(fontsize=8, ncols=2)
    ax.set_title("Leg growth measured at the references (IGM of the measured pose)", fontsize=11)
    return fig


def registration_figure(result: ProcessResult) -> Figure:
    """Registration residual (RMS, um) of every step over time, one marker style per kind.

    Lines are labelled by step kind (``"origin"``, ``"reference"``, ``"target"``).
    """
    kinds = np.array(result.session.plan.kinds)
    hours = hours_since_start(result, result.centres.times_s)
    rms = result.registration.rms_um
    fig = _new_figure(9.0, 3.5, bottom=0.14, top=0.9)
    ax = fig.subplots()
    for kind, (colour, marker) in KIND_STYLES.items():
        mask = kinds == kind
        if np.any(mask):
            ax.plot(
                hours[mask],
                rms[mask],
                linestyle="none",
                marker=marker,
                markersize=4,
                color=colour,
                label=kind,
            )
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time since start (h)")
    ax.set_ylabel("registration RMS (um)")
    ax.grid(True, linewidth=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Registration residual of every step", fontsize=11)
    return fig


def figure_png(fig: Figure, dpi: int = FIGURE_DPI) -> bytes:
    """The figure as PNG bytes."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, metadata={"Software": None})
    return buffer.getvalue()


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
