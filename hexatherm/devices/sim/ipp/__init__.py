"""A simulated I++ DME server: a CMM probing balls, for tests and rehearsals.

:class:`IppSimServer` listens on 127.0.0.1 (port 0 picks a free one: :attr:`IppSimServer.port`)
and speaks the dialect of :mod:`hexatherm.devices.ipp` (I++ DME 1.4.3): ``&`` at once, the
data, then ``%``; errors as ``Error(severity, number, "method", "text")`` followed by ``%``;
after an error of severity >= 2 only ``ClearAllErrors()``, the error-status queries and the
session commands are executed (the others get error 0514) [6.2.5].

What it simulates
-----------------
- The machine: homed or not (moves need ``Home()``), a tool-centre position, a box of
  travel limits (error 2500), a tool table (``ChangeTool``, ``FindTool``, ``SetTool``,
  ``EnumTools``) with per-tool properties ``PtMeasPar.{Speed, Accel, Approach, Search,
  Retract}``, ``GoToPar.{Speed, Accel}``, ``AvrRadius`` (read only) and ``Name``.
- The balls, from a pluggable :class:`CmmBackend` asked at the time of each move or touch
  (``time_s``: seconds since the server started, or the caller's clock): every move
  (``GoTo`` and the moves inside ``PtMeas``) is checked against the balls grown by the tip
  radius; a crossing is a collision (error 2504, severity 3, the probe stays where it was).
- ``PtMeas(X(x), Y(y), Z(z), IJK(i, j, k))`` [6.3.2.13]: the tip centre goes to the approach
  position ``p + (Approach + r) u`` (``u`` the normalized IJK, ``r`` the tip radius) and
  searches along ``-u`` until ``Search`` mm past the nominal contact (tip centre at
  ``p + (r - Search) u``). At the first ball it touches it reports the touched surface
  point ``c + R n`` (``n`` the ball's outward normal there; with ``compensated=False`` the
  tip centre ``c + (R + r) n``), plus ``N(0, noise)`` along ``n``; ``IJK`` is ``n`` and
  ``ER`` the tip radius. Touching nothing is error 1006 "Surface not found" (severity 2).
  Then the tip retracts ``Retract`` mm along ``u`` (to the approach position if negative).
  Without IJK, ``u`` points from the nominal point to the current position (spec).

Fault injection (:class:`Fault`), deterministic: each fault fires once, on the ``nth``
command received by the server (all connections), or the ``nth`` of one method:

- ``error``: the command is not executed; ``&``, ``! Error(severity, number, ...)``, ``%``.
- ``event``: ``E0000`` lines interleaved with the response (after ``&``, between data lines,
  before ``%``).
- ``drop``: the connection is closed after ``after_lines`` lines of the response.
- ``split``: every response line of the command goes out in writes of ``chunk_bytes``.
- ``delay``: ``delay_s`` between ``&`` and the rest of the response.

Examples
--------
>>> balls = StaticBalls([[0.0, 0.0, 0.0]], [12.7])
>>> with IppSimServer(balls, tools={"Probe1": 2.0}) as server:
...     from hexatherm.devices.ipp import IppClient
...     with IppClient("127.0.0.1", server.port, timeout_s=30) as cmm:
...         stale = cmm.start_session()  # True when a stale session was ended first
...         cmm.home(); cmm.change_tool("Probe1")
...         cmm.goto(0, 0, 30)
...         p = cmm.pt_meas(0, 0, 12.7, 0, 0, 1)
>>> p.point_mm, stale
((0.0, 0.0, 12.7), False)
"""

from __future__ import annotations

from hexatherm.devices.sim.ipp.contact import (
    first_contact,
    segment_hits,
)
from hexatherm.devices.sim.ipp.model import (
    CMM_DIALECTS,
    DEFAULT_EVENTS,
    DEFAULT_FAULT_NUMBER,
    ERROR_TEXTS,
    PROPERTY_DEFAULTS,
    CmmBackend,
    Fault,
    FaultKind,
    StaticBalls,
)
from hexatherm.devices.sim.ipp.server import (
    IppSimServer,
)

__all__ = [
    "CMM_DIALECTS",
    "CmmBackend",
    "DEFAULT_EVENTS",
    "DEFAULT_FAULT_NUMBER",
    "ERROR_TEXTS",
    "Fault",
    "FaultKind",
    "IppSimServer",
    "PROPERTY_DEFAULTS",
    "StaticBalls",
    "first_contact",
    "segment_hits",
]
