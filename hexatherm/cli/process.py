"""``hexatherm process``: conventional and thermal deflection decoupled poses of a session."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from hexatherm.cli.options import (
    CHECK_FAILED_EXIT,
    CheckedFloat,
    ProgressBars,
    check_draws,
    clean_errors,
    coverage_factor_option,
    decision_rule_options,
    echo_err,
    imports_done,
    interpolation_option,
    mc_option,
    output_dir_option,
    overwrite_option,
    pose_tolerance_option,
    quality_threshold_option,
    reading_options,
    seed_option,
    tolerance_option,
)
from hexatherm.workflows.common import ReadOptions
from hexatherm.workflows.limits import DEFAULTS, DISTANCE_REFUSAL_UM

if TYPE_CHECKING:
    from hexatherm.workflows.common import Tolerance


@click.command("process")
@click.argument("session", type=click.Path(exists=True, path_type=Path))
@output_dir_option
@overwrite_option
@interpolation_option
@click.option(
    "--fixed-diameter",
    "fixed_diameter",
    is_flag=True,
    help="Fit spheres to probed points with the radius fixed to the balls file's "
    "(plus the probe tip's when points are not compensated); default: free radius.",
)
@click.option(
    "--distance-tolerance-um",
    type=CheckedFloat(min=0, allow_inf=True),
    default=DISTANCE_REFUSAL_UM,
    show_default=True,
    help="Refuse a step whose inter-ball distances deviate more from the balls file (um; a "
    "gross error: swapped balls, inch read as mm; inf: no check). Smaller deviations beyond "
    "the quality limit distance_dev_um are processed and flagged.",
)
@click.option(
    "--registration-tolerance-um",
    type=CheckedFloat(min=0, allow_inf=True),
    default=DEFAULTS.registration_rms_um,
    show_default=True,
    help="Warn about a step whose registration RMS residual is larger (um; the quality "
    "limit registration_rms_um).",
)
@click.option(
    "--strict-registration",
    is_flag=True,
    help="Fail instead of warning when a registration exceeds its tolerance.",
)
@pose_tolerance_option
@mc_option
@seed_option
@quality_threshold_option
@click.option(
    "--method",
    "methods",
    type=click.Choice(["references", "twin"]),
    multiple=True,
    default=("references",),
    show_default=True,
    help="Corrections to report; 'twin' adds the poses corrected by the twin from "
    "the thermocouples alone (Tx_twin_mm ...), no reference needed.",
)
@click.option(
    "--hexapod",
    "hexapod_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="The twin's model for --method twin (e.g. the hexapod.yaml of hexatherm "
    "diagnose); default: the session's hexapod file.",
)
@click.option(
    "--strict",
    is_flag=True,
    help=f"Exit with status {CHECK_FAILED_EXIT} when a quality check fails (the results "
    "are still written); without it a failed check is a warning.",
)
@click.option(
    "--covariance/--no-covariance",
    "between",
    default=None,
    help="Write covariance.csv, the covariance between every pair of targets "
    "[default: up to 200 targets; a 1000-target campaign makes it 120 MB].",
)
@tolerance_option
@decision_rule_options
@coverage_factor_option("that the conformity columns of poses.csv use (with tolerances)")
@reading_options
@clean_errors
def command(
    session: Path,
    out: str | None,
    overwrite: bool,
    interpolation: str,
    fixed_diameter: bool,
    distance_tolerance_um: float,
    registration_tolerance_um: float,
    strict_registration: bool,
    pose_tolerance: tuple[float, float] | None,
    mc: int,
    seed: int,
    quality_thresholds: tuple[str, ...],
    methods: tuple[str, ...],
    hexapod_path: Path | None,
    strict: bool,
    between: bool | None,
    tolerances: dict[str, Tolerance],
    decision_rule: str | None,
    guard_factor: float | None,
    coverage_factor: float,
    reading: ReadOptions,
) -> None:
    """Process SESSION (a folder with session.yaml, or the file itself).

    Measurement files may hold ball centres or probed points (CSV or DMIS);
    points are fitted with spheres. Writes OUT/poses.csv (conventional and
    corrected pose of every target, with standard uncertainties and their parts
    common to all targets and of their own), OUT/covariance.csv (covariance between
    targets), OUT/legs.csv (pose, IGM leg lengths and registration residual of every
    step), OUT/fits.csv (quality of every ball centre) and OUT/quality.csv (quality
    checks of every step), and prints the deviations from the commanded poses side by
    side, in um and urad. Repeated O and R0 (plan --origin-repeats ...) are averaged.
    """
    from hexatherm.workflows.process.outputs import deviation_table, significance_lines
    from hexatherm.workflows.process.run import ProcessRequest, process
    from hexatherm.workflows.process.summary import (
        failure_text,
        session_lines,
        uncertainty_summary,
    )

    imports_done()
    check_draws(mc)  # and --seed without --mc
    if hexapod_path is not None and "twin" not in methods:
        raise click.BadParameter(
            "--hexapod is the twin's model: use it with --method twin", param_hint="'--hexapod'"
        )
    request = ProcessRequest(
        session=session,
        out=Path(out) if out is not None else None,
        overwrite=overwrite,
        interpolation=interpolation,
        fixed_diameter=fixed_diameter,
        distance_tolerance_um=distance_tolerance_um,
        registration_tolerance_um=registration_tolerance_um,
        strict_registration=strict_registration,
        pose_tolerance=pose_tolerance,
        mc=mc,
        seed=seed,
        quality_thresholds=quality_thresholds,
        methods=methods,
        hexapod_path=hexapod_path,
        between=between,
        tolerances=tolerances,
        decision_rule=decision_rule,
        guard_factor=guard_factor,
        coverage_factor=coverage_factor,
        reading=reading,
    )
    with ProgressBars() as bars:
        outcome = process(request, bars.reading, bars.draws)
    for warning in outcome.result.warnings:
        echo_err(f"warning: {warning}")
    if outcome.twin_note:
        echo_err(outcome.twin_note)
    given = click.get_current_context().get_parameter_source("coverage_factor")
    if not outcome.tolerances and given is click.core.ParameterSource.COMMANDLINE:
        echo_err(
            "warning: --coverage-factor: no tolerance to judge against (--tolerance, or "
            "tolerances: in the session file): it changes nothing"
        )
    for line in session_lines(outcome):
        echo_err(line)
    click.echo(
        deviation_table(
            outcome.result, outcome.twin, outcome.uncertainty, coverage_factor, outcome.poses_csv
        )
    )
    for line in significance_lines(outcome.result, outcome.uncertainty, coverage_factor):
        click.echo(line)
    for line in uncertainty_summary(outcome.uncertainty):
        echo_err(line)
    echo_err(f"quality checks of {len(outcome.quality.frame)} steps:")
    for line in outcome.quality.summary():
        echo_err(line)
    if outcome.conformity is not None:
        from hexatherm.workflows.process.conformity import conformity_line  # with tolerances

        echo_err(conformity_line(outcome.conformity))
    for path in outcome.written:
        echo_err(f"wrote {path}")
    failed = failure_text(outcome)
    if failed is not None:
        if strict:
            echo_err(f"error: {failed}; exit status {CHECK_FAILED_EXIT} (--strict)")
            raise SystemExit(CHECK_FAILED_EXIT)
        echo_err(f"warning: {failed}")
