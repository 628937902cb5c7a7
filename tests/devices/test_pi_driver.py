"""hexatherm's PI driver checks the controller before moving and stops it as PI's own
software does: against the twin's PI controller (:mod:`hexatherm.devices.sim.pi`) in the
states a lab may find it in (servo off, not referenced, busy, a user coordinate system)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pytest

from hexatherm.core.geometry import transform_from_pose
from hexatherm.devices.pi import PIController
from hexatherm.devices.sim.pi import PISimulator, PIStart
from hexatherm.devices.sim.symetrie import ManualClock, SimulatedHexapod
from hexatherm.errors import ControllerError
from tests.devices.test_controllers import make_hexapod


@dataclass
class Setup:
    clock: ManualClock
    model: SimulatedHexapod
    sim: PISimulator
    driver: PIController


@contextmanager
def setup(start: PIStart | None = None) -> Iterator[Setup]:
    clock = ManualClock(1000.0)
    model = SimulatedHexapod(make_hexapod("pi"), clock=clock)
    with PISimulator(model, start=start) as sim:
        driver = PIController(sim.host, sim.port, clock=clock, sleep=clock.sleep)
        driver.connect()
        try:
            yield Setup(clock, model, sim, driver)
        finally:
            driver.close()


def test_identification_fields_and_a_ready_controller() -> None:
    with setup() as s:
        info = s.driver.info
        assert (info["manufacturer"], info["model"], info["serial"]) == (
            "hexatherm twin",
            "C-887",
            "0",
        )
        s.driver.check_ready()
        assert s.driver.readiness == {
            "servo": "yes (SVO? X=1 Y=1 Z=1 U=1 V=1 W=1)",
            "referenced": "yes (FRF? X=1 Y=1 Z=1 U=1 V=1 W=1)",
            "ready": "yes (#7 0xB1)",
            "coordinate_system": "ZERO=ZERO",
            "pivot_point": "R=0.000000 S=0.000000 T=0.000000",
        }
        assert {"SVO?", "FRF?", "#7", "KEN?", "SPI?"} <= set(s.sim.received)
        assert s.sim.error_code == 0 and s.model.moves == 0


@pytest.mark.parametrize(
    ("start", "key", "state", "message"),
    [
        (PIStart(servo_on=False), "servo", "no (SVO? X=0", r"servo off on X Y Z U V W: .*SVO"),
        (PIStart(referenced=False), "referenced", "no (FRF? X=0", r"not referenced on X Y .*FRF"),
        (PIStart(busy=True), "ready", "no (#7 0xB0)", r"busy \(#7 answers 0xB0"),
        (
            PIStart(coordinate_system="TOOL1"),
            "coordinate_system",
            "TOOL1=KSD",
            r"coordinate system TOOL1 enabled .*enable ZERO first",
        ),
        (
            PIStart(pivot=(0.0, 0.0, 100.0)),
            "pivot_point",
            "R=0.000000 S=0.000000 T=100.000000",
            r"pivot point R=0.000000 S=0.000000 T=100.000000 mm \(SPI\?\).*SPI R 0 S 0 T 0",
        ),
    ],
)
def test_a_controller_not_ready_is_refused_and_recorded(
    start: PIStart, key: str, state: str, message: str
) -> None:
    with setup(start) as s:
        with pytest.raises(ControllerError, match=message + r".*Nothing was moved"):
            s.driver.check_ready()
        assert s.driver.readiness[key].startswith(state)
        assert len(s.driver.readiness) == 5  # every state found is recorded
        assert s.model.moves == 0 and not any(c.startswith("MOV") for c in s.sim.received)


def test_all_problems_are_named_at_once() -> None:
    with setup(PIStart(servo_on=False, referenced=False, coordinate_system="A1")) as s:
        with pytest.raises(ControllerError, match=r"servo off .*; not referenced .*; coordinate"):
            s.driver.check_ready()


def test_a_controller_without_ready_byte_or_coordinate_systems() -> None:
    """An older GCS controller that knows neither #7 nor KEN? (error 2): unknown, not
    refused; the error is read and cleared."""
    with setup() as s:
        s.sim.faults.errors.update({"#7": [2], "KEN?": [2]})
        s.driver.check_ready()
        assert s.driver.readiness["ready"] == "unknown (#7 not known)"
        assert s.driver.readiness["coordinate_system"] == "unknown (KEN? not known)"
        assert s.sim.error_code == 0


def test_stop_sends_stop_all_then_stp() -> None:
    with setup() as s:
        s.driver.move_absolute(np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0]))
        s.clock.sleep(1.0)
        assert s.model.moving()
        s.driver.stop()
        assert not s.model.moving()
        tail = s.sim.received[-3:]
        assert tail == ["#24", "STP", "ERR?"], tail
        assert "error_at_stop" not in s.driver.info and s.sim.error_code == 0
        np.testing.assert_allclose(s.model.true_pose()[2], 1.0, atol=1e-12)  # 1 mm/s, 1 s


def test_the_twins_pivot_point_is_what_u_v_w_rotate_about() -> None:
    """Truth: the platform's point at the pivot goes where the translation alone takes it,
    whatever the rotation (C-887, SPI); with the pivot at zero the pose is the wire's."""
    pivot = np.array([10.0, -20.0, 100.0])
    wire = np.array([1.0, 2.0, -3.0, 2.0, -1.5, 3.0])
    with setup(PIStart(pivot=tuple(pivot))) as s:
        s.sim.respond("MOV " + " ".join(f"{a} {v}" for a, v in zip("XYZUVW", wire, strict=True)))
        assert s.sim.error_code == 0
        frame = transform_from_pose(s.model.target, s.model.convention)
        np.testing.assert_allclose(
            frame[:3, :3] @ pivot + frame[:3, 3], pivot + wire[:3], atol=1e-9
        )
        # the wire reads back what was commanded (the inverse composition)
        read = [float(x.split("=")[1]) for x in s.sim.respond("MOV?")]
        np.testing.assert_allclose(read, wire, atol=1e-6)
        s.sim.respond("SPI R 0 S 0 T 0")
        assert s.sim.respond("SPI?") == ["R=0.000000 ", "S=0.000000 ", "T=0.000000"]
        s.driver.check_ready()
        assert s.driver.readiness["pivot_point"] == "R=0.000000 S=0.000000 T=0.000000"
