"""The manifest of an output folder: what hexatherm wrote there, so that ``--overwrite``
replaces only that.

``.hexatherm-manifest.json`` lists the files hexatherm wrote in a folder (relative
path, SHA-256, size, time, and the command that wrote it), the sub-folders it made,
and the hexatherm version.
:func:`foreign_entries` names what a folder holds beyond that: files not listed,
files changed since they were written, folders nobody vouches for. The rules that
use it are in :mod:`hexatherm.io.outputs`.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path

from hexatherm import __version__
from hexatherm.io.files import digest_of

#: the manifest's file name, in every folder hexatherm writes into
MANIFEST_NAME = ".hexatherm-manifest.json"
#: the manifest's format tag
MANIFEST_FORMAT = "hexatherm-manifest/1"
#: a manifest larger than this is not hexatherm's (bytes)
MANIFEST_MAX_BYTES = 64 * 1024 * 1024
#: how many foreign entries a message names
_CHUNK = 1 << 20

PathLike = str | os.PathLike[str]


# --------------------------------------------------------------------------- manifest


def _now_utc() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


@dataclass
class Manifest:
    """What hexatherm wrote in one folder.

    Attributes
    ----------
    files : dict of str to tuple of str
        Relative path (``/``-separated) -> the SHA-256 (hex) its content may have;
        the first is the content written, a second one the content it replaces
        while a replacement is under way (so that a kill leaves either one owned).
    sizes : dict of str to int
        Relative path -> size in bytes, as written.
    times : dict of str to str
        Relative path -> UTC time of the write (ISO 8601).
    folders : tuple of str
        Sub-folders hexatherm created (relative paths).
    version : str
        hexatherm's version that wrote the manifest last.
    recorder : str or None
        The recording command (``run``, ``acquire``) whose session folder this is
        (JSON ``recorded_by``); ``None`` for a folder written whole by
        :func:`hexatherm.io.outputs.output_dir`. See :mod:`hexatherm.io.recording`.
    recorded : tuple of str
        The files the recording command wrote (JSON ``recorded_files``): measured data,
        which no ``--overwrite`` replaces.
    commands : dict of str to str
        Relative path -> the command that wrote it (JSON ``command`` of its entry:
        ``process``, ``report``); absent for a file written outside a command line, or
        by a hexatherm that did not say.
    """

    files: dict[str, tuple[str, ...]] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)
    times: dict[str, str] = field(default_factory=dict)
    folders: tuple[str, ...] = ()
    version: str = __version__
    recorder: str | None = None
    recorded: tuple[str, ...] = ()
    commands: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> bytes:
        """The manifest file's content (JSON, UTF-8)."""
        files: dict[str, dict[str, object]] = {}
        for name in sorted(self.files):
            hashes = self.files[name]
            entry: dict[str, object] = {"sha256": hashes[0]}
            if len(hashes) > 1:
                entry["replaces_sha256"] = hashes[1]
            if name in self.sizes:
                entry["bytes"] = self.sizes[name]
            if name in self.times:
                entry["written_utc"] = self.times[name]
            if name in self.commands:
                entry["command"] = self.commands[name]
            files[name] = entry
        doc = {
            "format": MANIFEST_FORMAT,
            "hexatherm": __version__,
            "written_utc": _now_utc(),
            "files": files,
            "folders": sorted(self.folders),
        }
        if self.recorder is not None:
            doc["recorded_by"] = self.recorder
            doc["recorded_files"] = sorted(self.recorded)
        return (json.dumps(doc, indent=1) + "\n").encode("utf-8")

    @classmethod
    def from_json(cls, data: bytes) -> Manifest:
        """Parse a manifest file; ``ValueError`` when it is not one."""
        doc = json.loads(data.decode("utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != MANIFEST_FORMAT:
            raise ValueError(f"not a {MANIFEST_FORMAT} file")
        raw_files = doc.get("files")
        raw_folders = doc.get("folders", [])
        if not isinstance(raw_files, dict) or not isinstance(raw_folders, list):
            raise ValueError("'files' must be a mapping and 'folders' a list")
        recorder = doc.get("recorded_by")
        if recorder is not None and not isinstance(recorder, str):
            raise ValueError("'recorded_by' must be a command's name")
        recorded = doc.get("recorded_files", [])
        if not isinstance(recorded, list) or not all(isinstance(n, str) for n in recorded):
            raise ValueError("'recorded_files' must be a list of names")
        manifest = cls(
            version=str(doc.get("hexatherm", "")), recorder=recorder, recorded=tuple(recorded)
        )
        for name, entry in raw_files.items():
            if not isinstance(entry, dict) or not isinstance(entry.get("sha256"), str):
                raise ValueError(f"entry {name!r} has no sha256")
            hashes = [entry["sha256"]]
            if isinstance(entry.get("replaces_sha256"), str):
                hashes.append(entry["replaces_sha256"])
            manifest.files[str(name)] = tuple(hashes)
            if isinstance(entry.get("bytes"), int):
                manifest.sizes[str(name)] = entry["bytes"]
            if isinstance(entry.get("written_utc"), str):
                manifest.times[str(name)] = entry["written_utc"]
            if isinstance(entry.get("command"), str):
                manifest.commands[str(name)] = entry["command"]
        manifest.folders = tuple(str(f) for f in raw_folders)
        return manifest

    def record(
        self,
        name: str,
        digest: str,
        size: int,
        replaces: str | None = None,
        command: str | None = None,
    ) -> None:
        """Record that ``name`` is written with content ``digest`` (replacing ``replaces``),
        by the command ``command`` (``None``: outside a command line)."""
        self.files[name] = (digest,) if replaces is None else (digest, replaces)
        self.sizes[name] = size
        self.times[name] = _now_utc()
        if command is None:
            self.commands.pop(name, None)
        else:
            self.commands[name] = command


def read_regular_bytes(path: Path, limit: int) -> bytes:
    """Content of a regular file (no link, no FIFO), at most ``limit`` bytes; ``OSError``."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK)
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise OSError(f"{path} is not a regular file")
        if info.st_size > limit:
            raise OSError(f"{path} is larger than {limit} bytes")
        chunks = []
        while chunk := os.read(fd, _CHUNK):
            chunks.append(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


def read_manifest(folder: PathLike) -> Manifest | None:
    """The manifest of ``folder``, or ``None`` when it has none (or an unreadable one).

    An unreadable manifest vouches for nothing: the folder is then treated as
    holding only foreign files. So does one nested deeper than JSON is read (a
    hand-made ``[[[[...]]]]``: Python's parser recurses).
    """
    try:
        return Manifest.from_json(
            read_regular_bytes(Path(folder) / MANIFEST_NAME, MANIFEST_MAX_BYTES)
        )
    except (OSError, ValueError, RecursionError):
        return None


def sha256_file(path: Path) -> str | None:
    """SHA-256 of a regular file's content (not following links); ``None`` if unreadable."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK)
    except OSError:
        return None

    def content() -> str:
        digest = hashlib.sha256()
        while chunk := os.read(fd, _CHUNK):
            digest.update(chunk)
        return digest.hexdigest()

    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            return None
        # within a command that keeps digests, a file of the same identity is read once
        return digest_of(fd, info, content)
    except OSError:
        return None
    finally:
        os.close(fd)


def foreign_entries(folder: PathLike) -> list[tuple[str, str]]:
    """Entries of ``folder`` that hexatherm did not write, or that changed since.

    Returns
    -------
    list of (str, str)
        ``(relative path, reason)``, sorted; empty when replacing ``folder`` loses
        nothing but hexatherm's own unchanged output. A sub-folder is foreign unless
        the manifest lists it (then each of its entries is checked); one with a manifest
        of its own is another output, written there by another run, and foreign too.
    """
    top = Path(folder)
    manifest = read_manifest(top)
    found: list[tuple[str, str]] = []
    _foreign_walk(top, "", manifest, found)
    return sorted(found)


def _foreign_walk(
    folder: Path, prefix: str, manifest: Manifest | None, found: list[tuple[str, str]]
) -> None:
    """Add the foreign entries of ``folder`` (``prefix`` relative to ``manifest``'s folder)."""
    no_manifest = "not written by hexatherm: no " + MANIFEST_NAME
    try:
        entries = sorted(os.scandir(folder), key=lambda e: e.name)
    except OSError as exc:
        found.append((prefix or ".", f"cannot be listed ({exc.strerror})"))
        return
    for entry in entries:
        rel = prefix + entry.name
        if rel == MANIFEST_NAME and manifest is not None and entry.is_file(follow_symlinks=False):
            continue
        if entry.is_symlink():
            found.append((rel, "a symbolic link hexatherm did not make"))
        elif entry.is_dir(follow_symlinks=False):
            sub = Path(entry.path)
            if manifest is not None and rel in manifest.folders:
                _foreign_walk(sub, rel + "/", manifest, found)
            elif read_manifest(sub) is not None:
                # another output (results/smooth, an older results folder moved in):
                # its own manifest vouches for it, not for replacing it with this folder
                found.append((rel + "/", "another output, not listed by this folder's manifest"))
            else:
                why = no_manifest if manifest is None else "a folder hexatherm did not write"
                found.append((rel + "/", why))
        elif not entry.is_file(follow_symlinks=False):
            found.append((rel, "not a regular file"))
        elif manifest is None:
            found.append((rel, no_manifest))
        elif rel not in manifest.files:
            found.append((rel, "not written by hexatherm"))
        elif sha256_file(Path(entry.path)) not in manifest.files[rel]:
            found.append((rel, "changed since hexatherm wrote it"))


def manifest_for_tree(folder: Path, command: str | None = None) -> Manifest:
    """A manifest of every file and folder under ``folder`` (a freshly written output),
    each file written by ``command``."""
    manifest = Manifest()
    folders: list[str] = []
    for top, dirs, files in os.walk(folder):
        rel_top = Path(top).relative_to(folder).as_posix()
        prefix = "" if rel_top == "." else rel_top + "/"
        folders.extend(prefix + d for d in dirs)
        for name in files:
            rel = prefix + name
            if rel == MANIFEST_NAME:
                continue
            full = Path(top) / name
            digest = sha256_file(full)
            if digest is not None:
                manifest.record(rel, digest, full.lstat().st_size, command=command)
    manifest.folders = tuple(sorted(folders))
    return manifest
