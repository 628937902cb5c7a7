"""What hexatherm run is asked for and reports: options, ball checks, results."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.serialport import PortSettings
from hexatherm.typing import FloatArray
from hexatherm.workflows.limits import DEFAULTS, radius_limit_um
from hexatherm.workflows.run.resume import (
    ProbeSettings,
)

Notify = Callable[[str, str], None]


@dataclass(frozen=True)
class BallChecks:
    """When a ball's live fit calls for probing it again.

    Attributes
    ----------
    radius_tol_um : float
        Largest deviation of the fitted radius from the nominal (ball radius, plus the tip
        radius when the probe is not compensated), um: half the diameter limit of the
        table of limits (:mod:`hexatherm.limits`), so that a ball ``run`` accepts is not
        flagged by ``process``.
    form_um : float
        Largest form error (max - min residual), um (the table's ``form_um``).
    rms_um : float
        Largest RMS of the residuals, um.
    centre_tol_mm : float
        Largest distance of the fitted centre from the predicted one, mm (a larger one means
        the prediction, hence the touch points, were off: probed again around the fit).
    """

    radius_tol_um: float = radius_limit_um()
    form_um: float = DEFAULTS.form_um
    rms_um: float = 3.0
    centre_tol_mm: float = 0.5


@dataclass(frozen=True)
class RunOptions:
    """Options of ``hexatherm run`` (see its ``--help``).

    Attributes
    ----------
    session : Path
        The session folder.
    cmm_url, controller_url : str
        ``ipp://HOST[:PORT]``; ``symetrie://HOST[:PORT]`` or ``pi://HOST[:PORT]``.
    origin_on_cmm : tuple of 6 floats, optional
        Nominal placement of frame O on the CMM (hexapod's convention, mm and deg);
        required for a new run, taken from ``run.yaml`` on a resume.
    resume : bool
    probe : ProbeSettings
    checks : BallChecks
    criteria : InPositionCriteria
    max_gap_s : float
        Largest time between a target and the reference right before it, s.
    cmm_limits_mm : pair of 3 floats, optional
        Lower and upper corners of the CMM's travel, mm: every probe position is checked.
    temperature_port : PortSettings, optional
        A thermocouple logger on a serial port (as ``acquire --temperature-port``).
    durable : bool
        fsync every log line (the default); flushing alone survives a killed process.
    reconnects : int
        Attempts to reopen a dropped connection per ball or per move (each failed attempt,
        a refused connection or a cut during the greeting, counts).
    reconnect_wait_s : float
        Wait before the first attempt to reopen a connection, s, doubled before each next
        (:mod:`.reconnect`; the thermocouple port: between attempts, at least 0.05 s).
    ipp_timeout_s : float
        Longest I++ transaction, s.
    reply_timeout_s : float
        Longest wait for a controller's reply, s.
    """

    session: Path
    cmm_url: str
    controller_url: str
    origin_on_cmm: tuple[float, ...] | None = None
    resume: bool = False
    probe: ProbeSettings = field(default_factory=ProbeSettings)
    checks: BallChecks = field(default_factory=BallChecks)
    criteria: InPositionCriteria = field(default_factory=InPositionCriteria)
    max_gap_s: float = 600.0
    cmm_limits_mm: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    temperature_port: PortSettings | None = None
    durable: bool = True
    reconnects: int = 3
    reconnect_wait_s: float = 1.0
    ipp_timeout_s: float = 120.0
    reply_timeout_s: float = 5.0


@dataclass(frozen=True)
class BallResult:
    """The live fit of one accepted ball.

    Attributes
    ----------
    label, ball : str
    n : int
    centre_mm : ndarray, shape (3,)
        Fitted centre (NaN when the fit failed).
    radius_mm, form_um, rms_um : float
    predicted_mm : ndarray, shape (3,)
        The centre the touch points were planned around.
    attempts : int
        Probings of this ball in this visit (2: probed again).
    problems : tuple of str
        Checks the kept probing still fails.
    """

    label: str
    ball: str
    n: int
    centre_mm: FloatArray
    radius_mm: float
    form_um: float
    rms_um: float
    predicted_mm: FloatArray
    attempts: int
    problems: tuple[str, ...]


@dataclass(frozen=True)
class RunResult:
    """What a run produced."""

    session: Path
    n_points: int
    balls: tuple[BallResult, ...]
    remeasured: tuple[str, ...]
    session_file: Path
    #: balls kept although their probing still fails a check after the re-probe (plan order;
    #: on a resume, the balls accepted before it are checked again: radius, form, RMS)
    failed: tuple[BallResult, ...] = ()
