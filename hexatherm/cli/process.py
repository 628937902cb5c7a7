"""``hexatherm process``: conventional and thermal deflection decoupled poses of a session."""

from __future__ import annotations

from pathlib import Path

import click

from hexatherm.cli.options import (
    clean_errors,
    echo_err,
    interpolation_option,
    output_dir_option,
    overwrite_option,
)


@click.command("process")
@click.argument("session", type=click.Path(exists=True, path_type=Path))
@output_dir_option
@overwrite_option
@interpolation_option
@click.option("--fixed-diameter", "fixed_diameter", is_flag=True,
              help="Fit spheres to probed points with the radius fixed to the balls file's "
              "(plus the probe tip's when points are not compensated); default: free radius.")
@click.option("--distance-tolerance-um", type=click.FloatRange(min=0), default=50.0,
              show_default=True, help="Refuse a step whose inter-ball distances deviate more.")
@click.option("--registration-tolerance-um", type=click.FloatRange(min=0), default=10.0,
              show_default=True, help="Warn about a step whose registration RMS is larger.")
@click.option("--strict-registration", is_flag=True,
              help="Fail instead of warning when a registration exceeds its tolerance.")
@clean_errors
def command(session: Path, out: str | None, overwrite: bool, interpolation: str,
            fixed_diameter: bool, distance_tolerance_um: float,
            registration_tolerance_um: float, strict_registration: bool) -> None:
    """Process SESSION (a folder with session.yaml, or the file itself).

    Measurement files may hold ball centres or probed points (CSV or DMIS);
    points are fitted with spheres. Writes OUT/poses.csv (conventional and
    corrected pose of every target), OUT/legs.csv (pose, IGM leg lengths and
    registration residual of every step) and OUT/fits.csv (quality of every ball
    centre), and prints the deviations from the commanded poses side by side, in
    um and urad.
    """
    from hexatherm.io.atomic import refuse_existing
    from hexatherm.io.results import deviation_table, write_results
    from hexatherm.pipeline import Checks, process_session

    folder = session if session.is_dir() else session.parent
    out_dir = Path(out) if out is not None else folder / "results"
    refuse_existing(out_dir, overwrite)
    checks = Checks(distance_tolerance_um, registration_tolerance_um, strict_registration)
    result = process_session(session, interpolation,  # type: ignore[arg-type]
                             0.0 if fixed_diameter else None, checks)
    for warning in result.warnings:
        echo_err(f"warning: {warning}")
    written = write_results(result, out_dir, overwrite=overwrite)
    n = len(result.correction.target_index)
    echo_err(f"session {result.session.name}: {len(result.session.plan.labels)} steps, "
             f"{n} targets, interpolation {interpolation}")
    click.echo(deviation_table(result))
    for path in written:
        echo_err(f"wrote {path}")
