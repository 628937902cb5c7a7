"""``hexatherm report``: a self-contained HTML page of a session, with figures."""

from __future__ import annotations

import os
from pathlib import Path

import click

from hexatherm.cli.options import (
    ProgressBars,
    check_draws,
    clean_errors,
    coverage_factor_option,
    decision_rule_options,
    document_options,
    echo_err,
    imports_done,
    interpolation_option,
    lab_option,
    mc_option,
    overwrite_option,
    pose_tolerance_option,
    quality_threshold_option,
    reading_options,
    seed_option,
    template_dir_option,
    template_files,
    template_folder,
    tolerance_option,
)
from hexatherm.io.files import ReadOptions
from hexatherm.session import Tolerance


def _file_name(ctx: click.Context, param: click.Parameter, value: str | None) -> Path | None:
    """``-o`` as given: a file's name (not empty, not a folder's: ``new/``)."""
    if value is None:
        return None
    if not value:
        raise click.BadParameter("empty; give the report's file name", ctx, param)
    if value.endswith(("/", os.sep)):
        raise click.BadParameter(
            f"{value!r} names a folder; give the report's file name ({value}report.html)",
            ctx,
            param,
        )
    return Path(value)


@click.command("report")
@click.argument("session", type=click.Path(exists=True, path_type=Path))
@click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(dir_okay=False),
    callback=_file_name,
    default=None,
    help="Output HTML file [default: SESSION/report.html].",
)
@overwrite_option
@interpolation_option
@click.option(
    "--fixed-diameter",
    "fixed_diameter",
    is_flag=True,
    help="Fit spheres to probed points with the radius fixed to the balls file's "
    "(as in process); default: free radius.",
)
@pose_tolerance_option
@mc_option
@seed_option
@quality_threshold_option
@coverage_factor_option(
    "in the figure, the tables and the verdict (2, as calibration certificates use)"
)
@lab_option
@template_dir_option
@tolerance_option
@decision_rule_options
@document_options
@reading_options
@clean_errors
def command(
    session: Path,
    out: Path | None,
    overwrite: bool,
    interpolation: str,
    fixed_diameter: bool,
    pose_tolerance: tuple[float, float] | None,
    mc: int,
    seed: int,
    quality_thresholds: tuple[str, ...],
    coverage_factor: float,
    lab: Path | None,
    template_dir: Path | None,
    tolerances: dict[str, Tolerance],
    decision_rule: str | None,
    guard_factor: float | None,
    report_number: str | None,
    title: str | None,
    reading: ReadOptions,
) -> None:
    """Process SESSION (a folder with session.yaml, or the file itself) and write its report.

    One HTML file, figures embedded, that prints on A4: a verdict first (targets,
    failed checks, the largest corrected deviation with its expanded uncertainty
    U = k u, the thermal correction's size); the pose parameters of every target,
    conventional and corrected, as deviations from the commanded pose with U (the
    paper's Figure 6); the temperatures (Figure 7); the legs' growth at the
    references; the registration residuals; quality flags; the session's metadata
    and the provenance (command line, options, limits, inputs' SHA-256). Nothing is
    written when processing fails. A lab's own templates (--template-dir, or the lab
    file's templates:) give the page its letterhead and wording.
    """
    from hexatherm.io.config import read_session
    from hexatherm.io.config.identity import read_lab
    from hexatherm.io.outputs import check_output_settled, write_output_file
    from hexatherm.workflows.process.conformity import decision_rule as rule_of
    from hexatherm.workflows.process.pipeline import Checks, process_session
    from hexatherm.workflows.process.quality import parse_threshold, session_thresholds
    from hexatherm.workflows.report import Verdict, build_report, verdict_items

    imports_done()
    check_draws(mc)
    lab_fields, lab_tolerances = read_lab(lab) if lab is not None else ({}, {})
    templates = template_folder(template_dir, lab)
    extra_inputs = ([] if lab is None else [lab]) + template_files(templates, lab)
    overrides = dict(parse_threshold(t) for t in quality_thresholds)
    folder = session if session.is_dir() else session.parent
    out_file = out if out is not None else folder / "report.html"
    inputs = read_session(session).input_files() + extra_inputs
    check_output_settled(out_file, kind="file", inputs=inputs, overwrite=overwrite)
    with ProgressBars() as bars:
        result = process_session(
            session,
            interpolation,  # type: ignore[arg-type]
            0.0 if fixed_diameter else None,
            Checks(pose_tolerance=pose_tolerance),
            progress=bars.reading,
            reading=reading,
        )
    for warning in result.warnings:
        echo_err(f"warning: {warning}")
    verdicts: list[Verdict] = []
    with ProgressBars() as bars:
        page = build_report(
            result,
            mc,
            seed,
            session_thresholds(result.session, overrides),
            progress=bars.draws,
            coverage_factor=coverage_factor,
            on_verdict=verdicts.append,
            lab_fields=lab_fields,
            tolerances={**lab_tolerances, **result.session.tolerances, **tolerances},
            extra_inputs=extra_inputs,
            template_dir=templates,
            rule=rule_of(lab_fields, decision_rule, guard_factor),
            report_number=report_number,
            title=title,
        )
    write_output_file(out_file, page, inputs=inputs, overwrite=overwrite)
    for summary in verdicts:  # the page's verdict, on the screen too
        for head, text in verdict_items(summary):
            click.echo(f"{head}{'' if text.startswith('(') else ':'} {text}")
    echo_err(f"wrote {out_file}")
