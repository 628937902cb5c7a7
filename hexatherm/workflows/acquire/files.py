"""The files of an acquired session: the copies of plan, hexapod and balls files, the
session file written at the end, and the lock that keeps two acquisitions apart.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.core.plan import Plan
from hexatherm.errors import AcquisitionError, InputError
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.seriallog import POINTS_NAME, TEMPERATURES_NAME
from hexatherm.session import Balls
from hexatherm.workflows.acquire.recorder import Notify


# -------------------------------------------------------------------- sessions
@dataclass(frozen=True)
class SessionFiles:
    """The configuration an acquisition runs with (already validated).

    Attributes
    ----------
    plan : Plan
    balls : Balls
    plan_text, hexapod_text, balls_text : str
        The files' text, copied into the session folder.
    convention : {"symetrie", "pi"}
        Rotation convention of the plan's poses (the hexapod file's).
    paths : tuple of Path
        The files read (plan, hexapod, balls): the session folder may not hold them.
    """

    plan: Plan
    balls: Balls
    plan_text: str
    hexapod_text: str
    balls_text: str
    convention: str = "symetrie"
    paths: tuple[Path, ...] = ()


def load_files(plan_path: Path, hexapod_path: Path, balls_path: Path) -> SessionFiles:
    """Read and validate the plan, hexapod and balls files."""
    from hexatherm.io.config import read_balls, read_hexapod, read_plan
    from hexatherm.io.csvtext import read_text

    plan = read_plan(plan_path)
    hexapod = read_hexapod(hexapod_path)
    balls = read_balls(balls_path)
    return SessionFiles(
        plan,
        balls,
        read_text(plan_path),
        read_text(hexapod_path),
        read_text(balls_path),
        hexapod.convention,
        (Path(plan_path), Path(hexapod_path), Path(balls_path)),
    )


def check_same_files(given: SessionFiles, folder: Path) -> None:
    """Refuse to resume a session with a different plan or balls file than it started with."""
    from hexatherm.io.config import plan_to_yaml, read_balls, read_plan

    plan_copy = read_plan(folder / "plan.yaml")
    if plan_to_yaml(plan_copy) != plan_to_yaml(given.plan):
        raise AcquisitionError(
            f"the plan differs from the session's {folder / 'plan.yaml'}; "
            "resume with the plan the session started with"
        )
    balls_copy = read_balls(folder / "balls.yaml")
    same = (
        balls_copy.names == given.balls.names
        and np.array_equal(balls_copy.centres_mm, given.balls.centres_mm)
        and np.array_equal(balls_copy.diameters_mm, given.balls.diameters_mm)
        and balls_copy.probe_compensated == given.balls.probe_compensated
        and balls_copy.tip_diameter_mm == given.balls.tip_diameter_mm
    )
    if not same:
        raise AcquisitionError(f"the balls file differs from the session's {folder / 'balls.yaml'}")


def write_copies(folder: Path, files: SessionFiles) -> None:
    """Copy the plan, hexapod and balls files into the session folder."""
    for name, text in (
        ("plan.yaml", files.plan_text),
        ("hexapod.yaml", files.hexapod_text),
        ("balls.yaml", files.balls_text),
    ):
        atomic_write_text(folder / name, text)


def finish_session(folder: Path, notify: Notify, temperatures_file: Path | None = None) -> Path:
    """Write ``session.yaml`` so that ``hexatherm process`` takes the folder as it is.

    A thermocouple log (``temperatures_file`` copied in, or the one recorded
    from a second port) is attached when it reads as a temperatures file with
    ISO times like the points; otherwise a warning says why it was left out. The
    session declares ``utc_offset: "+00:00"`` (the points' and a recorded log's times are
    this computer's clock in UTC) unless ``temperatures_file`` came from elsewhere.
    """
    from hexatherm.io.config import session_to_yaml
    from hexatherm.io.temperatures import read_temperatures

    target = folder / TEMPERATURES_NAME
    if temperatures_file is not None:
        try:
            data = Path(temperatures_file).read_bytes()
        except OSError as exc:
            notify(
                "warn",
                f"cannot read {temperatures_file}: {exc.strerror}; session without temperatures",
            )
        else:
            atomic_write_text(target, data.decode("utf-8-sig", "replace"))
    temperatures = None
    if target.is_file():
        try:
            table = read_temperatures(target)
        except InputError as exc:
            notify("warn", f"temperatures left out of the session: {exc}")
        else:
            if table.time_kind != "iso":
                notify(
                    "warn",
                    f"temperatures left out of the session: {target} has times in "
                    "seconds but the points have ISO 8601 times",
                )
            else:
                temperatures = TEMPERATURES_NAME
    # every time in the folder is hexatherm's own clock (UTC, written naive) unless a
    # logger's file was copied in: its naive times may be local, so nothing is declared
    utc_offset = "+00:00" if temperatures_file is None else None
    path = folder / "session.yaml"
    atomic_write_text(
        path,
        session_to_yaml(
            folder.name,
            "hexapod.yaml",
            "balls.yaml",
            "plan.yaml",
            [POINTS_NAME],
            temperatures,
            utc_offset=utc_offset,
        ),
    )
    return path


@contextlib.contextmanager
def session_lock(folder: Path) -> Any:
    """Hold an exclusive lock on the session folder (POSIX; released if the process dies)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    handle = open(folder / ".acquire.lock", "a")  # noqa: SIM115
    try:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise AcquisitionError(f"another hexatherm acquire is recording {folder}") from None
        yield
    finally:
        handle.close()
