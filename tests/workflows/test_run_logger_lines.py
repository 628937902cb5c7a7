"""``run --temperature-port`` with a logger that misbehaves: one that floods (a burst far
faster than a log can be written, then its normal lines), one that sends NaN rows."""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from hexatherm.devices.probestream import format_number, parse_numbers
from hexatherm.devices.serialport import PortSettings
from hexatherm.devices.sim.thermocouples import ThermocoupleSimulator, format_sample
from hexatherm.errors import AcquisitionError, InputError
from hexatherm.workflows.acquire.run import session_from_log
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.run.support import _Thermocouples
from tests.waiting import wait_for
from tests.workflows.test_run import make_bench

SHORT = {"targets": [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]], "points_per_ball": 6}
#: the burst: this many lines at once, each a distinct row (leg1 counts them, in mK)
BURST = 60_000


def burst_line(k: int) -> bytes:
    return format_sample([20.0 + 1e-3 * k, 21.0, 22.0, 23.0, 24.0, 25.0, 19.0])


class FloodingLogger(ThermocoupleSimulator):
    """The twin's logger, but every connection first gets :data:`BURST` lines at once, and
    the logger's own lines once the run has taken the burst's last line as a row (in
    ``session``'s temperatures.csv).

    Were they sent at once, a log whose thread is held up past the whole burst (a loaded
    machine) takes the burst and the first line in one batch: a flood whose newest row is
    that line, no row of the burst kept (the flake at load 25+; a drain held back until
    the burst and a line arrived fails so every time)."""

    def __init__(self, *args: Any, session: Path, **kwargs: Any) -> None:
        self.session = session
        super().__init__(*args, **kwargs)

    def _serve(self, sock: socket.socket) -> None:
        try:
            sock.sendall(b"".join(burst_line(k) for k in range(BURST)))
        except OSError:
            return
        values = parse_numbers(burst_line(BURST - 1), 6)
        assert values is not None
        row = "," + ",".join(format_number(v) for v in values) + "\n"
        table = self.session / "temperatures.csv"
        wait_for(
            lambda: self._closing.is_set() or (table.is_file() and row in table.read_text()),
            "the burst's last row",
        )
        super()._serve(sock)


def test_a_flooding_logger_keeps_the_newest_rows_and_the_session_processes(
    tmp_path: Path,
) -> None:
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    logger = FloodingLogger(
        b.world.thermocouples_C, clock=b.world.clock, period_s=10.0, session=b.session
    )
    try:
        b.run(temperature_port=PortSettings(logger.url))
    finally:
        logger.close()
        b.machines.close()
    session = b.session
    said = [m for _, m in b.messages if "sends faster than the log can be written" in m]
    assert len(said) == 1
    log = (session / "serial.log").read_text()
    skipped = sum(
        int(line.split('"')[1].split()[0]) for line in log.splitlines() if " skip " in line
    )
    rows = pd.read_csv(session / "temperatures.csv")
    burst = rows[rows["leg1"] < 20.0 + 1e-3 * BURST - 1e-9]
    burst = burst[burst["leg2"] == 21.0]
    # every line the logger sent is a row or counted as left out (the last lines sent may
    # have been in flight when the run ended); the burst's rows kept are its lines in order
    sent = len(logger.sent)
    assert BURST <= skipped + len(rows) <= BURST + sent and skipped > 0
    assert len(rows) - len(burst) <= sent
    k = np.round((burst["leg1"].to_numpy() - 20.0) * 1e3).astype(int)
    assert (np.diff(k) > 0).all() and len(k) >= 1
    # the log goes on after the burst and spans the steps: process takes the session
    assert len(rows) - len(burst) >= 10
    process_session(session)
    # serial.log replays into the same temperatures.csv, byte for byte
    session_from_log(b.files, session / "serial.log", tmp_path / "replay", b.notify)
    assert (tmp_path / "replay" / "temperatures.csv").read_bytes() == (
        session / "temperatures.csv"
    ).read_bytes()


