"""``hexatherm fit-spheres``: ball centres from probed points (CSV or DMIS)."""

from __future__ import annotations

import functools
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
from hexatherm.io.files import ReadOptions


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
    import numpy as np

    from hexatherm.io.csvfile import centres_to_csv
    from hexatherm.io.measurements import read_measurements
    from hexatherm.io.outputs import check_output_settled, write_output_file
    from hexatherm.io.records import Records, concat_records, refuse_groups_in_two_files
    from hexatherm.workflows.process.measured import fit_points

    imports_done()
    if out is not None:
        check_output_settled(out, kind="file", inputs=points, overwrite=overwrite)
    probed: list[Records] = []
    for path in points:
        with ProgressBars() as bars:
            records = read_measurements(
                path,
                progress=functools.partial(bars.reading, str(path)),
                allow_truncated=reading.allow_truncated,
                keep_later=reading.keep_later,
            )
        found = [r for r in records if r.kind == "points"]
        if not found:
            echo_err(f"{path}: no probed points, skipped")
        probed.extend(found)
    # a step's ball in two files would be two centres that process refuses: say so here
    refuse_groups_in_two_files(probed)
    fitted = [fit_points(r, fixed_diameter_mm=fixed_diameter) for r in probed]
    if not fitted:
        raise click.ClickException("no probed points in the given files")
    kinds = {r.time_kind for r in fitted}
    if len(kinds) > 1:
        raise click.ClickException("the files mix ISO 8601 times and seconds")
    text = centres_to_csv(concat_records(fitted))
    if out is None:
        sys.stdout.write(text)
    else:
        write_output_file(out, text, inputs=points, overwrite=overwrite)
        echo_err(f"wrote {out}")
    for rec in fitted:
        form_um = float(np.max(np.asarray(rec.extra["form_um"], dtype=float)))
        echo_err(f"{rec.path}: {len(rec)} spheres, form error up to {form_um:.2f} um")
