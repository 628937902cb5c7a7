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
  every round, the tables before and after, the tests, links to the figures)
  and :func:`write_report_files` writes it with the PNGs into a folder.

matplotlib is imported inside the figure functions only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from hexatherm.core.diagnosis import Diagnosis, PoseResiduals
from hexatherm.core.residuals import (
    ALPHA,
    LEG_NAMES,
    POSE_COMPONENTS,
    POSE_UNITS,
    TIME_PARTS,
    ResidualSummary,
    SeriesTests,
    WorstStep,
    summarize,
)
from hexatherm.io.records import seconds_to_iso

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from hexatherm.workflows.diagnose.run import DiagnosisResult

from hexatherm.typing import FloatArray

BEFORE_COLOUR = "#d62728"
AFTER_COLOUR = "#1f77b4"
TEMPERATURE_COLOUR = "#7f7f7f"
FIGURE_DPI = 100
_HOUR_S = 3600.0
#: figure key -> file name of the PNG written by :func:`write_report_files`
FIGURE_FILES: dict[str, str] = {
    "pose_time": "residuals_time.png",
    "legs_time": "residuals_legs_time.png",
    "centre_rms": "residuals_steps.png",
    "temperature": "residuals_temperature.png",
}
FIGURE_CAPTIONS: dict[str, str] = {
    "pose_time": "Pose residuals (measured - twin) vs time, before and after",
    "legs_time": "Leg-space residuals (IGM) vs time, before and after",
    "centre_rms": "Centre RMS of every step vs time, with the mean leg temperature",
    "temperature": "Pose residuals vs mean leg temperature, before and after",
}
REPORT_FILE = "report.md"


# ----------------------------------------------------------------- summaries
def changed(result: DiagnosisResult) -> bool:
    """Whether the diagnosis added an effect (else before and after are the same model)."""
    return bool(result.diagnosis.added)


def start_time_s(result: DiagnosisResult) -> float:
    """The session's start: the first temperature sample or the first step, whichever first."""
    obs = result.data.observations
    return float(min(obs.log.t0_s, float(np.min(obs.times_s))))


def summaries(result: DiagnosisResult, n_worst: int = 5) -> tuple[ResidualSummary, ResidualSummary]:
    """Summaries of the residuals before and after the diagnosis (equal when nothing added)."""
    obs = result.data.observations
    temperature = obs.log.legs_at(obs.times_s)
    labels, kinds = obs.plan.labels, obs.plan.kinds

    def one(res: PoseResiduals) -> ResidualSummary:
        return summarize(res, labels, kinds, obs.times_s, temperature, n_worst=n_worst)

    before = one(result.before)
    return before, (one(result.after) if changed(result) else before)


# -------------------------------------------------------------------- tables
@dataclass(frozen=True)
class Table:
    """A table: a title, column headers (units in them), rows of text.

    ``align`` holds ``"l"`` or ``"r"`` per column.
    """

    title: str
    headers: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    align: str

    def __post_init__(self) -> None:
        if len(self.align) != len(self.headers):
            raise ValueError("one alignment per column")
        if any(len(r) != len(self.headers) for r in self.rows):
            raise ValueError("every row needs one cell per column")


def render_text(table: Table) -> str:
    """Fixed-width text of a table (title, header, rule, rows).

    >>> print(render_text(Table("T", ("a", "value (um)"), (("x", "1.0"),), "lr")))
    T
    a  value (um)
    -  ----------
    x         1.0
    """
    widths = [max([len(h)] + [len(r[i]) for r in table.rows]) for i, h in enumerate(table.headers)]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(
            c.rjust(w) if a == "r" else c.ljust(w)
            for c, w, a in zip(cells, widths, table.align, strict=True)
        ).rstrip()

    out = [table.title, line(table.headers), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in table.rows]
    return "\n".join(out)


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def render_markdown(table: Table, heading: str = "###") -> str:
    """Markdown of a table, its title as a heading (none when ``heading`` is empty).

    >>> print(render_markdown(Table("T", ("a", "b (um)"), (("x", "1"),), "lr")))
    ### T
    <BLANKLINE>
    | a | b (um) |
    |:--|--:|
    | x | 1 |
    """
    out = [f"{heading} {table.title}", ""] if heading else []
    out.append("| " + " | ".join(_md_cell(h) for h in table.headers) + " |")
    out.append("|" + "|".join(":--" if a == "l" else "--:" for a in table.align) + "|")
    out += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in table.rows]
    return "\n".join(out)


