"""``calibrate`` refuses a measurement file two sessions hold (by SHA-256) and reads a
file for it only when another has its size (one content needs one size): a scanning
session's 150 MB points file is no longer read once more before the campaign is read."""

from __future__ import annotations

import hashlib
from pathlib import Path
from types import SimpleNamespace

import pytest

from hexatherm.errors import InputError
from hexatherm.workflows.calibrate import checks


def spec(folder: Path, *files: str) -> SimpleNamespace:
    return SimpleNamespace(path=folder / "session.yaml", measurements=[folder / f for f in files])


@pytest.fixture
def hashed(monkeypatch: pytest.MonkeyPatch) -> list[Path]:
    """The files check_distinct_sessions reads (the former code read every one)."""
    calls: list[Path] = []
    real = checks.sha256_file

    def counting(path: Path) -> str | None:
        calls.append(Path(path))
        return real(path)

    monkeypatch.setattr(checks, "sha256_file", counting)
    return calls


def test_files_alone_in_their_size_are_not_read(tmp_path: Path, hashed: list[Path]) -> None:
    for name, text in (("a.csv", "1,2\n"), ("b.csv", "1,2,3\n"), ("c.csv", "12345678\n")):
        (tmp_path / name).write_text(text)
    checks.check_distinct_sessions([spec(tmp_path, "a.csv")])  # type: ignore[list-item]
    checks.check_distinct_sessions(
        [spec(tmp_path, "a.csv", "b.csv"), spec(tmp_path, "c.csv")]  # type: ignore[list-item]
    )
    assert hashed == []


def test_one_size_other_content_is_taken_the_same_content_refused(
    tmp_path: Path, hashed: list[Path]
) -> None:
    one, other = tmp_path / "one", tmp_path / "other"
    one.mkdir()
    other.mkdir()
    (one / "p.csv").write_text("1,2\n")
    (other / "p.csv").write_text("1,3\n")
    (other / "q.csv").write_text("1,2\n")
    (other / "missing.csv").with_suffix(".dir").mkdir()  # not a regular file: not read
    checks.check_distinct_sessions(
        [spec(one, "p.csv"), spec(other, "p.csv", "missing.dir")]  # type: ignore[list-item]
    )
    assert sorted(hashed) == [one / "p.csv", other / "p.csv"]
    with pytest.raises(InputError) as refused:
        checks.check_distinct_sessions(
            [spec(one, "p.csv"), spec(other, "p.csv", "q.csv")]  # type: ignore[list-item]
        )
    digest = hashlib.sha256(b"1,2\n").hexdigest()[:12]
    assert f"its p.csv and q.csv have one SHA-256, {digest}..." in str(refused.value)
    assert "holds the same measurements as" in str(refused.value)


def test_the_sessions_read_once_make_the_same_campaign(monkeypatch: pytest.MonkeyPatch) -> None:
    # the former code read each session file again in read_campaign and process_session
    import numpy as np

    from hexatherm.io.config import read_session
    from hexatherm.workflows.calibrate import run
    from hexatherm.workflows.process import pipeline
    from tests.shipped import SHIPPED

    session = SHIPPED / "calibration-geometry"
    before = run.read_campaign([session])
    spec = read_session(session)
    reads: list[object] = []

    def refused(path: object) -> None:
        reads.append(path)
        raise AssertionError("the session was read again")

    monkeypatch.setattr(run, "read_session", refused)
    monkeypatch.setattr(pipeline, "read_session", refused)
    now = run.read_campaign([session], specs=[spec])
    assert reads == []
    assert now.labels == before.labels
    for name in ("commanded", "measured", "covariance"):
        assert np.array_equal(getattr(now, name), getattr(before, name)), name
