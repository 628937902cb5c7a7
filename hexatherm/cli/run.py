"""``hexatherm run``: an unattended campaign over I++ DME and a hexapod controller."""

from __future__ import annotations

import contextlib
import sys
from pathlib import Path

import click

from hexatherm.cli.options import (
    CHECK_FAILED_EXIT,
    CheckedFloat,
    clean_errors,
    echo_err,
    imports_done,
)
from hexatherm.cli.signals import signals_interrupt
from hexatherm.errors import Terminated
from hexatherm.workflows.limits import DEFAULTS, radius_limit_um

#: the largest coordinate (mm) or angle (deg) an option of run or serve-twin takes
LARGEST_MM = 1e5


def _numbers(text: str | None, n: int, what: str) -> tuple[float, ...] | None:
    """``n`` comma-separated finite numbers, none beyond :data:`LARGEST_MM` (or None)."""
    if text is None:
        return None
    try:
        values = tuple(float(c) for c in text.replace(";", ",").split(","))
    except ValueError:
        values = ()
    if len(values) != n or not all(abs(v) < float("inf") for v in values):
        raise click.BadParameter(f"{text!r}: expected {n} finite numbers", param_hint=what)
    if max(abs(v) for v in values) > LARGEST_MM:
        raise click.BadParameter(
            f"{text!r}: a number beyond {LARGEST_MM:g} (mm, deg) is no machine's", param_hint=what
        )
    return values


