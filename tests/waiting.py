"""Waiting in tests: on an event (a line read, a file written, a process ended), never on
the wall clock.

Every wait here has a safety net of :data:`SAFETY_S` seconds against a hung process or
thread; no passing run comes near it on a machine at any load, so it never decides a pass.
Polls sleep a few milliseconds between looks: how often they look, not how long they wait.
"""

from __future__ import annotations

import time
from collections.abc import Callable

#: the longest any test waits for an event before it calls the wait hung, s
SAFETY_S = 600.0


def wait_for(predicate: Callable[[], object], what: str, timeout: float = SAFETY_S) -> None:
    """Return once ``predicate()`` is true; AssertionError naming ``what`` after ``timeout``."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"no {what} after {timeout:g} s: hung?")
        time.sleep(0.005)
