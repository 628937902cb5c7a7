"""``hexatherm process``: conventional and thermal deflection decoupled poses of a session."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

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
from hexatherm.io.files import ReadOptions
from hexatherm.workflows.limits import DEFAULTS, DISTANCE_REFUSAL_UM

if TYPE_CHECKING:
    from hexatherm.session import Tolerance
    from hexatherm.workflows.process.uncertainty import PoseUncertainty


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
    from hexatherm.io.config import read_session
    from hexatherm.io.outputs import check_output_settled
    from hexatherm.workflows.process.carryerror import carry_line
    from hexatherm.workflows.process.outputs import (
        deviation_table,
        significance_lines,
        write_results,
    )
    from hexatherm.workflows.process.pipeline import Checks, process_session
    from hexatherm.workflows.process.quality import (
        parse_threshold,
        quality_checks,
        session_thresholds,
    )
    from hexatherm.workflows.process.uncertainty import pose_uncertainty

    imports_done()
    check_draws(mc)  # and --seed without --mc
    if hexapod_path is not None and "twin" not in methods:
        raise click.BadParameter(
            "--hexapod is the twin's model: use it with --method twin", param_hint="'--hexapod'"
        )
    overrides = dict(parse_threshold(t) for t in quality_thresholds)
    folder = session if session.is_dir() else session.parent
    out_dir = Path(out) if out is not None else folder / "results"
    # before any work: never into, around or onto the session's files (checked again under
    # the output's lock when the results are written)
    session_file = read_session(session)
    # the twin's model is an input too (diagnose's hexapod.yaml, in a folder of hexatherm's)
    extra_inputs = [] if hexapod_path is None else [hexapod_path]
    check_output_settled(
        out_dir,
        kind="folder",
        inputs=[*session_file.input_files(), *extra_inputs],
        overwrite=overwrite,
    )
    if "twin" in methods and session_file.temperatures is None:
        from hexatherm.errors import InputError

        raise InputError(
            "the twin corrects from the thermocouple log: add 'temperatures: "
            "temperatures.csv' to the session",
            path=str(session_file.path),
            field="temperatures",
        )
    checks = Checks(
        distance_tolerance_um, registration_tolerance_um, strict_registration, pose_tolerance
    )
    with ProgressBars() as bars:
        result = process_session(
            session,
            interpolation,  # type: ignore[arg-type]
            0.0 if fixed_diameter else None,
            checks,
            bars.reading,
            reading,
            session=session_file,
        )
    for warning in result.warnings:
        echo_err(f"warning: {warning}")
    twin = None
    if "twin" in methods:
        from hexatherm.io.config import read_hexapod
        from hexatherm.workflows.process.twin import twin_poses

        model = result.session.hexapod if hexapod_path is None else read_hexapod(hexapod_path)
        twin = twin_poses(result, model, str(hexapod_path or ""))
        gap = (twin - result.correction.corrected)[:, :3] * 1e3
        effects = ", ".join(e["name"] for e in model.effects) or "none"
        echo_err(
            f"twin ({hexapod_path or 'the session hexapod'}; effects: {effects}): "
            f"twin-corrected minus corrected by the references, RMS "
            f"{np.sqrt(np.mean(gap**2)):.3f} um over the targets' translations"
        )
    with ProgressBars() as bars:
        uncertainty = pose_uncertainty(
            result, mc=mc, seed=seed, progress=bars.draws, between=between
        )
    quality = quality_checks(result, session_thresholds(result.session, overrides))
    tolerances = {**result.session.tolerances, **tolerances}
    judged = None
    given = click.get_current_context().get_parameter_source("coverage_factor")
    if not tolerances and given is click.core.ParameterSource.COMMANDLINE:
        echo_err(
            "warning: --coverage-factor: no tolerance to judge against (--tolerance, or "
            "tolerances: in the session file): it changes nothing"
        )
    if tolerances:
        from hexatherm.workflows.process.conformity import conformity
        from hexatherm.workflows.process.conformity import decision_rule as rule_of

        rule = rule_of({}, decision_rule, guard_factor)
        judged = conformity(result, uncertainty, tolerances, coverage_factor, rule)
    from hexatherm.workflows.process.conformity import conformity_line

    written = write_results(
        result,
        out_dir,
        overwrite=overwrite,
        uncertainty=uncertainty,
        quality=quality,
        twin=twin,
        conformity=judged,
        extra_inputs=extra_inputs,
    )
    n = len(result.correction.target_index)
    averaged = "".join(
        f", {g.label} averaged over {len(g.labels)} measurements" for g in result.repeats
    )
    echo_err(
        f"session {result.session.name}: {len(result.session.plan.labels)} steps, "
        f"{n} targets, interpolation {interpolation}{averaged}"
    )
    carried = carry_line(result, uncertainty.carry)
    if carried:
        echo_err(carried)
    smooth = result.correction.smooth
    if smooth is not None:
        lams = ", ".join(sorted({f"{v:.2g}" for v in smooth.lam})) if smooth.used else ""
        echo_err(
            f"interpolation smooth: {smooth.reason}"
            + (f" (smoothing {lams}, times scaled to [0, 1])" if lams else "")
        )
    click.echo(deviation_table(result, twin, uncertainty, coverage_factor))
    for line in significance_lines(result, uncertainty, coverage_factor):
        click.echo(line)
    for line in uncertainty_summary(uncertainty):
        echo_err(line)
    echo_err(f"quality checks of {len(quality.frame)} steps:")
    for line in quality.summary():
        echo_err(line)
    if judged is not None:
        echo_err(conformity_line(judged))
    for path in written:
        echo_err(f"wrote {path}")
    if quality.any_failed:
        steps = quality.failed_steps
        what = (
            f"quality checks failed at {len(steps)} step(s) ({', '.join(steps[:5])}"
            + (" ..." if len(steps) > 5 else "")
            + ")"
        )
        if strict:
            echo_err(f"error: {what}; exit status {CHECK_FAILED_EXIT} (--strict)")
            raise SystemExit(CHECK_FAILED_EXIT)
        echo_err(f"warning: {what}")


#: the largest relative standard uncertainty of a Monte Carlo u said without a warning
#: (1/sqrt(2 (M - 1)): 10 % at 51 draws)
MC_RELATIVE_LIMIT = 0.1


def uncertainty_summary(uncertainty: PoseUncertainty) -> list[str]:
    """Screen lines: where the centre uncertainties came from, and the largest pose ones."""
    lines = [f"uncertainty: centres from {uncertainty.centres.description}"]
    for name, u in (
        ("conventional", uncertainty.conventional_u),
        ("corrected", uncertainty.corrected_u),
    ):
        if u.size == 0:
            continue
        t_um, r_urad = u[:, :3].max() * 1e3, np.deg2rad(u[:, 3:]).max() * 1e6
        lines.append(
            f"  u ({uncertainty.method}, k=1) of the {name} poses: up to "
            f"{t_um:.3f} um, {r_urad:.2f} urad"
        )
    lines.extend(shared_summary(uncertainty))
    excess = uncertainty.smooth_excess
    if excess is not None:
        residuals = (
            f"the references' standardized residuals from the smooth fit {excess.observed_um:.3g}"
            f" um RMS, {excess.noise_um:.3g} um from their noise alone"
        )
        lines.append(
            f"  smooth fit's own error (bias, smoothing chosen from the data): growth at R "
            f"{excess.excess_um:.3g} um RMS over the legs added to each corrected pose's own u "
            f"({residuals})"
            if excess.excess_um > 0
            else f"  smooth fit's own error: nothing added ({residuals})"
        )
    for check in uncertainty.repeats:
        line = (
            f"  {check.label} measured {check.n} times, averaged: their scatter is "
            f"{check.ratio:.2f}x the claimed u (chi2 {check.chi2:.1f} over {check.dof} dof"
            + (", after a straight-line drift" if check.n >= 3 else "")
            + ")"
        )
        lines.append(line)
        if not check.ok:
            lines.append(
                f"warning: the {check.n} measurements of {check.label} scatter more than "
                f"their u allows (p = {check.p_value:.1g}): the platform moved or drifted "
                "between them, or a ball was probed badly; the average is used, and u "
                "does not include that scatter"
            )
    if uncertainty.method == "monte-carlo":
        ratio = uncertainty.ratio_to_linear()
        if np.isfinite(ratio).any():
            drawn = (
                "probed points drawn, spheres refitted"
                if uncertainty.drawn == "points"
                else "centres drawn from their covariance"
            )
            lines.append(
                f"  Monte Carlo ({uncertainty.draws} draws, seed {uncertainty.seed}) "
                f"over linear propagation: {np.nanmin(ratio):.3f} to "
                f"{np.nanmax(ratio):.3f} ({drawn})"
            )
        # a standard deviation of M draws is itself uncertain by 1/sqrt(2 (M - 1)) (k=1)
        relative = 1 / np.sqrt(2 * (uncertainty.draws - 1))
        if relative > MC_RELATIVE_LIMIT:
            lines.append(
                f"warning: {uncertainty.draws} Monte Carlo draws: every u written is the "
                f"standard deviation of {uncertainty.draws} values, itself uncertain by "
                f"about {relative * 100:.0f} % (k=1); --mc 1000 or more for a u to rely on"
            )
    return lines


def shared_summary(uncertainty: PoseUncertainty) -> list[str]:
    """Screen lines: the parts of u common to all targets (O and R0) and of their own."""
    common, own = uncertainty.common_u, uncertainty.own_u
    if common is None or own is None or common.size == 0:
        return []
    from hexatherm.core.geometry import to_um_urad

    def rms(values: np.ndarray) -> str:
        v = np.sqrt(np.mean(to_um_urad(values) ** 2, axis=0))
        return (
            " ".join(f"{n} {x:.3g}" for n, x in zip(("Tx", "Ty", "Tz"), v[:3], strict=True))
            + " um, "
            + " ".join(f"{n} {x:.3g}" for n, x in zip(("Rx", "Ry", "Rz"), v[3:], strict=True))
            + " urad"
        )

    scaled = " (linear shares of the Monte Carlo u)" if uncertainty.method == "monte-carlo" else ""
    lines = [
        "  parts of u, RMS over the targets" + scaled + ": common to all targets (the one "
        "measurement of O and R0 every pose carries; it shifts all targets together and "
        "cancels in their differences) and own (the target's step and its references):"
    ]
    for name, cols in (("conventional", slice(0, 6)), ("corrected", slice(6, 12))):
        lines.append(f"    {name:12} common {rms(common[:, cols])}")
        lines.append(f"    {'':12} own    {rms(own[:, cols])}")
    if uncertainty.between_covariance is not None:
        lines.append("  covariance between targets: covariance.csv")
    else:
        m = len(common)
        lines.append(
            f"  covariance between targets: not written for {m} targets "
            f"({m * (m + 1) // 2:,} pairs); --covariance writes covariance.csv"
        )
    return lines