def test_lines_that_waited_while_the_machine_was_loaded_are_all_logged(tmp_path: Path) -> None:
    """A loaded machine holds the log up (its reader or writer thread not scheduled for a
    while): the reads that waited are taken together. Ten, or a hundred, lines of a logger
    at its normal pace are no flood: every one is a row, none is left out (a whole-suite
    run at load 8-15 lost ten of the twin's lines this way, row 16 of 53, when a batch of
    more than 10 lines was a flood). The batch is handed over as the drain takes it from
    the queue (one read per line), on a port nothing else writes to (``loop://``)."""
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    b.machines.close()
    folder = tmp_path / "log"
    folder.mkdir()
    thermo = _Thermocouples(folder, PortSettings("loop://"), b.files, clock=b.clock)
    lines = [burst_line(k) for k in range(100)]
    try:
        reads = [("rx", "temperature", thermo.stamp(), line) for line in lines]
        thermo._record_reads(reads)
    finally:
        thermo.close("complete")
    rows = pd.read_csv(folder / "temperatures.csv")
    k = np.round((rows["leg1"].to_numpy() - 20.0) * 1e3).astype(int)
    assert k.tolist() == list(range(100))
    assert " skip " not in (folder / "serial.log").read_text()
    assert not b.messages


def test_a_flood_after_a_partial_line_leaves_it_out_and_replays(tmp_path: Path) -> None:
    """A flood whose first line completes a line the previous read began: that line is one
    of those left out (never glued to the newest row the flood keeps), the line the flood
    leaves pending is completed by the next read, and ``serial.log`` replays into the same
    ``temperatures.csv``."""
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    b.machines.close()
    folder = tmp_path / "log"
    folder.mkdir()
    thermo = _Thermocouples(folder, PortSettings("loop://"), b.files, clock=b.clock)
    first, pending = burst_line(0), burst_line(2000)
    flood = first[12:] + b"".join(burst_line(k) for k in range(1, 1501)) + pending[:9]
    try:
        thermo._record_reads([("rx", "temperature", thermo.stamp(), first[:12])])
        thermo._record_reads([("rx", "temperature", thermo.stamp(), flood)])
        thermo._record_reads([("rx", "temperature", thermo.stamp(), pending[9:])])
    finally:
        thermo.close("complete")
    rows = pd.read_csv(folder / "temperatures.csv")
    k = np.round((rows["leg1"].to_numpy() - 20.0) * 1e3).astype(int)
    assert k.tolist() == [1500, 2000]  # the flood's newest row, then the pending line
    assert (rows["leg2"] == 21.0).all() and (rows["ch7"] == 19.0).all()
    assert thermo.skipped_lines == 1500  # line 0 (begun before the flood) and 1..1499
    session_from_log(b.files, folder / "serial.log", tmp_path / "replay", b.notify)
    assert (tmp_path / "replay" / "temperatures.csv").read_bytes() == (
        folder / "temperatures.csv"
    ).read_bytes()


def test_a_logger_sending_nan_rows_is_said_at_once(tmp_path: Path) -> None:
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]

    state = {"open": True}  # leg3's thermocouple open (NaN) until the run says so

    def sample(t_s: float) -> list[float]:
        values = list(b.world.thermocouples_C(t_s))
        if state["open"]:
            values[2] = float("nan")
        return values

    nan_logger = ThermocoupleSimulator(sample, clock=b.world.clock, period_s=10.0)
    said: list[str] = []

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if "sends NaN" in message and not said:
            said.append(message)
            state["open"] = False  # the thermocouple plugged back

    b.notify = notify  # type: ignore[method-assign]
    try:
        b.run(temperature_port=PortSettings(nan_logger.url))
    finally:
        nan_logger.close()
        b.machines.close()
    assert len(said) == 1 and "nan" in said[0].lower()
    assert format_sample([float("nan")] * 6).startswith(b"nan")
    assert not any("no temperature row" in m for _, m in b.messages)


def test_a_run_whose_session_process_would_refuse_does_not_end_complete(tmp_path: Path) -> None:
    """A logger that sends its lines for 40 s and then nothing (its clock stuck): the log does
    not span the steps, process would refuse the session; the run says so instead of
    ending as if complete (every measured point is kept)."""
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    start = b.world.clock()
    stuck = ThermocoupleSimulator(
        b.world.thermocouples_C, clock=lambda: min(b.world.clock(), start + 40.0), period_s=10.0
    )
    try:
        with pytest.raises(AcquisitionError, match="process would refuse .*outside the thermo"):
            b.run(temperature_port=PortSettings(stuck.url))
    finally:
        stuck.close()
        b.machines.close()
    assert len(pd.read_csv(b.session / "points.csv")) == 4 * 3 * 6
    with pytest.raises(InputError, match="outside the thermocouple log"):
        process_session(b.session)
