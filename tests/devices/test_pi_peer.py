"""The twin's PI controller driven by PI's own Python library, ``pipython``.

``pipython`` (PyPI, "Other/Proprietary License": a test dependency only, see
docs/design.md) is what a PI user scripts a C-887 with: its pure-Python ``PISocket``,
``GCSMessages`` and ``GCSCommands``, and the ``pitools`` helpers. These tests send a PI
user's first commands to :class:`~hexatherm.devices.sim.pi.PISimulator` (in process, on a
ManualClock, and once through ``hexatherm serve-twin --dialect pi``) and check every
answer against the twin's truth: the simulated hexapod's pose, stroke and speeds.
"""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pipython import GCSError, pitools
from pipython.pidevice.gcscommands import GCSCommands
from pipython.pidevice.gcsmessages import GCSMessages
from pipython.pidevice.interfaces.pisocket import PISocket

from hexatherm.devices.pi import AXES
from hexatherm.devices.sim.pi import PISimulator, PIStart
from hexatherm.devices.sim.symetrie import ManualClock, SimulatedHexapod
from tests.devices.test_controllers import make_hexapod

ROOT = Path(__file__).resolve().parents[2]
POSE = np.array([1.2, -2.5, 3.0, 0.4, -0.3, 1.5])  # X Y Z mm, U V W deg (pi convention)


@dataclass
class Peer:
    """A simulated PI controller on a ManualClock and pipython connected to it."""

    clock: ManualClock
    model: SimulatedHexapod
    sim: PISimulator
    device: Any  # pipython's GCSCommands (untyped)

    def truth(self) -> np.ndarray:
        """The platform's pose now (no noise), pi convention."""
        return self.model.true_pose()

    def settle(self) -> None:
        """Let simulated time pass until the move and the settle are over."""
        while not self.model.in_position():
            self.clock.sleep(1.0)


@contextmanager
def pipython_on(host: str, port: int) -> Iterator[Any]:
    with PISocket(host, port) as gateway:
        messages = GCSMessages(gateway)
        messages.timeout = 120_000  # ms: a loaded machine, not a timed assertion
        with GCSCommands(messages) as device:
            yield device


@contextmanager
def peer(start: PIStart | None = None) -> Iterator[Peer]:
    clock = ManualClock(1000.0)
    model = SimulatedHexapod(make_hexapod("pi"), clock=clock, speed_mm_s=2.0, speed_deg_s=1.0)
    with PISimulator(model, start=start) as sim, pipython_on(sim.host, sim.port) as device:
        yield Peer(clock, model, sim, device)


def test_identification_devname_and_help() -> None:
    with peer() as p:
        idn = p.device.qIDN()
        fields = [f.strip() for f in idn.split(",")]
        assert len(fields) == 4 and fields[1] == "C-887", idn
        assert p.device.devname == "C-887"  # pipython's own parsing of *IDN?
        assert p.device.qCSV() == 2.0 and p.device.isgcs2
        assert p.device.qSAI() == list(AXES) and p.device.qSAI_ALL() == list(AXES)
        funcs = set(p.device.funcs)  # parsed from HLP? by pipython
        wanted = {"qPOS", "MOV", "qMOV", "qONT", "SVO", "qSVO", "FRF", "qFRF", "qTMN", "qTMX"}
        wanted |= {"VLS", "qVLS", "HLT", "STP", "KEN", "qKEN", "KSD", "qKET", "qVEL", "qHLP"}
        wanted |= {"IsMoving", "IsControllerReady", "StopAll", "qIDN", "qCSV", "qSAI"}
        assert wanted <= funcs, wanted - funcs
        assert p.device.qERR() == 0


def test_positions_answer_the_axes_asked_in_fixed_decimals() -> None:
    with peer() as p:
        p.model.start_move(POSE)
        p.settle()
        truth = np.round(p.truth(), 6)
        assert p.device.qPOS("Z") == {"Z": truth[2]}
        assert list(p.device.qPOS(["W", "X"]).items()) == [("W", truth[5]), ("X", truth[0])]
        assert list(p.device.qPOS().values()) == truth.tolist()
        for k, axis in enumerate(AXES):  # one axis at a time, as a PI user's script does
            assert p.device.qPOS(axis)[axis] == truth[k]
            assert p.device.qMOV(axis)[axis] == round(POSE[k], 6)
        raw = p.device.messages.read("POS? X")
        assert re.fullmatch(r"X=-?\d+\.\d{6}\n", raw), raw
        with pytest.raises(GCSError) as err:  # no answer, error 15 (invalid axis)
            p.device.messages.send("POS? Q")  # then ERR?, as pipython's send does
        assert err.value.val == 15
        assert p.device.qERR() == 0  # read and cleared by pipython's error check


