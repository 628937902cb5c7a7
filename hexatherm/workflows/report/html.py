"""The report's page: verdict, figures, tables, session and provenance, and build_report."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hexatherm import __version__
from hexatherm.workflows.process.pipeline import ProcessResult
from hexatherm.workflows.process.views import Processed, Uncertain
from hexatherm.workflows.report.document import (
    Document,
    document,
    identification_block,
    offset_time,
    span_text,
    template_variables,
)
from hexatherm.workflows.report.figures import (
    POSE_NAMES,
    _time_text,
    growth_figure,
    pose_figure,
    registration_figure,
    start_time_s,
    temperature_figure,
)
from hexatherm.workflows.report.page import (
    STYLE,
    figure,
    provenance,
    signature_table,
    table,
)
from hexatherm.workflows.report.render import Table, render_page
from hexatherm.workflows.report.tables import (
    FAIL_MARK,
    QUALITY_HEADS,
    failing_rows,
    growth_table,
    poses_table,
    quality_summary,
    quality_table,
    shared_parts_table,
)
from hexatherm.workflows.report.text import exact, fixed, unit_text
from hexatherm.workflows.report.verdict import Extreme, Verdict, verdict

__all__ = ["STYLE", "build_report", "metadata_rows", "provenance_block", "report_html"]

if TYPE_CHECKING:
    from hexatherm.core.conformity import DecisionRule
    from hexatherm.io.provenance import RunFacts
    from hexatherm.session import Identification, QualityLimits, Tolerance
    from hexatherm.workflows.process.quality import QualityReport


def _session_files(result: Processed) -> dict[str, str]:
    """The hexapod, balls and plan file names as the session file gives them."""
    from hexatherm.io.yamlfile import YamlDoc

    data = YamlDoc.load(result.session.path).data
    return {key: str(data.get(key, "")) for key in ("hexapod", "balls", "plan")}


def metadata_rows(result: Processed) -> list[tuple[str, str]]:
    """``(field, value)`` rows describing the session and how it was processed."""
    session, plan = result.session, result.session.plan
    files = _session_files(result)
    times = result.centres.times_s
    first, last = float(np.min(times)), float(np.max(times))
    start = start_time_s(result)
    end = last
    if result.temperatures is not None:
        end = max(end, float(result.temperatures.time_s[-1]))
    temps = result.temperatures
    columns = "none"
    if temps is not None:
        columns = ", ".join([f"leg{i}" for i in range(1, 7)] + list(temps.others_C))
    n_refs = len(plan.reference_indices)
    return [
        ("session", session.name),
        ("session file", session.path.name),
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
        ("reference pose (mm, \u00b0)", ", ".join(exact(v) for v in plan.reference_pose)),
        ("measured", f"{session_dates(result)} ({(last - first) / 3600:.2f} h)"),
        (
            "temperature log",
            "none"
            if temps is None
            else f"{measured_time(result, start)} to {measured_time(result, end)} "
            f"({(end - start) / 3600:.2f} h)",
        ),
        ("interpolation", result.interpolation),
        ("hexatherm", __version__),
    ]


def measured_time(result: Processed, seconds: float) -> str:
    """A time of the session as a report prints it: ISO 8601 with its UTC offset
    (:func:`~hexatherm.workflows.report.document.offset_time`), or seconds."""
    if result.centres.time_kind != "iso":
        return _time_text(result, seconds)
    return offset_time(seconds, result.session.utc_offset_s, result.centres.time_aware)


def session_dates(result: Processed) -> str:
    """The dates of the session's measurements: first and last step, with their UTC
    offset (the one time span every part of a report prints)."""
    times = result.centres.times_s
    first = measured_time(result, float(np.min(times)))
    return span_text(first, measured_time(result, float(np.max(times))))


def header_rows(
    doc: Document, ident: Identification | None, dates: str, hexapod: str
) -> list[tuple[str, str]]:
    """The running header's ``(name, text)`` rows: the document's number, title and date
    of issue, every identification field given (a session's report number but the
    document's own), the hexapod, the dates measured and the signatories."""
    rows = [
        ("Report number", doc.number or "none assigned"),
        ("Report", doc.title),
        ("Date of issue", doc.issue_date),
    ]
    if ident is None or not (ident.fields or ident.signatures):
        rows.append(("Identification", "none given (session.yaml identification:, --lab)"))
    else:
        rows += [row for row in ident.rows() if row[0] != "Report number"]
    rows += [("Hexapod", hexapod), ("Measured", dates)]
    if ident is not None and ident.signatures:
        rows.append(("Signed by", ", ".join(f"{name} ({role})" for role, name in ident.signatures)))
    return rows


def _text_or_none(value: object) -> str | None:
    return None if value is None else str(value)


def _extreme_text(extreme: Extreme, unit: str, k: float) -> str:
    if not extreme.parameter:
        return "none"
    text = (
        f"{fixed(extreme.value, unit)} {unit_text(unit)} ({extreme.parameter} of {extreme.target})"
    )
    if np.isfinite(extreme.expanded_u):
        text += f", U = {fixed(extreme.expanded_u, unit)} {unit_text(unit)} (k = {exact(k)})"
    return text


def _steps_text(steps: list[tuple[str, str]]) -> str:
    return "; ".join(f"{label} ({checks})" for label, checks in steps)


def verdict_items(summary: Verdict) -> list[tuple[str, str]]:
    """The verdict as ``(heading, text)`` items, plain text: the page prints them in its
    verdict block, ``report`` on the screen."""
    k = summary.coverage_factor
    n_fail = len(summary.failing_targets)
    if not summary.quality_ran:
        checks = "quality checks not available"
    elif n_fail == 0:
        checks = f"all {summary.targets} targets passed every quality check"
    else:
        checks = (
            f"{n_fail} of {summary.targets} targets failed a quality check "
            f"(marked {FAIL_MARK.strip()} in every table, shaded in the pose figure): "
            + _steps_text(summary.failing_targets)
        )
    items = [("Targets", f"{summary.targets}; {checks}.")]
    if summary.failing_other:
        items.append(
            ("Origin and references failing a check", _steps_text(summary.failing_other) + ".")
        )
    items += [
        (
            "Largest corrected deviation from the commanded pose",
            "translation "
            + _extreme_text(summary.deviation_um, "um", k)
            + "; rotation "
            + _extreme_text(summary.deviation_urad, "urad", k)
            + ".",
        ),
        (
            "Thermal correction",
            "(largest |corrected \u2212 conventional|): translation "
            + _extreme_text(summary.correction_um, "um", k)
            + "; rotation "
            + _extreme_text(summary.correction_urad, "urad", k)
            + ".",
        ),
        *(
            [
                (
                    "Not significant",
                    "the thermal correction is smaller than its U on "
                    + ", ".join(
                        f"{name} (at most {fixed(effect, unit)} {unit_text(unit)} against "
                        f"U = {fixed(big_u, unit)} {unit_text(unit)})"
                        for name, effect, big_u in summary.insignificant
                        for unit in ("um" if name[0] == "T" else "urad",)
                    )
                    + f" (k = {exact(k)}, U the median over the targets): there the corrected "
                    "pose is not known better than the correction moved it.",
                )
            ]
            if summary.insignificant
            else []
        ),
        (
            "Uncertainty",
            f"{summary.basis}; expanded uncertainty U = k\u00b7u with coverage factor "
            f"k = {exact(k)} wherever U or error bars appear.",
        ),
    ]
    if summary.common_u is not None:
        c = summary.common_u
        items.append(
            (
                "Shared by all targets",
                f"of U, the common part from the one measurement of O and R0 (k = {exact(k)}): "
                + ", ".join(
                    f"{name} {fixed(c[j], unit)} {unit_text(unit)}"
                    for j, (name, unit) in enumerate(
                        zip(POSE_NAMES, ("um",) * 3 + ("urad",) * 3, strict=True)
                    )
                )
                + " at most; it shifts every corrected pose together (the band in Figure 6): "
                "a difference between two targets cancels it, their mean keeps it.",
            )
        )
    if summary.conformity is not None:
        from hexatherm.workflows.report.conformity import conformity_item

        items.insert(1, conformity_item(summary.conformity))
    return items


def verdict_failed(summary: Verdict) -> bool:
    """Whether the verdict block is drawn as failed (a target or reference failed a check)."""
    return bool(summary.failing_targets or summary.failing_other)


def threshold_texts(thresholds: QualityLimits) -> list[str]:
    """Every quality limit as ``form \u2264 10 \u00b5m``."""
    from hexatherm.workflows.process.quality import CHECKS

    texts = []
    for column, field, at_least in CHECKS.values():
        name, unit = QUALITY_HEADS.get(column, (column, ""))
        sign = "\u2265" if at_least else "\u2264"
        value = getattr(thresholds, field)
        texts.append(f"{name} {sign} {exact(value)}" + (f" {unit_text(unit)}" if unit else ""))
    return texts


def provenance_block(
    result: Processed,
    quality: QualityReport | None,
    facts: RunFacts | None,
    generated: str,
    extra_inputs: Sequence[Path] = (),
    number: str | None = None,
) -> dict[str, Table]:
    """The provenance block of a session's report (:func:`page.provenance`), with the
    report's ``number`` and the quality limits; ``extra_inputs``: further files the page
    was made from (a lab file)."""
    limits = "not available" if quality is None else "; ".join(threshold_texts(quality.thresholds))
    return provenance(
        facts,
        [*result.session.input_files(), *extra_inputs],
        result.session.path.parent,
        generated,
        extra=[("quality limits", limits)],
        number=number,
    )


def report_html(
    result: Processed,
    uncertainty: Uncertain | None = None,
    quality: QualityReport | None = None,
    coverage_factor: float = 2.0,
    facts: RunFacts | None = None,
    generated: str | None = None,
    on_verdict: Callable[[Verdict], None] | None = None,
    identification: Identification | None = None,
    tolerances: dict[str, Tolerance] | None = None,
    extra_inputs: Sequence[Path] = (),
    template_dir: Path | None = None,
    rule: DecisionRule | None = None,
    report_number: str | None = None,
    title: str | None = None,
) -> str:
    """The report page of a processed session (see the package's docstring).

    Parameters
    ----------
    result : ProcessResult
    uncertainty : PoseUncertainty, optional
        Standard uncertainties of the poses; without it the figure has no error
        bars and the page says "uncertainty not available".
    quality : QualityReport, optional
        Quality checks; without it the page says "quality checks not available".
    coverage_factor : float
        ``k`` of the expanded uncertainties ``U = k u`` of the figure and tables (> 0).
    facts : RunFacts, optional
        The command line's facts of the run (default: :func:`current_run`, None
        outside the command line: the page says "not run from the command line").
    generated : str, optional
        Generation time, ISO 8601 with UTC offset (default: now).
    on_verdict : callable, optional
        Called with the page's verdict (the command line prints it).
    identification : Identification, optional
        Lab, customer, CMM, hexapod ... (:func:`hexatherm.io.config.identity.identification`):
        printed in the header every printed page repeats, and the signature block.
    tolerances : dict, optional
        ``Tx_um`` .. ``Rz_urad`` -> T: the conformity statement (verdict and a table).
    extra_inputs : sequence of Path
        Further input files listed in the provenance (the lab file).
    template_dir : Path, optional
        A lab's templates, over the package's (:mod:`~hexatherm.workflows.report.render`).
    rule : DecisionRule, optional
        The conformity statement's decision rule (default: the lab file's
        ``decision_rule:``, else ISO 14253-1 with w = U).
    report_number, title : str, optional
        The document's number and title (``--report-number``, ``--title``), over the lab
        file's ``numbering:`` and ``titles:`` (:mod:`~hexatherm.workflows.report.document`).

    Returns
    -------
    str
        One self-contained HTML document.
    """
    from hexatherm.io.provenance import current_run, now_iso
    from hexatherm.workflows.process.conformity import decision_rule

    if facts is None:
        facts = current_run()
    fields = dict(identification.fields) if identification is not None else {}
    issued = generated or now_iso()
    session = result.session
    doc = document(
        "report",
        issued,
        fields,
        [_text_or_none(session.identification.get("report_number"))],
        [session.name],
        report_number,
        title,
    )
    rule = decision_rule(fields) if rule is None else rule
    summary = verdict(result, uncertainty, quality, coverage_factor, tolerances, rule)
    if on_verdict is not None:
        on_verdict(summary)
    failing = dict(summary.failing_targets + summary.failing_other)
    k_text = exact(coverage_factor)
    pose_caption = (
        "Deviations of the conventional (measured) and corrected (thermal state "
        "of R0) poses from the commanded pose: translations in \u00b5m, rotations in "
        "\u00b5rad."
        + (
            f" Error bars: expanded uncertainty U = k\u00b7u, k = {k_text}."
            if uncertainty is not None
            else ""
        )
        + (
            " Band: \u00b1k\u00b7u_common, U's share from O and R0, the same for all targets."
            if summary.common_u is not None
            else ""
        )
        + (" Shaded: targets that failed a quality check." if summary.failing_targets else "")
    )
    quality_part = None
    if quality is not None:
        quality_part = {
            "failed": sum(failing_rows(quality.frame)),
            "mark": FAIL_MARK.strip(),
            "summary": quality_summary(quality),
            "table": quality_table(quality),
        }
    conformity = None
    if summary.conformity is not None:
        from hexatherm.workflows.report.conformity import conformity_table

        conformity = conformity_table(summary.conformity)
    hexapod = f"{session.hexapod.name} ({_session_files(result)['hexapod']})"
    signatories = () if identification is None else identification.signatures
    item = f"hexapod {session.hexapod.name}" + "".join(
        f", {name.lower()} {value}"
        for key, name in (("hexapod.model", "model"), ("hexapod.serial", "serial"))
        if (value := fields.get(key)) is not None
    )
    return render_page(
        "process.html.j2",
        template_dir,
        title=doc.title,
        subtitle=f"Thermally corrected 6-DOF poses of session {session.name}",
        **template_variables(doc, fields),
        ident_block=identification_block(
            doc,
            fields,
            item,
            session_dates(result),
            summary.basis,
            f"the corrected pose deviations of {summary.targets} targets from the commanded "
            "pose (µm, µrad) with U = k·u below",
            signatories,
        ),
        header_rows=header_rows(doc, identification, session_dates(result), hexapod),
        signatures=None
        if identification is None
        else signature_table(identification.signatures, doc.issue_date),
        verdict=verdict_items(summary),
        verdict_failed=verdict_failed(summary),
        warnings=list(result.warnings),
        uncertainty_given=uncertainty is not None,
        pose_figure=figure(
            lambda: pose_figure(result, uncertainty, coverage_factor, failing),
            "pose parameters per trial",
            pose_caption,
        ),
        conventional=poses_table(result, uncertainty, "conventional", coverage_factor, failing),
        corrected=poses_table(result, uncertainty, "corrected", coverage_factor, failing),
        conformity=conformity,
        shared=None if uncertainty is None else shared_parts_table(uncertainty, coverage_factor),
        uncertainty_note=None
        if uncertainty is None
        else f"Uncertainty: {summary.basis}; ball centres: {uncertainty.centres.description}. "
        f"U = k\u00b7u with k = {k_text}.",
        temperature_figure=None
        if result.temperatures is None  # no log: no Figure 7
        else figure(
            lambda: temperature_figure(result),
            "measured temperatures",
            "Thermocouple temperatures over time; ticks at the bottom: the targets' times.",
        ),
        growth_figure=figure(
            lambda: growth_figure(result),
            "leg growth at the references",
            "Growth of each leg since R0 (\u00b5m), from the IGM of the measured reference "
            "poses; ticks at the bottom: the targets' times.",
        ),
        growth=growth_table(result, failing),
        registration_figure=figure(
            lambda: registration_figure(result),
            "registration residuals",
            "RMS distance between the measured ball centres and the registered "
            "balls file, per step (\u00b5m).",
        ),
        quality=quality_part,
        session=table(
            [[("field", 1), ("value", 1)]],
            [[k, v] for k, v in metadata_rows(result)],
            numeric_from=99,
            css="meta",
        ),
        provenance=provenance_block(result, quality, facts, issued, extra_inputs, doc.number),
    )


def build_report(
    result: ProcessResult,
    mc: int = 0,
    seed: int = 0,
    thresholds: QualityLimits | None = None,
    progress: Callable[[int, int], None] | None = None,
    coverage_factor: float = 2.0,
    on_verdict: Callable[[Verdict], None] | None = None,
    lab_fields: dict[str, object] | None = None,
    tolerances: dict[str, Tolerance] | None = None,
    extra_inputs: Sequence[Path] = (),
    template_dir: Path | None = None,
    rule: DecisionRule | None = None,
    report_number: str | None = None,
    title: str | None = None,
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
    coverage_factor : float
        ``k`` of the expanded uncertainties (> 0).
    on_verdict : callable, optional
        As :func:`report_html`.
    lab_fields : dict, optional
        A lab file's identification fields (:func:`hexatherm.io.config.identity.read_lab`);
        the session's own ``identification:`` wins key by key.
    tolerances : dict, optional
        The tolerances to judge (default: the session's ``tolerances:``; the command line
        merges a lab file's, the session's and ``--tolerance``'s, in that order).
    extra_inputs : sequence of Path
        Further input files for the provenance (the lab file).
    template_dir : Path, optional
        A lab's templates, over the package's.
    rule, report_number, title : optional
        As :func:`report_html`.
    """
    from hexatherm.io.config.identity import identification
    from hexatherm.workflows.process.quality import quality_checks
    from hexatherm.workflows.process.uncertainty import pose_uncertainty

    return report_html(
        result,
        uncertainty=pose_uncertainty(result, mc=mc, seed=seed, progress=progress),
        quality=quality_checks(result, thresholds),
        coverage_factor=coverage_factor,
        on_verdict=on_verdict,
        identification=identification(result.session.identification, lab_fields),
        tolerances=result.session.tolerances if tolerances is None else tolerances,
        extra_inputs=extra_inputs,
        template_dir=template_dir,
        rule=rule,
        report_number=report_number,
        title=title,
    )
