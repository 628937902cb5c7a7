"""Serial ports: their settings (``serial://`` URLs, pyserial's ``loop://``) and a reader thread
that hands every chunk of bytes received, with its arrival time, to a callback.
"""

from __future__ import annotations

import contextlib
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hexatherm.errors import AcquisitionError
from hexatherm.io.seriallog import now_iso


# ------------------------------------------------------------------------- ports
@dataclass(frozen=True)
class PortSettings:
    """How to open a serial port with :func:`serial.serial_for_url`.

    ``url`` is a device (``/dev/ttyUSB0``, ``COM3``) or a pyserial URL
    (``socket://host:port``, ``rfc2217://host:port``, ``loop://``).
    """

    url: str
    baudrate: int = 9600
    bytesize: int = 8
    parity: str = "N"
    stopbits: float = 1
    xonxoff: bool = False
    rtscts: bool = False
    dsrdtr: bool = False
    timeout_s: float = 0.1

    def open(self) -> Any:
        """Open the port (AcquisitionError with the reason when it does not open)."""
        import serial

        stopbits: float = int(self.stopbits) if float(self.stopbits).is_integer() else self.stopbits
        try:
            return serial.serial_for_url(
                self.url,
                baudrate=self.baudrate,
                bytesize=self.bytesize,
                parity=self.parity,
                stopbits=stopbits,
                xonxoff=self.xonxoff,
                rtscts=self.rtscts,
                dsrdtr=self.dsrdtr,
                timeout=self.timeout_s,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise AcquisitionError(f"cannot open port {self.url}: {exc}") from None

    def describe(self) -> str:
        """The settings, for the log."""
        return (
            f"{self.url} {self.baudrate} {self.bytesize}{self.parity}{self.stopbits:g}"
            + (" xonxoff" if self.xonxoff else "")
            + (" rtscts" if self.rtscts else "")
            + (" dsrdtr" if self.dsrdtr else "")
        )


class PortReader(threading.Thread):
    """Reads a port into a queue; reopens it when it is lost.

    Puts ``("rx", source, time, bytes)``, ``("lost", source, time, reason)`` and
    ``("reopen", source, time, url)`` items; the main loop logs and applies them. ``time``
    is ``stamp()`` at the arrival (default :func:`~hexatherm.io.seriallog.now_iso`; a run
    stamps with its own clock, the one its other logs use).
    """

    def __init__(
        self,
        source: str,
        settings: PortSettings,
        port: Any,
        out: queue.Queue[Any],
        stop: threading.Event,
        reopen_interval_s: float = 1.0,
        stamp: Callable[[], str] = now_iso,
    ) -> None:
        super().__init__(name=f"hexatherm-{source}", daemon=True)
        self.source = source
        self.settings = settings
        self.port = port
        self.out = out
        self.stop = stop
        self.reopen_interval_s = reopen_interval_s
        self.stamp = stamp

    def run(self) -> None:
        import serial

        try:
            while not self.stop.is_set():
                try:
                    data = self.port.read(1)
                    while data and len(data) < 65536 and (waiting := self.port.in_waiting):
                        data += self._read_waiting(waiting, 65536 - len(data))
                except (serial.SerialException, OSError) as exc:
                    self.out.put(("lost", self.source, self.stamp(), str(exc)))
                    self._close()
                    self._reopen()
                    continue
                if data:
                    self.out.put(("rx", self.source, self.stamp(), bytes(data)))
        finally:
            self._close()

    def _read_waiting(self, waiting: int, room: int) -> bytes:
        """The bytes waiting, in one read: a serial port counts them (``in_waiting``); a
        pyserial ``socket://`` port only says whether there are any (1), so it is read
        without waiting (timeout 0) for as many as there are (one byte at a time, a logger
        that floods would outrun the reader)."""
        if not self.settings.url.startswith("socket://"):
            return bytes(self.port.read(min(waiting, room)))
        timeout = self.port.timeout
        self.port.timeout = 0
        try:
            return bytes(self.port.read(room))
        finally:
            self.port.timeout = timeout

    def _close(self) -> None:
        if self.port is not None:
            with contextlib.suppress(Exception):
                self.port.close()
            self.port = None

    def _reopen(self) -> None:
        while not self.stop.wait(self.reopen_interval_s):
            try:
                self.port = self.settings.open()
            except AcquisitionError:
                continue
            self.out.put(("reopen", self.source, self.stamp(), self.settings.url))
            return
