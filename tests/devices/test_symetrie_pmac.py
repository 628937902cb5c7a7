"""Symétrie's Power PMAC gpascii dialect: hexatherm's driver and the twin's server.

Everything runs on 127.0.0.1 on a ManualClock shared by driver and twin (no wall-clock
waits). Truths: the twin's model (true pose, its own IGM), and, for the wire, the
exchanges CGSE's ``symetrie-hexapod`` documents (written here by hand from its reading).
"""

from __future__ import annotations

import math
import socket
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from hexatherm.core.frames import platform_in_machine
from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.sim.symetrie import Faults, ManualClock, SimulatedHexapod
from hexatherm.devices.sim.symetriepmac import SymetriePmacSimulator, move_target, strip_telnet
from hexatherm.devices.symetriepmac import SymetriePmacController
from hexatherm.devices.urls import controller_from_url
from hexatherm.errors import (
    ControllerConnectionError,
    ControllerError,
    ControllerReplyError,
    PoseRefusedError,
)

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "symetrie-like.yaml"
POSE = np.array([1.2, -2.5, 3.0, 0.4, -0.3, 1.5])
OUT_OF_STROKE = np.array([0.0, 0.0, 80.0, 0.0, 0.0, 0.0])


def make_hexapod() -> Hexapod:
    data = yaml.safe_load(CONFIG.read_text())
    return Hexapod(
        name=data["name"],
        convention="symetrie",
        base_joints_mm=np.array(data["base_joints"], dtype=float),
        platform_joints_mm=np.array(data["platform_joints"], dtype=float),
        stroke_mm=np.array(data["stroke"], dtype=float),
    )


class Rig:
    def __init__(self, **model: Any) -> None:
        self.clock = ManualClock(500.0)
        self.model = SimulatedHexapod(make_hexapod(), clock=self.clock, **model)
        self.sim = SymetriePmacSimulator(self.model)
        self.lines: list[tuple[str, str]] = []
        self.driver = controller_from_url(
            self.sim.url,
            clock=self.clock,
            sleep=self.clock.sleep,
            log=lambda d, line: self.lines.append((d, line)),
        )

    def close(self) -> None:
        self.driver.close()
        self.sim.close()


@pytest.fixture
def rig() -> Iterator[Callable[..., Rig]]:
    rigs: list[Rig] = []

    def make(**model: Any) -> Rig:
        r = Rig(**model)
        rigs.append(r)
        r.driver.connect()
        return r

    yield make
    for r in rigs:
        r.close()


def test_driver_moves_the_twin_and_reads_its_truth(rig: Callable[..., Rig]) -> None:
    r = rig(noise_um=0.02, noise_urad=0.1, seed=4)
    assert isinstance(r.driver, SymetriePmacController)
    assert r.driver.info["api_version"] == "2.7.1.0"
    assert r.driver.info["user_frame_in_machine"].startswith("[0.0000, 0.0000, 0.0000] mm")
    r.driver.move_absolute(POSE)
    sent = [line for d, line in r.lines if d == "tx"]
    move = next(line for line in sent if line.endswith("c_cmd=C_MOVE_PTP"))
    assert move.startswith("c_par(0)=0 c_par(1)=1.200000000000 c_par(2)=-2.500000000000 ")
    # the state was checked and the pose validated before the move
    assert sent.index("s_hexa") < sent.index(move)
    assert any(line.endswith("c_cmd=C_VALID_PTP") for line in sent[: sent.index(move)])
    record = r.driver.wait_in_position(InPositionCriteria(settle_s=1.0, poll_s=0.5))
    truth = r.model.true_pose()
    np.testing.assert_allclose(truth, POSE, atol=1e-12)
    dev_um = (record.pose_mm_deg[:3] - truth[:3]) * 1e3
    dev_urad = np.deg2rad(record.pose_mm_deg[3:] - truth[3:]) * 1e6
    assert np.abs(dev_um).max() < 0.1 and np.abs(dev_urad).max() < 0.5  # noise, not bias
    np.testing.assert_allclose(record.actuators_mm, r.model.hexapod.igm(POSE)[0], atol=1e-8)
    assert record.temperatures_C.shape == (0,)
    r.driver.move_absolute(np.zeros(6))
    r.clock.sleep(1.0)
    r.driver.stop()
    assert not r.model.moving() and ("tx", "c_cmd=C_STOP") in r.lines
    stopped = r.model.true_pose()
    assert 0 < np.abs(stopped).max() < np.abs(POSE).max()


