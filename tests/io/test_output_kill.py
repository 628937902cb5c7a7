"""Killed and concurrent writes (issue 12, item 2): child processes killed with SIGKILL
at the worst moments, and runs racing for one output.

No sleeps: the kills are injected at exact points (``os.replace`` patched in the
child), and the concurrency tests hold the lock themselves, so that what they assert
cannot depend on the machine's load.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from hexatherm.errors import OutputExistsError
from hexatherm.io.atomic import output_lock, recover_output
from hexatherm.io.manifest import MANIFEST_NAME, foreign_entries
from hexatherm.io.outputs import output_dir, write_output_file
from tests.io.test_output_safety import leftovers, snapshot
from tests.waiting import SAFETY_S

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and flock")

#: the child: writes OUT (a folder or a file), killing itself where told
CHILD = r"""
import os, signal, sys
from hexatherm.errors import HexathermError
from hexatherm.io.outputs import output_dir, write_output_file

kill_at, kind, out, content, timeout, overwrite = sys.argv[1:7]
real_replace = os.replace


def die():
    os.kill(os.getpid(), signal.SIGKILL)


def replace(src, dst, *args, **kwargs):
    src, dst = os.fspath(src), os.fspath(dst)
    if kill_at == "before-file" and dst == out:
        die()
    real_replace(src, dst, *args, **kwargs)
    if kill_at == "window" and src == out:  # OUT -> .OUT.old.<pid>, before tmp -> OUT
        die()
    if kill_at in ("after-swap", "after-file") and dst == out:
        die()


os.replace = replace


def waiting(folder):
    print("waiting", flush=True)


try:
    if kind == "folder":
        with output_dir(
            out, overwrite=overwrite == "1", lock_timeout_s=float(timeout), on_wait=waiting
        ) as tmp:
            (tmp / "poses.csv").write_text(content)
            if kill_at == "in-block":
                die()
            (tmp / "sub").mkdir()
            (tmp / "sub" / "legs.csv").write_text(content * 2)
    else:
        write_output_file(
            out, content, overwrite=overwrite == "1", lock_timeout_s=float(timeout),
            on_wait=waiting,
        )
except HexathermError as exc:
    print(f"error: {exc}", file=sys.stderr)
    sys.exit(1)
print("done", flush=True)
"""


def child(
    out: Path,
    content: str,
    *,
    kill_at: str = "never",
    kind: str = "folder",
    timeout_s: float = SAFETY_S,
    overwrite: bool = True,
) -> subprocess.Popen[str]:
    args = [kill_at, kind, str(out), content, str(timeout_s), "1" if overwrite else "0"]
    return subprocess.Popen(
        [sys.executable, "-c", CHILD, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"),
    )


def finish(proc: subprocess.Popen[str]) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=SAFETY_S)
    return proc.returncode, out, err


def read_line(proc: subprocess.Popen[str], timeout_s: float = SAFETY_S) -> str:
    """The child's next line of standard output (fails after a generous timeout)."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout_s)
    assert ready, "the child said nothing"
    return proc.stdout.readline().strip()


def write(out: Path, content: str, **kwargs: object) -> None:
    """What the child writes, in this process."""
    with output_dir(out, **kwargs) as tmp:  # type: ignore[arg-type]
        (tmp / "poses.csv").write_text(content)
        (tmp / "sub").mkdir()
        (tmp / "sub" / "legs.csv").write_text(content * 2)


def complete(out: Path, content: str) -> bool:
    """``out`` holds exactly what :func:`write` writes with ``content``, vouched for."""
    return (
        sorted(p.relative_to(out).as_posix() for p in out.rglob("*"))
        == [MANIFEST_NAME, "poses.csv", "sub", "sub/legs.csv"]
        and (out / "poses.csv").read_text() == content
        and (out / "sub" / "legs.csv").read_text() == content * 2
        and foreign_entries(out) == []
    )


@pytest.fixture
def results(tmp_path: Path) -> Path:
    session = tmp_path.resolve() / "session"
    session.mkdir()
    (session / "centres.csv").write_bytes(b"step,ball,x_mm\nO,B1,1\n")
    out = session / "results"
    write(out, "v1")
    return out


def test_a_kill_between_the_renames_is_repaired_by_the_next_run(results):
    session = results.parent
    before = snapshot(session)
    rc, _, err = finish(child(results, "v2", kill_at="window"))
    assert rc == -signal.SIGKILL, err
    hidden = sorted(p.name for p in session.iterdir() if p.name.startswith("."))
    assert not results.exists() and len(hidden) == 2  # the window: .results.old.<pid>, tmp
    assert any(".results.old." in h for h in hidden) and any(h.endswith(".tmp") for h in hidden)
    write(results, "v3", overwrite=True)  # the next normal run
    assert complete(results, "v3")
    assert (session / "centres.csv").read_bytes() == before["centres.csv"]
    assert leftovers(session) == []


