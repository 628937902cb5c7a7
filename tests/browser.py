"""One headless Chromium per test process, printing pages to PDF as ``--print-to-pdf`` does.

``chromium --headless --print-to-pdf`` starts a browser for every page it prints (a new
profile, its processes, then the page); the report tests print some fifteen pages. Here
one browser is started on the first print and kept until the end of the session: it is
driven through the DevTools protocol on a pipe (``--remote-debugging-pipe``: JSON
messages ended by a NUL byte, commands on its descriptor 3, answers and events on 4; no
socket, no dependency), and each page is opened in a new tab, printed with
``Page.printToPDF`` and closed.

The print is the command line's: ``printBackground`` and ``preferCSSPageSize`` on (the
page's ``@page`` size, A4), no header and footer (``--no-pdf-header-footer``), once the
page's load event has fired. The report of ``with-hidden-effect`` and of
``paper-zero-pose`` printed both ways gave the same PDF but for its creation date (the
same bytes' size, the same words and boxes by ``pdftotext -bbox``, the same images by
``pdfimages -list``) with Chromium 150.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import signal
import tempfile
import time
from pathlib import Path
from typing import Any

from tests.waiting import SAFETY_S

#: what ``--print-to-pdf --no-pdf-header-footer`` asks of the page
PRINT = {"printBackground": True, "preferCSSPageSize": True, "displayHeaderFooter": False}


class BrowserError(AssertionError):
    """The browser answered an error, or ended, or said nothing within the safety net."""


class Chromium:
    """A headless Chromium driven on a pipe; :meth:`print_pdf` prints a page."""

    def __init__(self, executable: str) -> None:
        self.profile = Path(tempfile.mkdtemp(prefix="hexatherm-chromium-"))
        commands_read, self._commands = os.pipe()
        self._answers, answers_write = os.pipe()
        # above 4 first, so that putting them at 3 and 4 in the child overwrites neither
        high = [fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10) for fd in (commands_read, answers_write)]
        os.close(commands_read)
        os.close(answers_write)
        null = os.open(os.devnull, os.O_RDWR | os.O_CLOEXEC)
        args = [
            executable,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--remote-debugging-pipe",
            f"--user-data-dir={self.profile}",
            "about:blank",
        ]
        try:
            self.pid: int | None = os.posix_spawn(
                executable,
                args,
                os.environ,
                file_actions=[
                    (os.POSIX_SPAWN_DUP2, high[0], 3),
                    (os.POSIX_SPAWN_DUP2, high[1], 4),
                    *((os.POSIX_SPAWN_DUP2, null, fd) for fd in (0, 1, 2)),
                ],
                setsid=True,  # its processes are a group of their own, ended together
            )
        finally:
            for fd in (*high, null):
                os.close(fd)
        self._buffer = b""
        self._last_id = 0
        self.call("Browser.getVersion")  # started and listening

    def alive(self) -> bool:
        if self.pid is not None and os.waitpid(self.pid, os.WNOHANG) != (0, 0):
            self.pid = None  # ended (and now reaped)
        return self.pid is not None

    def call(self, method: str, session: str | None = None, **params: Any) -> dict[str, Any]:
        """Send a command and return its result (BrowserError on an error)."""
        self._last_id += 1
        message: dict[str, Any] = {"id": self._last_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self._commands, json.dumps(message).encode() + b"\0")
        sent = self._last_id
        answer = self._wait(lambda m: m.get("id") == sent, method)
        if "error" in answer:
            raise BrowserError(f"Chromium refused {method}: {answer['error']}")
        result: dict[str, Any] = answer.get("result", {})
        return result

    def _wait(self, wanted: Any, what: str) -> dict[str, Any]:
        """The first message ``wanted`` accepts (the others are dropped)."""
        end = time.monotonic() + SAFETY_S
        while True:
            while b"\0" not in self._buffer:
                left = end - time.monotonic()
                if left <= 0 or not select.select([self._answers], [], [], left)[0]:
                    raise BrowserError(f"no answer to {what} after {SAFETY_S:g} s: hung?")
                data = os.read(self._answers, 1 << 20)
                if not data:
                    raise BrowserError(f"Chromium ended while waiting for {what}")
                self._buffer += data
            text, self._buffer = self._buffer.split(b"\0", 1)
            message: dict[str, Any] = json.loads(text)
            if wanted(message):
                return message

    def print_pdf(self, page: Path, pdf: Path) -> None:
        """Print the HTML file ``page`` to ``pdf`` in a tab of its own."""
        target = self.call("Target.createTarget", url="about:blank")["targetId"]
        try:
            attached = self.call("Target.attachToTarget", targetId=target, flatten=True)
            session = attached["sessionId"]
            self.call("Page.enable", session)
            self.call("Page.navigate", session, url=page.resolve().as_uri())
            self._wait(
                lambda m: (
                    m.get("method") == "Page.loadEventFired" and m.get("sessionId") == session
                ),
                f"the load of {page}",
            )
            data = self.call("Page.printToPDF", session, **PRINT)["data"]
            pdf.write_bytes(base64.b64decode(data))
        finally:
            self.call("Target.closeTarget", targetId=target)

    def close(self) -> None:
        if self.pid is not None:
            try:
                self.call("Browser.close")
            except (BrowserError, OSError):
                pass
            try:
                os.killpg(self.pid, signal.SIGKILL)  # what is left of it, if anything
            except ProcessLookupError:
                pass
            os.waitpid(self.pid, 0)
            self.pid = None
        for fd in (self._commands, self._answers):
            try:
                os.close(fd)
            except OSError:
                pass
        shutil.rmtree(self.profile, ignore_errors=True)


_SHARED: dict[str, Chromium] = {}


def shared(executable: str) -> Chromium:
    """This process's browser: started on first use, again if it ended."""
    browser = _SHARED.get(executable)
    if browser is None or not browser.alive():
        if browser is not None:
            browser.close()
        browser = _SHARED[executable] = Chromium(executable)
    return browser


def close_shared() -> None:
    """End the browsers :func:`shared` started (at the end of the session)."""
    while _SHARED:
        _, browser = _SHARED.popitem()
        browser.close()
