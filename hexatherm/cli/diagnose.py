"""``hexatherm diagnose``: where the twin and the measurements disagree, and what is missing."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from hexatherm.cli.options import (
    ProgressBars,
    clean_errors,
    echo_err,
    folder_name,
    imports_done,
    overwrite_option,
    reading_options,
    template_dir_option,
    template_files,
    template_folder,
)
from hexatherm.workflows.common import ReadOptions

if TYPE_CHECKING:
    from hexatherm.workflows.diagnose.run import SessionData


@click.command("diagnose")
@click.argument("session", type=click.Path(exists=True, path_type=Path))
@click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(file_okay=False),
    default=None,
    callback=folder_name,
    help="Output folder [default: SESSION/diagnosis].",
)
@overwrite_option
@click.option(
    "--hexapod",
    "hexapod_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="The model to diagnose (a hexapod file, e.g. an earlier diagnosis' "
    "hexapod.yaml) instead of the session's; its thermal_model effects are kept.",
)
@template_dir_option
@reading_options
@clean_errors
def command(
    session: Path,
    out: str | None,
    overwrite: bool,
    hexapod_path: Path | None,
    template_dir: Path | None,
    reading: ReadOptions,
) -> None:
    """Compare SESSION's measurements with the twin and find the missing effects.

    The twin predicts every ball of every step from the commanded poses and the
    thermocouple log (temperatures.csv, required). Each candidate effect of the
    twin is fitted to the measured ball centres, frame O being fitted as a
    nuisance in every model; the best is added when it lowers BIC by more than 10
    and lowers the RMS of held-out steps, and the search repeats.

    Writes OUT/diagnosis.json, OUT/hexapod.yaml (the model with the added
    effects in its thermal_model, for simulate and process --method twin) and
    OUT/report.md with its figures and OUT/report.html (the same, one page); prints the
    story to standard output.
    """
    from hexatherm.workflows.diagnose.command import diagnose
    from hexatherm.workflows.diagnose.outputs import story
    from hexatherm.workflows.diagnose.report import terminal_tables

    imports_done()
    templates = template_folder(template_dir, None)

    def said(data: SessionData) -> None:
        echo_err(f"diagnosing {data.session.name}: {data.observations.n_steps} steps")
        for warning in data.warnings:
            echo_err(f"warning: {warning}")

    with ProgressBars() as bars:
        outcome = diagnose(
            session,
            Path(out) if out is not None else None,
            overwrite,
            hexapod_path,
            templates,
            template_files(templates),
            reading,
            on_read=said,
            progress=lambda round_, done, total: bars.update(
                f"round {round_}: candidates", done, total
            ),
        )
    click.echo(terminal_tables(outcome.result, tests=False))
    click.echo()
    click.echo(story(outcome.result))
    for path in outcome.written:
        echo_err(f"wrote {path}")
