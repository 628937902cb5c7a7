"""``hexatherm calibrate``: the hexapod's geometry from thermally decoupled poses."""

from __future__ import annotations

from pathlib import Path

import click

from hexatherm.cli.options import (
    CHECK_FAILED_EXIT,
    clean_errors,
    coverage_factor_option,
    document_options,
    echo_err,
    imports_done,
    interpolation_option,
    lab_option,
    overwrite_option,
    reading_options,
    template_dir_option,
    template_files,
    template_folder,
)
from hexatherm.workflows.common import ReadOptions


@click.command("calibrate")
@click.argument("sessions", nargs=-1, required=True, type=click.Path(exists=True, path_type=Path))
@click.option(
    "-o",
    "--out",
    "out",
    default=None,
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder: hexapod.yaml, parameters.csv, residuals.csv, calibration.json, "
    "report.html, provenance.json, and controller.yaml when the calibration is to be "
    "applied [default: the first session's folder/calibration].",
)
@coverage_factor_option(
    "of parameters.csv (U, U_um, U_ppm), the report and the new-pose claim on screen"
)
@click.option(
    "--poses",
    type=click.Choice(["corrected", "conventional", "twin"]),
    default="corrected",
    show_default=True,
    help="Fit the thermally corrected poses (the thermal state of each session's R0), "
    "the conventional ones (drift included, for comparison), or the poses the twin "
    "corrects from the thermocouples alone (needs --twin-model).",
)
@click.option(
    "--twin-model",
    "twin_model",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="The twin's model for --poses twin: a hexapod file with thermal_model effects "
    "(e.g. the hexapod.yaml of hexatherm diagnose). Only with --poses twin.",
)
@click.option(
    "--strict",
    is_flag=True,
    help=f"Exit with status {CHECK_FAILED_EXIT} when the model does not explain the poses "
    "(chi-square test at p = 0.001; the outputs are still written); without it, a warning.",
)
@click.option(
    "--level",
    type=click.Choice(["auto", "offsets", "joints", "joints+gains"]),
    default="auto",
    show_default=True,
    help="The model: 6 leg offsets, 42 joint coordinates and offsets, or 48 with the leg "
    "gains; auto chooses as diagnose does (BIC and held-out folds of poses).",
)
@click.option(
    "--residuals",
    type=click.Choice(["pose", "leg"]),
    default="pose",
    show_default=True,
    help="Residual space of the least squares.",
)
@click.option(
    "--iterate",
    is_flag=True,
    help="Reprocess the sessions with the calibrated geometry (the thermal correction's "
    "IGM and FGM) and calibrate again, until the parameters stop moving.",
)
@interpolation_option
@overwrite_option
@lab_option
@template_dir_option
@document_options
@reading_options
@clean_errors
def command(
    sessions: tuple[Path, ...],
    out: Path | None,
    coverage_factor: float,
    poses: str,
    twin_model: Path | None,
    strict: bool,
    level: str,
    residuals: str,
    iterate: bool,
    interpolation: str,
    overwrite: bool,
    lab: Path | None,
    template_dir: Path | None,
    report_number: str | None,
    title: str | None,
    reading: ReadOptions,
) -> None:
    """Calibrate the geometry of the hexapod of SESSIONS from their measured poses.

    Every session is processed as 'process' does; their targets are pooled and the
    geometry (leg offsets, joint centres, leg gains) is fitted by weighted least
    squares, each pose weighted by its covariance. The sessions must share one hexapod
    file. Prints the level and the residuals before (nominal geometry) and after
    (calibrated, held out when the level is chosen); writes OUT/hexapod.yaml (usable by
    process, plan and simulate) and the parameters with their uncertainties.
    """
    from hexatherm.workflows.calibrate.checks import session_warnings
    from hexatherm.workflows.calibrate.command import run_calibrate
    from hexatherm.workflows.calibrate.outputs import (
        claim_lines,
        span_lines,
        summary_lines,
        unexplained_claim_lines,
    )

    imports_done()
    if poses == "twin" and twin_model is None:
        raise click.UsageError("--poses twin needs the twin's model: give --twin-model FILE")
    if poses != "twin" and twin_model is not None:
        raise click.UsageError(
            f"--twin-model is the twin's model for --poses twin, not for --poses {poses}"
        )
    templates = template_folder(template_dir, lab)
    done = run_calibrate(
        sessions,
        out,
        poses,
        twin_model,
        level,
        residuals,
        iterate,
        interpolation,
        overwrite,
        lab,
        templates,
        template_files(templates, lab),
        coverage_factor,
        report_number,
        title,
        reading,
    )
    run, files, out = done.run, done.files, done.out
    for k, move in enumerate(done.moves, 2):
        echo_err(
            f"round {k}: reprocessed with the calibrated geometry; the parameters "
            f"moved at most {move * 1e3:.3g} um"
        )
    model = "" if twin_model is None else f" (twin model {twin_model})"
    # after the outputs: a run refused while computing or writing them says one line
    echo_err(
        f"calibrated from {len(run.campaign.labels)} {poses} poses{model} of "
        f"{len(sessions)} session(s)"
    )
    for line in session_warnings(run.campaign.results):
        echo_err(f"warning: {line}")
    claim = claim_lines(files["calibration.json"], coverage_factor) + span_lines(run)
    claim += unexplained_claim_lines(run)
    for line in summary_lines(run) + claim:
        click.echo(line)
    for name in files:
        echo_err(f"wrote {out / name}")
    if strict and not run.fit.explains_poses:
        echo_err(
            "error: the model does not explain the poses (chi-square test); "
            f"exit status {CHECK_FAILED_EXIT} (--strict)"
        )
        raise SystemExit(CHECK_FAILED_EXIT)
