"""``hexatherm run`` against each dialect of the twin's CMM (issue 23): a dialect change
cannot pass CI unnoticed.

``dme-1.4`` is a plain DME 1.4 server as the NIST I++ DME Test Suite's: ``DMEVersion("1.4")``,
no ``Tool.AvrRadius``, ``PtMeas`` fields in its own order, a lax ``FindTool``, the session
kept across connections. The truth is the twin's, as in ``test_run.py``.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import yaml

from hexatherm.devices.sim.ipp import CMM_DIALECTS, Fault
from hexatherm.errors import AcquisitionError, IncompleteSession
from hexatherm.workflows.run.resume import ProbeSettings, read_run_settings
from tests.workflows.test_run import check_complete, make_bench, run_to_the_truth

SHORT = {"targets": [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]], "points_per_ball": 6}


@pytest.mark.parametrize("dialect", CMM_DIALECTS)
def test_run_then_process_against_each_cmm_dialect(tmp_path: Path, dialect: str) -> None:
    b = make_bench(tmp_path, cmm_dialect=dialect)
    try:
        run_to_the_truth(b)
        commands = [c[6:] for c in b.machines.cmm.commands]
        # the version is the first question of the session, and only what it has is asked
        assert commands[:2] == ["StartSession()", "GetDMEVersion()"]
        facts = yaml.safe_load((b.session / "run.yaml").read_text())["cmm"]
        read_run_settings(b.session)  # still what a resume reads
        if dialect == "dme-1.4":
            assert not any("AvrRadius" in c for c in commands)
            assert facts["dme_version"] == "1.4" and facts["tool_avr_radius_mm"] == "unknown"
            assert "1.4.2" in facts["unknown"][0]
            assert any("tip radius is unknown" in m for _, m in b.messages)
        else:
            assert "GetProp(Tool.AvrRadius())" in commands
            assert facts["dme_version"] == "1.4.3" and facts["unknown"] == []
            assert facts["tool_avr_radius_mm"] == 0.5 * b.files.balls.tip_diameter_mm
        assert commands[-1] == "EndSession()"
        assert not any("Error(" in line for line in (b.session / "ipp.transcript").open())
    finally:
        b.machines.close()


def test_a_refused_optional_query_is_unknown_not_the_end(tmp_path: Path) -> None:
    """A 1.4.3 server that refuses AvrRadius all the same: cleared, warned, the run goes on."""
    b = make_bench(tmp_path, ipp_faults=[Fault("error", 1, "GetProp", severity=3)], **SHORT)
    try:
        b.run()
        check_complete(b)
        facts = yaml.safe_load((b.session / "run.yaml").read_text())["cmm"]
        assert facts["tool_avr_radius_mm"] == "unknown"
        assert "refused" in facts["unknown"][0]
        commands = [c[6:] for c in b.machines.cmm.commands]
        i = commands.index("GetProp(Tool.AvrRadius())")
        assert commands[i + 1] == "ClearAllErrors()"
        assert any("tip radius is unknown" in m for _, m in b.messages)
    finally:
        b.machines.close()


def test_resume_on_a_server_that_kept_the_session(tmp_path: Path) -> None:
    b = make_bench(
        tmp_path,
        cmm_dialect="dme-1.4",
        ipp_faults=[Fault("error", 20, "PtMeas", severity=3)],
        **SHORT,
    )
    try:
        with pytest.raises(IncompleteSession, match="--resume"):
            b.run()
        before = pd.read_csv(b.session / "points.csv")
        b.run(resume=True)  # the stale session is ended, a new one started
        after = check_complete(b)
        pd.testing.assert_frame_equal(after.iloc[: len(before)], before)
        text = (b.session / "ipp.transcript").read_text()
        assert '! Error(3, 0507, \\"StartSession\\"' in text  # the transcript escapes quotes
        assert any("still had a session open" in m for _, m in b.messages)
    finally:
        b.machines.close()


@pytest.mark.parametrize("dialect", CMM_DIALECTS)
def test_dry_run_checks_the_tool_where_find_tool_is_lax(tmp_path: Path, dialect: str) -> None:
    b = make_bench(tmp_path, cmm_dialect=dialect, **SHORT)
    try:
        with pytest.raises(AcquisitionError, match="no tool 'Probe9'.*Probe1"):
            b.dry_run(probe=ProbeSettings(tool="Probe9"))
        assert b.dry_run() == 4
        assert not b.session.exists()  # a dry run keeps nothing: no folder, no transcript
        assert b.machines.cmm.touches == 0
    finally:
        b.machines.close()


def test_warnings_are_said_and_kept(tmp_path: Path) -> None:
    faults = [Fault("error", 3, "PtMeas", severity=1, number=1005)]
    b = make_bench(tmp_path, ipp_faults=faults, **SHORT)
    try:
        b.run()
        check_complete(b)
        said = [m for level, m in b.messages if level == "warn" and "CMM warning" in m]
        assert len(said) == 1 and "PtMeas" in said[0] and "1005" in said[0]
        assert '! Error(1, 1005, \\"PtMeas\\"' in (b.session / "ipp.transcript").read_text()
    finally:
        b.machines.close()


@pytest.mark.parametrize("controller", ["symetrie", "pi", "symetrie-pmac"])
def test_a_plain_dme_1_4_server_with_each_controller_dialect(
    tmp_path: Path, controller: str
) -> None:
    """issue 23: a campaign against a standard DME 1.4 server completes with a controller
    of each dialect (Symetrie API v2, PI GCS, Symetrie gpascii), and processes to the
    twin's truth."""
    b = make_bench(tmp_path, **SHORT, cmm_dialect="dme-1.4")  # type: ignore[arg-type]
    b.restart(dialect=controller, cmm_dialect="dme-1.4")
    try:
        run_to_the_truth(b)
        assert b.machines.cmm_url.startswith("ipp://")
        assert controller in b.machines.controller_url.split(":")[0]
    finally:
        b.machines.close()