def test_move_wait_on_target_and_motion_status() -> None:
    with peer() as p:
        assert p.device.qSVO() == dict.fromkeys(AXES, True)
        assert p.device.qFRF() == dict.fromkeys(AXES, True)
        assert p.device.IsControllerReady() is True
        p.device.MOV(list(AXES), POSE.tolist())
        assert p.device.IsMoving() == dict.fromkeys(AXES, True)
        assert p.device.qONT() == dict.fromkeys(AXES, False)
        assert p.device.qMOV() == dict(zip(AXES, POSE.tolist(), strict=True))
        p.settle()
        pitools.waitontarget(p.device, timeout=300)  # PI's helper: #7, SVO?, ONT?
        assert p.device.IsMoving() == dict.fromkeys(AXES, False)
        np.testing.assert_allclose(list(p.device.qPOS().values()), POSE, atol=5e-7)
        np.testing.assert_allclose(p.truth(), POSE, atol=1e-12)


def test_stop_all_is_one_byte_that_does_not_stick_to_the_next_command() -> None:
    with peer() as p:
        p.device.MOV("Z", 5.0)
        p.clock.sleep(1.0)  # 2 mm of 5 done
        p.device.StopAll(noraise=True)  # chr(24) then ERR? on the same write
        assert not p.model.moving()
        np.testing.assert_allclose(p.truth()[2], 2.0, atol=1e-12)
        assert "#24" in p.sim.received and "ERR?" in p.sim.received
        assert not any("\x18" in line for line in p.sim.received)
        p.device.MOV("Z", 3.0)
        with pytest.raises(GCSError) as err:
            p.device.StopAll()
        assert err.value.val == 10  # stopped by command
        pitools.stopall(p.device)  # PI's helper: #24, then #7 until ready
        for name in ("STP", "HLT"):
            p.device.MOV("X", 1.0)
            getattr(p.device, name)(noraise=True)
            assert not p.model.moving()
        assert p.device.qERR() == 0


def test_servo_referencing_and_readiness() -> None:
    with peer(PIStart(servo_on=False, referenced=False)) as p:
        p.model.start_move(POSE)  # where the platform was left
        p.settle()
        assert p.device.qSVO() == dict.fromkeys(AXES, False)
        assert p.device.qFRF("Y") == {"Y": False}
        with pytest.raises(GCSError) as err:
            p.device.MOV("X", 1.0)
        assert err.value.val == 5 and p.model.moves == 1
        with pytest.raises(GCSError) as err:
            p.device.FRF()
        assert err.value.val == 5
        p.device.SVO("X", True)  # a hexapod's axes are coupled: all six
        assert pitools.getservo(p.device, None) == dict.fromkeys(AXES, True)
        p.device.FRF()
        assert p.device.IsControllerReady() is False and p.device.qFRF("X") == {"X": False}
        p.settle()
        pitools.waitonreferencing(p.device, timeout=300)
        assert p.device.IsControllerReady() is True
        assert p.device.qFRF() == dict.fromkeys(AXES, True)
        np.testing.assert_allclose(p.truth(), 0.0, atol=1e-12)  # the reference pose
        p.device.MOV("X", 1.0)
        p.settle()
        assert p.truth()[0] == 1.0


def test_travel_range_and_velocities_are_the_twins() -> None:
    with peer() as p:
        low, high = p.device.qTMN(), p.device.qTMX()
        hexapod = p.model.hexapod
        for k, axis in enumerate(AXES):
            assert low[axis] < 0 < high[axis]
            for value, inside in ((high[axis], True), (low[axis], True)):
                for scale, ok in ((1.0, inside), (1.0 + 1e-4, False)):
                    pose = np.zeros(6)
                    pose[k] = value * scale
                    assert (not hexapod.check_stroke(hexapod.igm(pose)).any()) == ok, (axis, scale)
        assert p.device.qVLS() == 2.0
        assert p.device.qVEL() == {"X": 2.0, "Y": 2.0, "Z": 2.0, "U": 1.0, "V": 1.0, "W": 1.0}
        p.device.VLS(4.0)
        assert p.device.qVLS() == 4.0 and p.device.qVEL("W") == {"W": 2.0}
        p.device.MOV("X", 2.0)
        p.clock.sleep(0.25)
        np.testing.assert_allclose(p.truth()[0], 1.0, atol=1e-12)  # 4 mm/s


def test_coordinate_systems() -> None:
    with peer() as p:
        assert p.device.qKEN() == {"ZERO": "ZERO"}
        assert p.device.qKET() == {"ZERO": "ZERO"}
        p.device.KSD("SAMPLE", {"Z": 10.0, "X": 1.0})
        p.device.KEN("SAMPLE")
        assert p.device.qKEN() == {"SAMPLE": "KSD"} and p.device.qKET() == {"KSD": "SAMPLE"}
        # poses are now in SAMPLE: Z 0 there is Z 10 of ZERO
        p.device.MOV(["X", "Z"], [0.0, 0.0])
        p.settle()
        np.testing.assert_allclose(p.truth(), [1.0, 0, 10.0, 0, 0, 0], atol=1e-12)
        assert p.device.qPOS("Z") == {"Z": 0.0}
        p.device.KEN("ZERO")
        assert p.device.qPOS("Z") == {"Z": 10.0}
        with pytest.raises(GCSError) as err:
            p.device.KEN("NOSUCH")
        assert err.value.val == 530


