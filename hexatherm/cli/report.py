"""``hexatherm report``: a self-contained HTML page of a session, with figures."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import click

from hexatherm.cli.options import (
    F,
    ProgressBars,
    clean_errors,
    document_options,
    echo_err,
    imports_done,
    lab_option,
    overwrite_option,
    template_dir_option,
    template_files,
    template_folder,
)


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


#: process's options that report took before issue 34: refused, naming process
PROCESS_OPTIONS = {
    "--interpolation": True,
    "--fixed-diameter": False,
    "--pose-tolerance": True,
    "--mc": True,
    "--seed": True,
    "--quality-threshold": True,
    "--coverage-factor": True,
    "--tolerance": True,
    "--decision-rule": True,
    "--guard-factor": True,
    "--allow-truncated": False,
    "--keep-later": False,
}


def _process_option(ctx: click.Context, param: click.Parameter, value: object) -> None:
    """A process option given to report: a usage error saying where it goes."""
    if value not in (None, False, ()):
        name = param.opts[0]
        raise click.UsageError(
            f"{name} is an option of process: report renders what process wrote, with "
            f"process's options (recorded in the results' provenance.json); run "
            f"'hexatherm process SESSION {name} ...', then 'hexatherm report SESSION'",
            ctx,
        )


def refused_process_options(func: F) -> F:
    """Every option of :data:`PROCESS_OPTIONS`, hidden, refused when given."""
    for name, takes_value in PROCESS_OPTIONS.items():
        kind: dict[str, Any] = (
            {"type": click.STRING, "multiple": name in ("--quality-threshold", "--tolerance")}
            if takes_value
            else {"is_flag": True}
        )
        func = click.option(
            name, hidden=True, expose_value=False, callback=_process_option, **kind
        )(func)
    return func


@click.command("report")
@click.argument("source", metavar="RESULTS", type=click.Path(exists=True, path_type=Path))
@click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(dir_okay=False),
    callback=_file_name,
    default=None,
    help="Output HTML file [default: report.html beside the results folder, in the session].",
)
@overwrite_option
@lab_option
@template_dir_option
@document_options
@refused_process_options
@clean_errors
def command(
    source: Path,
    out: Path | None,
    overwrite: bool,
    lab: Path | None,
    template_dir: Path | None,
    report_number: str | None,
    title: str | None,
) -> None:
    """Write the report of RESULTS, a results folder that process wrote (or a session,
    whose results/ it reports).

    One HTML file, figures embedded, that prints on A4: a verdict first (targets,
    failed checks, the largest corrected deviation with its expanded uncertainty
    U = k u, the thermal correction's size); the pose parameters of every target,
    conventional and corrected, as deviations from the commanded pose with U (the
    paper's Figure 6); the temperatures (Figure 7); the legs' growth at the
    references; the registration residuals; quality flags; the session's metadata
    and the provenance (command line, options, limits, inputs' and results' SHA-256).

    The page shows process's results and nothing else: process's options (interpolation,
    Monte Carlo draws, limits, tolerances and decision rule, coverage factor k) are the
    ones process recorded in provenance.json, and report asks none again; a lab file's
    tolerances for components process did not judge are judged on the numbers process
    wrote, and the screen says so. Results whose inputs
    changed since process wrote them are refused (stale: run process again); a session
    without results is processed first with process's defaults, as 'hexatherm process
    SESSION' does (SESSION/results), and the screen says so. A lab's own templates (--template-dir,
    or the lab file's templates:) give the page its letterhead and wording.
    """
    from hexatherm.workflows.report import verdict_items
    from hexatherm.workflows.report.run import ReportRequest, report

    imports_done()
    templates = template_folder(template_dir, lab)
    extra_inputs = ([] if lab is None else [lab]) + template_files(templates, lab)
    request = ReportRequest(
        source, out, overwrite, lab, templates, extra_inputs, report_number, title
    )
    with ProgressBars() as bars:
        outcome = report(request, bars.reading, bars.draws)
    for warning in outcome.result.warnings:
        echo_err(f"warning: {warning}")
    if outcome.processed_first:
        for path in outcome.processed_first:
            echo_err(f"wrote {path}")
        echo_err(
            f"no results in {source}: processed it first as 'hexatherm process {source}' "
            "does, with process's defaults (run process with options of your own, then "
            "report)"
        )
    echo_err(f"rendered {outcome.results.folder} ({outcome.results.command_line})")
    if outcome.lab_judged:
        echo_err(
            f"conformity: {', '.join(outcome.lab_judged)} judged against the lab file's "
            "tolerances on the numbers process wrote (process did not judge them: "
            "give process --tolerance to have them in poses.csv)"
        )
    if outcome.rule_ignored:
        echo_err(
            f"warning: the lab file's decision_rule {outcome.rule_ignored} is not used: "
            "process judged the tolerances with its own rule (recorded); give process "
            "--decision-rule"
        )
    for summary in outcome.verdicts:  # the page's verdict, on the screen too
        for head, text in verdict_items(summary):
            click.echo(f"{head}{'' if text.startswith('(') else ':'} {text}")
    echo_err(f"wrote {outcome.out_file}")
