"""The report's numbers and figures (matplotlib).

The paper's Figures 6 and 7, the growth at the references, the registration residuals,
drawn at :data:`FIGURE_DPI` with units as the report writes them (µm, µrad, °C)."""

from __future__ import annotations

import functools
import io
from collections.abc import Collection, Sequence
from typing import TYPE_CHECKING, cast

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import to_um_urad
from hexatherm.io.records import seconds_to_iso
from hexatherm.typing import FloatArray
from hexatherm.workflows.report.text import exact, unit_text

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.legend import Legend
    from matplotlib.ticker import MaxNLocator

    from hexatherm.workflows.process.views import Processed, Uncertain


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


FIGURE_DPI = 150

#: zlib level of the figures' PNGs (0-9). The pixels are the same at every level; 3
#: encodes in about two thirds of the time of zlib's default (6) for about 10 % more bytes
#: (diagnose's four figures: 0.30 -> 0.21 s, 1.36 -> 1.49 MB at 16 targets)
PNG_COMPRESS_LEVEL = 3


#: line style and marker of each leg (and of the further temperature columns), so
#: that no line hides another where they overlap
LEG_STYLES = (
    ("-", "o"),
    ("--", "s"),
    ("-.", "^"),
    (":", "D"),
    ((0, (6, 2, 1, 2, 1, 2)), "v"),
    ((0, (1, 1)), "P"),
)

#: markers along a line of many samples: about this many per line, shifted per leg
MARKS_PER_LINE = 12


# --------------------------------------------------------------------- numbers
def target_labels(result: Processed) -> list[str]:
    """Labels of the targets, in plan order."""
    return [result.session.plan.labels[i] for i in result.correction.target_index]


def pose_deviations(result: Processed) -> tuple[FloatArray, FloatArray]:
    """Conventional and corrected poses minus the commanded pose, um and urad, shape (M, 6)."""
    corr = result.correction
    commanded = result.session.plan.poses[corr.target_index]
    return to_um_urad(corr.conventional - commanded), to_um_urad(corr.corrected - commanded)


def start_time_s(result: Processed) -> float:
    """Start of the session: its first temperature sample or its first step, the earlier."""
    start = float(np.min(result.centres.times_s))
    if result.temperatures is not None and result.temperatures.time_s.size:
        start = min(start, float(result.temperatures.time_s[0]))
    return start


def hours_since_start(result: Processed, times_s: npt.ArrayLike) -> FloatArray:
    """Times in hours since :func:`start_time_s`."""
    return (np.asarray(times_s, dtype=float) - start_time_s(result)) / 3600.0


def reference_growth_um(result: Processed) -> tuple[npt.NDArray[np.intp], FloatArray]:
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


def _time_text(result: Processed, seconds: float) -> str:
    if result.centres.time_kind == "iso":
        return seconds_to_iso(seconds)[:19]
    return f"{seconds:g} s"


# --------------------------------------------------------------------- ticks
#: the most intervals between ticks on an axis of a grid of panels, counted from the
#: tick at or below the axis' start to the one at or above its end (as
#: :class:`~matplotlib.ticker.MaxNLocator` counts them), and the tick steps
#: (matplotlib's default gives up to 9 ticks an axis): every tick is an object
#: matplotlib makes and draws with its line, grid line and label, most of a panel's
#: drawing; a reader still finds a labelled grid line every 1-2 divisions of the data
TICK_INTERVALS = 4
TICK_STEPS = (1.0, 2.0, 2.5, 5.0, 10.0)

#: the same for a figure's one wide panel (or two side by side) and a colour bar: 4-6
#: labelled ticks
WIDE_TICK_INTERVALS = 6

#: the fewest labelled ticks an axis shows
MIN_TICKS = 3