def _num(x: float, decimals: int = 2) -> str:
    return "-" if not np.isfinite(x) else f"{x:.{decimals}f}"


def _p(p: float) -> str:
    if not np.isfinite(p):
        return "-"
    return f"{p:.3f}" if p >= 1e-3 else f"{p:.0e}"


def format_value(value: float, std_error: float | None = None, unit: str = "") -> str:
    """A parameter with its standard error, to the se's precision (two digits).

    >>> format_value(1509.358, 35.9, "s"), format_value(1.23e-5, 4.1e-7, "1/K")
    ('1509 ± 36 s', '1.230e-05 ± 4.1e-07 1/K')
    >>> format_value(0.5, None, "1")
    '0.5'
    """
    suffix = "" if unit in ("", "1") else f" {unit}"
    if std_error is None or not np.isfinite(std_error) or std_error <= 0:
        return f"{value:.4g}{suffix}"
    size = max(abs(value), std_error)
    if not 1e-3 <= size < 1e6:
        return f"{value:.3e} ± {std_error:.1e}{suffix}"
    decimals = max(0, 1 - int(np.floor(np.log10(std_error))))
    return f"{value:.{decimals}f} ± {std_error:.{decimals}f}{suffix}"


def _states(after: bool) -> tuple[str, ...]:
    return ("before", "after") if after else ("",)


def _h(label: str, state: str) -> str:
    """A header with the state (before/after) before the unit: 'RMS before (um)'."""
    if not state:
        return label
    name, _, unit = label.partition(" (")
    return f"{name} {state} ({unit}" if unit else f"{name} {state}"


def summary_tables(
    before: ResidualSummary,
    after: ResidualSummary | None = None,
    *,
    t0_s: float = 0.0,
    iso: bool = False,
) -> list[Table]:
    """Tables of the summaries: by component, by leg, by step kind, over time, worst steps.

    Parameters
    ----------
    before : ResidualSummary
    after : ResidualSummary, optional
        Side by side with ``before`` when given; alone, ``before`` is the model.
    t0_s : float
        Start of the session: times are shown in hours since it.
    iso : bool
        Times are POSIX seconds: the worst steps also show their UTC clock time.
    """
    pair = (before,) if after is None else (before, after)
    states = _states(after is not None)

    comp_rows = []
    for j, name in enumerate(POSE_COMPONENTS):
        comp_rows.append(
            (
                name,
                POSE_UNITS[j],
                *[_num(s.component_rms[j]) for s in pair],
                *[_num(s.component_mean[j]) for s in pair],
            )
        )
    comp = Table(
        "Pose residuals by component (measured - twin; um and urad)",
        ("component", "unit", *[_h("RMS", s) for s in states], *[_h("mean", s) for s in states]),
        tuple(comp_rows),
        "ll" + "r" * 2 * len(pair),
    )

    leg_rows = tuple(
        (name, *[_num(s.leg_rms_um[j]) for s in pair], *[_num(s.leg_mean_um[j]) for s in pair])
        for j, name in enumerate(LEG_NAMES)
    )
    legs = Table(
        "Leg-space residuals (IGM of the measured pose - IGM of the twin's)",
        ("leg", *[_h("RMS (um)", s) for s in states], *[_h("mean (um)", s) for s in states]),
        leg_rows,
        "l" + "r" * 2 * len(pair),
    )

    kind_rows = [
        (kind, str(count), *[_num(s.kind_rms_um[kind]) for s in pair])
        for kind, count in before.kind_count.items()
    ]
    kind_rows.append(("all", str(before.n_steps), *[_num(s.centre_rms_um) for s in pair]))
    kinds = Table(
        "Centre residuals by step kind",
        ("kind", "steps", *[_h("centre RMS (um)", s) for s in states]),
        tuple(kind_rows),
        "lr" + "r" * len(pair),
    )

    part_rows = []
    for b in range(TIME_PARTS):
        lo, hi = (before.part_span_s[b] - t0_s) / _HOUR_S
        part_rows.append(
            (f"{b + 1}/{TIME_PARTS}", _num(lo), _num(hi), *[_num(s.part_rms_um[b]) for s in pair])
        )
    parts = Table(
        "Centre residuals over time (steps in time order, in quarters)",
        ("part", "from (h)", "to (h)", *[_h("centre RMS (um)", s) for s in states]),
        tuple(part_rows),
        "lrr" + "r" * len(pair),
    )

    tables = [comp, legs, kinds, parts]
    for state, s in zip(states, pair, strict=True):
        tables.append(
            worst_table(s.worst, f"Worst steps{' ' + state if state else ''}", t0_s=t0_s, iso=iso)
        )
    return tables


