"""Record ``sessions/serial-capture`` through ``hexatherm acquire``, as on a real probe.

A small zero-pose session (O, R0, then S1..S3 with references around them) is
simulated as probed points (``configs/scenarios/serial-capture.yaml``, twin with
heated legs and 1 um point noise); its points are sent, as a DRO would, as lines
``X+0427.4517 Y+0408.8473 Z+0252.5323`` through a pseudo-terminal pair, with a
garbage line, an echoed command and mixed line ends, to ``hexatherm acquire
--auto``. What ``acquire`` recorded (``serial.log``, ``points.csv``,
``session.yaml`` and the copies of the configs) is the session; its times are the
capture's clock. Run from the repository root (Linux/macOS):

    python sessions/make_serial_capture.py
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import tty
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent
TARGET = ROOT / "sessions" / "serial-capture"

README = """# serial-capture

A session recorded through `hexatherm acquire` from a probe on a serial line: the raw
`serial.log` (every byte received, time-stamped) and the `points.csv` that acquire
assigned to steps and balls, with the copies of the plan, hexapod and balls files and
the `session.yaml` it wrote at the end.

The probe was the twin: `configs/scenarios/serial-capture.yaml` (the zero pose measured
3 times, R = [0, 0, -40, 0, 0, 0] around each, legs heated, 1 um point noise) simulated as
points, sent as DRO lines `X+0427.4517 Y+0408.8473 Z+0252.5323` (4 decimals: 0.1 um) over
a pseudo-terminal pair, with a garbage line, an echoed command and mixed CR/LF/CRLF line
ends. The times are the capture's own clock (a few seconds in all), so the thermal
correction here only shows that the recorded stream processes as it should; the truth of
the simulation is not part of this session.

`expected/` holds the output of `hexatherm process`. `hexatherm acquire PLAN --replay
serial.log --session NEW` gives `points.csv` back byte for byte (tested).

Made by `python sessions/make_serial_capture.py`.
"""


def dro_line(x: float, y: float, z: float) -> bytes:
    return f"X{x:+010.4f} Y{y:+010.4f} Z{z:+010.4f}".encode()


def main() -> None:
    if TARGET.exists():
        shutil.rmtree(TARGET)
    with tempfile.TemporaryDirectory() as tmp:
        sim = Path(tmp) / "sim"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "hexatherm",
                "simulate",
                str(ROOT / "configs" / "scenarios" / "serial-capture.yaml"),
                "-o",
                str(sim),
            ],
            check=True,
        )
        points = pd.read_csv(sim / "points.csv")
        master, slave = os.openpty()
        tty.setraw(slave)
        port = os.ttyname(slave)

        def probe() -> None:
            time.sleep(1.0)
            os.write(master, b"\x00%garbage from the DRO\r\n*IDN?\r\n")
            for k, row in enumerate(points.itertuples()):
                end = (b"\r\n", b"\n", b"\r")[k % 3]
                os.write(master, dro_line(row.x, row.y, row.z) + end)
                time.sleep(0.002)

        thread = threading.Thread(target=probe, daemon=True)
        thread.start()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "hexatherm",
                "acquire",
                str(sim / "plan.yaml"),
                "--hexapod",
                str(sim / "hexapod.yaml"),
                "--balls",
                str(sim / "balls.yaml"),
                "--port",
                port,
                "--session",
                str(TARGET),
                "--auto",
                "--idle-timeout",
                "10",
                "--read-timeout",
                "0.05",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        thread.join(5)
        os.close(master)
        os.close(slave)
    (TARGET / "README.md").write_text(README)
    (TARGET / "expected").mkdir()
    subprocess.run(
        [sys.executable, "-m", "hexatherm", "replay", str(TARGET), "--update"], check=True
    )


if __name__ == "__main__":
    main()
