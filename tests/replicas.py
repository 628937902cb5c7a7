"""Noise replicas of twin sessions for the statistical tests: written plainly, read once.

The replica tests process hundreds of simulated sessions, each as ``process`` reads a
session folder (its measurement file and thermocouple log through the readers). Two
things of the usual path are no part of what they test and cost more than the processing:

- :func:`~hexatherm.workflows.simulate.twinsession.write_files` writes through the output
  guard (a temporary folder swapped in, its manifest; 7-10 ms of CPU and some 100 ms at
  load 11 per session, fsync stubbed as in the tests): :func:`write_session` writes the
  files as plain files (about 2 ms), and leaves out the twin's ``truth/`` unless asked
  (the tests that compare with the truth take it from
  :func:`~hexatherm.workflows.simulate.twinsession.simulate_session`);
- every replica's session, hexapod, balls and plan files are the same text:
  :class:`SessionReader` reads them once and points the session at each replica's folder
  (``process_session(folder, session=...)``, as ``hexatherm process`` passes the session it
  has read), so that only the measurement files and the log are read again.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

from hexatherm.io.config import read_session
from hexatherm.session import Session
from hexatherm.workflows.process.pipeline import ProcessResult, process_session

#: the files of a session folder whose text makes its Session (beside the measurements)
CONFIG_FILES = ("session.yaml", "hexapod.yaml", "balls.yaml", "plan.yaml")


def write_session(files: Mapping[str, str], folder: Path, truth: bool = False) -> Path:
    """Write the simulated ``files`` (relative path -> text) into ``folder`` as plain files
    (``truth/`` only when ``truth``); returns ``folder``."""
    for rel, text in files.items():
        if rel.startswith("truth/") and not truth:
            continue
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8", newline="")
    return folder


def rebased(session: Session, folder: Path) -> Session:
    """``session`` read from another folder, its files in ``folder`` instead."""
    old = session.path.parent

    def move(path: Path) -> Path:
        return folder / path.relative_to(old)

    return dataclasses.replace(
        session,
        path=move(session.path),
        measurements=tuple(move(p) for p in session.measurements),
        temperatures=None if session.temperatures is None else move(session.temperatures),
        config_files=tuple(move(p) for p in session.config_files),
        formats={move(p): f for p, f in session.formats.items()},
        measurement_files=tuple(move(p) for p in session.measurement_files),
    )


class SessionReader:
    """``process_session`` of replica folders, each session's YAML files read once per
    text (the session file, hexapod, balls and plan all the same as a folder read
    before: that folder's Session, pointed at this one)."""

    def __init__(self) -> None:
        self._read: dict[tuple[str, ...], Session] = {}

    def session(self, folder: Path) -> Session:
        key = tuple((folder / name).read_text(encoding="utf-8") for name in CONFIG_FILES)
        if key not in self._read:
            self._read[key] = read_session(folder)
            return self._read[key]
        return rebased(self._read[key], folder)

    def process(self, folder: Path, **options: object) -> ProcessResult:
        """:func:`~hexatherm.workflows.process.pipeline.process_session` of ``folder``."""
        return process_session(folder, session=self.session(folder), **options)  # type: ignore[arg-type]
