"""Summaries and tables of diagnose.

Residuals by component, leg, step kind and time, the worst steps, structure tests, candidates.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.diagnosis import Diagnosis
from hexatherm.core.residuals import (
    ALPHA,
    LEG_NAMES,
    POSE_COMPONENTS,
    POSE_UNITS,
    TIME_PARTS,
    PoseResiduals,
    ResidualSummary,
    SeriesTests,
    WorstStep,
    summarize,
)
from hexatherm.io.records import seconds_to_iso

if TYPE_CHECKING:
    from hexatherm.workflows.diagnose.run import DiagnosisResult


if TYPE_CHECKING:
    from hexatherm.workflows.diagnose.run import DiagnosisResult


BEFORE_COLOUR = "#d62728"


AFTER_COLOUR = "#1f77b4"


TEMPERATURE_COLOUR = "#7f7f7f"


FIGURE_DPI = 150


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


#: what Markdown would read as markup in a user's text: HTML and entities (``<``, ``&``),
#: emphasis, code, links, table cells, a heading's closing ``#``, strike-through, and ``_``
#: where it can open or close emphasis (not inside a word: ``leg_thermal_lag`` stays)
_MD_SPECIAL = re.compile(r"[\\`*\[\]<>&|#~!]|(?<![A-Za-z0-9])_|_(?![A-Za-z0-9])")


def md_text(value: object) -> str:
    r"""A user's text (a session's name, a path) as Markdown that shows it as it is.

    Line breaks become spaces; every character Markdown could read as markup is
    backslash-escaped (CommonMark: a backslash before ASCII punctuation makes it literal),
    so that ``<script>`` or ``</table>`` is text, not HTML.

    >>> print(md_text("a <b>*c*</b> | d_e _f_"))
    a \<b\>\*c\*\</b\> \| d_e \_f\_
    """
    text = " ".join(str(value).splitlines())
    return _MD_SPECIAL.sub(lambda m: "\\" + m[0], text)


def md_code(value: object) -> str:
    r"""A user's text as a Markdown code span (literal), or as :func:`md_text` when it
    holds a backtick (which would end the span) or what is markup outside a code span
    (``<``, ``>``, ``&``: a viewer that does not know code spans, or a tool that reads
    the file as HTML, never meets a raw ``<script>``).

    >>> print(md_code("s/session.yaml"), md_code("a`b"), md_code("<script>"))
    `s/session.yaml` a\`b \<script\>
    """
    text = " ".join(str(value).splitlines())
    return md_text(text) if any(c in text for c in "`<>&") else f"`{text}`"


#: in a table cell (numbers, ranges ``[0, 3e-05]``, step labels): what would end the cell
#: or make HTML, code or emphasis; brackets and ``#`` are left as they read
_CELL_SPECIAL = re.compile(r"[\\`*<>&|]")


def _md_cell(text: str) -> str:
    return _CELL_SPECIAL.sub(lambda m: "\\" + m[0], " ".join(text.splitlines()))


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
    """A parameter with its standard error, to the se's precision (two digits), labelled
    k = 1 (a standard uncertainty, not the U = 2u of ``report`` and ``calibrate``).

    >>> format_value(1509.358, 35.9, "s"), format_value(1.23e-5, 4.1e-7, "1/K")
    ('1509 ± 36 s (k = 1)', '1.230e-05 ± 4.1e-07 1/K (k = 1)')
    >>> format_value(0.5, None, "1")
    '0.5'
    """
    suffix = "" if unit in ("", "1") else f" {unit}"
    if std_error is None or not np.isfinite(std_error) or std_error <= 0:
        return f"{value:.4g}{suffix}"
    size = max(abs(value), std_error)
    if not 1e-3 <= size < 1e6:
        return f"{value:.3e} ± {std_error:.1e}{suffix} (k = 1)"
    decimals = max(0, 1 - int(np.floor(np.log10(std_error))))
    return f"{value:.{decimals}f} ± {std_error:.{decimals}f}{suffix} (k = 1)"


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