@click.command("run")
@click.argument("plan", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--cmm", "cmm_url", required=True, help="The CMM's I++ DME server: ipp://HOST:1294.")
@click.option(
    "--controller",
    "controller_url",
    required=True,
    help="The hexapod controller: symetrie://HOST:61559, pi://HOST:50000 or "
    "symetrie-pmac://HOST:23.",
)
@click.option(
    "--session",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Session folder to record into.",
)
@click.option(
    "--hexapod",
    "hexapod_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Hexapod file [with --resume: the session's copy].",
)
@click.option(
    "--balls",
    "balls_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Balls file [with --resume: the session's copy].",
)
@click.option(
    "--origin-on-cmm",
    metavar="Tx,Ty,Tz,Rx,Ry,Rz",
    help="Nominal placement of frame O on the CMM, as plan --dmis takes it (the balls are "
    "predicted from it until O is measured) [with --resume: the session's run.yaml].",
)
@click.option(
    "--dry-run", is_flag=True, help="Check the whole plan on both machines; move nothing."
)
@click.option(
    "--dry-run-transcript",
    "dry_run_transcript",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="With --dry-run: keep its I++ transcript in this file (written once the CMM was "
    "reached, whether the check passed or not; never replaced without --overwrite, never "
    "an input, never inside SESSION, which a dry run leaves untouched).",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace an existing --dry-run-transcript file that hexatherm wrote.",
)
@click.option("--resume", is_flag=True, help="Continue an interrupted run at its first open ball.")
@click.option("--tool", default="Probe1", show_default=True, help="The CMM's tool (ChangeTool).")
@click.option(
    "--cap-angle",
    type=CheckedFloat(min=1, max=90),
    default=70.0,
    show_default=True,
    help="Half-angle of the probed upper cap (deg).",
)
@click.option(
    "--approach",
    type=CheckedFloat(min=0.01, max=100),
    default=2.0,
    show_default=True,
    help="Approach distance off the predicted surface (mm).",
)
@click.option(
    "--clearance",
    type=CheckedFloat(min=0.01, max=1000),
    default=5.0,
    show_default=True,
    help="Safe plane above each ball's top (mm).",
)
@click.option(
    "--travel",
    type=CheckedFloat(min=0, max=2000),
    default=30.0,
    show_default=True,
    help="Travel height above the plan's highest ball top while the hexapod moves (mm).",
)
@click.option(
    "--cmm-limits",
    metavar="X0,Y0,Z0,X1,Y1,Z1",
    help="The CMM's travel box (mm): every probe position of the plan is checked against it.",
)
@click.option(
    "--max-gap",
    type=CheckedFloat(min=0, allow_inf=True),
    default=600.0,
    show_default=True,
    help="Largest time from a target to the references right before and after it (s): "
    "a delay that breaks it has the reference before measured again, or, when the "
    "reference after comes too late, the target with it (inf: never).",
)
@click.option(
    "--settle",
    type=CheckedFloat(min=0, max=3600),
    default=2.0,
    show_default=True,
    help="Wait after the in-position flag (s).",
)
@click.option(
    "--poll",
    type=CheckedFloat(min=0.001, max=60),
    default=0.2,
    show_default=True,
    help="Interval of the controller's status queries (s).",
)
@click.option(
    "--in-position-timeout",
    type=CheckedFloat(min=0.001, max=86400),
    default=120.0,
    show_default=True,
    help="Longest wait for the in-position flag (s).",
)
@click.option(
    "--readback-tol-um",
    type=CheckedFloat(min=0, max=10000),
    default=0.5,
    show_default=True,
    help="Largest spread of the stable read-back poses (um; urad x5).",
)
@click.option(
    "--readings",
    type=click.IntRange(min=1, max=1000),
    default=3,
    show_default=True,
    help="Consecutive read-backs that must agree.",
)
@click.option(
    "--radius-tol-um",
    type=CheckedFloat(min=0, max=10000),
    default=radius_limit_um(),
    show_default=True,
    help="Probe a ball again when its fitted radius is further off its nominal (um; half "
    "the quality limit diameter_dev_um, so that a ball accepted here is not flagged by "
    "process).",
)
@click.option(
    "--form-tol-um",
    type=CheckedFloat(min=0, max=10000),
    default=DEFAULTS.form_um,
    show_default=True,
    help="Probe a ball again when its form error is larger (um; the quality limit form_um).",
)
@click.option(
    "--rms-tol-um",
    type=CheckedFloat(min=0, max=10000),
    default=3.0,
    show_default=True,
    help="Probe a ball again when its fit RMS is larger (um).",
)
@click.option(
    "--centre-tol-mm",
    type=CheckedFloat(min=0, max=100),
    default=0.5,
    show_default=True,
    help="Probe a ball again around its fit when it is further from the prediction.",
)
@click.option(
    "--temperature-port",
    help="A thermocouple logger's port (as acquire: lines of six or more numbers).",
)
@click.option(
    "--temperature-baud",
    type=click.IntRange(min=1, max=10_000_000),
    default=9600,
    show_default=True,
    help="The thermocouple logger's serial line speed on --temperature-port (baud; 8 data "
    "bits, no parity, 1 stop bit).",
)
@click.option(
    "--reconnects",
    type=click.IntRange(min=0, max=1000),
    default=3,
    show_default=True,
    help="Attempts to reopen a dropped connection per ball or move (waiting 1 s before the "
    "first, twice as long before each next).",
)
@click.option(
    "--ipp-timeout",
    type=CheckedFloat(min=0.001, max=86400),
    default=120.0,
    show_default=True,
    help="Longest I++ transaction (s).",
)
@click.option(
    "--fsync/--no-fsync",
    default=True,
    show_default=True,
    help="Make every log line durable (fsync) before acting on it.",
)
@clean_errors
def command(
    plan: Path,
    cmm_url: str,
    controller_url: str,
    session: Path,
    hexapod_path: Path | None,
    balls_path: Path | None,
    origin_on_cmm: str | None,
    dry_run: bool,
    dry_run_transcript: Path | None,
    overwrite: bool,
    resume: bool,
    tool: str,
    cap_angle: float,
    approach: float,
    clearance: float,
    travel: float,
    cmm_limits: str | None,
    max_gap: float,
    settle: float,
    poll: float,
    in_position_timeout: float,
    readback_tol_um: float,
    readings: int,
    radius_tol_um: float,
    form_tol_um: float,
    rms_tol_um: float,
    centre_tol_mm: float,
    temperature_port: str | None,
    temperature_baud: int,
    reconnects: int,
    ipp_timeout: float,
    fsync: bool,
) -> None:
    """Measure PLAN unattended: the hexapod controller moves, the CMM probes over I++ DME.

    Walks the plan (O, R0, then the targets with their references): validates every pose
    first, then for each step moves the hexapod and waits until it is in position, probes
    every ball's upper cap around its predicted position, fits it at once (a bad ball is
    probed again once) and measures a reference (or a target with its references) again
    when a delay breaks --max-gap. SESSION gets the I++ transcript, the controller log,
    steps.csv and points.csv as it goes (with --temperature-port also serial.log and
    temperatures.csv), and session.yaml at the end (then: hexatherm process SESSION). Ctrl-C, a
    terminating signal (SIGTERM, SIGHUP, SIGQUIT, ...: exit status 130) or an error stops the
    hexapod; --resume continues. The balls' fits go to standard output.
    """
    from hexatherm.workflows.run.campaign import STOPPED_NOTE
    from hexatherm.workflows.run.options import BallChecks
    from hexatherm.workflows.run.run import RunRequest, run

    imports_done()

    if dry_run and resume:
        raise click.UsageError("--dry-run checks a plan: not with --resume")
    if (dry_run_transcript is not None or overwrite) and not dry_run:
        raise click.UsageError("--dry-run-transcript and --overwrite go with --dry-run")
    if (hexapod_path is None or balls_path is None) and not resume:
        raise click.UsageError("--hexapod and --balls are needed (except with --resume)")
    if origin_on_cmm is None and not resume:
        raise click.UsageError("--origin-on-cmm is needed (except with --resume)")
    origin = _numbers(origin_on_cmm, 6, "--origin-on-cmm")
    limits = _numbers(cmm_limits, 6, "--cmm-limits")
    if limits is not None and not all(a < b for a, b in zip(limits[:3], limits[3:], strict=True)):
        raise click.BadParameter(
            f"{cmm_limits!r}: the lower corner X0,Y0,Z0 must be below the upper X1,Y1,Z1",
            param_hint="--cmm-limits",
        )
    if dry_run_transcript is not None and session.resolve() in dry_run_transcript.resolve().parents:
        raise click.BadParameter(
            f"{dry_run_transcript} is inside the session folder {session}, which a dry run "
            "leaves untouched",
            param_hint="--dry-run-transcript",
        )
    request = RunRequest(
        plan=plan,
        session=session,
        cmm_url=cmm_url,
        controller_url=controller_url,
        hexapod=hexapod_path,
        balls=balls_path,
        origin_on_cmm=origin,
        dry_run=dry_run,
        dry_run_transcript=dry_run_transcript,
        overwrite=overwrite,
        resume=resume,
        tool=tool,
        cap_angle_deg=cap_angle,
        approach_mm=approach,
        clearance_mm=clearance,
        travel_mm=travel,
        cmm_limits_mm=limits,
        max_gap_s=max_gap,
        settle_s=settle,
        poll_s=poll,
        in_position_timeout_s=in_position_timeout,
        readback_tol_um=readback_tol_um,
        readings=readings,
        checks=BallChecks(radius_tol_um, form_tol_um, rms_tol_um, centre_tol_mm),
        temperature_port=temperature_port,
        temperature_baud=temperature_baud,
        reconnects=reconnects,
        ipp_timeout_s=ipp_timeout,
        durable=fsync,
    )

    def notify(level: str, message: str) -> None:
        echo_err(("warning: " if level == "warn" else "") + message)

    try:
        # SIGTERM, SIGHUP, SIGQUIT, ... take Ctrl-C's path: the hexapod is sent STOP
        with signals_interrupt():
            done = run(request, notify)
    except KeyboardInterrupt as exc:
        how = exc.name if isinstance(exc, Terminated) else "Ctrl-C"
        # what became of the hexapod and the session, said once (the campaign's note)
        notes = [n for n in getattr(exc, "__notes__", ()) if n.startswith(STOPPED_NOTE)]
        said = (
            notes[-1][len(STOPPED_NOTE) :]
            if notes
            else f"the hexapod was sent STOP; everything measured is in {session}; "
            "continue with --resume"
        )
        with contextlib.suppress(OSError):  # SIGHUP: the terminal may be gone
            echo_err(f"interrupted ({how}): {said}")
        sys.exit(130)
    result = done.result
    if result is None:  # a dry run
        return
    lines = ["label,ball,n,x,y,z,radius_mm,form_um,rms_um,attempts,problems"]
    for b in result.balls:
        lines.append(
            ",".join(
                [b.label, b.ball, str(b.n)]
                + [f"{v:.6f}" for v in b.centre_mm]
                + [f"{b.radius_mm:.6f}", f"{b.form_um:.3f}", f"{b.rms_um:.3f}", str(b.attempts)]
                + [str(len(b.problems))]
            )
        )
    click.echo("\n".join(lines))
    if result.remeasured:
        echo_err(f"measured again (gap): {', '.join(result.remeasured)}")
    echo_err(f"{result.n_points} points in {result.session / 'points.csv'}")
    echo_err(f"wrote {result.session_file}")
    if result.failed:
        first = result.failed[0]
        echo_err(
            f"error: {len(result.failed)} of {done.n_balls} balls still fail their checks after "
            f"probing them again: {', '.join(f'{b.label} {b.ball}' for b in result.failed)} "
            f"(first: {first.label} {first.ball}: {'; '.join(first.problems)}); the session is "
            "recorded, but check the balls file, the CMM's tool and the plan before processing "
            f"it (exit status {CHECK_FAILED_EXIT})"
        )
        sys.exit(CHECK_FAILED_EXIT)