def test_the_recovery_restores_the_old_folder_byte_for_byte(results):
    session = results.parent
    before = snapshot(session)
    rc, _, err = finish(child(results, "v2", kill_at="window"))
    assert rc == -signal.SIGKILL, err
    with output_lock(results):
        done = recover_output(results)
    assert [d.split(" ")[0] for d in done] == ["restored", "removed"]
    assert snapshot(session) == before and complete(results, "v1")
    assert leftovers(session) == []
    with output_lock(results):
        assert recover_output(results) == []


def test_a_run_without_overwrite_after_the_kill_restores_and_refuses(results):
    session = results.parent
    before = snapshot(session)
    rc, _, _ = finish(child(results, "v2", kill_at="window"))
    assert rc == -signal.SIGKILL and not results.exists()
    with pytest.raises(OutputExistsError, match="use --overwrite"):
        write(results, "v3")
    assert snapshot(session) == before
    assert leftovers(session) == []


@pytest.mark.parametrize(("kill_at", "expected"), [("after-swap", "v2"), ("in-block", "v1")])
def test_kills_before_and_after_the_window_leave_a_complete_folder(results, kill_at, expected):
    session = results.parent
    rc, _, err = finish(child(results, "v2", kill_at=kill_at))
    assert rc == -signal.SIGKILL, err
    assert complete(results, expected) and len(leftovers(session)) == 1
    write(results, "v3", overwrite=True)
    assert complete(results, "v3") and leftovers(session) == []


@pytest.mark.parametrize(("kill_at", "expected"), [("before-file", "v1"), ("after-file", "v2")])
def test_a_killed_file_write_leaves_a_file_hexatherm_still_owns(tmp_path, kill_at, expected):
    page = tmp_path.resolve() / "report.html"
    write_output_file(page, "v1")
    rc, _, err = finish(child(page, "v2", kill_at=kill_at, kind="file"))
    assert rc == -signal.SIGKILL, err
    assert page.read_text() == expected
    assert len(leftovers(tmp_path)) == (1 if kill_at == "before-file" else 0)
    write_output_file(page, "v3", overwrite=True)  # still hexatherm's: replaced
    assert page.read_text() == "v3" and leftovers(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST_NAME, "report.html"]


def test_a_busy_output_is_refused_cleanly_without_waiting(results):
    session = results.parent
    before = snapshot(session)
    with output_lock(results):
        rc, out, err = finish(child(results, "v2", timeout_s=0.0))
    assert rc == 1 and out == ""
    assert err.startswith("error: cannot write") and "another hexatherm run is writing" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert snapshot(session) == before and leftovers(session) == []


def test_a_second_run_waits_for_the_first(results):
    session = results.parent
    with output_lock(results):
        proc = child(results, "v2", timeout_s=SAFETY_S)
        assert read_line(proc) == "waiting"
        assert complete(results, "v1")  # it cannot swap while the lock is held
    rc, out, err = finish(proc)
    assert rc == 0 and out.strip() == "done", err
    assert complete(results, "v2") and leftovers(session) == []


def test_racing_runs_with_overwrite_both_finish_and_one_wins_whole(results):
    session = results.parent
    procs = [child(results, f"run{i}") for i in range(3)]
    outcomes = [finish(p) for p in procs]
    assert all(rc == 0 for rc, _, _ in outcomes), outcomes
    assert any(complete(results, f"run{i}") for i in range(3))
    assert leftovers(session) == []


def test_racing_runs_without_overwrite_one_writes_the_others_are_refused(tmp_path):
    out = tmp_path.resolve() / "new"
    with output_lock(out):  # all three get past the first check before any can swap
        procs = [child(out, f"run{i}", overwrite=False) for i in range(3)]
        assert [read_line(p) for p in procs] == ["waiting"] * 3
    outcomes = [finish(p) for p in procs]
    assert sorted(rc for rc, _, _ in outcomes) == [0, 1, 1], outcomes
    for rc, _, err in outcomes:
        if rc == 1:
            assert err.strip().endswith("exists; use --overwrite to replace it")
            assert len(err.strip().splitlines()) == 1
    assert any(complete(out, f"run{i}") for i in range(3))
    assert leftovers(tmp_path) == []
