"""``hexatherm inspect``: list the features a measurement file holds."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from hexatherm.cli.options import clean_errors, echo_err, reading_options
from hexatherm.workflows.common import ReadOptions


@click.command("inspect")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--csv", "as_csv", is_flag=True, help="Write the table as CSV instead of text.")
@reading_options
@clean_errors
def command(file: Path, as_csv: bool, reading: ReadOptions) -> None:
    """List the actual features of FILE (DMIS output, centres or points CSV).

    One row per feature: line, label, type, x, y, z (mm), size (diameter, mm)
    and time. For DMIS files every actual feature FA(...) is listed, whatever its
    label; for CSV files every row is a feature (SPHERE centres or POINTs).
    """
    from hexatherm.workflows.inspect import feature_table, program_without_actuals

    table = feature_table(file, reading)
    if as_csv:
        table.to_csv(sys.stdout, index=False, lineterminator="\n")
    else:
        click.echo(
            table.to_string(index=False, na_rep="", float_format=lambda v: f"{v:.4f}")
            if len(table)
            else "(no features)"
        )
    counts = table["type"].value_counts()
    echo_err(
        f"{file}: {len(table)} features ("
        + ", ".join(f"{n} {kind}" for kind, n in counts.items())
        + ")"
    )
    if program_without_actuals(file, table):
        echo_err(
            f"{file} is a DMIS program (nominal features and MEAS statements, as plan --dmis "
            "writes), not the CMM's output of running it: inspect lists the actual "
            "features FA(...) of that output"
        )