def test_refusals_name_the_limits_and_move_nothing(rig: Callable[..., Rig]) -> None:
    r = rig(faults=Faults(refuse=lambda p: p[2] > 2.0))
    with pytest.raises(PoseRefusedError, match="actuator limits"):
        r.driver.move_absolute(OUT_OF_STROKE)
    with pytest.raises(PoseRefusedError, match="user workspace limits"):
        r.driver.move_absolute(POSE)  # Tz 3 mm: the user limit
    assert r.model.moves == 0
    assert not any("C_MOVE_PTP" in line for line in r.sim.received)
    r.model.faults.errors["MOVE_PTP"] = [-40]
    with pytest.raises(PoseRefusedError, match=r"requested move not feasible \(-40\)"):
        r.driver.move_absolute([0.5, 0, 0, 0, 0, 0])
    r.model.faults.errors["MOVE_PTP"] = [-35]
    with pytest.raises(ControllerReplyError, match=r"control on \(-35\)"):
        r.driver.move_absolute([0.5, 0, 0, 0, 0, 0])
    assert r.model.moves == 0


def test_status_is_checked_before_moving(rig: Callable[..., Rig]) -> None:
    r = rig()
    sim = r.sim
    assert isinstance(sim, SymetriePmacSimulator)
    sim.control_on, sim.error = False, True
    with pytest.raises(ControllerError, match="in error .*control loop is off"):
        r.driver.validate(POSE)  # what --dry-run calls: nothing moved
    state = r.driver.state()
    assert state.error and not state.ready and "error" in state.message
    assert r.model.moves == 0 and not any("C_MOVE_PTP" in c for c in sim.received)
    sim.control_on, sim.error = True, False
    r.driver.move_absolute(POSE)
    assert r.model.moves == 1


def test_wrong_login_is_refused() -> None:
    clock = ManualClock()
    sim = SymetriePmacSimulator(SimulatedHexapod(make_hexapod(), clock=clock))
    driver = SymetriePmacController("127.0.0.1", sim.port, clock=clock, sleep=clock.sleep)
    driver.password = "wrong"
    try:
        with pytest.raises(ControllerConnectionError, match="refused the login 'root'"):
            driver.connect()
        assert not driver.connected
    finally:
        sim.close()


def test_wire_as_cgse_reads_it() -> None:
    """The twin's bytes, read as CGSE's AlphaPlusTelnetInterface reads them: telnet
    login, ``gpascii -2`` and ``echo7`` answered up to one ``\\x06\\r\\n``; an answer is the
    echoed command, its values, one a line, then ``\\x06\\r\\n``."""
    clock = ManualClock()
    sim = SymetriePmacSimulator(SimulatedHexapod(make_hexapod(), clock=clock))
    sock = socket.create_connection(("127.0.0.1", sim.port), timeout=10)
    received = b""

    def until(marker: bytes) -> bytes:
        nonlocal received
        while marker not in received:
            data = sock.recv(4096)
            assert data, f"closed before {marker!r}"
            received += data
        end = received.index(marker) + len(marker)
        head, received = received[:end], received[end:]
        return strip_telnet(head)[0]

    try:
        assert until(b"login: ").endswith(b"ppmac login: ")
        sock.sendall(b"root\r\n")
        until(b"Password: ")
        sock.sendall(b"deltatau\r\n")
        until(b"ppmac# ")
        sock.sendall(b"gpascii -2\r\necho7\r\n")  # together, as CGSE's ZONDA sends them
        started = until(b"\x06\r\n")
        assert started.startswith(b"gpascii -2\r\n") and started.endswith(b"echo7\r\n\x06\r\n")
        sock.sendall(b"c_cmd\r\n")
        assert until(b"\x06\r\n") == b"c_cmd\r\n0\r\n\x06\r\n"
        sock.sendall(b"c_par(0)=1 c_par(1)=0 c_par(2)=0 c_par(3)=0 c_par(4)=90 ")
        sock.sendall(b"c_par(5)=0 c_par(6)=0 c_par(7)=0 c_cmd=C_VALID_PTP\r\n")
        until(b"\x06\r\n")
        codes = []
        while not codes or codes[-1] > 0:
            sock.sendall(b"c_cmd\r\n")
            codes.append(int(until(b"\x06\r\n").split(b"\r\n")[1]))
        assert codes == [1, 0]  # running once, then done
        sock.sendall(b"c_par(0)\r\n")
        assert until(b"\x06\r\n") == b"c_par(0)\r\n8\r\n\x06\r\n"  # bit 3: actuator limits
        sock.sendall(b"s_uto_tx,6,1\r\n")
        assert until(b"\x06\r\n") == b"s_uto_tx,6,1\r\n" + b"0\r\n" * 6 + b"\x06\r\n"
        sock.sendall(b"s_hexa\r\n")
        word = int(until(b"\x06\r\n").split(b"\r\n")[1])
        assert word & 0b1001100 == 0b1001100  # control on, in position, home complete
        sock.sendall(b"no_such_variable\r\n")
        assert b"error #" in until(b"\x06\r\n")
    finally:
        sock.close()
        sim.close()


