"""A failure while reconnecting does not end the night while ``--reconnects`` lasts: a
second cut during the new connection's greeting, a server that refuses connections for
5 s while it restarts (the waits grow, through the run's own sleep: nothing waits for
the wall clock)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hexatherm.devices.sim.ipp import Fault, IppSimServer
from hexatherm.devices.sim.symetrie import Faults, SymetrieSimulator
from hexatherm.errors import IncompleteSession
from tests.workflows.test_run import TEST_CYCLE_S, Bench, check_complete, make_bench

SHORT = {"targets": [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]], "points_per_ball": 6}
#: the restart's length, s of the run's clock
DOWN_S = 5.0


def transcript(b: Bench) -> str:
    return (b.session / "ipp.transcript").read_text()


def test_a_second_cut_during_the_reconnections_start_session_is_retried(tmp_path: Path) -> None:
    faults = [Fault("drop", 12, "PtMeas", after_lines=2), Fault("drop", 2, "StartSession")]
    b = make_bench(tmp_path, ipp_faults=faults, **SHORT)  # type: ignore[arg-type]
    try:
        b.run()
        text = transcript(b)
        assert text.count("connect 127.0.0.1") == 3
        assert any("CMM reconnection failed" in m for _, m in b.messages)
        check_complete(b)
    finally:
        b.machines.close()


class Restart:
    """Takes a machine's server down when the run says it lost it, and brings it back on
    the same port once the run's clock has gone ``DOWN_S`` further (the run's sleeps)."""

    def __init__(self, b: Bench, lost: str, down, up) -> None:
        self.b, self.lost, self.down, self.up = b, lost, down, up
        self.down_at: float | None = None
        self.waits: list[float] = []

    def notify(self, level: str, message: str) -> None:
        self.b.messages.append((level, message))
        if message.startswith(self.lost) and self.down_at is None:
            self.down()
            self.down_at = self.b.clock()

    def sleep(self, seconds: float) -> None:
        if self.down_at is not None:
            self.waits.append(seconds)
        self.b.clock.sleep(seconds)
        if self.down_at is not None and self.b.clock() - self.down_at >= DOWN_S:
            self.down_at = float("inf")  # once
            self.up()

    def run(self, **options: object):
        from hexatherm.workflows.run.campaign import run_campaign

        return run_campaign(
            self.b.files,
            self.b.world.hexapod,
            self.b.options(reconnect_wait_s=1.0, **options),
            self.notify,
            clock=self.b.clock,
            sleep=self.sleep,
        )


def test_a_cmm_refusing_connections_while_it_restarts_is_waited_for(tmp_path: Path) -> None:
    b = make_bench(tmp_path, ipp_faults=[Fault("drop", 12, "PtMeas", after_lines=2)], **SHORT)  # type: ignore[arg-type]
    old = b.machines.cmm

    def up() -> None:
        b.machines.cmm = IppSimServer(
            b.world,
            port=old.port,
            tools={"Probe1": 2.0},
            compensated=old.compensated,
            time_s=b.world.cmm_time_s,
            home_mm=tuple(old.home_mm),
            limits_mm=old.limits_mm,
        )

    restart = Restart(b, "CMM connection lost", old.close, up)
    try:
        restart.run()
        # refused after 1 s and after 3 s, taken after 7 s: the default 3 attempts
        assert restart.waits[:3] == [1.0, 2.0, 4.0]
        assert sum("CMM reconnection failed" in m for _, m in b.messages) == 2
        check_complete(b)
    finally:
        b.machines.close()


def test_a_cmm_away_longer_than_the_budget_stops_the_run(tmp_path: Path) -> None:
    b = make_bench(tmp_path, ipp_faults=[Fault("drop", 12, "PtMeas", after_lines=2)], **SHORT)  # type: ignore[arg-type]
    restart = Restart(b, "CMM connection lost", b.machines.cmm.close, lambda: None)
    try:
        with pytest.raises(IncompleteSession, match="cannot connect to the CMM"):
            restart.run(reconnects=2)
        assert restart.waits == [1.0, 2.0]
    finally:
        b.machines.close()


def test_a_controller_refusing_connections_while_it_restarts_is_waited_for(
    tmp_path: Path,
) -> None:
    b = make_bench(tmp_path, faults=Faults(drop_mid_move=True), **SHORT)  # type: ignore[arg-type]
    old = b.machines.controller

    def up() -> None:
        b.machines.controller = SymetrieSimulator(
            b.world.model, port=old.port, cycle_s=TEST_CYCLE_S
        )

    restart = Restart(b, "controller connection lost", old.close, up)
    try:
        restart.run()
        assert restart.waits[:3] == [1.0, 2.0, 4.0]
        assert "run reconnect failed" in (b.session / "controller.log").read_text()
        check_complete(b)
    finally:
        b.machines.close()
