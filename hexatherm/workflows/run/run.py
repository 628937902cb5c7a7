"""``hexatherm run`` from a request to its outcome: the command's steps, start to end.

:func:`run` reads the plan, hexapod and balls files (the session's copies on a resume),
turns the request into the campaign's options and runs the campaign
(:func:`~hexatherm.workflows.run.campaign.run_campaign`), or with ``dry_run`` checks the
whole plan on both machines (:func:`~hexatherm.workflows.run.support.dry_run`), its I++
transcript kept in a file when asked. The command line (``hexatherm.cli.run``) turns its
options into a :class:`RunRequest` and prints the :class:`RunOutcome`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.serialport import PortSettings
from hexatherm.io.config import read_hexapod
from hexatherm.io.outputs import check_output_settled, write_output_file
from hexatherm.workflows.acquire.files import SessionFiles, load_files
from hexatherm.workflows.run.campaign import NOT_MOVED, STOPPED_NOTE, run_campaign
from hexatherm.workflows.run.options import BallChecks, Notify, RunOptions, RunResult
from hexatherm.workflows.run.resume import ProbeSettings
from hexatherm.workflows.run.support import dry_run as check_plan


@dataclass(frozen=True)
class RunRequest:
    """What ``hexatherm run`` was asked (its options, in the workflow's units: see its
    ``--help``). ``hexapod`` and ``balls`` default to the session's copies."""

    plan: Path
    session: Path
    cmm_url: str
    controller_url: str
    hexapod: Path | None = None
    balls: Path | None = None
    origin_on_cmm: tuple[float, ...] | None = None
    dry_run: bool = False
    dry_run_transcript: Path | None = None
    overwrite: bool = False
    resume: bool = False
    tool: str = "Probe1"
    cap_angle_deg: float = 70.0
    approach_mm: float = 2.0
    clearance_mm: float = 5.0
    travel_mm: float = 30.0
    cmm_limits_mm: tuple[float, ...] | None = None
    max_gap_s: float = 600.0
    settle_s: float = 2.0
    poll_s: float = 0.2
    in_position_timeout_s: float = 120.0
    readback_tol_um: float = 0.5
    readings: int = 3
    checks: BallChecks = field(default_factory=BallChecks)
    temperature_port: str | None = None
    temperature_baud: int = 9600
    reconnects: int = 3
    ipp_timeout_s: float = 120.0
    durable: bool = True


@dataclass(frozen=True)
class RunOutcome:
    """What ``hexatherm run`` did: the campaign's result (None after a dry run) and the
    number of balls the plan measures (steps x balls)."""

    result: RunResult | None
    n_balls: int


def run(request: RunRequest, notify: Notify) -> RunOutcome:
    """Run (or with ``request.dry_run`` check) the campaign of ``request``."""
    hexapod_path = request.hexapod or request.session / "hexapod.yaml"
    balls_path = request.balls or request.session / "balls.yaml"
    try:
        files = load_files(request.plan, hexapod_path, balls_path)
        hexapod = read_hexapod(hexapod_path)
    except KeyboardInterrupt as exc:  # said as the campaign says it
        exc.add_note(f"{STOPPED_NOTE}{NOT_MOVED}; nothing was written")
        raise
    limits = request.cmm_limits_mm
    options = RunOptions(
        session=request.session,
        cmm_url=request.cmm_url,
        controller_url=request.controller_url,
        origin_on_cmm=request.origin_on_cmm,
        resume=request.resume,
        probe=ProbeSettings(
            request.tool,
            request.cap_angle_deg,
            request.approach_mm,
            max(request.clearance_mm, request.approach_mm),
            request.travel_mm,
        ),
        checks=request.checks,
        criteria=InPositionCriteria(
            settle_s=request.settle_s,
            tolerance_um=request.readback_tol_um,
            tolerance_urad=5 * request.readback_tol_um,
            n_readings=request.readings,
            poll_s=request.poll_s,
            timeout_s=request.in_position_timeout_s,
        ),
        max_gap_s=request.max_gap_s,
        cmm_limits_mm=None if limits is None else (limits[:3], limits[3:]),  # type: ignore[arg-type]
        temperature_port=None
        if request.temperature_port is None
        else PortSettings(request.temperature_port, baudrate=request.temperature_baud),
        durable=request.durable,
        reconnects=request.reconnects,
        ipp_timeout_s=request.ipp_timeout_s,
    )
    n_balls = len(files.plan.labels) * len(files.balls.names)
    if request.dry_run:
        _dry_run(files, hexapod, options, notify, request.dry_run_transcript, request.overwrite)
        return RunOutcome(None, n_balls)
    return RunOutcome(run_campaign(files, hexapod, options, notify), n_balls)


def _dry_run(
    files: SessionFiles,
    hexapod: Hexapod,
    options: RunOptions,
    notify: Notify,
    transcript: Path | None,
    overwrite: bool,
) -> None:
    """``run --dry-run``, its I++ transcript kept in ``transcript`` when given: checked as
    an output first (not an input; the command line refuses one inside the session
    folder), written at the end whatever the check found."""
    if transcript is None:
        check_plan(files, hexapod, options, notify)
        return
    inputs = list(files.paths)
    check_output_settled(
        transcript, kind="file", inputs=inputs, overwrite=overwrite, option="--dry-run-transcript"
    )
    lines: list[str] = []
    try:
        check_plan(files, hexapod, options, notify, transcript=lines.append)
    finally:
        if lines:
            text = "".join(line if line.endswith("\n") else line + "\n" for line in lines)
            write_output_file(
                transcript, text, inputs=inputs, overwrite=True, option="--dry-run-transcript"
            )
            notify("info", f"wrote {transcript} ({len(lines)} lines)")