FAST = InPositionCriteria(settle_s=1.0, poll_s=0.5, timeout_s=900.0)


def test_late_flag_and_replies_in_pieces(rig: Callable[..., Rig]) -> None:
    r = rig()
    r.model.faults.late_in_position_s = 20.0
    r.model.faults.split_writes = True
    r.driver.move_absolute(POSE)
    record = r.driver.wait_in_position(FAST)
    assert record.flag_after_s >= 20.0 + r.model.settle_s
    np.testing.assert_allclose(record.pose_mm_deg, r.model.true_pose(), atol=1e-9)


def test_dropped_connection_mid_move_then_stop(rig: Callable[..., Rig]) -> None:
    r = rig()
    r.model.faults.drop_mid_move = True
    r.driver.move_absolute(POSE)
    with pytest.raises(ControllerConnectionError):
        r.driver.wait_in_position(FAST)
    assert not r.driver.connected and r.model.moving()
    r.clock.sleep(1.0)
    r.driver.stop()  # a new telnet login to deliver C_STOP
    assert r.sim.connections == 2 and not r.model.moving()
    np.testing.assert_allclose(r.driver.read_pose(), r.model.true_pose(), atol=1e-9)


def test_stop_after_an_interrupted_query(rig: Callable[..., Rig]) -> None:
    """Ctrl-C between a query and its answer: the stop skips the stale answer."""
    r = rig()
    r.driver.move_absolute(POSE)
    r.clock.sleep(1.0)
    r.driver._send("s_uto_tx,6,1")  # never read
    r.driver.stop()
    assert not r.model.moving()
    here = r.model.true_pose()
    np.testing.assert_allclose(r.driver.read_pose(), here, atol=1e-9)
    # 1 s of a 3 s move, and the 10 ms poll of c_cmd while C_STOP ran
    np.testing.assert_allclose(here, POSE * 1.01 / 3, atol=1e-9)


def test_emergency_stop_while_moving_is_an_error(rig: Callable[..., Rig]) -> None:
    r = rig()
    sim = r.sim
    assert isinstance(sim, SymetriePmacSimulator)
    r.driver.move_absolute(POSE)
    r.clock.sleep(1.0)
    sim.press_emergency_stop()
    with pytest.raises(ControllerError, match="reports an error .*emergency stop"):
        r.driver.wait_in_position(FAST)
    r.driver.stop()  # still delivered
    with pytest.raises(ControllerError, match="in error or its emergency stop is pressed"):
        r.driver.move_absolute(np.zeros(6))
    assert r.model.moves == 1


