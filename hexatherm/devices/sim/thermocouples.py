"""A simulated thermocouple logger on a TCP port (pyserial's ``socket://127.0.0.1:PORT``).

The counterpart of a logger on a serial port (``acquire --temperature-port``,
``run --temperature-port``): to every client it writes one line per sample, the channels'
temperatures in deg C separated by ``", "`` with three decimals and a CRLF,

    20.123, 20.456, 21.002, 20.871, 22.310, 20.640, 20.000

which is what :func:`hexatherm.devices.probestream.parse_numbers` reads (six or more
numbers: ``leg1`` .. ``leg6`` and further channels). A sample is taken every ``period_s``
of the given clock (the twin's, which may run faster than the wall clock or move only when
told), on the logger's own schedule (from the server's start, not from a client's
connection), with the temperatures at the time the clock shows when the line goes out; a
sample whose time passed while none could go out (a clock that jumped) is not sent late.
Every line sent is kept with its clock time (:attr:`ThermocoupleSimulator.sent`), the
truth a test compares the recorded log with.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Callable, Sequence

from hexatherm.devices.sim.tcpservice import TcpService

__all__ = ["SentSample", "ThermocoupleSimulator", "format_sample"]

#: a line sent: (connection number from 1, clock time s, the channels' values, the bytes)
SentSample = tuple[int, float, tuple[float, ...], bytes]


def format_sample(values: Sequence[float]) -> bytes:
    """One logger line: the values with three decimals, ``", "``-separated, CRLF.

    >>> format_sample([20.0, 21.25, -0.0004, 19.9996, 20.5, 20.0])
    b'20.000, 21.250, -0.000, 20.000, 20.500, 20.000\\r\\n'
    """
    return (", ".join(f"{float(v):.3f}" for v in values) + "\r\n").encode("ascii")


class ThermocoupleSimulator(TcpService):
    """A threaded TCP server that streams samples of ``sample(t_s)`` to each client.

    Parameters
    ----------
    sample : callable
        ``sample(t_s)``: the channels' temperatures (six or more, deg C) at clock time
        ``t_s``.
    clock : callable
        The clock, s (``time.time``, an accelerated or a manual clock).
    period_s : float
        Sampling period on that clock, s (> 0).
    host : str
        Address to listen on (``127.0.0.1``).
    port : int
        TCP port (0: a free one).
    poll_s : float
        Wall-clock interval at which a connection looks at the clock, s: the clock may be
        one that only another thread moves, so it is read, never slept on.

    Attributes
    ----------
    sent : list of SentSample
        Every line written, in order, from every connection.
    connections : int
        Connections accepted so far.

    Examples
    --------
    >>> sim = ThermocoupleSimulator(lambda t: [20.0] * 6, clock=lambda: 0.0, period_s=1.0)
    >>> sim.url.startswith("socket://127.0.0.1:")
    True
    >>> sim.close()
    """

    def __init__(
        self,
        sample: Callable[[float], Sequence[float]],
        *,
        clock: Callable[[], float] = time.time,
        period_s: float = 1.0,
        host: str = "127.0.0.1",
        port: int = 0,
        poll_s: float = 0.005,
    ) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"the sampling period must be > 0 s, got {period_s!r}")
        if not (math.isfinite(poll_s) and poll_s > 0):
            raise ValueError(f"the poll interval must be > 0 s, got {poll_s!r}")
        self.sample, self.clock = sample, clock
        self.period_s, self.poll_s = float(period_s), float(poll_s)
        self.sent: list[SentSample] = []
        self._closing = threading.Event()
        self._start_s = float(clock())
        self._host = host
        self._start(host, port)

    @property
    def url(self) -> str:
        """``socket://HOST:PORT``: what ``--temperature-port`` takes (pyserial's URL)."""
        return f"socket://{self._host}:{self.port}"

    def _serve(self, sock: socket.socket) -> None:
        number = self._accepted(sock)
        try:
            due = self._start_s
            while not self._closing.is_set():
                now = self.clock()
                if now >= due:
                    values = tuple(float(v) for v in self.sample(now))
                    line = format_sample(values)
                    with self._lock:
                        # recorded before it goes out: a line lost in a dropped connection
                        # is in ``sent`` but never received
                        self.sent.append((number, now, values, line))
                    sock.sendall(line)
                    # the next sample on the grid after now (missed ones are not sent late)
                    due += self.period_s * (math.floor((now - due) / self.period_s) + 1)
                    continue
                if self._closing.wait(self.poll_s):
                    return
        except OSError:
            return
        finally:
            self._finished(sock)

    def close(self) -> None:
        """Stop serving and drop every connection (a logger switched off)."""
        self._closing.set()
        super().close()

    def __enter__(self) -> ThermocoupleSimulator:
        return self
