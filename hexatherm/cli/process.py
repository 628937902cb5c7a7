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
@clean_errors
def command(session: Path, out: str | None, overwrite: bool, interpolation: str) -> None:
    """Process SESSION (a folder with session.yaml, or the file itself).

    Writes OUT/poses.csv (conventional and corrected pose of every target) and
    OUT/legs.csv (IGM leg lengths of every step), and prints the deviations from
    the commanded poses side by side, in um and urad.
    """
    from hexatherm.io.results import deviation_table, write_results
    from hexatherm.pipeline import process_session

    folder = session if session.is_dir() else session.parent
    out_dir = Path(out) if out is not None else folder / "results"
    if out_dir.exists() and not overwrite:
        raise click.ClickException(f"{out_dir} exists; use --overwrite to replace it")
    result = process_session(session, interpolation)  # type: ignore[arg-type]
    written = write_results(result, out_dir, overwrite=overwrite)
    n = len(result.correction.target_index)
    echo_err(f"session {result.session.name}: {len(result.session.plan.labels)} steps, "
             f"{n} targets, interpolation {interpolation}")
    click.echo(deviation_table(result))
    for path in written:
        echo_err(f"wrote {path}")