class Gpascii:
    """A bare gpascii session on the twin, as CGSE's interface opens one (login,
    ``gpascii -2``, ``echo7``): each line's answer values, a command's return code."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.received = b""
        self.until(b"login: ")
        self.sock.sendall(b"root\r\n")
        self.until(b"Password: ")
        self.sock.sendall(b"deltatau\r\n")
        self.until(b"ppmac# ")
        self.sock.sendall(b"gpascii -2\r\necho7\r\n")
        self.until(b"\x06\r\n")

    def until(self, marker: bytes) -> bytes:
        while marker not in self.received:
            data = self.sock.recv(4096)
            assert data, f"closed before {marker!r}"
            self.received += data
        end = self.received.index(marker) + len(marker)
        head, self.received = self.received[:end], self.received[end:]
        return strip_telnet(head)[0]

    def ask(self, line: str) -> list[str]:
        """The lines answered to ``line`` (its echo and the acknowledge left out)."""
        self.sock.sendall(line.encode() + b"\r\n")
        return self.until(b"\x06\r\n").decode().split("\r\n")[1:-2]

    def command(self, line: str) -> int:
        """Send a command line, then read ``c_cmd`` until it is no longer running."""
        assert not any("error #" in x for x in self.ask(line))
        code = 1
        while code > 0:
            code = int(self.ask("c_cmd")[0])
        return code

    def pars(self, count: int) -> np.ndarray:
        return np.array([float(v) for v in self.ask(f"c_par(0),{count},1")])

    def move(self, mode: int, pose: Any) -> int:
        values = " ".join(f"c_par({k + 1})={v!r}" for k, v in enumerate(map(float, pose)))
        return self.command(f"c_par(0)={mode} {values} c_cmd=C_MOVE_PTP")

    def valid(self, mode: int, pose: Any) -> int:
        values = " ".join(f"c_par({k + 2})={v!r}" for k, v in enumerate(map(float, pose)))
        assert self.command(f"c_par(0)=1 c_par(1)={mode} {values} c_cmd=C_VALID_PTP") == 0
        return int(self.pars(1)[0])


@pytest.fixture
def gpascii() -> Iterator[tuple[SimulatedHexapod, ManualClock, Gpascii]]:
    clock = ManualClock(500.0)
    model = SimulatedHexapod(make_hexapod(), clock=clock)
    sim = SymetriePmacSimulator(model)
    client = Gpascii(sim.port)
    yield model, clock, client
    client.sock.close()
    sim.close()


def settle(model: SimulatedHexapod, clock: ManualClock) -> None:
    while not model.in_position():
        clock.sleep(0.5)


def test_relative_moves_in_the_object_and_the_user_frame(
    gpascii: tuple[SimulatedHexapod, ManualClock, Gpascii],
) -> None:
    """Truth by geometry: with the platform turned 15 deg about Z, a step of +1 mm along
    the object's X goes along (cos 15, sin 15) of the user's frame; a step along the
    user's X along X."""
    model, clock, g = gpascii
    c, s = math.cos(math.radians(15.0)), math.sin(math.radians(15.0))
    assert g.move(0, [1.0, 2.0, 0.5, 0.0, 0.0, 15.0]) == 0
    settle(model, clock)
    assert g.move(1, [1.0, 0, 0, 0, 0, 0]) == 0  # object relative
    settle(model, clock)
    np.testing.assert_allclose(model.true_pose(), [1 + c, 2 + s, 0.5, 0, 0, 15.0], atol=1e-9)
    assert g.move(2, [1.0, 0, 0, 0, 0, 0]) == 0  # user relative
    settle(model, clock)
    np.testing.assert_allclose(model.true_pose(), [2 + c, 2 + s, 0.5, 0, 0, 15.0], atol=1e-9)
    # a user-relative turn: about the object's own axes, the position kept (CGSE's rule;
    # composed in the user frame, T(step) T(now), it would swing the platform about the
    # user frame's origin: 0.2 mm here)
    assert g.move(2, [0, 0, 0, 0, 0, 5.0]) == 0
    settle(model, clock)
    np.testing.assert_allclose(model.true_pose(), [2 + c, 2 + s, 0.5, 0, 0, 20.0], atol=1e-9)
    # checks: a relative step beyond the stroke breaks the actuator limits (bit 3) and is
    # refused as a move (-40: not feasible); nothing moves
    assert g.valid(1, [0, 0, 0, 0, 0, 0]) == 0
    assert g.valid(1, OUT_OF_STROKE) == 1 << 3
    moves = model.moves
    assert g.move(2, OUT_OF_STROKE) == -40 and model.moves == moves


#: CGSE's own test of its hexapod simulators (github.com/IvS-KULeuven/cgse,
#: projects/generic/symetrie-hexapod/tests/test_puna_simulator.py, test_absolute_movement,
#: since commit 0801fe6c): the frames it sets, its moves and the object (user) and
#: platform (machine) poses it expects, 10 digits, checked there to a relative 1e-5
CGSE_FRAMES = [-2, -2, -2, -3, -4, -5, 0, 0, 3, 30.0, 30.0, 0]
CGSE_MOVES = [
    (0, [1, 3, 4, 35, 25, 10], (-0.5550577685, 1.2043056694, -1.0689145898, 1.0195290202,
                                -8.466485292, 2.79932335)),
    (1, [-1, -1, -1, 1, 7, -1], (-2.317005597, 0.8737649564, -2.006061295, 3.052233715,
                                 -1.9466592653, 4.741402017)),
    (2, [-2, -2, -2, 1, 7, -1], (-4.710341626, -0.97799175, -4.017462423, 5.310002306,
                                 4.496313461, 6.918574645)),
]  # fmt: skip
CGSE_OBJECT = [
    (1.0, 3.0, 4.0, 35.0, 25.0, 10.0),
    (-0.4295447122, 2.49856887, 3.160383195, 37.82597474, 31.25750377, 13.736721917),
    (-2.429542106, 0.4985648, 1.1603886537, 41.37225134, 37.32309944, 18.14008525),
]


