"""report.md of diagnose.

The headline (the adequacy verdict first), the story's sections, the files.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.diagnosis import Diagnosis
from hexatherm.workflows.diagnose.nextsteps import next_steps
from hexatherm.workflows.diagnose.outputs import verdict_line
from hexatherm.workflows.diagnose.report.tables import (
    _HOUR_S,
    FIGURE_CAPTIONS,
    FIGURE_FILES,
    Table,
    _num,
    candidate_tables,
    changed,
    format_value,
    md_code,
    md_text,
    render_markdown,
    start_time_s,
    structure_tables,
    summaries,
    summary_tables,
)

if TYPE_CHECKING:
    from hexatherm.workflows.diagnose.run import DiagnosisResult


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
    verdict = None if d.adequacy is None else verdict_line(d.adequacy.summary(), d.cautions())
    out = [] if verdict is None else [f"**{verdict}**"]
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
    md += [f"- caution: {c}" for c in diagnosis.cautions()]
    if not v.adequate:
        md += [f"- it shows in: {'; '.join(v.where())}"]
        md += [f"- **next:** {step}" for step in next_steps(v)]
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

    md = [f"# Diagnosis of {md_text(data.session.name)}", "", headline(result), ""]
    md += [
        "## Session",
        "",
        f"- session: {md_code(data.session.path)}",
        f"- hexapod: {md_text(data.hexapod_source)} ({md_code(data.hexapod.name)})",
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