@functools.cache
def _in_view_class() -> type[MaxNLocator]:
    from matplotlib.ticker import MaxNLocator

    class InViewLocator(MaxNLocator):
        """MaxNLocator's ticks that lie in the view (see :func:`in_view_locator`)."""

        def tick_values(self, vmin: float, vmax: float) -> Sequence[float]:
            ticks = np.asarray(super().tick_values(vmin, vmax), dtype=float)
            low, high = sorted((vmin, vmax))
            # as matplotlib keeps a tick to draw: within the view, to rounding
            slack = 1e-10 * max(high - low, abs(high), abs(low))
            return cast("Sequence[float]", ticks[(ticks >= low - slack) & (ticks <= high + slack)])

    return InViewLocator


def in_view_locator(nbins: int = TICK_INTERVALS) -> MaxNLocator:
    """A :class:`~matplotlib.ticker.MaxNLocator` of at most ``nbins`` intervals, nice
    steps (:data:`TICK_STEPS`) and at least :data:`MIN_TICKS` ticks in the view, that
    gives only the ticks in the view: matplotlib makes a tick (its two lines, grid line
    and two labels) for every location a locator gives and draws those in the view only;
    MaxNLocator gives one beyond each end. The same ticks drawn, a quarter to a third
    fewer made."""
    return _in_view_class()(nbins=nbins, steps=list(TICK_STEPS), min_n_ticks=MIN_TICKS)


def few_ticks(ax: Axes, which: str = "xy", nbins: int = TICK_INTERVALS) -> None:
    """At most ``nbins`` intervals between the ticks of ``ax``'s axes named in ``which``
    (``"x"``, ``"y"``), at least :data:`MIN_TICKS` of them, the ticks in the view only
    (:func:`in_view_locator`; shared axes share the locator)."""
    for name in which:
        (ax.xaxis if name == "x" else ax.yaxis).set_major_locator(in_view_locator(nbins))


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


#: the longest target label a tick of Figure 6 prints whole; a longer one keeps its first
#: 5 and last 6 characters about an ellipsis (the tables print it whole)
TICK_CHARS = 12


def tick_labels(labels: Sequence[str]) -> list[str]:
    """The targets' labels as ticks print them: whole up to :data:`TICK_CHARS`, else
    shortened in the middle; the trial numbers 1..M if shortened ones would collide.

    >>> tick_labels(["S1", "S2-WORKSPACE-CORNER-A", "S3-WORKSPACE-CORNER-B"])
    ['S1', 'S2-WO…RNER-A', 'S3-WO…RNER-B']
    >>> tick_labels(["A-WORKSPACE-1", "A-WORKSPACE-1-B-WORKSPACE-1"])
    ['1', '2']
    """
    head, tail = TICK_CHARS // 2 - 1, TICK_CHARS // 2
    shown = [s if len(s) <= TICK_CHARS else s[:head] + "\u2026" + s[-tail:] for s in labels]
    if len(set(shown)) < len(set(labels)):
        return [str(i) for i in range(1, len(labels) + 1)]
    return shown


def _trial_ticks(ax: Axes, labels: Sequence[str]) -> None:
    """Trial positions 1..M labelled with the targets' labels (thinned when many; long
    ones shortened, :func:`tick_labels`)."""
    every = max(1, int(np.ceil(len(labels) / 12)))
    positions = np.arange(1, len(labels) + 1)[::every]
    ticks = tick_labels(labels)
    shown = [ticks[p - 1] for p in positions]
    ax.set_xticks(positions, shown, rotation=90 if sum(map(len, shown)) > 16 else 0, fontsize=8)
    ax.set_xlim(0.4, len(labels) + 0.6)


