"""``hexatherm acquire``: record a session from a serial probe stream, resume it, replay it."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import click

from hexatherm.cli.options import (
    MAX_BAUD,
    CheckedFloat,
    clean_errors,
    echo_err,
    imports_done,
    max_gap_option,
)
from hexatherm.workflows.limits import DEFAULTS, radius_limit_um

if TYPE_CHECKING:
    from hexatherm.workflows.acquire.recorder import BallFit


def _fits_table(fits: Sequence[BallFit]) -> str:
    """CSV table of the live ball fits (standard output)."""
    lines = ["label,ball,n,x,y,z,radius_mm,form_um,warnings"]
    for fit in fits:
        centre = fit.centre_mm or (float("nan"),) * 3
        lines.append(
            ",".join(
                [fit.label, fit.ball, str(fit.n)]
                + [f"{v:.6f}" for v in centre]
                + [f"{fit.radius_mm:.6f}", f"{fit.form_um:.2f}", str(len(fit.warnings))]
            )
        )
    return "\n".join(lines)


@click.command("acquire")
@click.argument("plan", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--hexapod",
    "hexapod_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Hexapod file [with --resume or --replay: the session's copy].",
)
@click.option(
    "--balls",
    "balls_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Balls file [with --resume or --replay: the session's copy].",
)
@click.option(
    "--port",
    help="Probe port: a device (/dev/ttyUSB0, COM3) or a pyserial URL "
    "(socket://host:port, rfc2217://host:port, loop://).",
)
@click.option(
    "--session",
    "session",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Session folder to record into (or, with --replay, to create).",
)
@click.option(
    "--baud",
    type=click.IntRange(min=1, max=MAX_BAUD),
    default=9600,
    show_default=True,
    help="The probe's serial line speed (baud, bits per second), as its interface sends.",
)
@click.option(
    "--bytesize",
    type=click.Choice(["5", "6", "7", "8"]),
    default="8",
    show_default=True,
    help="Data bits per character of the probe's serial line.",
)
@click.option(
    "--parity",
    type=click.Choice(["N", "E", "O", "M", "S"], case_sensitive=False),
    default="N",
    show_default=True,
    help="Parity of the probe's serial line: N none, E even, O odd, M mark, S space.",
)
@click.option(
    "--stopbits",
    type=click.Choice(["1", "1.5", "2"]),
    default="1",
    show_default=True,
    help="Stop bits per character of the probe's serial line.",
)
@click.option("--xonxoff", is_flag=True, help="Software flow control.")
@click.option("--rtscts", is_flag=True, help="Hardware (RTS/CTS) flow control.")
@click.option("--dsrdtr", is_flag=True, help="Hardware (DSR/DTR) flow control.")
@click.option(
    "--read-timeout",
    type=CheckedFloat(min=0.001),
    default=0.1,
    show_default=True,
    help="Serial read timeout (s); partial lines are kept.",
)
@click.option(
    "--reopen-interval",
    type=CheckedFloat(min=0.001),
    default=1.0,
    show_default=True,
    help="Seconds between attempts to reopen a lost port.",
)
@click.option(
    "--units",
    "unit",
    type=click.Choice(["mm", "inch", "um"]),
    default="mm",
    show_default=True,
    help="Unit of numbers the probe sends without a unit.",
)
@click.option(
    "--auto",
    is_flag=True,
    help="Non-interactive: move to the next ball as soon as it has its points.",
)
@click.option(
    "--resume", is_flag=True, help="Continue an interrupted session at its first incomplete ball."
)
@click.option(
    "--replay",
    "replay_log",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Re-run a recorded serial.log instead of reading a port.",
)
@click.option(
    "--idle-timeout",
    type=CheckedFloat(min=0),
    default=None,
    help="Stop (resumable) when the probe sends nothing for this long (s).",
)
@max_gap_option
@click.option(
    "--radius-tol-um",
    type=CheckedFloat(min=0),
    default=radius_limit_um(),
    show_default=True,
    help="Warn when a ball's fitted radius is further off its nominal (um; half the "
    "quality limit diameter_dev_um, so that a ball accepted here is not flagged by process).",
)
@click.option(
    "--form-tol-um",
    type=CheckedFloat(min=0),
    default=DEFAULTS.form_um,
    show_default=True,
    help="Warn when a ball's form error is larger (um; the quality limit form_um).",
)
@click.option(
    "--min-points",
    type=click.IntRange(min=1, max=100_000),
    default=5,
    show_default=True,
    help="Warn when a ball has fewer points.",
)
@click.option(
    "--surface-tol-um",
    type=CheckedFloat(min=0, min_open=True),
    default=500.0,
    show_default=True,
    help="Once O is measured, a point goes to the ball whose commanded surface it lies "
    "on within this (hexapod positioning and thermal error); others are rejected.",
)
@click.option(
    "--temperatures",
    "temperatures_file",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Thermocouple log to attach to the session (copied at the end).",
)
@click.option(
    "--temperature-port",
    help="Second port with a thermocouple logger (lines of "
    "six or more numbers: leg1..leg6, then others).",
)
@click.option(
    "--temperature-baud",
    type=click.IntRange(min=1, max=MAX_BAUD),
    default=9600,
    show_default=True,
    help="The thermocouple logger's serial line speed (baud; 8 data bits, no parity, 1 stop bit).",
)
@clean_errors
def command(
    plan: Path,
    hexapod_path: Path | None,
    balls_path: Path | None,
    port: str | None,
    session: Path,
    baud: int,
    bytesize: str,
    parity: str,
    stopbits: str,
    xonxoff: bool,
    rtscts: bool,
    dsrdtr: bool,
    read_timeout: float,
    reopen_interval: float,
    unit: str,
    auto: bool,
    resume: bool,
    replay_log: Path | None,
    idle_timeout: float | None,
    max_gap: float,
    radius_tol_um: float,
    form_tol_um: float,
    min_points: int,
    surface_tol_um: float,
    temperatures_file: Path | None,
    temperature_port: str | None,
    temperature_baud: int,
) -> None:
    """Record a session following PLAN from a probe on a serial port.

    Walks the operator through the plan (pose to command, ball to probe, points
    to go), assigns each point the probe sends to its step and ball, and writes
    SESSION/serial.log (every byte, time-stamped) and SESSION/points.csv as the
    data arrives. A sphere is fitted to each ball when it has its points. At
    the end SESSION/session.yaml makes the folder a session for
    ``hexatherm process``. Interactive commands (standard input): Enter or
    'next', 'redo', 'quit'. The fits go to standard output as CSV.

    Once O is measured, each point goes to the ball whose surface, at its
    commanded pose, it lies on (--surface-tol-um): the current ball, or the
    next one (which moves on); any other point is rejected, told and written
    to SESSION/rejected.csv. On --resume the interrupted ball's points are
    set aside there, and you are told what to probe.
    """
    from hexatherm.workflows.acquire.recorder import FitChecks
    from hexatherm.workflows.acquire.run import AcquireRequest, PortSettings, record

    imports_done()

    if replay_log is not None:
        if port is not None or resume or temperature_port is not None:
            raise click.UsageError(
                "--replay reads a recording: no --port, --resume or --temperature-port"
            )
    else:
        if port is None:
            raise click.UsageError("give the probe's --port (or --replay a recording)")
        if temperatures_file is not None and temperature_port is not None:
            raise click.UsageError("give --temperatures or --temperature-port, not both")
    if (hexapod_path is None or balls_path is None) and replay_log is None and not resume:
        raise click.UsageError(
            "--hexapod and --balls are needed (except with --resume or "
            "--replay, which use the session's copies)"
        )

    def notify(level: str, message: str) -> None:
        if level == "progress" and auto:
            return
        echo_err(("warning: " if level == "warn" else "") + message)

    probe = None
    if port is not None:
        probe = PortSettings(
            port,
            baudrate=baud,
            bytesize=int(bytesize),
            parity=parity.upper(),
            stopbits=float(stopbits),
            xonxoff=xonxoff,
            rtscts=rtscts,
            dsrdtr=dsrdtr,
            timeout_s=read_timeout,
        )
    request = AcquireRequest(
        plan=plan,
        session=session,
        hexapod=hexapod_path,
        balls=balls_path,
        probe=probe,
        reopen_interval_s=reopen_interval,
        unit=unit,
        auto=auto,
        resume=resume,
        replay_log=replay_log,
        idle_timeout_s=idle_timeout,
        max_gap_s=max_gap,
        checks=FitChecks(
            radius_tol_mm=radius_tol_um / 1e3,
            form_tol_um=form_tol_um,
            min_points=min_points,
            surface_tol_mm=surface_tol_um / 1e3,
        ),
        temperatures_file=temperatures_file,
        temperature_port=None
        if temperature_port is None
        else PortSettings(temperature_port, baudrate=temperature_baud, timeout_s=read_timeout),
    )
    try:
        result = record(request, notify, None if auto else sys.stdin)
    except KeyboardInterrupt:
        if replay_log is not None:
            raise
        echo_err(f"interrupted: everything received is in {session}; continue with --resume")
        sys.exit(130)
    click.echo(_fits_table(result.fits))
    n_warn = sum(bool(f.warnings) for f in result.fits)
    echo_err(
        f"{result.n_points} points in {result.session / 'points.csv'}"
        + (f"; {n_warn} ball(s) with warnings" if n_warn else "")
    )
    if result.session_file is not None:
        echo_err(f"wrote {result.session_file}")
