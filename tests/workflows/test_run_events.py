"""The CMM's event lines during a run: one not understood is a warning and the run goes
on; a tool the CMM changed by itself is changed back before anything more is probed, and
what was probed with the other tool is probed again."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from hexatherm.devices.sim.ipp import Fault, IppSimServer
from hexatherm.errors import AcquisitionError, IncompleteSession
from hexatherm.workflows.run.files import accepted_balls
from tests.workflows.test_run import Bench, check_complete, make_bench

SHORT = {"targets": [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]], "points_per_ball": 6}
#: the run's tool (balls-3.yaml's 2 mm tip) and the one the CMM changes to
TOOLS = {"Probe1": 2.0, "RefTool": 5.0}


def bench_with_tools(tmp: Path, faults: Sequence[Fault]) -> Bench:
    """The twin's CMM with a second tool in its table."""
    b = make_bench(tmp, **SHORT)  # type: ignore[arg-type]
    old = b.machines.cmm
    old.close()
    b.machines.cmm = IppSimServer(
        b.world,
        tools=TOOLS,
        faults=faults,
        compensated=old.compensated,
        time_s=b.world.cmm_time_s,
        home_mm=tuple(old.home_mm),
        limits_mm=old.limits_mm,
    )
    return b


def test_event_lines_not_understood_are_warnings_and_the_run_goes_on(tmp_path: Path) -> None:
    bad = ("Blah(", '! Error(1, 0, "Info", "Temp\xe9rature stable")')
    b = make_bench(tmp_path, ipp_faults=[Fault("event", 3, "PtMeas", events=bad)], **SHORT)  # type: ignore[arg-type]
    try:
        b.run()
        said = [m for level, m in b.messages if "CMM event not understood" in m]
        assert len(said) == 2 and "Temp\\xe9rature" in said[1]
        assert "E0000 # Blah(" in (b.session / "ipp.transcript").read_text()
        check_complete(b)
    finally:
        b.machines.close()


def test_a_tool_changed_by_the_cmm_is_changed_back_and_the_ball_probed_again(
    tmp_path: Path,
) -> None:
    # the 10th touch (O's second ball) sees the CMM change to RefTool
    b = bench_with_tools(
        tmp_path, [Fault("event", 10, "PtMeas", events=('ChangeTool("RefTool")',))]
    )
    try:
        b.run()
        text = (b.session / "ipp.transcript").read_text()
        assert "run abandon O B2 tool changed" in text
        assert text.count('ChangeTool(\\"Probe1\\")') == 2
        said = [m for _, m in b.messages if "changed its tool" in m]
        assert len(said) == 1 and said[0].endswith("changed back to Probe1")
        # the truth: the CMM reports the active tool's radius with every point (ER); every
        # point kept was probed with the run's tool (1 mm), none with RefTool (2.5 mm)
        kept = [p.er_mm for ball in accepted_balls(text).values() for p in ball.points]
        assert len(kept) == 4 * 3 * 6 and np.all(np.array(kept) == 1.0)
        check_complete(b)
    finally:
        b.machines.close()


def test_a_tool_changed_again_while_the_ball_is_probed_again_stops_the_run(
    tmp_path: Path,
) -> None:
    change = ('ChangeTool("RefTool")',)
    faults = [
        Fault("event", 10, "PtMeas", events=change),
        Fault("event", 14, "PtMeas", events=change),
    ]
    b = bench_with_tools(tmp_path, faults)
    try:
        with pytest.raises(IncompleteSession, match="changed its tool again while O B2"):
            b.run()
        assert "STOP" in b.machines.controller.received
    finally:
        b.machines.close()


@pytest.mark.parametrize("resume", [False, True])
def test_a_fifo_in_place_of_the_transcript_is_named_as_such(tmp_path: Path, resume: bool) -> None:
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    try:
        b.session.mkdir()
        os.mkfifo(b.session / "ipp.transcript")
        with pytest.raises(AcquisitionError, match="ipp.transcript is not a regular file"):
            b.run(resume=resume)
        assert b.machines.cmm.commands == [] and b.world.model.moves == 0
    finally:
        b.machines.close()
