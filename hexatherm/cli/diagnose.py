"""``hexatherm diagnose``: where the twin and the measurements disagree, and what is missing."""

from __future__ import annotations

from pathlib import Path

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
from hexatherm.io.files import ReadOptions


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
    from hexatherm.io.config import read_session
    from hexatherm.io.outputs import check_output_settled, output_dir
    from hexatherm.workflows.diagnose.outputs import diagnosed_hexapod_yaml, diagnosis_json, story
    from hexatherm.workflows.diagnose.report import terminal_tables, write_report_files
    from hexatherm.workflows.diagnose.run import read_for_diagnosis, run_diagnosis

    imports_done()
    folder = session if session.is_dir() else session.parent
    out_dir = Path(out) if out is not None else folder / "diagnosis"
    inputs = read_session(session).input_files()
    extra_inputs = [hexapod_path] if hexapod_path is not None else []
    templates = template_folder(template_dir, None)
    extra_inputs += template_files(templates)
    inputs += extra_inputs
    # before any work: never into, around or onto the session's files (checked again
    # under the output's lock when the results are written)
    check_output_settled(out_dir, kind="folder", inputs=inputs, overwrite=overwrite)
    data = read_for_diagnosis(session, hexapod_path, reading)
    echo_err(f"diagnosing {data.session.name}: {data.observations.n_steps} steps")
    for warning in data.warnings:
        echo_err(f"warning: {warning}")
    with ProgressBars() as bars:
        result = run_diagnosis(
            data,
            lambda round_, done, total: bars.update(f"round {round_}: candidates", done, total),
        )
    files = {
        "diagnosis.json": diagnosis_json(result),
        "hexapod.yaml": diagnosed_hexapod_yaml(result),
    }
    written: list[Path] = []
    with output_dir(out_dir, inputs=inputs, overwrite=overwrite) as tmp:
        for name, text in files.items():
            (tmp / name).write_text(text, encoding="utf-8")
            written.append(out_dir / name)
        pages = write_report_files(result, tmp, template_dir=templates, extra_inputs=extra_inputs)
        written += [out_dir / p.relative_to(tmp) for p in pages]
    click.echo(terminal_tables(result, tests=False))
    click.echo()
    click.echo(story(result))
    for path in written:
        echo_err(f"wrote {path}")
