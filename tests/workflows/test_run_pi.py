"""``hexatherm run`` against the twin's PI controller in the states a lab may find it in:
the run checks servo, referencing, readiness and the coordinate system before any move
(and in ``--dry-run``), records them in ``run.yaml``, and refuses each bad one."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from pipython.pidevice.gcscommands import GCSCommands
from pipython.pidevice.gcsmessages import GCSMessages
from pipython.pidevice.interfaces.pisocket import PISocket

from hexatherm.errors import ControllerError, IncompleteSession
from hexatherm.workflows.serve import parse_fault
from tests.workflows.test_run import check_complete
from tests.workflows.test_run_faults import bench_with

FAULTS = [
    ("pi-servo-off", "servo", r"servo off on X Y Z U V W"),
    ("pi-unreferenced", "referenced", r"not referenced on X Y Z U V W"),
    ("pi-busy", "ready", r"busy \(#7 answers 0xB0"),
    ("pi-coordinate-system:name=SAMPLE", "coordinate_system", r"coordinate system SAMPLE"),
    ("pi-pivot:t=100", "pivot_point", r"pivot point R=0.000000 S=0.000000 T=100.000000 mm"),
]


def controller_records(session: Path) -> list[dict[str, object]]:
    doc = yaml.safe_load((session / "run.yaml").read_text())
    records = doc["controller"]
    assert isinstance(records, list)
    return records


@pytest.mark.parametrize(("fault", "key", "message"), FAULTS)
def test_run_refuses_a_controller_not_ready_before_any_move(
    tmp_path: Path, fault: str, key: str, message: str
) -> None:
    b = bench_with(tmp_path)
    b.restart(dialect="pi", pi_start=parse_fault(fault).pi)
    try:
        with pytest.raises(ControllerError, match=message + ".*Nothing was moved"):
            b.dry_run()
        assert not b.session.exists()
        with pytest.raises(IncompleteSession, match=message):
            b.run()
        assert b.world.model.moves == 0 and b.machines.cmm.touches == 0
        received = b.machines.controller.received
        assert not any(c.startswith(("MOV", "VMO?")) for c in received)
        assert received[-3:] == ["#24", "STP", "ERR?"]  # the run's stop, all the same
        (record,) = controller_records(b.session)
        checks = record["checks"]
        assert isinstance(checks, dict) and set(checks) == {
            "servo",
            "referenced",
            "ready",
            "coordinate_system",
            "pivot_point",
        }
        assert not str(checks[key]).startswith(("yes", "ZERO=ZERO", "R=0.000000 S=0.000000 T=0."))
        assert record["model"] == "C-887" and str(record["url"]).startswith("pi://")
    finally:
        b.machines.close()


def test_referenced_by_pi_software_then_resumed(tmp_path: Path) -> None:
    """Refused unreferenced; the lab references the hexapod with PI's own library; the
    resumed run completes and run.yaml keeps both connections' records."""
    b = bench_with(tmp_path)
    b.restart(dialect="pi", pi_start=parse_fault("pi-unreferenced").pi)
    try:
        with pytest.raises(IncompleteSession, match="not referenced"):
            b.run()
        sim = b.machines.controller
        with PISocket(sim.host, sim.port) as gateway:
            messages = GCSMessages(gateway)
            messages.timeout = 120_000  # ms: a loaded machine, not a timed assertion
            with GCSCommands(messages) as device:  # unregisters pipython's callback
                device.FRF()
                while not device.IsControllerReady():  # the reference move, simulated time
                    b.clock.sleep(1.0)
                assert all(device.qFRF().values())
        b.run(resume=True)
        check_complete(b)
        first, second = controller_records(b.session)
        assert str(first["checks"]["referenced"]).startswith("no")  # type: ignore[index]
        assert second["checks"] == {  # type: ignore[comparison-overlap]
            "servo": "yes (SVO? X=1 Y=1 Z=1 U=1 V=1 W=1)",
            "referenced": "yes (FRF? X=1 Y=1 Z=1 U=1 V=1 W=1)",
            "ready": "yes (#7 0xB1)",
            "coordinate_system": "ZERO=ZERO",
            "pivot_point": "R=0.000000 S=0.000000 T=0.000000",
        }
    finally:
        b.machines.close()


def test_dry_run_reports_the_controller_state(tmp_path: Path) -> None:
    b = bench_with(tmp_path)
    b.restart(dialect="pi")
    try:
        assert b.dry_run() == 4
        (line,) = [m for level, m in b.messages if m.startswith("controller: ")]
        assert "servo yes" in line and "referenced yes" in line and "ZERO=ZERO" in line
        assert b.world.model.moves == 0 and not b.session.exists()
    finally:
        b.machines.close()
