"""``run --resume`` whatever the kill caught inside a ball (issue 22, item 10, the run's side).

The run's primary record is the I++ transcript: a ball's points are those between its
``begin`` and its ``accept`` note; ``points.csv`` is appended after the ``accept``. A kill
can fall before the ``accept`` (points probed, none kept) or after it but before
``points.csv`` got the ball. Each state is built on disk from a completed run's files
(the transcript cut where the kill fell, ``points.csv`` as it stood), not raced with a
real kill, and resumed against the same twin: the ball is probed again from its start in
the first case, restored bit for bit from the transcript in the second, and either way
every ball of every step has its own points once, as the transcript replays.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from hexatherm.workflows.run.files import points_csv_from_transcript
from tests.workflows.test_run import check_complete, make_bench
from tests.workflows.test_run_resume import SHORT

BALL = ("R0", "B2")


def _cut(lines: list[str], note: str) -> int:
    """Index of the transcript line holding the run's ``note``."""
    return next(k for k, line in enumerate(lines) if f'"run {note}"' in line)


@pytest.mark.parametrize("kill", ["before-accept", "after-accept-before-points"])
def test_a_kill_inside_a_ball_then_resume(tmp_path: Path, kill: str) -> None:
    b = make_bench(tmp_path, **SHORT)  # type: ignore[arg-type]
    try:
        b.run()
        session = b.session
        full = (session / "ipp.transcript").read_text().splitlines(keepends=True)
        label, ball = BALL
        accept = _cut(full, f"accept {label} {ball}")
        begin = _cut(full, f"begin {label} {ball} attempt 1")
        assert begin < accept - 6  # the ball's PtMeas transactions lie between
        end = accept if kill == "before-accept" else accept + 1
        transcript = "".join(full[:end])
        (session / "ipp.transcript").write_text(transcript)
        # points.csv as it stood: the balls accepted before this one (not yet this one)
        before = points_csv_from_transcript("".join(full[:begin]), b.files.plan, b.files.balls)
        (session / "points.csv").write_text(before)
        steps = (session / "steps.csv").read_text().splitlines(keepends=True)
        (session / "steps.csv").write_text("".join(steps[:3]))  # O and R0 in position
        (session / "session.yaml").unlink()
        original = pd.read_csv(
            pd.io.common.StringIO(
                points_csv_from_transcript("".join(full), b.files.plan, b.files.balls)
            )
        )
        b.messages.clear()
        b.run(resume=True)
        after = check_complete(b, max_rms_um=3.0)  # the resume measured later: heating
        mine = (after["label"] == label) & (after["ball"] == ball)
        was = (original["label"] == label) & (original["ball"] == ball)
        said = [m for _, m in b.messages]
        if kill == "before-accept":  # probed again from its start: new touches
            assert not any("restored" in m for m in said), said
            assert (after.loc[mine, "time"].to_numpy() > original.loc[was, "time"].max()).all()
        else:  # kept: the transcript's points, bit for bit, restored to points.csv
            assert "points.csv: 6 line(s) restored from the transcript" in said, said
            pd.testing.assert_frame_equal(
                after.loc[mine].reset_index(drop=True), original.loc[was].reset_index(drop=True)
            )
        # every ball before it kept as it was
        n_before = before.count("\n") - 1
        pd.testing.assert_frame_equal(after.iloc[:n_before], original.iloc[:n_before])
    finally:
        b.machines.close()