def worst_table(
    worst: Sequence[WorstStep], title: str = "Worst steps", *, t0_s: float = 0.0, iso: bool = False
) -> Table:
    """The worst steps, largest centre RMS first."""
    rows = []
    for rank, w in enumerate(worst, start=1):
        clock = (seconds_to_iso(w.time_s)[:19],) if iso else ()
        rows.append(
            (
                str(rank),
                w.label,
                w.kind,
                _num((w.time_s - t0_s) / _HOUR_S),
                *clock,
                _num(w.centre_rms_um),
            )
        )
    headers = (
        "rank",
        "step",
        "kind",
        "time (h)",
        *(("time (UTC)",) if iso else ()),
        "centre RMS (um)",
    )
    return Table(title, headers, tuple(rows), "rllr" + ("l" if iso else "") + "r")


def structure_table(tests: Sequence[SeriesTests], title: str = "Whiteness and trend") -> Table:
    """Ljung-Box, trend and Spearman correlations of every series (time order)."""
    rows = []
    for s in tests:
        lb, tr = s.whiteness, s.trend
        white = "-" if not np.isfinite(lb.p_value) else ("yes" if lb.white() else "NO")
        rows.append(
            (
                s.name,
                s.unit,
                _num(lb.q, 1),
                str(lb.lags),
                _p(lb.p_value),
                white,
                _num(tr.slope_per_h, 3),
                _num(tr.std_error_per_h, 3),
                _num(tr.t, 1),
                _p(tr.p_value),
                _num(s.vs_time.rho),
                _p(s.vs_time.p_value),
                _num(s.vs_temperature.rho),
                _p(s.vs_temperature.p_value),
            )
        )
    headers = (
        "series",
        "unit",
        "LB Q",
        "lags",
        "p(LB)",
        f"white ({ALPHA:.0%})",
        "slope (unit/h)",
        "se (unit/h)",
        "t",
        "p(t)",
        "rho(time)",
        "p",
        "rho(temp)",
        "p",
    )
    return Table(title, headers, tuple(rows), "ll" + "r" * 12)


def structure_tables(before: ResidualSummary, after: ResidualSummary | None = None) -> list[Table]:
    """The tests' tables: one per model (before, after)."""
    if after is None:
        return [structure_table(before.tests)]
    return [
        structure_table(before.tests, "Whiteness and trend before"),
        structure_table(after.tests, "Whiteness and trend after"),
    ]


