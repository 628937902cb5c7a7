"""``hexatherm run --resume`` after a crash of hexatherm (SIGKILL) or of either machine."""

from __future__ import annotations

import multiprocessing
import multiprocessing.process
import os
import signal
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.core.heating import Mat, MatHeating
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.errors import IncompleteSession
from hexatherm.workflows.run.campaign import run_campaign
from hexatherm.workflows.serve import AcceleratedClock, TwinWorld
from tests.sessions import ROOT
from tests.waiting import SAFETY_S, wait_for
from tests.workflows.test_run import (
    NOMINAL_ORIGIN,
    TRUE_ORIGIN,
    Bench,
    check_complete,
    make_bench,
    twin_machines,
)

#: mats off: on the wall clock (killed processes need real time) the balls must not drift
#: while a loaded machine probes them slowly, or load would decide the fits' agreement
STILL = MatHeating(tuple(Mat(0.0, 2400.0, ((0.0, float("inf")),)) for _ in range(6)))

SHORT = {"targets": [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]], "points_per_ball": 6}


def _lines(path: Path) -> int:
    try:
        with open(path, "rb") as handle:
            return handle.read().count(b"\n")
    except FileNotFoundError:
        return 0


def test_sigkill_of_run_at_random_points_then_resume(tmp_path: Path) -> None:
    """hexatherm killed twice (SIGKILL, at seeded random points of its transcript) while it
    measures against machines on accelerated time, then resumed to the end: every ball once,
    on its own step, and points.csv what the transcript replays to."""
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    b.machines.close()
    clock = AcceleratedClock(100.0)
    b.world = TwinWorld(
        b.world.hexapod,
        b.files.balls,
        heating=STILL,
        origin_on_cmm=TRUE_ORIGIN,
        clock=clock,
        sleep=clock.sleep,
        cmm_move_s=0.1,
    )
    b.machines = twin_machines(b.world)
    rng = np.random.default_rng(2024)
    transcript = b.session / "ipp.transcript"
    command = [
        sys.executable, "-m", "hexatherm", "run", str(tmp_path / "plan.yaml"),
        "--cmm", b.machines.cmm_url, "--controller", b.machines.controller_url,
        "--session", str(b.session),
        "--hexapod", str(ROOT / "configs" / "symetrie-like.yaml"),
        "--balls", str(ROOT / "configs" / "balls-3.yaml"),
        "--origin-on-cmm", ",".join(str(v) for v in NOMINAL_ORIGIN),
        "--settle", "0.02", "--poll", "0.01", "--readback-tol-um", "2", "--no-fsync",
    ]  # fmt: skip
    killed = 0
    try:
        for round_ in range(2):
            target = _lines(transcript) + int(rng.integers(150, 600))
            args = command + (["--resume"] if round_ else [])
            proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
            wait_for(
                lambda: proc.poll() is not None or _lines(transcript) >= target,  # noqa: B023
                "the run's progress",
            )
            if proc.poll() is None:
                os.kill(proc.pid, signal.SIGKILL)
                killed += 1
            _, err = proc.communicate(timeout=SAFETY_S)
            assert proc.returncode in (0, -signal.SIGKILL), err.decode()
        assert killed >= 1
        # the last resume in process, on the wall clock like the killed runs
        criteria = InPositionCriteria(settle_s=0.02, tolerance_um=2.0, poll_s=0.01)
        options = b.options(resume=True, reconnect_wait_s=0.1, criteria=criteria)
        run_campaign(b.files, b.world.hexapod, options, b.notify)
        text = transcript.read_text()
        assert text.count("run resume") == 2 and text.count("run start") == 1
        check_complete(b)
    finally:
        b.machines.close()


def _kill_on(b: Bench, prefix: str, which: str) -> None:
    """Close one server as soon as the run says ``prefix`` (a machine that crashes)."""
    done: list[bool] = []

    def notify(level: str, message: str) -> None:
        b.messages.append((level, message))
        if message.startswith(prefix) and not done:
            done.append(True)
            getattr(b.machines, which).close()

    b.notify = notify  # type: ignore[method-assign]


