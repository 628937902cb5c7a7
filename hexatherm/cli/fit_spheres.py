"""``hexatherm fit-spheres``: ball centres from probed points (CSV or DMIS)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from hexatherm.cli.options import (
    CheckedFloat,
    ProgressBars,
    clean_errors,
    echo_err,
    imports_done,
    overwrite_option,
    reading_options,
)
from hexatherm.workflows.common import ReadOptions


@click.command("fit-spheres")
@click.argument("points", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Centres CSV to write [default: standard output].",
)
@click.option(
    "--diameter-mm",
    "fixed_diameter",
    type=CheckedFloat(min=0, min_open=True),
    default=None,
    metavar="MM",
    help="Fix the sphere diameter to MM instead of fitting it: better on small caps "
    "(elsewhere --fixed-diameter is a flag that takes the balls file's diameters; "
    "fit-spheres has no balls file).",
)
@click.option(
    "--fixed-diameter",
    "old_fixed_diameter",
    type=CheckedFloat(min=0, min_open=True),
    default=None,
    hidden=True,
    help="The earlier name of --diameter-mm.",
)
@overwrite_option
@reading_options
@clean_errors
def command(
    points: tuple[Path, ...],
    out: Path | None,
    fixed_diameter: float | None,
    old_fixed_diameter: float | None,
    overwrite: bool,
    reading: ReadOptions,
) -> None:
    """Fit a sphere to every (label, ball) group of the POINTS files.

    Writes a centres file: label,ball,x,y,z,time (time: mean of the points),
    then diameter, form_um (max-min residual), n, u_um (standard uncertainty
    of the centre from the residuals, sqrt(tr C / 3)) and the centre's covariance C:
    u_x_um, u_y_um, u_z_um and the correlations r_xy, r_xz, r_yz.
    """
    if old_fixed_diameter is not None:
        if fixed_diameter is not None:
            raise click.UsageError("give --diameter-mm (the name of --fixed-diameter now) once")
        echo_err("warning: fit-spheres --fixed-diameter MM is now --diameter-mm MM")
        fixed_diameter = old_fixed_diameter
    from hexatherm.workflows.fit_spheres import fit_spheres

    imports_done()
    with ProgressBars() as bars:
        fitted = fit_spheres(
            points,
            out,
            fixed_diameter,
            overwrite,
            reading,
            progress=bars.reading,
            on_skipped=lambda path: echo_err(f"{path}: no probed points, skipped"),
        )
    if out is None:
        sys.stdout.write(fitted.text)
    else:
        echo_err(f"wrote {out}")
    for path, n, form_um in fitted.files:
        echo_err(f"{path}: {n} spheres, form error up to {form_um:.2f} um")