def candidate_tables(diagnosis: Diagnosis) -> list[Table]:
    """One table per round of the selection: every candidate tried and its scores."""
    tables = []
    current_rms, current_held = diagnosis.baseline_rms_um, diagnosis.baseline_heldout_rms_um
    for r, candidates in enumerate(diagnosis.rounds):
        chosen = diagnosis.added[r].effect.name if r < len(diagnosis.added) else None
        rows = []
        for c in candidates:
            params = ""
            if c.fit is not None and c.fit.effects:
                effect = c.fit.effects[-1]
                params = ", ".join(
                    f"{p} = {format_value(effect.values[p], None, u)}"
                    for p, u in zip(effect.parameters, effect.units, strict=True)
                )
            passes = ("yes, added" if c.name == chosen else "yes") if c.passes else "no"
            rows.append(
                (
                    c.name,
                    params,
                    _num(c.delta_bic, 1),
                    _num(c.rms_um),
                    _num(c.heldout_rms_um),
                    passes,
                    c.note,
                )
            )
        title = (
            f"Round {r + 1} (current model: RMS {current_rms:.2f} um, "
            f"held-out {current_held:.2f} um)"
        )
        tables.append(
            Table(
                title,
                ("candidate", "fitted", "ΔBIC", "RMS (um)", "held-out RMS (um)", "passes", "note"),
                tuple(rows),
                "llrrrll",
            )
        )
        if chosen is not None:
            current_rms = diagnosis.added[r].rms_after_um
            current_held = diagnosis.added[r].heldout_rms_after_um
    return tables


def terminal_tables(result: DiagnosisResult, *, tests: bool = True) -> str:
    """The summary tables (and the tests' tables) before and after, fixed-width text."""
    before, after = summaries(result)
    t0, iso = start_time_s(result), result.data.temperatures.time_kind == "iso"
    pair_after = after if changed(result) else None
    tables = summary_tables(before, pair_after, t0_s=t0, iso=iso)
    if tests:
        tables += structure_tables(before, pair_after)
    return "\n\n".join(render_text(t) for t in tables) + "\n"


