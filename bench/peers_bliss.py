"""ESRF BLISS's Symétrie API v2 client drives the twin's API v2 server (a script, not a
test; issue 36 item 12).

BLISS (ESRF, LGPL-3.0) is the beamline control software whose motor controller
``SHexapod`` drives Symétrie hexapods; for API v2 (TCP port 61559) it talks through
``bliss.controllers.motors.shexapodV2.HexapodProtocolV2``. This script drives the twin
with that class, unmodified, built as ``SHexapod.protocol()`` builds it (from the
controller's configuration, ``{"tcp": {"url": HOST:PORT}}``); ``SHexapod`` itself needs
a BLISS session (its axes' settings live in Redis through the Beacon server), which a
bench has no use for. BLISS pulls about 130 distributions (PyTango, PyQt5, h5py, silx,
gevent, ...; numpy below 2), so it is no test dependency of hexatherm: run this in an
environment of its own::

    python3 -m venv /tmp/venv-bliss
    /tmp/venv-bliss/bin/pip install bliss==2.4.0 -e .
    /tmp/venv-bliss/bin/python bench/peers_bliss.py

Installed so on 2026-11-28 (CPython 3.11.7, x86-64 Linux, every distribution a wheel,
3 min 48 s): bliss 2.4.0 with gevent 24.11.1, greenlet 3.3.2, numpy 1.26.4, tabulate
0.10.0 (what the client module imports), pytango 10.3.1, PyQt5 5.15.11 among 130.

Importing BLISS monkey-patches sockets and ``time.sleep`` for gevent (threads excepted),
so the twin runs in a child process (this script with ``--serve-twin``), as a
controller would: its API v2 server (:class:`hexatherm.devices.sim.symetrie.SymetrieSimulator`)
on 127.0.0.1, wall clock, around the hexapod of ``configs/symetrie-like.yaml``, answering
``truth`` on its standard input with its true pose. Each step prints what BLISS read
next to the twin's truth (the true pose, the IGM of ``configs/symetrie-like.yaml`` for
the legs, the speeds it was started with, its stroke for the limits) and the script
exits 1 on any difference over 1 nm (mm and deg) or any call that fails.

**The controller's frames.** BLISS's API v2 client reads the frames (``get_origin``,
``user_cs``, ``object_cs``: ``CFG#CS?3``) and both poses of ``STA#HEXAPOD?``
(``object_pose``, the object in the user frame, ``uTo``; ``platform_pose``, the platform
in the machine frame, ``mTp``) but cannot set them: ``HexapodProtocolV2`` has no
``set_origin`` (``SHexapod``'s ``user_origin``/``object_origin`` raise
``NotImplementedError`` on API v2; its gpascii and PMAC protocols set them). So a second
twin is started with frames already set (as Symétrie's own software would have left
them: ``FRAMES``, those of ``tests/workflows/test_run_frames.py``), and BLISS reads them,
moves to three poses (``MOVES``) and reads both poses and the legs, against hexatherm's
maths: :func:`hexatherm.core.frames.platform_in_machine` (``M = U X O^-1``) and the IGM
of the hexapod file (1 nm, 1 nrad). BLISS 2.4's ``get_origin`` hands the 12 values as
the wire has them, metres and radians (its poses are converted to mm and deg): the
script converts them before comparing.

``--cycle-ms`` sets the twin's cycle between a command's ``:1`` and ``:2`` (20 ms by
default): BLISS's reader fails a command ("Error 2") whose two replies it finds waiting
together, which a loaded machine makes more likely the shorter the cycle (docs/run.md).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
SPEED_MM_S, SPEED_DEG_S = 5.0, 5.0
POSE = [1.2, -2.5, 3.0, 0.4, -0.3, 1.5]
FAR = [-1.0, 2.0, -2.5, -0.2, 0.3, -1.0]  # the move stopped on its way
UNREACHABLE = [0.0, 0.0, 80.0, 0.0, 0.0, 0.0]
TOLERANCE = 1e-6  # mm and deg: 1 nm
CALL_TIMEOUT_S = 15.0
#: the twin's frames (user in machine, object in platform; mm, deg) and the moves in them
FRAMES = [0.8, -1.5, 122.0, 0.4, -0.3, 21.2, 0.5, -0.3, 120.0, 0.1, -0.2, 20.3]
MOVES = ([0.0] * 6, POSE, [-2.0, 1.5, -3.0, -2.5, 2.0, -4.0])
NM, NRAD = 1e-6, float(np.degrees(1e-9))  # mm, deg


def serve_twin(cycle_s: float, frames: list[float] | None = None) -> int:
    """The child: the twin's API v2 server (with ``frames`` set, 12 values, mm and deg);
    ``truth`` on stdin -> a JSON line."""
    from hexatherm.devices.sim.symetrie import SimulatedHexapod, SymetrieSimulator
    from hexatherm.io.config import read_hexapod

    model = SimulatedHexapod(
        read_hexapod(HEXAPOD), speed_mm_s=SPEED_MM_S, speed_deg_s=SPEED_DEG_S, settle_s=0.05
    )
    with SymetrieSimulator(model, cycle_s=cycle_s) as sim:
        if frames is not None:
            sim.frames = np.array(frames, dtype=float)
        print(sim.port, flush=True)
        for line in sys.stdin:
            if line.strip() != "truth":
                break
            truth = {
                "pose": model.true_pose().tolist(),
                "moving": bool(model.moving()),
                "in_position": bool(model.in_position()),
                "accelerations": list(sim.ACCELERATIONS),
                "received": len(sim.received),
            }
            print(json.dumps(truth), flush=True)
    return 0


class Twin:
    """The twin's process, asked for its truth."""

    def __init__(self, cycle_s: float, frames: list[float] | None = None) -> None:
        extra = [] if frames is None else ["--twin-frames", json.dumps(frames)]
        self.process = subprocess.Popen(
            [sys.executable, __file__, "--serve-twin", repr(cycle_s), *extra],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.process.stdout is not None
        self.port = int(self.process.stdout.readline())

    def truth(self) -> dict[str, Any]:
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.write("truth\n")
        self.process.stdin.flush()
        return dict(json.loads(self.process.stdout.readline()))

    def settled(self) -> None:
        """Wait (10 s at most) for the twin's in-position flag."""
        deadline = time.monotonic() + 10.0
        while not self.truth()["in_position"] and time.monotonic() < deadline:
            time.sleep(0.01)

    def close(self) -> None:
        assert self.process.stdin is not None
        self.process.stdin.close()
        self.process.wait(timeout=30)


class Peer:
    """BLISS's client and the twin's process: each call bounded in time and counted, each
    read-back compared with the twin's truth."""

    def __init__(self, client: Any, twin: Twin, hexapod: Any, timeout: Any) -> None:
        self.client, self.twin, self.hexapod, self.timeout = client, twin, hexapod, timeout
        self.problems: list[str] = []
        self.calls: list[str] = []
        self.bad: set[int] = set()  # the calls that failed or read other than the truth

    def call(self, name: str, fn: Any) -> Any:
        """One BLISS call; None (and a problem) if it fails or does not answer."""
        self.calls.append(name)
        try:
            with self.timeout(CALL_TIMEOUT_S):
                return fn()
        except self.timeout:
            self.problem(f"{name}: no answer within {CALL_TIMEOUT_S:.0f} s")
        except Exception as exc:  # what BLISS raised is the finding
            self.problem(f"{name}: {type(exc).__name__}: {exc}")
        print(f"{name}: FAILED ({self.problems[-1]})")
        return None

    def problem(self, text: str) -> None:
        self.problems.append(text)
        self.bad.add(len(self.calls))

    def compare(self, name: str, got: Any, truth: Any, what: str) -> None:
        if got is None:
            return
        diff = float(np.abs(np.asarray(got, float) - np.asarray(truth, float)).max())
        print(f"{name}: {np.asarray(got, float).tolist()}, {what}: max |diff| {diff:.2e}")
        if not diff < TOLERANCE:
            self.problem(f"{name}: differs from {what} by {diff:.2e}")

    def compare_pose(self, name: str, got: Any, truth: Any, what: str) -> None:
        """A pose (mm, deg) against hexatherm's: 1 nm, 1 nrad."""
        if got is None:
            return
        d = np.abs(np.asarray(got, float) - np.asarray(truth, float))
        dt, dr = float(d[:3].max()), float(d[3:].max())
        print(
            f"{name}: {np.round(np.asarray(got, float), 6).tolist()}, hexatherm's {what}:"
            f" max |diff| {dt:.1e} mm, {dr:.1e} deg"
        )
        if not (dt < NM and dr < NRAD):
            self.problem(f"{name}: differs from hexatherm's {what} by {dt:.1e} mm, {dr:.1e} deg")

    def on_path(self, name: str, got: Any, before: Any, after: Any, legs: bool) -> None:
        """What BLISS read against the twin's truth at some time between two asks of it:
        the pose (or its IGM, the legs) nearest on the straight path between them."""
        if got is None:
            return
        a, b = np.asarray(before, float), np.asarray(after, float)
        target = np.asarray(got, float)
        lo, hi = 0.0, 1.0
        for _ in range(3):  # the nearest point, to a millionth of the path and finer
            s = np.linspace(lo, hi, 1001)
            path = a + s[:, None] * (b - a)
            residual = np.abs((self.hexapod.igm(path) if legs else path) - target).max(axis=1)
            k = int(residual.argmin())
            lo, hi = s[max(k - 1, 0)], s[min(k + 1, s.size - 1)]
        diff = float(residual[k])
        what = "the IGM of the true pose (mm)" if legs else "the true pose"
        print(f"{name}: {target.tolist()}, {what}: max |diff| {diff:.2e}")
        if not diff < TOLERANCE:
            self.problem(f"{name}: differs from {what} by {diff:.2e}")

    def check_state(self, step: str) -> None:
        """The hexapod's and the actuators' status, the object and platform poses and
        the leg lengths, against the twin's truth asked just before and just after."""
        client = self.client
        before = self.twin.truth()
        full = self.call(
            f"{step}: full_system_status (STA#HEXAPOD?)", lambda: client.full_system_status
        )
        after = self.twin.truth()
        states = {(t["in_position"], t["moving"]) for t in (before, after)}
        if full is not None:
            status = full["status"]
            flags = {k: getattr(status, k) for k in ("in_position", "moving", "control", "error")}
            print(f"{step}: system status {flags}")
            if (status.in_position, status.moving) not in states:
                self.problem(f"{step}: system status {flags}, the twin's {states}")
            if not (status.ready and status.control and status.homing_done) or status.error:
                self.problem(f"{step}: system status {status}")
            for name in ("object_pose", "platform_pose"):
                self.on_path(f"{step}: {name}", full[name], before["pose"], after["pose"], False)
        before = after
        axes = self.call(
            f"{step}: full_actuators_status (STA#AXES?)", lambda: client.full_actuators_status
        )
        after = self.twin.truth()
        states = {(t["in_position"], t["moving"]) for t in (before, after)}
        if axes is not None:
            legs = [a["length"] for a in axes]
            self.on_path(f"{step}: leg lengths", legs, before["pose"], after["pose"], True)
            words = {(a["status"].in_position, a["status"].moving) for a in axes}
            print(f"{step}: actuators (in position, moving): {words}")
            if len(words) != 1 or not words <= states:
                self.problem(f"{step}: actuators' status {words}, the twin's {states}")


def configuration(peer: Peer) -> None:
    """The frames, speeds, accelerations and limits (CFG#...?) against the twin's."""
    client = peer.client
    origin = peer.call("get_origin (CFG#CS?3)", client.get_origin)
    if origin is not None:
        peer.compare("user_cs", origin["user_cs"], np.zeros(6), "the twin's user frame")
        peer.compare("object_cs", origin["object_cs"], np.zeros(6), "the twin's object frame")
    speeds = peer.call("speeds (CFG#SPD?)", lambda: client.speeds)
    if speeds is not None:
        got = [speeds[k] for k in ("tspeed", "rspeed", "max_tspeed", "max_rspeed")]
        peer.compare("speeds (mm/s, deg/s)", got, [SPEED_MM_S, SPEED_DEG_S] * 2, "the twin's")
    accelerations = peer.call("accelerations (CFG#ACC?)", lambda: client.accelerations)
    if accelerations is not None:
        keys = ("tacceleration", "racceleration", "max_tacceleration", "max_racceleration")
        a_m, a_rad = peer.twin.truth()["accelerations"]
        peer.compare(
            "accelerations (mm/s2, deg/s2)",
            [accelerations[k] for k in keys],
            [a_m * 1e3, np.rad2deg(a_rad)] * 2,
            "the twin's",
        )
    for cs, name in ((1, "machine_limits"), (2, "user_limits")):
        limits = peer.call(f"{name} (CFG#LIM#WS?{cs})", lambda n=name: getattr(client, n))
        if limits is not None:
            for text in limits_against_stroke(name, peer.hexapod, limits):
                peer.problem(text)
    for name, expected in (("machine_limits_enabled", True), ("user_limits_enabled", False)):
        enabled = peer.call(f"{name} (CFG#LIM#ENABLE?)", lambda n=name: getattr(client, n))
        print(f"{name}: {enabled}")
        if enabled is not None and enabled != expected:
            peer.problem(f"{name}: {enabled}, the twin's: {expected}")


def moves(peer: Peer, refusal: type[Exception]) -> None:
    """A move waited for, an unreachable pose refused, a move stopped on its way."""
    client, twin = peer.client, peer.twin
    peer.call("move (MOVE#ABS, waits for its :2)", lambda: client.move(POSE))
    truth = twin.truth()
    print(f"after move: the twin moving {truth['moving']}")
    if truth["moving"]:
        peer.problem("move returned while the twin still moves")
    peer.compare("move's end", truth["pose"], POSE, "the pose commanded")
    twin.settled()  # its settle (50 ms)
    peer.check_state("after move")

    peer.calls.append("move to an unreachable pose (MOVE#ABS)")
    try:
        with peer.timeout(CALL_TIMEOUT_S):
            client.move(UNREACHABLE)
        peer.problem("the unreachable pose was not refused")
    except refusal as exc:
        print(f"move to {UNREACHABLE}: refused, {exc}")
    except Exception as exc:
        peer.problem(f"unreachable move: {type(exc).__name__}: {exc}")
    peer.compare("after refusal", twin.truth()["pose"], POSE, "the pose before")

    done = peer.call("start_move (MOVE#ABS, asynchronous)", lambda: client.start_move(FAR))
    peer.check_state("moving")  # then stopped on its way (a move of 1.1 s)
    peer.call("stop (STOP)", client.stop)
    if done is not None:
        end = peer.call("the stopped move's end (its MOVE#ABS reply)", lambda: done.get())
        print(f"the stopped move's reply: {end!r}")
    truth = twin.truth()
    print(f"after stop: the twin moving {truth['moving']}, at {truth['pose']}")
    if truth["moving"] or np.allclose(truth["pose"], FAR) or np.allclose(truth["pose"], POSE):
        peer.problem("the move was not stopped on its way")
    twin.settled()
    peer.check_state("after stop")


def controller_frames(peer: Peer) -> None:
    """The frames BLISS reads and the poses and legs it reads after moves in them,
    against hexatherm's maths (the twin started with ``FRAMES`` set)."""
    from hexatherm.core.frames import platform_in_machine

    client, twin = peer.client, peer.twin
    origin = peer.call("frames: get_origin (CFG#CS?3)", client.get_origin)
    if origin is not None:
        raw = np.concatenate([origin["user_cs"], origin["object_cs"]])
        print(f"frames: get_origin {raw.tolist()} (as the wire has them: m, rad)")
        got = raw.reshape(2, 6) * np.array([1e3] * 3 + [np.degrees(1.0)] * 3)
        peer.compare_pose("frames: user frame (mm, deg)", got[0], FRAMES[:6], "set")
        peer.compare_pose("frames: object frame (mm, deg)", got[1], FRAMES[6:], "set")
    for k, pose in enumerate(MOVES):
        step = f"frames: move {k}"
        peer.call(f"{step} (MOVE#ABS, waits for its :2)", lambda p=pose: client.move(p))
        twin.settled()
        machine = platform_in_machine(FRAMES, pose, "symetrie")
        peer.compare_pose(f"{step}: twin's true pose", twin.truth()["pose"], machine, "M")
        full = peer.call(
            f"{step}: full_system_status (STA#HEXAPOD?)", lambda: client.full_system_status
        )
        if full is not None:
            peer.compare_pose(f"{step}: object_pose (uTo)", full["object_pose"], pose, "X")
            peer.compare_pose(f"{step}: platform_pose (mTp)", full["platform_pose"], machine, "M")
        axes = peer.call(
            f"{step}: full_actuators_status (STA#AXES?)", lambda: client.full_actuators_status
        )
        if axes is not None:
            igm = peer.hexapod.igm(machine)[0]
            peer.compare(f"{step}: leg lengths", [a["length"] for a in axes], igm, "IGM of M (mm)")


def main(cycle_ms: float | None) -> int:
    import warnings

    from hexatherm.devices.sim.symetrie import SymetrieSimulator

    warnings.simplefilter("ignore")
    try:
        from bliss.controllers.motors import shexapod  # noqa: F401  (imports V2 after itself)
        from bliss.controllers.motors.shexapodV2 import HexapodProtocolV2, HexapodV2Error
    except ImportError as exc:
        print(f"BLISS is not installed here ({exc}); see the docstring")
        return 2
    from importlib.metadata import version

    import gevent

    from hexatherm.io.config import read_hexapod

    cycle_s = SymetrieSimulator.CYCLE_S if cycle_ms is None else cycle_ms * 1e-3
    print(f"bliss {version('bliss')}, gevent {version('gevent')}, numpy {np.__version__}")
    print(f"the twin's controller cycle: {cycle_s * 1e3:g} ms")
    twin = Twin(cycle_s)
    client = HexapodProtocolV2({"tcp": {"url": f"127.0.0.1:{twin.port}"}})
    peer = Peer(client, twin, read_hexapod(HEXAPOD), gevent.Timeout)
    try:
        peer.call("connect (greeting)", client.connect)
        print(f"connect: API version {client.api_version!r}, project {client.project!r}")
        peer.call(
            "control = True (as SHexapod.initialize_hardware)",
            lambda: setattr(client, "control", True),
        )
        peer.check_state("at rest")
        configuration(peer)
        moves(peer, HexapodV2Error)
        info = peer.call("dump (every query of BLISS's hexapod info)", client.dump)
        if info is not None:
            print(info)
            if info.startswith("Cannot read"):
                peer.problem(f"dump: {info}")
    finally:
        # HexapodProtocolV2 has no disconnect, and its reader, on a closed socket, takes
        # the last reply again and dies on a KeyError (BLISS 2.4): end it first
        reader = getattr(client, "_HexapodProtocolV2__read_task", None)
        if reader is not None:
            reader.kill()
        client.comm.close()
        received = twin.truth()["received"]
        twin.close()
    print("a second twin, its frames set:", FRAMES)
    twin = Twin(cycle_s, FRAMES)
    client = HexapodProtocolV2({"tcp": {"url": f"127.0.0.1:{twin.port}"}})
    peer.client, peer.twin = client, twin
    try:
        peer.call("frames: connect (greeting)", client.connect)
        controller_frames(peer)
    finally:
        reader = getattr(client, "_HexapodProtocolV2__read_task", None)
        if reader is not None:
            reader.kill()
        client.comm.close()
        received += twin.truth()["received"]
        twin.close()
    n = len(peer.calls)
    print(f"{n - len(peer.bad)}/{n} BLISS calls read the twin's truth")
    print(f"the twin received {received} command lines")
    print("\n".join(peer.problems) or "every BLISS read-back equals the twin's truth")
    return 1 if peer.problems else 0


def limits_against_stroke(name: str, hexapod: Any, limits: dict[str, Any]) -> list[str]:
    """The limits BLISS read against the stroke: each single-axis limit within it, 1 um
    (or 1 mdeg) beyond out of it."""
    low, high = np.array(limits["low_pose"]), np.array(limits["high_pose"])
    print(f"{name}: low {low.tolist()}, high {high.tolist()}")
    problems = []
    for k in range(6):
        for edge in (low[k], high[k]):
            pose = np.zeros(6)
            pose[k] = edge
            inside = not hexapod.check_stroke(hexapod.igm(pose)).any()
            pose[k] = edge + np.sign(edge) * 1e-3
            beyond = bool(hexapod.check_stroke(hexapod.igm(pose)).any())
            if not (inside and beyond):
                problems.append(f"{name}: axis {k} limit {edge} is not the stroke's")
    return problems


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--cycle-ms",
        type=float,
        default=None,
        help="the twin's controller cycle between a command's :1 and :2 (default: its own)",
    )
    parser.add_argument("--serve-twin", type=float, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--twin-frames", type=json.loads, default=None, help=argparse.SUPPRESS)
    options = parser.parse_args()
    if options.serve_twin is not None:
        sys.exit(serve_twin(options.serve_twin, options.twin_frames))
    sys.exit(main(options.cycle_ms))