def test_user_coordinate_system_at_start() -> None:
    with peer(PIStart(coordinate_system="TOOL1")) as p:
        assert p.device.qKEN() == {"TOOL1": "KSD"}
        assert p.device.qPOS("Z") == {"Z": -10.0}  # the platform is at ZERO's origin


def test_unknown_commands_and_bad_arguments_set_gcs_errors() -> None:
    with peer() as p:
        for command, code in (("FOO", 2), ("MOV X abc", 25), ("MOV X", 24), ("MOV Q 1", 15)):
            with pytest.raises(GCSError) as err:
                p.device.messages.send(command)
            assert err.value.val == code, command
        assert p.model.moves == 0


def test_serve_twin_speaks_to_pipython(tmp_path: Path) -> None:
    """``hexatherm serve-twin --dialect pi`` as a lab runs it, pipython as its client."""
    command = [sys.executable, "-c", "from hexatherm.cli import main; main()", "serve-twin"]
    command += ["--dialect", "pi", "--time-scale", "1000", "--fault", "pi-unreferenced"]
    command += ["--hexapod", str(ROOT / "configs" / "symetrie-like.yaml")]
    command += ["--balls", str(ROOT / "configs" / "balls-3.yaml")]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert proc.stdout is not None
        urls = dict(proc.stdout.readline().strip().split(": ", 1) for _ in range(3))
        host, port = urls["controller"].removeprefix("pi://").rsplit(":", 1)
        with pipython_on(host, int(port)) as device:
            assert device.devname == "C-887"
            assert device.qFRF() == dict.fromkeys(AXES, False)  # --fault pi-unreferenced
            device.FRF()
            pitools.waitonreferencing(device, timeout=300)
            assert device.qFRF() == dict.fromkeys(AXES, True)
            device.MOV(["X", "W"], [0.5, 0.25])
            pitools.waitontarget(device, timeout=300)
            position = device.qPOS(["X", "W"])
            assert abs(position["X"] - 0.5) < 1e-3 and abs(position["W"] - 0.25) < 1e-3
            assert device.qMOV("X") == {"X": 0.5}
            pitools.stopall(device)
            assert device.qERR() == 0
    finally:
        proc.terminate()
        proc.wait()


def test_a_reference_move_ends_with_the_motion_without_polling() -> None:
    """FRF, a plain wait (nothing asked meanwhile), then MOV: accepted, as a C-887 does."""
    with peer(PIStart(referenced=False)) as p:
        p.model.start_move(POSE)
        p.settle()
        p.device.FRF()
        p.settle()  # simulated time passes; neither FRF? nor #7 is asked
        p.device.MOV("X", 1.0)
        p.settle()
        assert p.truth()[0] == 1.0 and p.device.qERR() == 0


def test_relative_moves_soft_limits_and_the_pivot_point() -> None:
    with peer() as p:
        p.device.MOV(["X", "W"], [1.0, 2.0])
        p.settle()
        p.device.MVR(["X", "W"], [0.5, -0.5])
        p.settle()
        np.testing.assert_allclose(p.truth()[[0, 5]], [1.5, 1.5], atol=1e-12)
        assert p.device.qMOV("X") == {"X": 1.5}
        # soft limits: the travel until set; a move beyond one is refused (error 7)
        assert p.device.qNLM("Z") == p.device.qTMN("Z") and p.device.qPLM() == p.device.qTMX()
        p.device.PLM("X", 2.0)
        p.device.NLM("X", -2.0)
        assert p.device.qPLM("X") == {"X": 2.0} and p.device.qNLM("X") == {"X": -2.0}
        for move in (lambda: p.device.MOV("X", 2.5), lambda: p.device.MVR("X", 0.75)):
            with pytest.raises(GCSError) as err:
                move()
            assert err.value.val == 7
        assert p.device.qVMO(["X"], [2.5]) is False
        with pytest.raises(GCSError) as err:
            p.device.PLM("X", 1e6)  # beyond the travel
        assert err.value.val == 17
        p.device.MVR("X", 0.5)
        p.settle()
        assert p.truth()[0] == 2.0
        # the pivot point: U V W rotate about it (C-887, SPI)
        assert p.device.qSPI() == {"R": 0.0, "S": 0.0, "T": 0.0}
        p.device.SPI(["T"], [50.0])
        assert p.device.qSPI("T") == {"T": 50.0}


def test_command_level_versions_and_echo() -> None:
    with peer() as p:
        assert p.device.qCCL() == 0
        with pytest.raises(GCSError) as err:
            p.device.CCL(1, "wrong")
        assert err.value.val == 17
        p.device.CCL(1, "advanced")
        assert p.device.qCCL() == 1
        p.device.CCL(0)
        versions = p.device.qVER()
        assert "C-887" in versions and "PIPython" in versions
        assert p.device.qECO("hello").strip() == "hello"