def _room_below(fig: Figure, ax: Axes) -> None:
    """Raise the bottom of ``fig``'s panels when ``ax``'s tick labels and x label need
    more room than the figure's margin gives (measured, not drawn: long labels); as it
    was otherwise."""
    from matplotlib import rcParams

    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    ticks = ax.get_xticklabels()
    points = fig.dpi / 72.0
    tick = max(t.get_tick_padding() for t in ax.xaxis.get_major_ticks())  # its length out
    need = (
        max((t.get_window_extent(renderer).height for t in ticks), default=0.0)
        + ax.xaxis.label.get_window_extent(renderer).height
        + (tick + float(rcParams["xtick.major.pad"]) + ax.xaxis.labelpad) * points
    )
    height = fig.bbox.height
    bottom = fig.subplotpars.bottom
    if need + 2.0 * points > bottom * height:
        fig.subplots_adjust(bottom=(need + 2.0 * points) / height)


def _room_above(fig: Figure, legend: Legend, axes: Sequence[Axes]) -> None:
    """Lower the top of ``fig``'s panels when their titles would reach into ``legend``
    (above them: a legend of two rows, measured, not drawn), by as much as they do and
    a gap of 2 points (a legend of one row leaves 2.2); as it was otherwise."""
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    floor = legend.get_window_extent(renderer).y0 - 2.0 * fig.dpi / 72.0
    reach = max(ax.title.get_window_extent(renderer).y1 for ax in axes)
    if reach > floor:
        height = fig.bbox.height
        fig.subplots_adjust(top=fig.subplotpars.top - (reach - floor) / height)


def pose_figure(
    result: Processed,
    uncertainty: Uncertain | None = None,
    coverage_factor: float = 2.0,
    failing: Collection[str] = (),
) -> Figure:
    """The paper's Figure 6: pose parameters per trial, conventional and corrected.

    One panel per pose parameter; each target (trial) is at position 1..M on x,
    the conventional pose slightly left of it and the corrected one slightly
    right, as deviations from the commanded pose (µm, µrad). With
    ``uncertainty``, each marker has an expanded uncertainty bar ``U = k u``
    (``k = coverage_factor``, stated in the title).

    With the uncertainty's common part (``common_u``), a band with gid ``"common"``
    spans ``+-k u_common`` of the corrected poses about zero: the part of U from the one
    measurement of O and R0, which shifts every target's corrected pose together.

    The lines are labelled ``"conventional"`` and ``"corrected"``; a target in
    ``failing`` (labels that failed a quality check) gets a shaded band with gid
    ``"failed"``, labelled ``"failed a check"`` in the legend.
    """
    conventional, corrected = pose_deviations(result)
    labels = target_labels(result)
    trials = np.arange(1, len(labels) + 1, dtype=float)
    bars: tuple[FloatArray | None, FloatArray | None] = (None, None)
    if uncertainty is not None:
        bars = (
            coverage_factor * to_um_urad(uncertainty.conventional_u),
            coverage_factor * to_um_urad(uncertainty.corrected_u),
        )
    common = None
    if uncertainty is not None and uncertainty.common_u is not None:
        common = coverage_factor * to_um_urad(uncertainty.common_u[:, 6:12])
    band_x = trials
    if common is not None and len(trials) == 1:  # one target: a band as wide as its trial
        band_x, common = np.array([1.0 - 2 * TRIAL_OFFSET, 1.0 + 2 * TRIAL_OFFSET]), common[[0, 0]]
    bad = [i for i, label in enumerate(labels) if label in failing]
    fig = _new_figure(9.5, 6.2, left=0.08, bottom=0.1, top=0.84, wspace=0.36, hspace=0.2)
    axes = fig.subplots(2, 3, sharex=True)
    for j, ax in enumerate(axes.flat):
        if common is not None:
            # the corrected poses' common part (O and R0, measured once): +-U_common about
            # zero, the shift every target shares
            ax.fill_between(
                band_x,
                -common[:, j],
                common[:, j],
                color=CORRECTED_COLOUR,
                alpha=0.15,
                linewidth=0,
                zorder=0,
                gid="common",
                label="common part of U (O, R0): shared by all targets",
            )
        for values, u, name, colour, marker, line, dx in (
            (conventional, bars[0], "conventional", CONVENTIONAL_COLOUR, "o", "--", -TRIAL_OFFSET),
            (corrected, bars[1], "corrected", CORRECTED_COLOUR, "s", "-", TRIAL_OFFSET),
        ):
            ax.errorbar(
                trials + dx,
                values[:, j],
                yerr=None if u is None else u[:, j],
                fmt=marker,
                linestyle=line,
                color=colour,
                label=name,
                markersize=4,
                linewidth=0.8,
                elinewidth=0.8,
                capsize=2,
            )
        for n, i in enumerate(bad):
            ax.axvspan(
                i + 0.55,
                i + 1.45,
                color="#f4a6a6",
                alpha=0.5,
                zorder=0,
                gid="failed",
                label="failed a check" if n == 0 else "_failed",
            )
        ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=0)
        unit = unit_text(DEVIATION_UNITS[j])
        ax.set_title(f"{POSE_NAMES[j]} ({unit})", fontsize=10)
        ax.set_ylabel(f"{POSE_NAMES[j]} \u2212 commanded ({unit})", fontsize=9)
        ax.grid(True, linewidth=0.3)
        few_ticks(ax, "y")
        if j >= 3:
            _trial_ticks(ax, labels)
            ax.set_xlabel("trial (target step)", fontsize=9)
    _room_below(fig, axes.flat[3])
    handles, names = axes.flat[0].get_legend_handles_labels()
    legend = fig.legend(
        handles, names, loc="upper center", bbox_to_anchor=(0.5, 0.925), ncols=3, fontsize=9
    )
    _room_above(fig, legend, axes.flat[:3])  # two rows (the failed checks' band)
    bar_text = (
        f"error bars: expanded uncertainty U = k\u00b7u, k = {exact(coverage_factor)}"
        if uncertainty is not None
        else "uncertainty not available: no error bars"
    )
    fig.suptitle(
        f"Measured pose parameters, deviation from the commanded pose\n{bar_text}", fontsize=11
    )
    return fig


