"""hexatherm's PI driver checks the controller before moving and stops it as PI's own
software does: against the twin's PI controller (:mod:`hexatherm.devices.pisim`) in the
states a lab may find it in (servo off, not referenced, busy, a user coordinate system)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import pytest

from hexatherm.devices.controllersim import ManualClock, SimulatedHexapod
from hexatherm.devices.pi import PIController
from hexatherm.devices.pisim import PISimulator, PIStart
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
        }
        assert {"SVO?", "FRF?", "#7", "KEN?"} <= set(s.sim.received)
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
    ],
)
def test_a_controller_not_ready_is_refused_and_recorded(
    start: PIStart, key: str, state: str, message: str
) -> None:
    with setup(start) as s:
        with pytest.raises(ControllerError, match=message + r".*Nothing was moved"):
            s.driver.check_ready()
        assert s.driver.readiness[key].startswith(state)
        assert len(s.driver.readiness) == 4  # every state found is recorded
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
