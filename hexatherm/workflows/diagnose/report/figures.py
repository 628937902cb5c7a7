"""The figures of diagnose: residuals over time (pose, legs), ball centres, temperatures."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

# diagnose always draws its figures: matplotlib's Figure and Agg canvas load with the
# command's modules, while the command line keeps the collector paused (until the
# command's ``imports_done``, cli/collector.py), not in the middle of its work, where
# every collection walked what they leave (about 100 of diagnose's 225 collections)
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hexatherm.core.residuals import (
    LEG_NAMES,
    POSE_COMPONENTS,
    POSE_UNITS,
    PoseResiduals,
)
from hexatherm.typing import FloatArray
from hexatherm.workflows.diagnose.report.tables import (
    _HOUR_S,
    AFTER_COLOUR,
    BEFORE_COLOUR,
    TEMPERATURE_COLOUR,
    changed,
    start_time_s,
)
from hexatherm.workflows.report.figures import WIDE_TICK_INTERVALS, few_ticks
from hexatherm.workflows.report.text import unit_text

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from hexatherm.workflows.diagnose.run import DiagnosisResult


# ------------------------------------------------------------------- figures
def _new_figure(width_in: float, height_in: float, **margins: float) -> Figure:
    """A figure on the Agg canvas (no pyplot: nothing global, nothing to close)."""
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
        return f"current model (nothing added), RMS {d.baseline_rms_um:.2f} µm"
    if state == "before":
        return f"before: current model, RMS {d.baseline_rms_um:.2f} µm"
    names = ", ".join(a.effect.name for a in d.added)
    return f"after: + {names}, RMS {d.final_rms_um:.2f} µm"


def _series_time_figure(
    result: DiagnosisResult, attribute: str, names: Sequence[str], units: Sequence[str], title: str
) -> Figure:
    order, hours = _time_order(result)
    models = _models(result)
    # (:func:`_refill_series` gives a drawn figure of these the values of another series)
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
            few_ticks(ax)
            ax.set_ylabel(f"{names[j]} ({unit_text(units[j])})", fontsize=9)
            if j == 0:
                ax.set_title(_model_title(result, state), fontsize=10)
        axes[-1, c].set_xlabel("time since start (h)", fontsize=9)
    fig.suptitle(title, fontsize=11)
    return fig


def _refill_series(
    fig: Figure,
    result: DiagnosisResult,
    attribute: str,
    names: Sequence[str],
    units: Sequence[str],
    title: str,
) -> Figure:
    """``fig``, a figure of :func:`_series_time_figure` for ``result``, turned into the
    one it makes for ``attribute``: each axes' line given the new values, its y label
    and the title replaced, its limits taken again from its lines (the axes, their
    ticks, already made by a draw, and the times stay). The same pixels as a figure
    built afresh (tested), without building and ticking 12 axes a second time."""
    order, _ = _time_order(result)
    models = _models(result)
    axes = np.array(fig.axes).reshape(6, len(models))
    for c, (_, res, _) in enumerate(models):
        values = getattr(res, attribute)
        for j in range(6):
            ax = axes[j, c]
            ax.lines[0].set_ydata(values[order, j])
            ax.set_ylabel(f"{names[j]} ({unit_text(units[j])})", fontsize=9)
            ax.relim()
            ax.autoscale_view()
    fig.suptitle(title, fontsize=11)
    return fig


#: what :func:`pose_time_figure` and :func:`legs_time_figure` plot: attribute of the
#: residuals, the rows' names and units, the title
_POSE_SERIES = (
    "pose_um",
    POSE_COMPONENTS,
    POSE_UNITS,
    "Pose residuals, measured − twin (µm, µrad)",
)
_LEGS_SERIES = (
    "legs_um",
    LEG_NAMES,
    ("um",) * 6,
    "Leg-space residuals, IGM(measured) − IGM(twin) (µm)",
)


def pose_time_figure(result: DiagnosisResult) -> Figure:
    """Pose residuals (Tx..Rz) vs time: one row per component, a column per model.

    Columns: before (current model) and after (with the added effects), each
    with its own scale; one column when nothing was added. Axes ``[j, c]`` hold
    one line, labelled ``"before"`` or ``"after"``, in time order.
    """
    return _series_time_figure(result, *_POSE_SERIES)


def legs_time_figure(result: DiagnosisResult) -> Figure:
    """Leg-space residuals (IGM of the measured minus the twin's pose) vs time, like
    :func:`pose_time_figure`."""
    return _series_time_figure(result, *_LEGS_SERIES)


def centre_rms_figure(result: DiagnosisResult) -> Figure:
    """Centre RMS of every step vs time, before and after, and the mean leg temperature.

    The first axes hold the lines labelled ``"before: RMS .. µm"`` (and ``"after: .."``)
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
    ax.set_ylabel("centre RMS of the step (µm)", fontsize=9)
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
    temp_ax.set_ylabel("mean leg temperature (°C)", fontsize=9, color=TEMPERATURE_COLOUR)
    few_ticks(ax, nbins=WIDE_TICK_INTERVALS)
    few_ticks(temp_ax, "y", nbins=WIDE_TICK_INTERVALS)
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
        few_ticks(ax)
        ax.set_title(POSE_COMPONENTS[j], fontsize=10)
        ax.set_ylabel(f"{POSE_COMPONENTS[j]} ({unit_text(POSE_UNITS[j])})", fontsize=9)
        if j >= 3:
            ax.set_xlabel("mean leg temperature (°C)", fontsize=9)
    _legend_below(fig, axes.flat[0])
    fig.suptitle("Pose residuals vs mean leg temperature (measured - twin)", fontsize=11)
    return fig


def _legend_below(fig: Figure, ax: Axes) -> None:
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=max(1, len(labels)), fontsize=9)


def report_pngs(result: DiagnosisResult, png: Callable[[Figure], bytes]) -> dict[str, bytes]:
    """Every figure of the report as ``png`` draws it, by key of :data:`FIGURE_FILES`,
    as :func:`report_figures`' figures, one after the other: the legs' figure is the
    pose's once drawn, its lines refilled (:func:`_refill_series`: 12 axes and their
    ticks not made again, the same pixels)."""
    pose = pose_time_figure(result)
    pngs = {"pose_time": png(pose)}
    pngs["legs_time"] = png(_refill_series(pose, result, *_LEGS_SERIES))
    pngs["centre_rms"] = png(centre_rms_figure(result))
    pngs["temperature"] = png(temperature_figure(result))
    return pngs


def report_figures(result: DiagnosisResult) -> dict[str, Figure]:
    """Every figure of the report, by key of :data:`FIGURE_FILES`."""
    return {
        "pose_time": pose_time_figure(result),
        "legs_time": legs_time_figure(result),
        "centre_rms": centre_rms_figure(result),
        "temperature": temperature_figure(result),
    }