def test_moves_give_the_poses_cgses_own_test_expects() -> None:
    """The twin's rules for absolute, object- and user-relative moves, and hexatherm's
    platform ``U X O^-1``, against the poses CGSE's test expects (as it checks them: a
    relative 1e-5). The user-relative one was 0.44 mm and 3.6 deg away with the step
    composed in the user frame."""
    now = np.zeros(6)
    for (mode, step, machine), expected in zip(CGSE_MOVES, CGSE_OBJECT, strict=True):
        now = move_target(mode, now, np.array(step, float))
        assert now.tolist() == pytest.approx(expected, rel=1e-5)
        platform = platform_in_machine(CGSE_FRAMES, now, "symetrie")
        assert platform.tolist() == pytest.approx(machine, rel=1e-5)


def test_workspace_limits_specific_positions_and_version(
    gpascii: tuple[SimulatedHexapod, ManualClock, Gpascii],
) -> None:
    model, clock, g = gpascii
    assert g.command("c_cfg=0 c_par(0)=1 c_cmd=C_CFG_LIMIT") == 0
    limits = g.pars(13)[1:]
    hexapod = model.hexapod
    for k in range(6):  # the truth: the struts allow each limit, not 1 % beyond it
        for edge in (limits[k], limits[6 + k]):
            pose = np.zeros(6)
            pose[k] = edge
            assert not hexapod.check_stroke(hexapod.igm(pose)).any()
            pose[k] *= 1.01
            assert hexapod.check_stroke(hexapod.igm(pose)).any()
    # user limits: Tz within [-1, 1] mm, enabled: a pose at Tz 2 breaks them (bit 2)
    user = limits.copy()
    user[2], user[8] = -1.0, 1.0
    values = " ".join(f"c_par({k + 1})={float(v)!r}" for k, v in enumerate(user))
    assert g.command(f"c_cfg=1 c_par(0)=2 {values} c_cmd=C_CFG_LIMIT") == 0
    assert g.command("c_cfg=1 c_par(0)=2 c_par(1)=1 c_cmd=C_CFG_LIMITENABLE") == 0
    assert g.command("c_cfg=0 c_par(0)=2 c_cmd=C_CFG_LIMITENABLE") == 0 and g.pars(2)[1] == 1
    assert g.valid(0, [0, 0, 2.0, 0, 0, 0]) == 1 << 2
    assert g.move(0, [0, 0, 2.0, 0, 0, 0]) == -40
    assert g.command("c_cfg=1 c_par(0)=0 c_cmd=C_CFG_LIMIT") == -31  # factory: get only
    assert g.command("c_cfg=1 c_par(0)=2 c_par(1)=0 c_cmd=C_CFG_LIMITENABLE") == 0
    assert g.valid(0, [0, 0, 2.0, 0, 0, 0]) == 0  # disabled: the struts alone
    # specific positions: 2 retracted (the lowest Tz), 1 the user zero
    assert g.command("c_par(0)=2 c_cmd=C_MOVE_SPECIFICPOS") == 0
    settle(model, clock)
    assert model.true_pose()[2] == limits[2] and not np.any(model.true_pose()[[0, 1, 3, 4, 5]])
    assert g.command("c_par(0)=1 c_cmd=C_MOVE_SPECIFICPOS") == 0
    settle(model, clock)
    np.testing.assert_allclose(model.true_pose(), 0.0, atol=1e-12)
    assert g.ask("vers") == ["5.3.0.0"]


def test_an_illegal_command_constant_leaves_no_stale_success(
    gpascii: tuple[SimulatedHexapod, ManualClock, Gpascii],
) -> None:
    _, _, g = gpascii
    assert g.command("c_cmd=C_VERSION") == 0  # c_cmd 0, c_par the version
    answer = g.ask("c_cmd=C_NO_SUCH_COMMAND")
    assert any("error #20: ILLEGAL CMD" in x for x in answer)
    assert int(g.ask("c_cmd")[0]) == -30  # unknown command number, not the last 0
