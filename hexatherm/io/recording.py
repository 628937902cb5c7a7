"""Session folders of the recording commands (``run``, ``acquire``): the output guard for
folders that grow while a machine measures.

A recording command cannot build its folder beside the target and swap it in: the
folder *is* the record, written line by line as the data arrives. It still follows the
rules of :mod:`hexatherm.io.outputs`, through the same manifest:

1. **Inputs are never outputs**: ``--session`` may not be, contain or sit inside the
   plan, hexapod, balls or temperatures file the command reads
   (:func:`~hexatherm.io.outputs.check_not_input`).
2. **A new recording goes into a new or empty folder, or one the same command recorded
   and left with nothing measured** (a run refused before its first probing can be
   started again). Such a folder's manifest, ``.hexatherm-manifest.json``, says which
   command recorded it (``recorded_by``) and lists the files it wrote, with their
   SHA-256 when the command last stopped. Anything else in the folder is foreign and
   the folder is refused before anything is written (:func:`check_new_recording`),
   naming what it holds: a session (``session.yaml``; a recorded, simulated or copied
   session is never written into), files hexatherm did not write, files changed since,
   a manifest of another command. The command's own check that nothing was measured yet
   comes first (its message says ``--resume``).
3. **``--resume`` continues only a folder the same command recorded**
   (:func:`check_resume`): a folder whose manifest names another command (a ``run``'s
   folder given to ``acquire --resume``, a simulated session) is refused. A recording
   made before the manifest existed has none and is resumed as before.

:func:`recording_manifest` keeps the manifest while the command records: written when
it starts and again when it stops for any reason (an error, Ctrl-C); a killed process
leaves the first one (its logs then count as changed, which only matters to a *new*
recording, and a killed run's folder is resumed anyway).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from hexatherm.errors import ForeignFilesError, HexathermError, OutputExistsError
from hexatherm.io.atomic import atomic_write_bytes
from hexatherm.io.manifest import (
    MANIFEST_NAME,
    Manifest,
    foreign_entries,
    read_manifest,
    sha256_file,
)
from hexatherm.io.outputs import SESSION_FILE, check_not_input, session_entries

__all__ = [
    "check_new_recording",
    "check_resume",
    "recording_manifest",
]

#: how many entries a message names
_NAMED = 5

PathLike = str | os.PathLike[str]


def _message(option: str, folder: str, command: str, entries: list[tuple[str, str]]) -> str:
    named = ", ".join(f"{name} ({why})" for name, why in entries[:_NAMED])
    more = f" and {len(entries) - _NAMED} more" if len(entries) > _NAMED else ""
    return (
        f"{option} {folder}: {command} records only into a new or empty folder, or one it "
        f"recorded itself (continue that with --resume), and it holds {named}{more}; "
        f"nothing was written; choose another {option}"
    )


def _top_entries(folder: Path, why: str) -> list[tuple[str, str]]:
    out = []
    try:
        listed = sorted(os.scandir(folder), key=lambda e: e.name)
    except OSError as exc:
        return [(".", f"cannot be listed ({exc.strerror})")]
    for entry in listed:
        is_dir = entry.is_dir(follow_symlinks=False)
        out.append((entry.name + ("/" if is_dir else ""), why))
    return out


def check_new_recording(
    folder: PathLike,
    *,
    command: str,
    inputs: Iterable[PathLike] = (),
    option: str = "--session",
) -> None:
    """Refuse a folder a new recording of ``command`` may not write into (rules 1 and 2).

    Reads only; call it before anything is created.

    Raises
    ------
    OutputIsInputError
        ``folder`` is, contains or sits inside an input.
    OutputExistsError
        ``folder`` exists and is not a folder.
    ForeignFilesError
        ``folder`` holds a session or anything ``command`` did not record there.
    """
    given = os.fspath(folder)
    check_not_input(given, list(inputs), option=option)
    path = Path(given)
    if not os.path.lexists(path):
        return
    if not path.is_dir():
        raise OutputExistsError(f"{option} {given} exists and is not a folder")
    entries = session_entries(path)
    manifest = read_manifest(path)
    if manifest is None or manifest.recorder != command:
        why = (
            f"not recorded by hexatherm {command}"
            if manifest is None
            else f"written by hexatherm {manifest.recorder or 'as an output'}, not by {command}"
        )
        entries += [e for e in _top_entries(path, why) if e[0] != SESSION_FILE]
    else:
        entries += [e for e in foreign_entries(path) if e[0] != SESSION_FILE]
        why = f"written by hexatherm as an output, not recorded by {command}"
        entries += [(n, why) for n in sorted(manifest.files) if n not in manifest.recorded]
    if entries:
        raise ForeignFilesError(_message(option, given, command, entries), entries=entries)


def check_resume(folder: PathLike, *, command: str, option: str = "--session") -> None:
    """Refuse ``--resume`` on a folder whose manifest says another command wrote it (rule 3)."""
    given = os.fspath(folder)
    manifest = read_manifest(given)
    if manifest is None or manifest.recorder == command:
        return
    who = f"hexatherm {manifest.recorder}" if manifest.recorder else "hexatherm as an output"
    entries = [(MANIFEST_NAME, f"written by {who}")]
    raise ForeignFilesError(
        f"{option} {given}: --resume continues a folder hexatherm {command} recorded, and "
        f"this one was written by {who}; nothing was written",
        entries=entries,
    )


def _record(folder: Path, command: str, names: Iterable[str]) -> None:
    """List in ``folder``'s manifest the files of ``names`` that are there, as they are now."""
    old = read_manifest(folder)
    manifest = Manifest(recorder=command)
    recorded = set(names)
    others: set[str] = set()  # files an output command wrote there since (a report)
    if old is not None and old.recorder == command:
        recorded |= set(old.recorded)
        others = {n for n in old.files if "/" not in n} - recorded
    present = []
    for name in sorted(recorded | others):
        path = folder / name
        digest = sha256_file(path)
        if digest is not None:
            manifest.record(name, digest, path.lstat().st_size)
            present.append(name)
    manifest.recorded = tuple(n for n in present if n in recorded)
    atomic_write_bytes(folder / MANIFEST_NAME, manifest.to_json())


@contextlib.contextmanager
def recording_manifest(folder: PathLike, command: str, names: Iterable[str]) -> Iterator[None]:
    """Keep ``folder``'s manifest while ``command`` records into it.

    Parameters
    ----------
    folder : path-like
        The session folder (it exists, and passed :func:`check_new_recording` or
        :func:`check_resume`).
    command : str
        ``run`` or ``acquire``.
    names : iterable of str
        The files the command writes there (only those are listed: a file of another
        name that appears meanwhile stays foreign).
    """
    path = Path(folder)
    names = tuple(names)
    _record(path, command, names)
    try:
        yield
    finally:
        # a manifest that cannot be written only makes a later new recording refuse
        with contextlib.suppress(OSError, HexathermError):
            _record(path, command, names)
