"""What the simulated CMM measures and how it fails: the backend protocol, static balls, faults."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.devices.ipp import (
    DEFAULT_REPORT,
    ErrorReport,
)
from hexatherm.errors import (
    IppDmeError,
)
from hexatherm.typing import FloatArray

_TAG = re.compile(r"[0-9]{5}|E[0-9]{4}")


FaultKind = Literal["error", "event", "drop", "split", "delay"]


DEFAULT_EVENTS = ('KeyPress("F1")', "GoTo(X(10), Y(-11.5), Z(3.25E+02))")
"""Bodies of the ``E0000 #`` lines an ``event`` fault sends by default (spec examples)."""


ERROR_TEXTS = {
    1: "Illegal tag",
    2: "No space at pos. 6",
    6: "Transaction aborted (Use ClearAllErrors To Continue)",
    8: "Protocol error",
    500: "Emergency stop",
    501: "Unsupported command",
    502: "Incorrect arguments",
    504: "Argument out of range",
    507: "Illegal command",
    508: "Bad context",
    510: "Bad property",
    511: "Error processing method",
    514: "Use ClearAllErrors to continue",
    1005: "Error during home",
    1006: "Surface not found",
    1010: "Vector has no norm",
    1011: "Unable to move",
    1502: "Tool not found",
    1503: "Tool not defined",
    2500: "Machine limit encountered [Move Out Of Limits]",
    2504: "Collision",
}
"""Texts of the errors the simulator sends (spec section 8.2)."""


DEFAULT_FAULT_NUMBER = {2: 1011, 3: 2504}
"""Error number of an ``error`` fault without one, by severity (else 511)."""


PROPERTY_DEFAULTS = {
    "PtMeasPar.Speed": 10.0,
    "PtMeasPar.Accel": 100.0,
    "PtMeasPar.Approach": 2.0,
    "PtMeasPar.Search": 5.0,
    "PtMeasPar.Retract": 2.0,
    "GoToPar.Speed": 100.0,
    "GoToPar.Accel": 500.0,
}
"""Settable tool properties and their values for a new tool (mm, mm/s, mm/s^2)."""


_IN_ERROR_OK = frozenset(
    {"ClearAllErrors", "GetErrStatusE", "GetXtdErrStatus", "StartSession", "AbortE"}
)
"""Methods served in an error state (6.2.5; a new session clears it; not EndSession)."""

CMM_DIALECTS = ("dme-1.4.3", "dme-1.4")
"""How the simulated CMM speaks: ``dme-1.4.3`` (the default: ``Tool.AvrRadius``, the
report in the order asked, ``FindTool`` refuses an unknown tool, one session per
connection) or ``dme-1.4``, a plain DME 1.4 server as the NIST I++ DME Test Suite's
(``DMEVersion("1.4")``, no ``AvrRadius``, ``PtMeas`` fields in its own order ``ER, IJK, X,
Y, Z``, a lax ``FindTool`` that leaves ``FoundTool`` unchanged, a second ``StartSession``
refused with error 0507), and one that keeps its session across connections (the NIST
server's own code ends the session, and un-homes, when the client goes; other servers
keep it, and a reconnecting client must end it first)."""


class CmmBackend(Protocol):
    """What the simulated CMM probes: balls that may move with time."""

    def ball_centres_mm(self, t_s: float) -> FloatArray:
        """(k, 3) ball centres in the CMM frame at time ``t_s`` (s), mm."""
        ...

    def ball_radii_mm(self, t_s: float) -> FloatArray:
        """(k,) ball radii at time ``t_s``, mm."""
        ...


class StaticBalls:
    """Fixed spheres: a :class:`CmmBackend` for tests.

    Parameters
    ----------
    centres_mm : array_like, shape (k, 3)
        Ball centres in the CMM frame, mm.
    radii_mm : array_like, shape (k,) or scalar
        Ball radii, mm.
    """

    def __init__(self, centres_mm: npt.ArrayLike, radii_mm: npt.ArrayLike) -> None:
        centres = np.array(centres_mm, dtype=float)
        if centres.ndim != 2 or centres.shape[1] != 3 or centres.shape[0] < 1:
            raise IppDmeError(f"centres_mm must have shape (k, 3), k >= 1, got {centres.shape}")
        radii = np.broadcast_to(np.array(radii_mm, dtype=float), centres.shape[:1]).copy()
        if not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
            raise IppDmeError("ball centres must be finite and radii positive")
        self.centres_mm = centres
        self.radii_mm = radii

    def ball_centres_mm(self, t_s: float) -> FloatArray:
        """See :class:`CmmBackend`."""
        return self.centres_mm.copy()

    def ball_radii_mm(self, t_s: float) -> FloatArray:
        """See :class:`CmmBackend`."""
        return self.radii_mm.copy()


@dataclass(frozen=True)
class Fault:
    """One injected fault (see the module docstring).

    Attributes
    ----------
    kind : {"error", "event", "drop", "split", "delay"}
    nth : int
        Fires on the ``nth`` (1-based) command received, counting only ``method`` if given.
    method : str, optional
        Count only commands of this method (``"PtMeas"``).
    severity, number, text
        Of an ``error`` (number by default 1011 "Unable to move" for severity 2, 2504
        "Collision" for 3).
    events : tuple of str
        Bodies of the ``E0000 #`` lines of an ``event`` fault (a body ``! Error(...)``
        makes an ``E0000 !`` line; Latin-1 characters are sent as such).
    after_lines : int
        Lines of the response sent before a ``drop`` closes the connection (1: after ``&``).
    chunk_bytes : int
        Size of the writes of a ``split``.
    delay_s : float
        Delay of a ``delay``, s.
    """

    kind: FaultKind
    nth: int
    method: str | None = None
    severity: int = 2
    number: int | None = None
    text: str | None = None
    events: tuple[str, ...] = DEFAULT_EVENTS
    after_lines: int = 1
    chunk_bytes: int = 3
    delay_s: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("error", "event", "drop", "split", "delay"):
            raise IppDmeError(f"unknown fault kind {self.kind!r}")
        if int(self.nth) != self.nth or self.nth < 1:
            raise IppDmeError(f"nth must be a positive integer, got {self.nth!r}")
        if not 0 <= self.severity <= 9:
            raise IppDmeError(f"severity must be 0..9, got {self.severity}")
        if self.after_lines < 0 or self.chunk_bytes < 1 or not self.delay_s >= 0:
            raise IppDmeError("after_lines >= 0, chunk_bytes >= 1 and delay_s >= 0 required")

    def error(self, method: str) -> ErrorReport:
        """The error an ``error`` fault sends for a command of ``method``."""
        number = (
            self.number if self.number is not None else DEFAULT_FAULT_NUMBER.get(self.severity, 511)
        )
        text = self.text if self.text is not None else ERROR_TEXTS.get(number, "Injected fault")
        return ErrorReport(self.severity, number, method, text)


class _Refusal(Exception):
    def __init__(self, severity: int, number: int, method: str) -> None:
        self.report = ErrorReport(severity, number, method, ERROR_TEXTS.get(number, "Error"))


@dataclass
class _Tool:
    name: str
    tip_radius_mm: float
    measures: bool = True
    props: dict[str, float] = field(default_factory=lambda: dict(PROPERTY_DEFAULTS))


@dataclass
class _Session:
    active: bool = False
    error: ErrorReport | None = None
    report: tuple[str, ...] = DEFAULT_REPORT
