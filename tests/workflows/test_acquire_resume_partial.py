"""Resume the operator's way, whatever the kill caught (issue 22, item 10).

``acquire`` is killed inside a ball (3 of its 5 touches sent) and resumed; the operator
probes the interrupted ball again from its first touch point (or continues it). Where the
kill fell decides what the killed process left on disk, and what the resumed one reads:

- ``after``: the 3 touches were logged in ``serial.log`` and written to ``points.csv``;
- ``log-only``: logged, but killed before ``points.csv`` got them;
- ``one``: killed after logging the first touch; the other 2 sat in the port's buffer and
  reach the resumed process first;
- ``none``: killed before logging any; all 3 reach the resumed process first.

Each case is built on disk as the kill leaves it (``serial.log`` written by replaying the
touches the killed process logged, ``points.csv`` cut when it was not flushed, the
unread bytes queued on the port ahead of the operator's) rather than raced with a real
kill, so every order is tested every time. All must give the same session: the ball is
the re-probe's touches alone, the 3 earlier ones set aside in ``rejected.csv`` with the
same reason (or, continued, the ball is the 3 and the 2 new ones), every other ball its
own touches, and the log replays to the same files.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from hexatherm.devices.serialport import PortSettings
from hexatherm.io.config import plan_to_yaml
from hexatherm.io.seriallog import LOG_MAGIC, entry
from hexatherm.workflows.acquire.files import load_files
from hexatherm.workflows.acquire.recorder import REPROBED
from hexatherm.workflows.acquire.run import AcquireOptions, acquire, session_from_log
from tests.cli.test_acquire import loop_device
from tests.workflows.test_acquire_assign import BALLS, BALLS_FILE, HEXAPOD_FILE, Probe, Touch
from tests.workflows.test_acquire_resume import PLAN, SLOTS

N = PLAN.points_per_ball
KILLED_IN = ("S1", "B1")
SENT = 3  # touches of the interrupted ball sent before the kill
#: a safety net for a hung acquisition (no data for this long), never what decides a pass
SAFETY_S = 600.0


def _table(path: Path) -> list[list[str]]:
    with open(path, newline="") as handle:
        return list(csv.reader(handle))


def _stream(touches: list[Touch]) -> bytes:
    return b"".join(t.line + b"\r\n" for t in touches)


def _killed_state(tmp: Path, files, logged: list[Touch], points_flushed: bool) -> Path:  # type: ignore[no-untyped-def]
    """The session folder as the killed process left it."""
    log = tmp / "killed.log"
    entries = [
        entry("config", "-", "units=mm", "2024-05-01T10:00:00.000000"),
        entry("mode", "-", "auto", "2024-05-01T10:00:00.000000"),
        entry("open", "probe", "loop:// 9600 8N1", "2024-05-01T10:00:00.000000"),
    ]
    for k, touch in enumerate(logged):
        when = f"2024-05-01T10:{k // 60 + 1:02d}:{k % 60:02d}.000000"
        entries.append(entry("rx", "probe", touch.line + b"\r\n", when))
    log.write_text(LOG_MAGIC + "\n" + "".join(e.format() for e in entries))
    session = tmp / "s"
    session_from_log(files, log, session, lambda level, message: None)
    if not points_flushed:  # the kill came between logging the bytes and writing their points
        points = session / "points.csv"
        lines = points.read_text().splitlines(keepends=True)
        kept = [x for x in lines if not x.startswith(",".join(KILLED_IN) + ",")]
        assert len(kept) < len(lines) or not any(t.label == "S1" for t in logged)
        points.write_text("".join(kept))
    return session


def _resume(session: Path, files, unread: bytes) -> list[str]:  # type: ignore[no-untyped-def]
    """``acquire --resume`` with ``unread`` queued on the port; what it told the operator."""
    told: list[str] = []

    def feed(port) -> None:  # type: ignore[no-untyped-def]
        port.write(unread)

    options = AcquireOptions(
        session=session,
        probe=PortSettings("loop://", timeout_s=0.05),
        auto=True,
        resume=True,
        idle_timeout_s=SAFETY_S,
    )
    with loop_device(feed) as threads:
        result = acquire(files, options, lambda level, message: told.append(message))
    for thread in threads:
        thread.join()
    assert result.complete
    return told


@pytest.mark.parametrize("protocol", ["again", "continue"])
@pytest.mark.parametrize(
    ("case", "n_logged", "points_flushed"),
    [("after", SENT, True), ("log-only", SENT, False), ("one", 1, False), ("none", 0, False)],
)
def test_where_the_kill_fell_does_not_matter(
    tmp_path: Path, case: str, n_logged: int, points_flushed: bool, protocol: str
) -> None:
    (tmp_path / "plan.yaml").write_text(plan_to_yaml(PLAN))
    files = load_files(tmp_path / "plan.yaml", HEXAPOD_FILE, BALLS_FILE)
    probe = Probe(PLAN, seed=31, error_um=30.0, error_urad=100.0)
    at = SLOTS.index(KILLED_IN)
    before = [t for label, ball in SLOTS[:at] for t in probe.ball(label, ball)]
    partial = probe.ball(*KILLED_IN, range(SENT))
    if protocol == "again":  # the whole ball again, from its first touch point
        operator = probe.ball(*KILLED_IN)
        ball = operator
    else:  # its remaining touches
        operator = probe.ball(*KILLED_IN, range(SENT, N))
        ball = partial + operator
    rest = [t for label, b in SLOTS[at + 1 :] for t in probe.ball(label, b)]
    session = _killed_state(tmp_path, files, before + partial[:n_logged], points_flushed)
    told = _resume(session, files, _stream(partial[n_logged:] + operator + rest))

    # points.csv: every ball its own touches, the interrupted one as the operator left it
    points = _table(session / "points.csv")
    got = [(r[0], r[1], float(r[2]), float(r[3]), float(r[4])) for r in points[1:]]
    assert got == [(t.label, t.ball, *t.xyz) for t in before + ball + rest]
    # rejected.csv: the earlier touches of a ball probed again whole, set aside, one reason
    if protocol == "again":
        rejected = _table(session / "rejected.csv")
        rows = [
            (r[0], r[1], float(r[2]), float(r[3]), float(r[4]), r[6], r[7]) for r in rejected[1:]
        ]
        assert rows == [(t.label, t.ball, *t.xyz, "set-aside", REPROBED) for t in partial]
        assert any(f"{BALLS.names[0]} of S1" in m and "again" in m for m in told), told
    else:
        assert not (session / "rejected.csv").exists() or len(_table(session / "rejected.csv")) == 1
    # and the log replays to the same files, byte for byte
    replay = tmp_path / "replay"
    session_from_log(files, session / "serial.log", replay, lambda level, message: None)
    for name in ("points.csv", "rejected.csv"):
        if (session / name).exists():
            assert (replay / name).read_bytes() == (session / name).read_bytes(), name
