"""The garbage collector while a command starts: paused while it imports, then kept off
what it imported.

numpy, pandas, scipy and hexatherm leave hundreds of thousands of objects that live as
long as the process. While they are made, the collector runs again and again, and every
full collection (one each time the heap has grown by a quarter) walks all of them: about
5 % of the CPU of ``process`` on 1000 targets while it imports (issue 37), 0.3-0.4 s of a
4 s ``diagnose`` while it computes, were they not frozen. So the command line pauses the
collector (:func:`paused`, around the whole run) and the command resumes it once its
modules are loaded (:func:`imports_done`), which first freezes what is there
(:func:`gc.freeze`: later full collections no longer walk it either). This is the
Python documentation's own recipe for :func:`gc.freeze` (disable early, freeze when the
long-lived objects are made). Nothing is computed differently; objects made after the
imports are collected as before.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

#: whether :func:`paused` turned the collector off (and :func:`imports_done` may resume it)
_PAUSED = [False]


@contextlib.contextmanager
def paused() -> Iterator[None]:
    """The collector off until :func:`imports_done` (or the end of the block), then as it
    was: a caller that keeps it off keeps it off."""
    was_enabled = gc.isenabled()
    gc.disable()
    _PAUSED[0] = was_enabled
    try:
        yield
    finally:
        _PAUSED[0] = False
        if was_enabled:
            gc.enable()


def imports_done() -> None:
    """Keep the collector off what the command has imported (:func:`gc.freeze`) and resume
    it if :func:`paused` stopped it.

    Called by every command once its modules are loaded. Only the first call freezes: a
    process that runs several commands (the tests) keeps collecting what the earlier ones
    left.
    """
    if gc.get_freeze_count() == 0:
        gc.freeze()
    if _PAUSED[0]:
        _PAUSED[0] = False
        gc.enable()