# ------------------------------------------------------------------- figures
def _new_figure(width_in: float, height_in: float, **margins: float) -> Figure:
    """A figure on the Agg canvas (no pyplot: nothing global, nothing to close)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in))
    FigureCanvasAgg(fig)
    fig.subplots_adjust(**{"left": 0.08, "right": 0.98, "bottom": 0.08, "top": 0.92, **margins})
    return fig


def _time_order(result: DiagnosisResult) -> tuple[npt.NDArray[np.intp], FloatArray]:
    """Steps in time order and their time in hours since the start."""
    times = result.data.observations.times_s
    order = np.argsort(times, kind="stable")
    return order, (times[order] - start_time_s(result)) / _HOUR_S


def _models(result: DiagnosisResult) -> list[tuple[str, PoseResiduals, str]]:
    if changed(result):
        return [("before", result.before, BEFORE_COLOUR), ("after", result.after, AFTER_COLOUR)]
    return [("before", result.before, BEFORE_COLOUR)]


def _model_title(result: DiagnosisResult, state: str) -> str:
    d = result.diagnosis
    if not changed(result):
        return f"current model (nothing added), RMS {d.baseline_rms_um:.2f} um"
    if state == "before":
        return f"before: current model, RMS {d.baseline_rms_um:.2f} um"
    names = ", ".join(a.effect.name for a in d.added)
    return f"after: + {names}, RMS {d.final_rms_um:.2f} um"


def _series_time_figure(
    result: DiagnosisResult, attribute: str, names: Sequence[str], units: Sequence[str], title: str
) -> Figure:
    order, hours = _time_order(result)
    models = _models(result)
    fig = _new_figure(
        5.5 * len(models) + 0.5,
        11.0,
        left=0.1 if len(models) == 1 else 0.075,
        hspace=0.15,
        wspace=0.22,
        top=0.93,
        bottom=0.06,
    )
    axes = fig.subplots(6, len(models), sharex=True, squeeze=False)
    for c, (state, res, colour) in enumerate(models):
        values = getattr(res, attribute)
        for j in range(6):
            ax = axes[j, c]
            ax.plot(
                hours,
                values[order, j],
                "o-",
                color=colour,
                markersize=3,
                linewidth=0.8,
                label=state,
            )
            ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=0)
            ax.grid(True, linewidth=0.3)
            ax.tick_params(labelsize=8)
            ax.set_ylabel(f"{names[j]} ({units[j]})", fontsize=9)
            if j == 0:
                ax.set_title(_model_title(result, state), fontsize=10)
        axes[-1, c].set_xlabel("time since start (h)", fontsize=9)
    fig.suptitle(title, fontsize=11)
    return fig


def pose_time_figure(result: DiagnosisResult) -> Figure:
    """Pose residuals (Tx..Rz) vs time: one row per component, a column per model.

    Columns: before (current model) and after (with the added effects), each
    with its own scale; one column when nothing was added. Axes ``[j, c]`` hold
    one line, labelled ``"before"`` or ``"after"``, in time order.
    """
    return _series_time_figure(
        result, "pose_um", POSE_COMPONENTS, POSE_UNITS, "Pose residuals, measured - twin (um, urad)"
    )


def legs_time_figure(result: DiagnosisResult) -> Figure:
    """Leg-space residuals (IGM of the measured minus the twin's pose) vs time, like
    :func:`pose_time_figure`."""
    return _series_time_figure(
        result,
        "legs_um",
        LEG_NAMES,
        ("um",) * 6,
        "Leg-space residuals, IGM(measured) - IGM(twin) (um)",
    )


def centre_rms_figure(result: DiagnosisResult) -> Figure:
    """Centre RMS of every step vs time, before and after, and the mean leg temperature.

    The first axes hold the lines labelled ``"before: RMS .. um"`` (and ``"after: .."``)
    in time order;
    the second (right) axis the line ``"mean leg temperature"``. Reference and
    origin steps are marked by hollow squares / a diamond on the residual lines.
    """
    order, hours = _time_order(result)
    obs = result.data.observations
    kinds = np.array(obs.plan.kinds)[order]
    fig = _new_figure(10.0, 4.5, right=0.9, bottom=0.14, top=0.88)
    ax = fig.subplots()
    for state, res, colour in _models(result):
        y = res.centre_rms_um[order]
        ax.plot(
            hours,
            y,
            "o-",
            color=colour,
            markersize=3,
            linewidth=0.8,
            label=f"{state}: {_model_title(result, state).split(', ')[-1]}",
        )
        for kind, marker in (("reference", "s"), ("origin", "D")):
            sel = kinds == kind
            if sel.any():
                ax.plot(
                    hours[sel],
                    y[sel],
                    marker,
                    markerfacecolor="none",
                    color=colour,
                    markersize=6,
                    linestyle="none",
                    label=f"_{kind} {state}",
                )
    ax.set_xlabel("time since start (h)", fontsize=9)
    ax.set_ylabel("centre RMS of the step (um)", fontsize=9)
    ax.set_ylim(bottom=0.0)
    ax.grid(True, linewidth=0.3)
    temp_ax = ax.twinx()
    temperature = obs.log.legs_at(obs.times_s).mean(axis=1)[order]
    temp_ax.plot(
        hours,
        temperature,
        "--",
        color=TEMPERATURE_COLOUR,
        linewidth=1.0,
        label="mean leg temperature",
    )
    temp_ax.set_ylabel("mean leg temperature (degC)", fontsize=9, color=TEMPERATURE_COLOUR)
    handles, labels = ax.get_legend_handles_labels()
    more, more_labels = temp_ax.get_legend_handles_labels()
    ax.legend(handles + more, labels + more_labels, fontsize=8, loc="upper left")
    fig.suptitle(
        "Centre residual of every step (squares: references, diamond: origin)", fontsize=11
    )
    return fig


def temperature_figure(result: DiagnosisResult) -> Figure:
    """Pose residuals vs the mean leg temperature at each step, before and after.

    2 x 3 panels (Tx..Rz); in each, the lines ``"before"`` (and ``"after"``)
    join the steps in time order (a loop means a lag behind the temperature).
    """
    order, _ = _time_order(result)
    obs = result.data.observations
    temperature = obs.log.legs_at(obs.times_s).mean(axis=1)[order]
    fig = _new_figure(12.0, 7.0, left=0.07, hspace=0.3, wspace=0.3, bottom=0.14, top=0.9)
    axes = fig.subplots(2, 3, sharex=True)
    for j, ax in enumerate(axes.flat):
        for state, res, colour in _models(result):
            ax.plot(
                temperature,
                res.pose_um[order, j],
                "o-",
                color=colour,
                markersize=3,
                linewidth=0.5,
                label=state,
            )
        ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=0)
        ax.grid(True, linewidth=0.3)
        ax.tick_params(labelsize=8)
        ax.set_title(POSE_COMPONENTS[j], fontsize=10)
        ax.set_ylabel(f"{POSE_COMPONENTS[j]} ({POSE_UNITS[j]})", fontsize=9)
        if j >= 3:
            ax.set_xlabel("mean leg temperature (degC)", fontsize=9)
    _legend_below(fig, axes.flat[0])
    fig.suptitle("Pose residuals vs mean leg temperature (measured - twin)", fontsize=11)
    return fig


def _legend_below(fig: Figure, ax: Axes) -> None:
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=max(1, len(labels)), fontsize=9)


def report_figures(result: DiagnosisResult) -> dict[str, Figure]:
    """Every figure of the report, by key of :data:`FIGURE_FILES`."""
    return {
        "pose_time": pose_time_figure(result),
        "legs_time": legs_time_figure(result),
        "centre_rms": centre_rms_figure(result),
        "temperature": temperature_figure(result),
    }


# ------------------------------------------------------------------ report.md
def _effects_text(effects: Sequence[object]) -> str:
    if not effects:
        return "no effect (thermocouple temperatures as they are, nominal CTEs)"
    return ", ".join(
        f"{e.name} ({', '.join(f'{p} = {v:g}' for p, v in e.values.items())})"  # type: ignore[attr-defined]
        for e in effects
    )


def headline(result: DiagnosisResult) -> str:
    """The story in a few lines of Markdown: baseline, what was added, before/after."""
    d = result.diagnosis
    current = ", ".join(e.name for e in result.data.current) or "no effect"
    out = [] if d.adequacy is None else [f"**{d.adequacy.summary()}**"]
    out += [
        f"**Current model** ({current}): RMS "
        f"{d.baseline_rms_um:.2f} um, held-out {d.baseline_heldout_rms_um:.2f} um."
    ]
    if not d.added:
        out.append(
            "**Nothing added**: no candidate lowers the BIC by more than 10 *and* the "
            "held-out RMS; the residuals below are those of the current model."
        )
        return "\n\n".join(out)
    for a in d.added:
        params = ", ".join(
            f"{p} = {format_value(a.effect.values[p], a.std_errors.get(p), u)}"
            for p, u in zip(a.effect.parameters, a.effect.units, strict=True)
        )
        out.append(
            f"**Added {a.effect.name}**: {params} (ΔBIC {a.delta_bic:.1f}); RMS "
            f"{a.rms_before_um:.2f} → {a.rms_after_um:.2f} um, held-out "
            f"{a.heldout_rms_before_um:.2f} → {a.heldout_rms_after_um:.2f} um."
            + (" It explains part of the disagreement only." if a.explains == "part" else "")
            + "".join(f" Flag: {flag}." for flag in a.flags)
        )
    if len(d.added) > 1:
        out.append(
            f"**After**: RMS {d.baseline_rms_um:.2f} → {d.final_rms_um:.2f} um, held-out "
            f"{d.baseline_heldout_rms_um:.2f} → {d.final_heldout_rms_um:.2f} um."
        )
    return "\n\n".join(out)


def _alternatives_text(diagnosis: Diagnosis) -> str:
    lines = []
    for a in diagnosis.added:
        if a.alternatives:
            others = "; ".join(
                f"{name} (ΔBIC {dbic:.1f}, cosine {cos:.3f})" for name, dbic, cos in a.alternatives
            )
            lines.append(
                f"- **{a.effect.name}** explains the same residual as: {others}. "
                "The choice is the larger ΔBIC (smaller BIC); the data may not "
                "tell them apart."
            )
        else:
            lines.append(
                f"- **{a.effect.name}**: no other passing candidate explains the same residual."
            )
    return "\n".join(lines) if lines else "None (nothing was added)."


def adequacy_section(diagnosis: Diagnosis) -> list[str]:
    """Lines of the ``## Adequacy`` section: the verdict's numbers, where the residual
    shows, the failed structure tests and how each named effect moves with its runner-up."""
    v = diagnosis.adequacy
    if v is None:
        return []
    md = [
        "## Adequacy",
        "",
        f"- verdict: **{'adequate' if v.adequate else 'NOT adequate'}**"
        + (f" ({'; '.join(v.reasons)})" if v.reasons else ""),
        f"- final RMS {v.final_rms_um:.3f} um; noise floor {v.noise_floor_um:.3f} um "
        f"(from the {v.noise_floor_source}); unexplained {v.unexplained_rms_um:.3f} um",
        f"- chi2/dof {v.chi2_per_dof:.2f}, expected 1 ± {v.chi2_spread:.2f} "
        f"({v.dof} degrees of freedom); limit {v.chi2_limit:.2f}",
        f"- structure tests: {len(v.findings)} of {v.n_tests} fail "
        "(Bonferroni, family level 0.001)",
    ]
    md += [f"- note: {n}" for n in v.notes]
    if not v.adequate:
        md += [f"- it shows in: {'; '.join(v.where())}"]
    md += [f"  - {f.text()}" for f in v.findings[:12]]
    for a in diagnosis.added:
        r = a.runner_up
        line = f"- {a.effect.name} explains {a.explains}"
        if a.flags:
            line += f"; flags: {'; '.join(a.flags)}"
        if r is not None:
            moves = ", ".join(
                f"{p} {shift:+.1f} SE (SE ×{r.se_ratio()[p]:.2f})"
                for p, shift in r.shift_in_se().items()
            )
            line += f"; with the runner-up {r.name} fitted too: {moves}"
        md.append(line)
    return md + [""]


def _figure_link(key: str, figure_names: Mapping[str, str]) -> str:
    if key not in figure_names:
        return ""
    return f"![{FIGURE_CAPTIONS.get(key, key)}]({figure_names[key]})\n\n"


def report_markdown(result: DiagnosisResult, figure_names: Mapping[str, str] | None = None) -> str:
    """The text of ``report.md``.

    Parameters
    ----------
    result : DiagnosisResult
    figure_names : mapping of str to str, optional
        Figure key (of :data:`FIGURE_FILES`) -> relative path of its PNG; figures
        not in it are not linked. Default :data:`FIGURE_FILES`.
    """
    names = FIGURE_FILES if figure_names is None else figure_names
    d, data = result.diagnosis, result.data
    obs = data.observations
    before, after = summaries(result)
    pair_after = after if changed(result) else None
    t0, iso = start_time_s(result), data.temperatures.time_kind == "iso"
    span_h = (float(np.max(obs.times_s)) - t0) / _HOUR_S
    counts = ", ".join(f"{n} {k}" for k, n in before.kind_count.items())

    md = [f"# Diagnosis of {data.session.name}", "", headline(result), ""]
    md += [
        "## Session",
        "",
        f"- session: `{data.session.path}`",
        f"- hexapod: {data.hexapod_source} (`{data.hexapod.name}`)",
        f"- steps: {obs.n_steps} ({counts}), over {span_h:.2f} h",
        f"- centres' uncertainties: {data.uncertainty_source}",
        f"- current model: {_effects_text(data.current)}",
        "",
    ]

    md += adequacy_section(d)
    md += ["## What was added", ""]
    if d.added:
        rows = []
        for i, a in enumerate(d.added, start=1):
            params = ", ".join(
                f"{p} = {format_value(a.effect.values[p], a.std_errors.get(p), u)}"
                for p, u in zip(a.effect.parameters, a.effect.units, strict=True)
            )
            rows.append(
                (
                    str(i),
                    a.effect.name,
                    params,
                    _num(a.delta_bic, 1),
                    f"{a.rms_before_um:.2f} → {a.rms_after_um:.2f}",
                    f"{a.heldout_rms_before_um:.2f} → {a.heldout_rms_after_um:.2f}",
                )
            )
        md += [
            render_markdown(
                Table(
                    "",
                    (
                        "#",
                        "effect",
                        "parameters (± standard error)",
                        "ΔBIC",
                        "RMS (um)",
                        "held-out RMS (um)",
                    ),
                    tuple(rows),
                    "rllrrr",
                ),
                heading="",
            ),
            "",
        ]
    else:
        md += ["Nothing: no candidate passed (ΔBIC > 10 and a lower held-out RMS).", ""]
    md += [
        "Flagged alternatives (other passing candidates whose fitted change of the "
        "residuals is nearly parallel, |cosine| > 0.9):",
        "",
        _alternatives_text(d),
        "",
    ]

    md += [
        "## Candidates",
        "",
        "Each round fits every remaining candidate jointly with the effects already "
        "added. A candidate passes when ΔBIC > 10 and its held-out RMS is lower than the "
        "current model's; the best passing one is added.",
        "",
    ]
    for table in candidate_tables(d):
        md += [render_markdown(table), ""]
    if d.skipped:
        md += ["Not tried:", ""]
        md += [f"- {name}: {why}" for name, why in d.skipped.items()]
        md += [""]

    tables = summary_tables(before, pair_after, t0_s=t0, iso=iso)
    comp, legs, kinds, parts, *worst = tables
    what = (
        "before (the current model) and after (with the added effects)"
        if pair_after
        else "of the current model"
    )
    md += [
        "## Where the twin and the measurements disagree",
        "",
        f"Residuals of every step (origin, references, targets), measured minus the "
        f"twin's prediction, {what}. Pose components in um (Tx, Ty, Tz) and urad "
        "(Rx, Ry, Rz); leg space through the IGM.",
        "",
    ]
    md += [_figure_link("pose_time", names) + render_markdown(comp), ""]
    md += [_figure_link("legs_time", names) + render_markdown(legs), ""]
    md += [
        _figure_link("centre_rms", names) + render_markdown(kinds),
        "",
        render_markdown(parts),
        "",
    ]
    md += [_figure_link("temperature", names).rstrip("\n"), ""] if "temperature" in names else []
    md += ["## Worst steps", ""]
    for table in worst:
        md += [render_markdown(table), ""]

    md += [
        "## Whiteness and trend",
        "",
        "For each series in time order: Ljung-Box Q over the first lags (p small: "
        "autocorrelated, not white), the least-squares slope against time with its standard "
        "error and t, and Spearman's correlation with time and with temperature (mean leg "
        "temperature for pose components, the leg's own for legs). p-values are per test "
        "and assume independent residuals.",
        "",
    ]
    for table in structure_tables(before, pair_after):
        md += [render_markdown(table), ""]
    return "\n".join(md).rstrip("\n") + "\n"


def write_report_files(
    result: DiagnosisResult, out_dir: Path, *, dpi: int = FIGURE_DPI
) -> list[Path]:
    """Write ``report.md`` and its PNG figures (:data:`FIGURE_FILES`) into the folder ``out_dir``.

    The folder must exist; files of the same names are replaced. Returns the
    paths written, ``report.md`` first.
    """
    out_dir = Path(out_dir)
    written = [out_dir / REPORT_FILE]
    for key, fig in report_figures(result).items():
        path = out_dir / FIGURE_FILES[key]
        fig.savefig(path, format="png", dpi=dpi, metadata={"Software": None})
        written.append(path)
    written[0].write_text(report_markdown(result, FIGURE_FILES), encoding="utf-8")
    return written
