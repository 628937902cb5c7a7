"""Hexapod controller drivers (Symetrie API v2, PI GCS) against their simulators.

Everything runs on 127.0.0.1 and on a ManualClock shared by driver and simulator, so
no test waits for wall-clock time. Truths are independent of the drivers: the test's
own Hexapod (IGM) built from configs/symetrie-like.yaml, scipy's Euler conventions,
hand-written reply lines.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import (
    HexapodController,
    InPositionCriteria,
    LineBuffer,
    SocketController,
    pose_deviation_um_urad,
)
from hexatherm.devices.pi import PIController, format_axes, parse_answer, parse_error
from hexatherm.devices.sim.pi import PISimulator
from hexatherm.devices.sim.symetrie import (
    ManualClock,
    SimulatedController,
    SimulatedHexapod,
    SymetrieSimulator,
)
from hexatherm.devices.symetrie import (
    SymetrieController,
    describe_status,
    format_wire,
    parse_reply,
    pose_from_wire,
    pose_to_wire,
)
from hexatherm.devices.urls import controller_from_url
from hexatherm.errors import (
    ControllerConnectionError,
    ControllerError,
    ControllerReplyError,
    ControllerTimeoutError,
    PoseRefusedError,
)

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "symetrie-like.yaml"
POSE = np.array([1.2, -2.5, 3.0, 0.4, -0.3, 1.5])
OUT_OF_STROKE = np.array([0.0, 0.0, 80.0, 0.0, 0.0, 0.0])  # legs far beyond 310 mm
NOISE_UM, NOISE_URAD = 0.05, 0.2
FAST = InPositionCriteria(settle_s=1.0, poll_s=0.5, timeout_s=60.0)
SIMULATORS: dict[str, type[SimulatedController]] = {
    "symetrie": SymetrieSimulator,
    "pi": PISimulator,
}


def make_hexapod(convention: str = "symetrie") -> Hexapod:
    data = yaml.safe_load(CONFIG.read_text())
    return Hexapod(
        name=data["name"],
        convention=convention,  # type: ignore[arg-type]
        base_joints_mm=np.array(data["base_joints"], dtype=float),
        platform_joints_mm=np.array(data["platform_joints"], dtype=float),
        stroke_mm=np.array(data["stroke"], dtype=float),
    )


def temperatures(t_s: float) -> list[float]:
    return [20.0 + 1e-3 * t_s, 21.5, 22.25]


class Rig:
    """A simulator and a connected driver on one ManualClock."""

    def __init__(
        self,
        dialect: str,
        convention: str | None = None,
        *,
        with_geometry: bool = False,
        **model_kwargs: Any,
    ) -> None:
        convention = dialect if convention is None else convention
        self.hexapod = make_hexapod(convention)
        self.clock = ManualClock(1000.0)
        kwargs: dict[str, Any] = {
            "noise_um": NOISE_UM,
            "noise_urad": NOISE_URAD,
            "seed": 7,
            "temperatures_C": temperatures,
        }
        kwargs.update(model_kwargs)
        self.model = SimulatedHexapod(self.hexapod, clock=self.clock, **kwargs)
        self.sim = SIMULATORS[dialect](self.model)
        self.lines: list[tuple[str, str]] = []
        self.driver = controller_from_url(
            self.sim.url,
            hexapod=self.hexapod if with_geometry else None,
            convention=convention,
            clock=self.clock,
            sleep=self.clock.sleep,
            log=lambda d, line: self.lines.append((d, line)),
        )
        self.driver.connect()

    def moves_sent(self) -> list[str]:
        return [c for c in self.sim.received if c.upper().startswith(("MOVE#ABS", "MOV "))]

    def close(self) -> None:
        self.driver.close()
        self.sim.close()


@pytest.fixture
def rig_factory() -> Iterator[Callable[..., Rig]]:
    rigs: list[Rig] = []

    def make(dialect: str, convention: str | None = None, **kwargs: Any) -> Rig:
        rig = Rig(dialect, convention, **kwargs)
        rigs.append(rig)
        return rig

    yield make
    for rig in rigs:
        rig.close()


def scipy_rotation(pose: np.ndarray, convention: str) -> np.ndarray:
    """The rotation matrix of a pose by scipy (docs/method.md: symetrie 'xyz', pi 'XYZ')."""
    seq = "xyz" if convention == "symetrie" else "XYZ"
    return Rotation.from_euler(seq, pose[3:], degrees=True).as_matrix()


# --------------------------------------------------------------- the protocol
@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_connect_and_state(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect)
    assert isinstance(rig.driver, HexapodController)
    key = "api_version" if dialect == "symetrie" else "identification"
    assert "hexatherm" in rig.driver.info[key]
    state = rig.driver.state()
    assert state.in_position and not state.moving and not state.error and state.ready


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_move_reaches_the_commanded_pose(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect)
    rig.driver.validate(POSE)
    assert rig.moves_sent() == [] and rig.model.moves == 0  # validation never moves
    rig.driver.move_absolute(POSE)
    record = rig.driver.wait_in_position(FAST)
    # the simulator's truth: the platform is at the commanded pose
    np.testing.assert_allclose(rig.model.true_pose(), POSE, atol=1e-9)
    # read-back equal within the noise (5 sigma of a mean of 3)
    assert record.readings_pose_mm_deg.shape == (FAST.n_readings, 6)
    dev = pose_deviation_um_urad(record.pose_mm_deg, POSE)
    assert np.all(np.abs(dev[:3]) < 5 * NOISE_UM) and np.all(np.abs(dev[3:]) < 5 * NOISE_URAD)
    np.testing.assert_allclose(record.deviation_um_urad, dev, atol=1e-9)
    assert np.all(record.spread_um_urad[:3] <= FAST.tolerance_um)
    # actuator lengths are the IGM of the pose (the test's own hexapod model)
    np.testing.assert_allclose(record.actuators_mm, make_hexapod(dialect).igm(POSE)[0], atol=1e-9)
    np.testing.assert_allclose(record.temperatures_C, temperatures(record.time_s), atol=1e-12)
    # the flag rose after the motion (3 mm at 1 mm/s) and the simulator's settle
    assert 3.0 + rig.model.settle_s <= record.flag_after_s <= 3.0 + rig.model.settle_s + 0.5
    np.testing.assert_array_equal(record.commanded_pose_mm_deg, POSE)
    assert record.convention == dialect


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_refused_pose_gives_a_clear_error_and_no_move(
    rig_factory: Callable[..., Rig], dialect: str
) -> None:
    rig = rig_factory(dialect)
    with pytest.raises(PoseRefusedError, match="refuses pose .*80.0000"):
        rig.driver.validate(OUT_OF_STROKE)
    with pytest.raises(PoseRefusedError, match="stroke|not allowed"):
        rig.driver.move_absolute(OUT_OF_STROKE)
    assert rig.moves_sent() == [] and rig.model.moves == 0
    np.testing.assert_allclose(rig.model.true_pose(), 0.0, atol=1e-12)
    with pytest.raises(ControllerError, match="without a move_absolute"):
        rig.driver.wait_in_position(FAST)


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_a_user_limit_refuses_a_pose_within_stroke(
    rig_factory: Callable[..., Rig], dialect: str
) -> None:
    rig = rig_factory(dialect)
    rig.sim.faults.refuse = lambda pose: bool(pose[2] > 2.0)
    with pytest.raises(PoseRefusedError, match="user workspace|not allowed"):
        rig.driver.move_absolute(POSE)
    assert rig.moves_sent() == []
    rig.driver.move_absolute(POSE * [1, 1, 0.5, 1, 1, 1])  # Tz = 1.5 mm passes
    assert len(rig.moves_sent()) == 1


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_geometry_checks_the_stroke_before_asking(
    rig_factory: Callable[..., Rig], dialect: str
) -> None:
    rig = rig_factory(dialect, with_geometry=True)
    with pytest.raises(PoseRefusedError, match=r"before asking.*leg 1 would be 3\d\d\.\d{4} mm"):
        rig.driver.validate(OUT_OF_STROKE)
    assert not any(c.upper().startswith(("VALID", "VMO")) for c in rig.sim.received)


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_both_conventions(rig_factory: Callable[..., Rig], dialect: str, convention: str) -> None:
    """The interface's convention may differ from the wire's: the rotation is the same."""
    pose = np.array([0.5, 1.0, -1.0, 2.0, -1.5, 3.0])  # large angles: conventions differ
    rig = rig_factory(dialect, convention, noise_um=0.0, noise_urad=0.0)
    rig.driver.move_absolute(pose)
    record = rig.driver.wait_in_position(FAST)
    # a PI controller answers 6 fixed decimals (1 nm, 1 udeg): that is its resolution
    atol = 1e-9 if dialect == "symetrie" else 1e-6
    np.testing.assert_allclose(record.pose_mm_deg, pose, atol=atol)
    np.testing.assert_allclose(record.actuators_mm, rig.hexapod.igm(pose)[0], atol=atol)
    # the numbers on the wire are the pose in the dialect's convention (scipy as truth)
    move = rig.moves_sent()[0]
    if dialect == "symetrie":
        wire = pose_from_wire([float(v) for v in move.removeprefix("MOVE#ABS").split(",")])
    else:
        wire = np.array([float(v) for v in move.split()[2::2]])
    np.testing.assert_allclose(wire[:3], pose[:3], atol=1e-9)
    np.testing.assert_allclose(
        scipy_rotation(wire, dialect), scipy_rotation(pose, convention), atol=1e-11
    )
    if dialect != convention:
        assert np.abs(wire[3:] - pose[3:]).max() > 1e-3  # a real conversion happened


# ------------------------------------------------------------------- units
def test_symetrie_units_round_trip() -> None:
    np.testing.assert_allclose(
        pose_to_wire([1000.0, -1.0, 0.5, 180.0, -90.0, 1.0]),
        [1.0, -0.001, 0.0005, np.pi, -np.pi / 2, np.pi / 180],
        rtol=1e-15,
    )
    poses = np.random.default_rng(1).uniform(-50, 50, (200, 6))
    np.testing.assert_allclose(pose_from_wire(pose_to_wire(poses)), poses, atol=1e-12)
    for pose in poses[:20]:
        text = format_wire(pose_to_wire(pose))
        back = pose_from_wire([float(v) for v in text.split(",")])
        assert np.abs(back - pose)[:3].max() < 1e-9  # mm: 12 decimals of m
        assert np.abs(back - pose)[3:].max() < 1e-9  # deg: 12 decimals of rad


def test_pi_axes_round_trip() -> None:
    pose = np.array([1.234567891, -0.5, 12.0, 0.001, -3.5, 179.25])
    tokens = format_axes(pose).split()
    assert tokens[::2] == ["X", "Y", "Z", "U", "V", "W"]
    np.testing.assert_allclose([float(v) for v in tokens[1::2]], pose, atol=5e-10)


# ----------------------------------------------------------------- faults
@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_late_in_position_flag(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect)
    rig.sim.faults.late_in_position_s = 20.0
    rig.driver.move_absolute(POSE)
    record = rig.driver.wait_in_position(FAST)
    assert record.flag_after_s >= 3.0 + rig.model.settle_s + 20.0
    np.testing.assert_allclose(rig.model.true_pose(), POSE, atol=1e-9)
    rig.driver.move_absolute(POSE * 0.5)
    short = InPositionCriteria(settle_s=1.0, poll_s=0.5, timeout_s=10.0)
    with pytest.raises(ControllerTimeoutError, match="no in-position flag within 10 s"):
        rig.driver.wait_in_position(short)


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_dropped_connection_mid_move(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect)
    rig.sim.faults.drop_mid_move = True
    rig.driver.move_absolute(POSE)
    with pytest.raises(ControllerConnectionError, match="closed the connection|lost"):
        rig.driver.wait_in_position(FAST)
    assert not rig.driver.connected
    rig.clock.sleep(1.0)
    assert rig.model.moving()
    rig.driver.stop()  # reconnects to deliver the stop
    assert rig.sim.connections == 2 and not rig.model.moving()
    stopped = rig.model.true_pose()
    assert 0 < stopped[0] < POSE[0]  # stopped on the way
    np.testing.assert_allclose(rig.driver.read_pose(), stopped, atol=2e-4)  # the noise


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_lines_split_across_writes(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect)
    rig.sim.faults.split_writes = True
    rig.driver.move_absolute(POSE * 0.1)
    record = rig.driver.wait_in_position(InPositionCriteria(settle_s=1.0, poll_s=2.0))
    np.testing.assert_allclose(record.pose_mm_deg, POSE * 0.1, atol=1e-3)
    assert np.isfinite(record.actuators_mm).all() and record.temperatures_C.size == 3


def test_line_buffer_is_independent_of_chunking() -> None:
    stream = b"STA#HEXAPOD:2,50,0.001,-2e-3\r\nX=1.5 \nY=2\nMOVE#ABS:1\r\n\r\nSTOP:2\npart"
    whole = LineBuffer().feed(stream)
    buffer = LineBuffer()
    bytewise = [line for i in range(len(stream)) for line in buffer.feed(stream[i : i + 1])]
    assert (
        whole
        == bytewise
        == [
            "STA#HEXAPOD:2,50,0.001,-2e-3",
            "X=1.5 ",
            "Y=2",
            "MOVE#ABS:1",
            "",
            "STOP:2",
        ]
    )
    assert buffer.pending == b"part"


@pytest.mark.parametrize(
    ("dialect", "code", "error", "match"),
    [
        ("symetrie", -104, PoseRefusedError, r"outside the workspace \(user frame\) \(-104\)"),
        ("symetrie", -67, ControllerReplyError, r"not allowed in the current state \(-67\)"),
        ("pi", 7, PoseRefusedError, r"position out of limits \(7\)"),
        ("pi", 5, ControllerReplyError, r"servo off \(5\)"),
    ],
)
def test_error_codes_are_decoded_and_nothing_moves(
    rig_factory: Callable[..., Rig],
    dialect: str,
    code: int,
    error: type[Exception],
    match: str,
) -> None:
    rig = rig_factory(dialect)
    rig.sim.faults.errors["MOVE#ABS" if dialect == "symetrie" else "MOV"] = [code]
    with pytest.raises(error, match=match):
        rig.driver.move_absolute(POSE)
    assert rig.model.moves == 0 and rig.driver.commanded_pose_mm_deg is None
    rig.driver.move_absolute(POSE)  # the next move goes through
    assert rig.model.moves == 1


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_unstable_read_back_times_out(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect, noise_um=5.0)
    rig.driver.move_absolute(POSE)
    short = InPositionCriteria(settle_s=1.0, poll_s=0.5, timeout_s=15.0)
    with pytest.raises(ControllerTimeoutError, match=r"did not settle .* spread \d+\.\d+ um"):
        rig.driver.wait_in_position(short)


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_missing_optional_readings(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect, temperatures_C=None, report_actuators=False)
    assert rig.driver.read_temperatures().shape == (0,)
    if dialect == "pi":
        assert np.isnan(rig.driver.read_actuators()).all()
    else:
        with pytest.raises(ControllerReplyError, match="unknown command"):
            rig.driver.read_actuators()
    assert rig.driver.state().in_position  # the exchange is still in step


# ------------------------------------------------------------------ stop
@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_stop_is_safe_at_any_time(rig_factory: Callable[..., Rig], dialect: str) -> None:
    rig = rig_factory(dialect)
    rig.driver.stop()  # nothing moving
    rig.driver.move_absolute(POSE)
    rig.clock.sleep(1.5)
    rig.driver.stop()  # mid-move
    assert not rig.model.moving()
    here = rig.model.true_pose()
    np.testing.assert_allclose(here, POSE * 0.5, atol=1e-9)  # 1.5 s of a 3 s move
    with pytest.raises(ControllerError, match="without a move_absolute"):
        rig.driver.wait_in_position(FAST)  # a stop forgets the command
    rig.driver.close()
    rig.driver.stop()  # after close: reconnects
    assert rig.sim.connections == 2
    port = rig.sim.port
    rig.sim.close()
    rig.driver.close()
    with pytest.raises(ControllerConnectionError, match="MAY STILL BE MOVING"):
        rig.driver.stop()
    with pytest.raises(ControllerConnectionError, match=f"127.0.0.1:{port}"):
        rig.driver.connect()


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_stop_after_an_interrupted_transaction(
    rig_factory: Callable[..., Rig], dialect: str
) -> None:
    """Ctrl-C between a query and its reply: the stop skips the stale reply."""
    rig = rig_factory(dialect)
    rig.driver.move_absolute(POSE)
    rig.clock.sleep(1.0)
    rig.driver._send("STA#HEXAPOD?" if dialect == "symetrie" else "POS?")  # never read
    rig.driver.stop()
    assert not rig.model.moving()
    np.testing.assert_allclose(rig.driver.read_pose(), POSE / 3, atol=2e-4)  # in step


@pytest.mark.parametrize("dialect", ["symetrie", "pi"])
def test_simulator_going_away_drops_the_connection(
    rig_factory: Callable[..., Rig], dialect: str
) -> None:
    rig = rig_factory(dialect)
    rig.sim.close()
    with pytest.raises(ControllerConnectionError):
        rig.driver.read_pose()
    assert not rig.driver.connected


# ----------------------------------------------------- hand-written replies
class ScriptedServer:
    """One connection to a server that answers every line by ``script(line)``."""

    def __init__(self, greeting: list[str], script: Callable[[str], list[str]]) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.greeting, self.script = greeting, script
        self.thread = threading.Thread(target=self.serve, daemon=True)
        self.thread.start()

    def serve(self) -> None:
        conn, _ = self.listener.accept()
        buffer = LineBuffer()
        with conn:
            conn.sendall("".join(g + "\r\n" for g in self.greeting).encode())
            while data := conn.recv(4096):
                for line in buffer.feed(data):
                    reply = self.script(line.strip())
                    conn.sendall("".join(r + "\r\n" for r in reply).encode())

    def close(self) -> None:
        self.listener.close()


GREETING = ["SYMETRIE controller", "API version: 2.7.1", "Project: lab", "Waiting for commands..."]
CS = "CFG#CS:2,3," + ",".join(["0"] * 12)  # the CS asked, then the two frames


def status_line(bits: int, pose_m_rad: list[float]) -> str:
    values = [str(bits)] + [repr(v) for v in pose_m_rad] * 2
    return "STA#HEXAPOD:2," + ",".join(values)


@pytest.fixture
def scripted() -> Iterator[Callable[..., SymetrieController]]:
    servers: list[ScriptedServer] = []
    drivers: list[SocketController] = []

    def make(script: Callable[[str], list[str]], **kwargs: Any) -> SymetrieController:
        server = ScriptedServer(GREETING, script)
        servers.append(server)
        clock = ManualClock()
        driver = SymetrieController(
            "127.0.0.1", server.port, clock=clock, sleep=clock.sleep, **kwargs
        )
        drivers.append(driver)
        driver.connect()
        return driver

    yield make
    for d in drivers:
        d.close()
    for s in servers:
        s.close()


def test_symetrie_replies_from_hand_written_lines(
    scripted: Callable[..., SymetrieController],
) -> None:
    """MOVE#ABS:2 arriving only at the motion's end (mixed into the status replies)."""
    target = [0.001, 0.0, -0.0005, 0.0, 0.0, 0.0]
    polls = {"n": 0}

    def script(line: str) -> list[str]:
        if line.startswith("CFG#CS?"):
            return ["CFG#CS:1", CS]
        if line.startswith("VALID#PTP?"):
            return ["VALID#PTP:2,0"]
        if line.startswith("MOVE#ABS"):
            return ["MOVE#ABS:1"]  # accepted; done comes later
        if line == "STA#HEXAPOD?":
            polls["n"] += 1
            if polls["n"] == 1:
                return [status_line(0b100010, [0.0005, 0, -0.00025, 0, 0, 0])]  # moving
            return (["MOVE#ABS:2"] if polls["n"] == 2 else []) + [
                status_line(0b010010, target)  # in position
            ]
        if line == "STA#AXES?":
            return ["STA#AXES:2,6," + ",".join(["0"] * 6) + ",0.25,0.26,0.27,0.28,0.29,0.3"]
        if line == "STA#TEMP?":
            return ["STA#TEMP:-23"]
        return [f"{line.rstrip('?')}:-6"]

    driver = scripted(script)
    assert driver.info["api_version"] == "2.7.1" and driver.info["project"] == "lab"
    driver.move_absolute([1.0, 0.0, -0.5, 0.0, 0.0, 0.0])
    record = driver.wait_in_position(InPositionCriteria(settle_s=0.5, poll_s=0.5))
    np.testing.assert_allclose(record.pose_mm_deg, [1.0, 0.0, -0.5, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(record.actuators_mm, [250, 260, 270, 280, 290, 300], atol=1e-9)
    assert record.temperatures_C.shape == (0,)


def test_symetrie_late_error_and_error_flag(scripted: Callable[..., SymetrieController]) -> None:
    replies = iter(
        [
            ["MOVE#ABS:-81", status_line(0b100010, [0.0] * 6)],  # a late failure of the move
            [status_line(0b000011, [0.0] * 6)],  # error bit
        ]
    )

    def script(line: str) -> list[str]:
        if line.startswith("CFG#CS?"):
            return [CS]
        if line.startswith("VALID#PTP?"):
            return ["VALID#PTP:1", "VALID#PTP:2,5"]
        if line == "STA#HEXAPOD?":
            return next(replies)
        return ["garbage without a code"]

    driver = scripted(script)
    with pytest.raises(PoseRefusedError, match="machine workspace limits, an actuator outside"):
        driver.validate([0.0] * 6)
    state = driver.state()
    assert state.error and "MOVE#ABS failed: in-position timeout (-81)" in state.message
    state = driver.state()
    assert state.error and state.message == "error, system ready"
    with pytest.raises(ControllerError, match="malformed reply .*'garbage without a code'"):
        driver.read_actuators()


def test_symetrie_without_validation_needs_the_geometry(
    scripted: Callable[..., SymetrieController],
) -> None:
    def script(line: str) -> list[str]:
        if line.startswith("CFG#CS?"):
            return [CS]
        if line.startswith("MOVE#ABS"):
            return ["MOVE#ABS:1", "MOVE#ABS:2"]
        return [f"{line.split('?')[0]}:-310"]  # no such command

    blind = scripted(script)
    with pytest.raises(ControllerError, match="cannot validate poses .* no hexapod geometry"):
        blind.move_absolute(POSE)
    checked = scripted(script, hexapod=make_hexapod())
    checked.move_absolute(POSE)  # the stroke check of the geometry is the validation
    assert "stroke of the hexapod geometry" in checked.info["validation"]
    with pytest.raises(PoseRefusedError, match="leg"):
        checked.move_absolute(OUT_OF_STROKE)


def test_silent_controller_times_out() -> None:
    server = ScriptedServer(GREETING, lambda line: [])
    driver = SymetrieController("127.0.0.1", server.port, reply_timeout_s=0.2)
    try:
        with pytest.raises(ControllerTimeoutError, match=r"no reply .* to 'CFG#CS\?' within 0.2 s"):
            driver.connect()
        assert not driver.connected
    finally:
        server.close()


def test_wire_parsing_of_hand_written_lines() -> None:
    assert parse_reply("STA#HEXAPOD:2,48,1e-3,-2.5E-4,0,0,0,0,0,0,0,0,0,0") == (
        "STA#HEXAPOD",
        2,
        "48,1e-3,-2.5E-4,0,0,0,0,0,0,0,0,0,0",
    )
    assert parse_reply(" MOVE#ABS:-1126 ") == ("MOVE#ABS", -1126, None)
    assert parse_reply("CFG#SAVE:1") == ("CFG#SAVE", 1, None)
    assert describe_status(0b110011) == "error, system ready, in position, moving"
    assert parse_answer(["X=1.0 ", "Y=-2.5e-3 ", "W=180"]) == {
        "X": "1.0",
        "Y": "-2.5e-3",
        "W": "180",
    }
    assert parse_error([" -1024 "]) == -1024
    with pytest.raises(ControllerError, match="malformed ERR"):
        parse_error(["X=1"])


# ---------------------------------------------------------------- URLs
def test_controller_from_url() -> None:
    s = controller_from_url("symetrie://hexa.lab")
    assert isinstance(s, SymetrieController) and (s.host, s.port) == ("hexa.lab", 61559)
    p = controller_from_url("PI://10.0.0.7:50001", hexapod=make_hexapod("pi"))
    assert isinstance(p, PIController) and (p.port, p.convention) == (50001, "pi")
    assert controller_from_url("pi://[::1]:5000").host == "::1"
    for bad, match in [
        ("http://hexa", "unknown controller URL scheme 'http'"),
        ("symetrie://", "no host"),
        ("pi://hexa:99999", "bad port"),
        ("pi://hexa:50000/x", "SCHEME://HOST"),
    ]:
        with pytest.raises(ControllerError, match=match):
            controller_from_url(bad)
    with pytest.raises(ValueError, match="must agree"):
        controller_from_url("pi://hexa", hexapod=make_hexapod("symetrie"), convention="pi")


def test_criteria_are_checked() -> None:
    with pytest.raises(ValueError, match="n_readings"):
        InPositionCriteria(n_readings=0)
    with pytest.raises(ValueError, match="poll_s"):
        InPositionCriteria(poll_s=0.0)
    with pytest.raises(ValueError, match="tolerance_um"):
        InPositionCriteria(tolerance_um=-1.0)


def test_symetrie_speaks_api_v2_as_bliss_parses_it(
    scripted: Callable[..., SymetrieController],
) -> None:
    """CFG#CS? takes the CS (3) and answers it first; an unknown STA# query (-23) is no
    end of the run; the status word is an integer (what BLISS's client sends and parses)."""
    word = {"text": "18"}  # ready, in position

    def script(line: str) -> list[str]:
        if line.startswith("CFG#CS?"):
            if line != "CFG#CS?3":
                return ["CFG#CS:-9"]  # wrong number of arguments
            return ["CFG#CS:1", "CFG#CS:2,3,0.001,0,0,0,0,0,0,0,0.5,0,0,0.0174532925199"]
        if line == "STA#HEXAPOD?":
            return [f"STA#HEXAPOD:2,{word['text']}," + ",".join(["0"] * 12)]
        if line == "STA#TEMP?":
            return ["STA#TEMP:-23"]  # Panel_UnknownStaCmd
        return [f"{line.split('?')[0]}:-6"]

    driver = scripted(script)
    assert driver.info["user_frame_in_machine"].startswith("[1.0000, 0.0000, 0.0000] mm")
    assert driver.info["object_frame_in_platform"] == (
        "[0.0000, 0.0000, 500.0000] mm, [0.00000, 0.00000, 1.00000] deg"
    )
    assert driver.read_temperatures().shape == (0,)
    assert driver.state().in_position
    word["text"] = "18.0"  # what BLISS's int() refuses
    with pytest.raises(ControllerError, match="malformed status word .*'18.0'"):
        driver.state()
