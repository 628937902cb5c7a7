"""ESRF BLISS's own Symétrie API v2 client against the twin, where BLISS is installed.

BLISS is no test dependency (about 130 distributions, numpy below 2: docs/design.md), so
this test runs only in an environment that has it (``bench/peers_bliss.py``'s docstring
says how to make one) and is skipped elsewhere, CI included. It runs the bench script in
a process of its own: importing BLISS monkey-patches sockets and ``time.sleep`` for
gevent, which the rest of the suite must never see. The script compares every read-back
with the twin's truth (true pose, IGM, stroke) and exits 1 on any difference.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[2] / "bench" / "peers_bliss.py"

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("bliss") is None,  # finds the package without importing it
    reason="ESRF BLISS is not installed here (bench/peers_bliss.py)",
)


def test_bliss_drives_the_twin() -> None:
    done = subprocess.run(
        [sys.executable, str(SCRIPT)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    counted = re.search(r"^(\d+)/(\d+) BLISS calls read the twin's truth$", done.stdout, re.M)
    assert counted is not None and counted[1] == counted[2] and int(counted[2]) >= 23
    assert "Error" not in done.stdout.replace("Error -126", "")  # the one refusal
