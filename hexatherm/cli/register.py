"""``hexatherm register``: the balls file from one measurement of the platform's datums."""

from __future__ import annotations

from pathlib import Path

import click

from hexatherm.cli.options import (
    CheckedFloat,
    clean_errors,
    echo_err,
    imports_done,
    overwrite_option,
    reading_options,
)
from hexatherm.workflows.common import ReadOptions


@click.command("register")
@click.argument("measurement", type=click.Path(path_type=Path))
@click.option(
    "--datums",
    "datums_path",
    required=True,
    type=click.Path(path_type=Path),
    help="Datums file (format: hexatherm-datums/1): names of the top-face, bore and "
    "ball features, origin offset, probe.",
)
@click.option(
    "-o",
    "--out",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Balls file to write.",
)
@click.option(
    "--fixed-diameter",
    is_flag=True,
    help="Fit the balls with their diameters fixed (plus the tip if uncompensated).",
)
@click.option(
    "--diameter-tolerance-um",
    type=CheckedFloat(min=0, allow_inf=True),
    default=20.0,
    show_default=True,
    help="Refuse a ball whose fitted diameter (free radius) deviates more from the datums "
    "file's (inf: no check).",
)
@overwrite_option
@reading_options
@clean_errors
def command(
    measurement: Path,
    datums_path: Path,
    out: Path,
    fixed_diameter: bool,
    diameter_tolerance_um: float,
    overwrite: bool,
    reading: ReadOptions,
) -> None:
    """Build the platform frame from MEASUREMENT and write the balls file.

    MEASUREMENT (points CSV or DMIS) holds probed points of the platform's top
    face, of two bores and of the balls, all under one step label; features are
    told apart by the 'ball' column (DMIS: FA(<step>_<feature>_<n>)). Z is the top
    face's normal (towards the balls), X runs from the first bore's centre to the
    second's, the origin is the first bore's centre on the face plus the offset.
    """
    from hexatherm.workflows.register import register

    imports_done()

    result = register(
        measurement, datums_path, out, fixed_diameter, diameter_tolerance_um, overwrite, reading
    )
    plane, (b1, b2) = result.frame.plane, result.frame.bores
    echo_err(f"top face: {plane.n} points, flatness {plane.form_um:.2f} um")
    echo_err(
        f"bores: {b1.n} and {b2.n} points, diameters {2 * b1.radius_mm:.4f} and "
        f"{2 * b2.radius_mm:.4f} mm, {result.bore_distance_mm:.4f} mm apart"
    )
    click.echo("ball   x_mm        y_mm        z_mm        diameter_mm  form_um  n")
    for name, c, d, f, n in zip(
        result.balls.names,
        result.balls.centres_mm,
        result.fitted_diameters_mm,
        result.form_um,
        result.n,
        strict=True,
    ):
        click.echo(f"{name:6} {c[0]:11.5f} {c[1]:11.5f} {c[2]:11.5f} {d:12.5f} {f:8.2f} {n:3d}")
    echo_err(f"wrote {out}")
