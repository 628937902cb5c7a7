"""``diagnose`` reads its session file once (issue 37: it read it twice, once to check the
output folder against its inputs, once more to diagnose)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.io.config import read_session
from hexatherm.workflows.diagnose import command
from hexatherm.workflows.diagnose import run as diagnose_run
from tests.shipped import SHIPPED


def test_the_session_read_once_gives_the_same_observations(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    session = SHIPPED / "with-hidden-effect"
    before = diagnose_run.read_for_diagnosis(session)
    spec = read_session(session)
    reads: list[object] = []

    def refused(path: object) -> None:
        reads.append(path)
        raise AssertionError("the session was read again")

    monkeypatch.setattr(diagnose_run, "read_session", refused)
    now = diagnose_run.read_for_diagnosis(session, session=spec)
    assert reads == []
    for name in ("times_s", "centres_mm", "balls_mm", "u_mm"):
        a, b = getattr(before.observations, name), getattr(now.observations, name)
        assert np.array_equal(a, b), name
    assert now.session.plan.labels == before.session.plan.labels


def test_diagnose_reads_the_session_file_once(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    session = SHIPPED / "with-hidden-effect"
    calls: list[object] = []

    def counted(path: object):  # type: ignore[no-untyped-def]
        calls.append(path)
        return read_session(path)  # type: ignore[arg-type]

    import hexatherm.io.config as config

    monkeypatch.setattr(config, "read_session", counted)  # command's import, at call time
    monkeypatch.setattr(diagnose_run, "read_session", counted)
    from hexatherm.io.files import STRICT

    done = command.diagnose(session, tmp_path / "out", False, None, None, [], STRICT)
    assert len(calls) == 1
    assert (tmp_path / "out" / "diagnosis.json") in done.written
