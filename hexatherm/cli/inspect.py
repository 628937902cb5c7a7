"""``hexatherm inspect``: list the features a measurement file holds."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from hexatherm.cli.options import clean_errors, echo_err, imports_done, reading_options
from hexatherm.workflows.common import ReadOptions


@click.command("inspect")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--csv", "as_csv", is_flag=True, help="Write the table as CSV instead of text.")
@click.option(
    "--session",
    type=click.Path(path_type=Path),
    help="A session (file or folder) whose feature_names map a QIF file's feature names.",
)
@reading_options
@clean_errors
def command(file: Path, as_csv: bool, session: Path | None, reading: ReadOptions) -> None:
    """List the actual features of FILE (DMIS output, centres or points CSV, QIF results).

    One row per feature: line, label, type, x, y, z (mm), size (diameter, mm)
    and time. For DMIS files every actual feature FA(...) is listed, whatever its
    label; for CSV files every row is a feature (SPHERE centres or POINTs); for a
    QIF 3 results file every sphere, with what was read (unit, steps, balls, times,
    names).

    Given a session (its folder or session.yaml), it says what each measurement entry
    reads (its format and column map, units, steps, balls, times: Calypso runs, mapped
    tables) and lists every centre read, with its file.
    """
    from hexatherm.workflows.inspect import (
        feature_listing,
        is_session,
        program_without_actuals,
        session_reading,
    )

    imports_done()

    if is_session(file):
        lines, listing = session_reading(file, reading)
        for line in lines:
            echo_err(line)
    else:
        listing = feature_listing(file, reading, session)
    if as_csv:
        listing.frame().to_csv(sys.stdout, index=False, lineterminator="\n")
    elif not len(listing):
        click.echo("(no features)")
    else:
        blocks = listing.text_blocks()
        if blocks is None:
            click.echo(listing.text())
        else:
            for block in blocks:
                click.echo(block, nl=False)
    for note in listing.notes:
        echo_err(note)
    echo_err(
        f"{file}: {len(listing)} features ("
        + ", ".join(f"{n} {kind}" for kind, n in listing.counts())
        + ")"
    )
    if not is_session(file) and program_without_actuals(file, len(listing)):
        echo_err(
            f"{file} is a DMIS program (nominal features and MEAS statements, as plan --dmis "
            "writes), not the CMM's output of running it: inspect lists the actual "
            "features FA(...) of that output"
        )
