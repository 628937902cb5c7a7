"""Devices: what talks to ports and sockets (serial probe streams, CMMs, hexapod controllers).

No click and no printing here: a device reports through return values and callbacks, and the
workflows decide what the operator sees.
"""

from __future__ import annotations

from typing import Any, Protocol

#: what a device hands over, on a queue: ``(kind, source, time, payload)``, with ``kind``
#: ``"rx"`` (payload: the bytes received), ``"lost"`` (payload: the reason) or ``"reopen"``
#: (payload: the port's URL), ``time`` ISO 8601 UTC of the arrival
Item = tuple[str, str, str, Any]


class PointSource(Protocol):
    """A device that hands what it receives to a queue of :data:`Item`, in its own thread.

    A serial port (:class:`hexatherm.devices.serialport.PortReader`) is one; a CMM client
    is the next. The acquisition starts every source, reads the one queue, logs every item
    before it acts on it, and joins the sources when it stops.
    """

    source: str

    def start(self) -> None:
        """Start handing over items."""

    def join(self, timeout: float | None = None) -> None:
        """Wait until the source has stopped (after the acquisition's stop event is set)."""