def _styled_line(
    ax: Axes, x: FloatArray, y: FloatArray, k: int, n_lines: int, **kw: object
) -> None:
    """A line in the style of :data:`LEG_STYLES` ``[k]``, its markers shifted per line so
    that lines lying on each other still show each one's markers."""
    style, marker = LEG_STYLES[k % len(LEG_STYLES)]
    every = max(1, len(x) // MARKS_PER_LINE)
    ax.plot(
        x,
        y,
        linestyle=style,
        marker=marker,
        markevery=(min(len(x) - 1, (k * every) // max(1, n_lines)), every) if len(x) else None,
        markersize=4,
        markerfacecolor="none",
        **kw,  # type: ignore[arg-type]
    )


def plain_text(text: str) -> str:
    r"""A user's ``text`` (a column's name) as matplotlib prints it character for character:
    its dollars escaped, so that no ``$...$`` is read as mathematics (``$x^2$`` printed as
    x², ``$\foo$`` a parse error).

    >>> plain_text("$x^2$ air")
    '\\$x^2\\$ air'
    """
    return text.replace("$", "\\$")


def temperature_figure(result: Processed) -> Figure | None:
    """The paper's Figure 7: leg temperatures (and air, ...) over time; None without a log.

    Lines are labelled ``"leg 1"`` .. ``"leg 6"`` and by the further columns' names
    (``"air"`` ...), x in hours since the start of the session; every line has its
    own colour, line style and marker (:data:`LEG_STYLES`).
    """
    temps = result.temperatures
    if temps is None:
        return None
    hours = hours_since_start(result, temps.time_s)
    fig = _new_figure(9.0, 4.5)
    ax = fig.subplots()
    n_lines = 6 + len(temps.others_C)
    for leg in range(6):
        _styled_line(
            ax,
            hours,
            temps.legs_C[:, leg],
            leg,
            n_lines,
            color=LEG_COLOURS[leg],
            linewidth=1.0,
            label=f"leg {leg + 1}",
        )
    handles, names = ax.get_legend_handles_labels()  # the legs'
    for k, (name, values) in enumerate(temps.others_C.items()):
        (line,) = ax.plot(
            hours,
            values,
            color="#000000" if k == 0 else "#7f7f7f",
            linewidth=1.0,
            linestyle=("--", ":", "-.")[k % 3],
            label=name,
        )
        handles.append(line)
        names.append(plain_text(name))  # the file's column, as it is: "_spare", "$x$"
    _mark_targets(ax, result)
    ax.set_xlabel("time since start (h)")
    ax.set_ylabel(f"temperature ({unit_text('degC')})")
    ax.grid(True, linewidth=0.3)
    few_ticks(ax, nbins=WIDE_TICK_INTERVALS)
    ax.legend(handles, names, fontsize=8, ncols=2)
    ax.set_title("Measured temperatures", fontsize=11)
    return fig


def _mark_targets(ax: Axes, result: Processed) -> None:
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


def growth_figure(result: Processed) -> Figure:
    """Thermal growth of every leg measured at the references since R0 (um) over time.

    One line per leg (labelled ``"leg 1"`` ..), one marker per reference step; the
    straight segments between them are what the linear interpolation uses.
    """
    refs, growth = reference_growth_um(result)
    hours = hours_since_start(result, result.centres.times_s[refs])
    fig = _new_figure(9.0, 4.5)
    ax = fig.subplots()
    for leg in range(6):
        style, marker = LEG_STYLES[leg]
        ax.plot(
            hours,
            growth[:, leg],
            linestyle=style,
            marker=marker,
            markersize=4,
            markerfacecolor="none",
            linewidth=1.0,
            color=LEG_COLOURS[leg],
            label=f"leg {leg + 1}",
        )
    ax.axhline(0.0, color="#999999", linewidth=0.6, zorder=0)
    _mark_targets(ax, result)
    ax.set_xlabel("time since start (h)")
    ax.set_ylabel(f"growth since R0 ({unit_text('um')})")
    ax.grid(True, linewidth=0.3)
    few_ticks(ax, nbins=WIDE_TICK_INTERVALS)
    ax.legend(fontsize=8, ncols=2)
    ax.set_title("Leg growth measured at the references (IGM of the measured pose)", fontsize=11)
    return fig


def registration_figure(result: Processed) -> Figure:
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
    ax.set_ylabel(f"registration RMS ({unit_text('um')})")
    ax.grid(True, linewidth=0.3)
    few_ticks(ax, nbins=WIDE_TICK_INTERVALS)
    ax.legend(fontsize=8)
    ax.set_title("Registration residual of every step", fontsize=11)
    return fig


def figure_png(fig: Figure, dpi: int = FIGURE_DPI) -> bytes:
    """The figure as PNG bytes: the pixels of ``fig.savefig(format="png", dpi=dpi)``,
    drawn once, written by Pillow at zlib level :data:`PNG_COMPRESS_LEVEL`, as RGB when
    every pixel is opaque (a figure's white face: the alpha channel, a quarter of the
    bytes to filter and compress, says nothing), RGBA otherwise."""
    from PIL import Image

    # savefig's own drawing (its dpi, face and edge colours) into raw RGBA bytes
    raw = io.BytesIO()
    fig.savefig(raw, format="rgba", dpi=dpi)
    width, height = (int(v) for v in fig.get_size_inches() * dpi)
    pixels = raw.getbuffer()
    assert len(pixels) == 4 * width * height, (len(pixels), width, height)
    opaque = np.frombuffer(pixels, dtype=np.uint8)[3::4].min() == 255
    mode = "RGB" if opaque else "RGBA"
    image = Image.frombytes(mode, (width, height), pixels, "raw", "RGBX" if opaque else "RGBA")
    buffer = io.BytesIO()
    image.save(buffer, format="png", compress_level=PNG_COMPRESS_LEVEL, dpi=(dpi, dpi))
    return buffer.getvalue()