@pytest.mark.parametrize(
    ("prefix", "which"),
    [("R0 B2:", "cmm"), ("step 3/4 S1", "cmm"), ("R0 B3:", "controller")],
    ids=["cmm-between-balls", "cmm-after-a-move", "controller"],
)
def test_a_machine_that_crashes_then_resume(tmp_path: Path, prefix: str, which: str) -> None:
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    _kill_on(b, prefix, which)
    try:
        with pytest.raises(IncompleteSession, match="--resume"):
            b.run(reconnects=2)
        before = pd.read_csv(b.session / "points.csv")
        assert 0 < len(before) < 4 * 3 * 6
        b.restart()  # the machine is back (new ports, the same twin)
        b.notify = lambda level, message: b.messages.append((level, message))  # type: ignore[method-assign]
        b.run(resume=True)
        after = check_complete(b)
        pd.testing.assert_frame_equal(after.iloc[: len(before)], before)
    finally:
        b.machines.close()


class _WallClock:
    """The twin's time on the wall clock, ``scale`` times faster from ``anchor`` (shared by
    every incarnation of a server process: a restarted server continues the same history)."""

    def __init__(self, scale: float, anchor_s: float) -> None:
        self.scale, self.anchor_s = scale, anchor_s

    def __call__(self) -> float:
        return self.anchor_s + self.scale * (time.time() - self.anchor_s)

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds / self.scale)


def _serve(b: Bench, clock: _WallClock, ports: tuple[int, int], pipe: Connection) -> None:
    """A server process: the twin's CMM and controller until it is killed."""
    world = TwinWorld(
        b.world.hexapod,
        b.files.balls,
        heating=STILL,
        origin_on_cmm=TRUE_ORIGIN,
        clock=clock,
        sleep=clock.sleep,
        start_s=clock.anchor_s,
        cmm_move_s=0.1,
    )
    machines = twin_machines(world, cmm_port=ports[0], controller_port=ports[1])
    pipe.send((machines.cmm.port, machines.controller.port))
    threading.Event().wait()  # serves until the test kills the process


def test_sigkill_of_the_server_process_then_resume(tmp_path: Path) -> None:
    """The process serving both machines is killed (SIGKILL, at a seeded random point of the
    transcript) under a running campaign: the run stops (the machines stay away), the
    server is started again on the same ports, continuing the same thermal history, and
    --resume finishes: every ball once, on its own step, what was accepted kept."""
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    b.machines.close()
    context = multiprocessing.get_context("fork")
    clock = _WallClock(1000.0, time.time())

    def start(
        ports: tuple[int, int],
    ) -> tuple[multiprocessing.process.BaseProcess, tuple[int, int]]:
        parent, child = context.Pipe()
        proc = context.Process(target=_serve, args=(b, clock, ports, child), daemon=True)
        proc.start()
        assert parent.poll(SAFETY_S), "the server did not start"
        return proc, parent.recv()

    server, ports = start((0, 0))
    urls = {"cmm_url": f"ipp://127.0.0.1:{ports[0]}",
            "controller_url": f"symetrie://127.0.0.1:{ports[1]}"}  # fmt: skip
    criteria = InPositionCriteria(settle_s=0.02, tolerance_um=2.0, poll_s=0.01)
    options = b.options(reconnects=1, reconnect_wait_s=0.05, criteria=criteria, **urls)
    failure: list[BaseException] = []

    def first_run() -> None:
        try:
            run_campaign(b.files, b.world.hexapod, options, b.notify)
        except BaseException as exc:  # noqa: BLE001 - handed to the test's thread
            failure.append(exc)

    transcript = b.session / "ipp.transcript"
    try:
        thread = threading.Thread(target=first_run)
        thread.start()
        target = int(np.random.default_rng(7).integers(150, 600))
        wait_for(
            lambda: not thread.is_alive() or _lines(transcript) >= target, "the run's progress"
        )
        os.kill(server.pid, signal.SIGKILL)
        server.join(timeout=SAFETY_S)
        thread.join(timeout=SAFETY_S)
        assert len(failure) == 1 and isinstance(failure[0], IncompleteSession), failure
        before = pd.read_csv(b.session / "points.csv")
        assert 0 < len(before) < 4 * 3 * 6
        server, again = start(ports)  # the machine is back, on its ports
        assert again == ports
        run_campaign(b.files, b.world.hexapod, b.options(resume=True, criteria=criteria, **urls),
                     b.notify)  # fmt: skip
        after = check_complete(b)
        pd.testing.assert_frame_equal(after.iloc[: len(before)], before)
        assert transcript.read_text().count("run resume") == 1
    finally:
        if server.is_alive():
            os.kill(server.pid, signal.SIGKILL)
            server.join(timeout=SAFETY_S)
