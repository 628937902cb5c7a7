"""Terminating signals turned into Ctrl-C while a command drives a machine.

A closed terminal (SIGHUP), ``kill`` or ``systemctl stop`` (SIGTERM), Ctrl-\\ (SIGQUIT), a
batch scheduler's warning or limit (SIGUSR1, SIGUSR2, SIGXCPU, SIGALRM, ...) would end
the process at once, without the ``STOP`` that Ctrl-C sends the hexapod. Inside
:func:`signals_interrupt` each of them raises :class:`~hexatherm.errors.Terminated` (a
:class:`KeyboardInterrupt`) in the main thread, so it takes Ctrl-C's path exactly. A
second signal while that path runs (the stop, the logs' last lines) is not allowed to cut
it short: it is noted and ignored. SIGKILL and SIGSTOP cannot be caught; the faults the
process raises itself (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT) leave no Python to run.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from types import FrameType

from hexatherm.errors import Terminated

#: the catchable signals whose default action ends the process (those that exist here)
TERMINATING = tuple(
    getattr(signal, name)
    for name in (
        "SIGTERM",
        "SIGHUP",
        "SIGQUIT",
        "SIGUSR1",
        "SIGUSR2",
        "SIGALRM",
        "SIGXCPU",
        "SIGXFSZ",
        "SIGVTALRM",
        "SIGPROF",
        "SIGPWR",
    )
    if hasattr(signal, name)
)


@contextlib.contextmanager
def signals_interrupt() -> Iterator[list[int]]:
    """Within: SIGINT and every :data:`TERMINATING` signal interrupt like Ctrl-C, once.

    Yields the list of the signals received (in order). Outside the main thread (where
    Python cannot set handlers) it changes nothing. The previous handlers are restored
    on exit.
    """
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        received.append(signum)
        if len(received) > 1:
            return  # the first one's stop is under way: let it finish
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise Terminated(signum)

    previous = {}
    for sig in (signal.SIGINT, *TERMINATING):
        with contextlib.suppress(OSError, ValueError):
            previous[sig] = signal.signal(sig, handler)
    try:
        yield received
    finally:
        for sig, old in previous.items():
            with contextlib.suppress(OSError, ValueError, TypeError):
                signal.signal(sig, old)


def exit_on_signals() -> None:
    """From now until :func:`signals_interrupt` takes over (and after it gives back):
    SIGINT and every :data:`TERMINATING` signal end the process with status 130, said in
    one line, instead of the default (killed: -15, -1) or click's "Aborted!" (1).

    ``hexatherm run`` calls it first thing (its module is imported before the options are
    read): a signal in its first moments, before any machine is contacted, is an
    interruption like any other. Outside the main thread it changes nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        how = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.write(f"interrupted ({how})\n")
            sys.stderr.flush()
        raise SystemExit(130)

    for sig in (signal.SIGINT, *TERMINATING):
        with contextlib.suppress(OSError, ValueError):
            signal.signal(sig, handler)
