"""``hexatherm replay``: re-process recorded sessions and compare with ``expected/``."""

from __future__ import annotations

from pathlib import Path

import click

from hexatherm.cli.options import CheckedFloat, clean_errors, echo_err, imports_done


@click.command("replay")
@click.argument(
    "sessions_dir",
    required=False,
    default="sessions",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
)
@click.option(
    "--update",
    is_flag=True,
    help="After a deliberate change: rewrite the files of expected/ whose values moved "
    "beyond the tolerances, and list them (nothing else there is touched).",
)
@click.option(
    "--tol-mm",
    type=CheckedFloat(min=0),
    default=1.5e-7,
    show_default=True,
    help="Tolerance of columns in mm.",
)
@click.option(
    "--tol-deg",
    type=CheckedFloat(min=0),
    default=1e-6,
    show_default=True,
    help="Tolerance of columns in deg.",
)
@clean_errors
def command(sessions_dir: Path, update: bool, tol_mm: float, tol_deg: float) -> None:
    """Re-process every session of SESSIONS_DIR that has an expected/ folder.

    Each output column is compared with expected/ (mm and deg as set, um 1.5e-4,
    urad 1.5e-3, C 1.5e-4, s 1e-6, others relative 1e-9: at least 1.5 steps of the
    resolution the files are written at). Prints one line per session with the
    worst deviation per unit; exits 1 on any mismatch, naming session, file, row
    and column.
    """
    from hexatherm.workflows.replay import (
        DEFAULT_TOLERANCES,
        find_sessions,
        format_worst,
        replay_session,
    )

    imports_done()

    tolerances = {**DEFAULT_TOLERANCES, "mm": tol_mm, "deg": tol_deg}
    sessions = find_sessions(sessions_dir)
    if not sessions:
        raise click.ClickException(f"no session with an expected/ folder in {sessions_dir}")
    failed = 0
    click.echo(f"{'session':28} {'status':8} worst deviation")
    for folder in sessions:
        result = replay_session(folder, tolerances, update=update)
        repaired = not result.ok and result.repaired
        status = "ok" if result.ok else ("updated" if repaired else "MISMATCH")
        click.echo(f"{folder.name:28} {status:8} {format_worst(result.worst)}")
        for line in result.mismatches:
            echo_err(("changed: " if repaired else "mismatch: ") + line)
        for path in result.updated:
            echo_err(f"rewrote {path}")
        failed += not (result.ok or repaired)
    if failed:
        raise click.ClickException(f"{failed} of {len(sessions)} session(s) do not replay")
    echo_err(f"{len(sessions)} session(s) replayed")
