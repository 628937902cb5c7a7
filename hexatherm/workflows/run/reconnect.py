"""Reopening a lost connection within the run's budget, with a growing wait.

A CMM or a controller that drops its connection may not take a new one at once (a server
restarting refuses connections for seconds; a second cut may come during the new
connection's greeting): each attempt to reopen it counts against ``--reconnects`` (per
ball or move), and the wait before each grows (the run's ``reconnect_wait_s``, 1 s, then
twice that, four times, ... up to :data:`LONGEST_RECONNECT_WAIT_S`): the default three
attempts wait 1, 2 and 4 s, through a restart of 5 s. The waits go through the run's
``sleep``, so a rehearsal on a manual clock and the tests never wait for the wall clock.
"""

from __future__ import annotations

from collections.abc import Callable

#: the longest wait between two attempts to reopen a connection, s (a longer first wait is
#: kept as it is)
LONGEST_RECONNECT_WAIT_S = 60.0


def reconnect_wait_s(first_s: float, failures: int) -> float:
    """The wait before an attempt after ``failures`` failed ones: doubled each time, capped.

    >>> [reconnect_wait_s(1.0, k) for k in range(8)]
    [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 60.0, 60.0]
    >>> reconnect_wait_s(90.0, 3), reconnect_wait_s(0.0, 5)
    (90.0, 0.0)
    """
    return min(first_s * 2.0 ** min(failures, 30), max(first_s, LONGEST_RECONNECT_WAIT_S))


def reopen(
    connect: Callable[[], None],
    errors: tuple[type[Exception], ...],
    *,
    tries: int,
    budget: int,
    first_wait_s: float,
    sleep: Callable[[float], None],
    failed: Callable[[Exception, float], None],
) -> int:
    """Wait, ``connect()``; on one of ``errors`` count a try and do it again, waiting longer.

    Parameters
    ----------
    connect : callable
        Opens the connection and greets the machine (all of it: a cut during the greeting
        is a failed attempt like a refused connection).
    errors : tuple of exception classes
        What a failed attempt raises.
    tries : int
        Tries of the budget used so far (the loss that calls for this one counted).
    budget : int
        ``--reconnects``: the attempts allowed per ball or move.
    first_wait_s : float
        The wait before the first attempt (``RunOptions.reconnect_wait_s``).
    sleep : callable
        The run's sleep.
    failed : callable
        ``failed(error, next_wait_s)`` after each failed attempt that leaves budget.

    Returns
    -------
    int
        The tries used, this reconnection's failed attempts included.

    Raises
    ------
    Exception
        The last error, once the tries exceed the budget.
    """
    failures = 0
    while True:
        sleep(reconnect_wait_s(first_wait_s, failures))
        try:
            connect()
        except errors as exc:
            tries += 1
            failures += 1
            if tries > budget:
                raise
            failed(exc, reconnect_wait_s(first_wait_s, failures))
            continue
        return tries
