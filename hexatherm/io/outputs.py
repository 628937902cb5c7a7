"""Outputs that never destroy recorded data: the checks every command makes before writing.

Three rules, for every output of every command:

1. **Inputs are never outputs.** An output may not be, contain, or sit inside any
   input the run reads (:func:`check_not_input`; symbolic links and ``..`` resolved,
   hard links to an input caught): ``-o .`` inside a session, ``-o`` the parent of
   several sessions, ``-o centres.csv`` are refused, naming the input.
2. **``--overwrite`` replaces only what hexatherm wrote.** Every folder hexatherm
   writes into holds a manifest, ``.hexatherm-manifest.json``, listing the files it
   wrote there (relative path, SHA-256, size, time) and the hexatherm version. A folder
   output is replaced only when every entry in it is a file of its manifest, unchanged
   since, or a sub-folder the manifest lists or whose own manifest vouches for all of
   it (:func:`foreign_entries`). A single-file output is replaced only when the
   manifest of its folder lists it with its current SHA-256. Anything else is refused
   with :class:`ForeignFilesError`, naming the files.

   A file *changed* since hexatherm wrote it counts as foreign: once a person has
   edited a result (a note, a corrected row), it is their data, and ``--overwrite``
   (which means "replace my previous run") must not destroy it silently. Moving it
   away or deleting it is one deliberate command. A folder without a manifest (an
   output of hexatherm before 0.1.0, or anything else) is refused unless it is empty.
3. **No half-written or lost output**, through :mod:`hexatherm.io.atomic`: a folder
   is built beside the target and swapped in under a lock, a killed swap is repaired
   by the next write of the same output, files and folders are fsynced, modes follow
   the umask, and file-system errors (disk full, read-only, dangling link) are one
   line (:class:`OutputWriteError`) with nothing left behind.

API for the commands
--------------------
``check_output(output, *, kind, inputs=(), overwrite=False, option="-o")``
    Every check, before any work: call it first so that a run that would be refused
    at the end is refused at the start.
``output_dir(output, *, inputs=(), overwrite=False, option="-o", lock_timeout_s=..., on_wait=None)``
    Context manager yielding a temporary folder to fill; checks again under the lock,
    adds the manifest and swaps the folder in when the block succeeds.
``write_output_file(output, data, *, inputs=(), overwrite=False, option="-o", ...)``
    Write one file (``str`` as UTF-8, or ``bytes``) and record it in its folder's
    manifest.
``check_not_input(output, inputs, *, option="-o")``, ``foreign_entries(folder)``,
``read_manifest(folder)``
    The pieces, for callers that need them alone.

Errors (all :class:`~hexatherm.errors.HexathermError`, one line):
:class:`OutputIsInputError`, :class:`ForeignFilesError` (an
:class:`~hexatherm.errors.OutputExistsError`), ``OutputExistsError`` (exists and no
``--overwrite``), :class:`OutputWriteError`, :class:`OutputBusyError`.

>>> import tempfile
>>> session = Path(tempfile.mkdtemp())
>>> _ = (session / "centres.csv").write_text("step,ball,x,y,z\\n")
>>> inputs = [session / "centres.csv"]
>>> with output_dir(session / "results", inputs=inputs) as tmp:
...     _ = (tmp / "poses.csv").write_text("Tx_mm\\n0.0\\n")
>>> sorted(read_manifest(session / "results").files)
['poses.csv']
>>> try:
...     check_output(session, kind="folder", inputs=inputs, overwrite=True)
... except OutputIsInputError as exc:
...     print(exc)
-o ...: the output folder contains the input .../centres.csv; choose another -o
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import stat
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from hexatherm import __version__
from hexatherm.errors import (
    ForeignFilesError,
    HexathermError,
    OutputExistsError,
    OutputIsInputError,
)
from hexatherm.io.atomic import (
    DEFAULT_LOCK_TIMEOUT_S,
    atomic_output_dir,
    atomic_write_bytes,
    make_parents,
    output_lock,
    recover_output,
    remove_created,
    resolve_output_path,
)

__all__ = [
    "MANIFEST_NAME",
    "Manifest",
    "check_not_input",
    "check_output",
    "check_output_settled",
    "foreign_entries",
    "output_dir",
    "read_manifest",
    "write_output_file",
]

#: the manifest's file name, in every folder hexatherm writes into
MANIFEST_NAME = ".hexatherm-manifest.json"
#: the manifest's format tag
MANIFEST_FORMAT = "hexatherm-manifest/1"
#: a manifest larger than this is not hexatherm's (bytes)
MANIFEST_MAX_BYTES = 64 * 1024 * 1024
#: how many foreign entries a message names
_NAMED = 5
_CHUNK = 1 << 20

PathLike = str | os.PathLike[str]


# --------------------------------------------------------------------------- inputs


def _real(path: PathLike) -> Path:
    return Path(os.path.normcase(os.path.realpath(path)))


def check_not_input(output: PathLike, inputs: Iterable[PathLike], *, option: str = "-o") -> None:
    """Refuse an output that is, contains, or sits inside an input.

    Parameters
    ----------
    output : path-like
        The output file or folder (need not exist).
    inputs : iterable of path-like
        Every file and folder the run reads. A folder input protects everything in
        it; a file input protects that file (give the files of a session, not the
        session folder, when the default output is inside the session).
    option : str
        The option the output came from, for the message (``-o``, ``--dump``).

    Raises
    ------
    OutputIsInputError
        Naming the option, the output and the input.

    Examples
    --------
    >>> check_not_input("s/results", ["s/centres.csv", "s/session.yaml"])
    >>> try:
    ...     check_not_input("s/./", ["s/centres.csv"])
    ... except OutputIsInputError as exc:
    ...     print(exc)
    -o s/./: the output folder contains the input s/centres.csv; choose another -o
    """
    out = os.fspath(output)
    real_out = _real(out)
    out_exists = os.path.exists(out)
    for item in inputs:
        given = os.fspath(item)
        real_in = _real(given)
        if real_in == real_out or (
            out_exists and os.path.exists(given) and os.path.samefile(out, given)
        ):
            what = "is the input"
        elif real_in.is_relative_to(real_out):
            what = "folder contains the input"
        elif real_out.is_relative_to(real_in):
            what = "is inside the input folder" if os.path.isdir(given) else "is inside the input"
        else:
            continue
        raise OutputIsInputError(
            f"{option} {out}: the output {what} {given}; choose another {option}",
            output=out,
            input=given,
        )


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
    """

    files: dict[str, tuple[str, ...]] = field(default_factory=dict)
    sizes: dict[str, int] = field(default_factory=dict)
    times: dict[str, str] = field(default_factory=dict)
    folders: tuple[str, ...] = ()
    version: str = __version__

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
            files[name] = entry
        doc = {
            "format": MANIFEST_FORMAT,
            "hexatherm": __version__,
            "written_utc": _now_utc(),
            "files": files,
            "folders": sorted(self.folders),
        }
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
        manifest = cls(version=str(doc.get("hexatherm", "")))
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
        manifest.folders = tuple(str(f) for f in raw_folders)
        return manifest

    def record(self, name: str, digest: str, size: int, replaces: str | None = None) -> None:
        """Record that ``name`` is written with content ``digest`` (replacing ``replaces``)."""
        self.files[name] = (digest,) if replaces is None else (digest, replaces)
        self.sizes[name] = size
        self.times[name] = _now_utc()


def _read_regular(path: Path, limit: int) -> bytes:
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
    holding only foreign files.
    """
    try:
        return Manifest.from_json(_read_regular(Path(folder) / MANIFEST_NAME, MANIFEST_MAX_BYTES))
    except (OSError, ValueError):
        return None


def _sha256_file(path: Path) -> str | None:
    """SHA-256 of a regular file's content (not following links); ``None`` if unreadable."""
    digest = hashlib.sha256()
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        while chunk := os.read(fd, _CHUNK):
            digest.update(chunk)
    except OSError:
        return None
    finally:
        os.close(fd)
    return digest.hexdigest()


def foreign_entries(folder: PathLike) -> list[tuple[str, str]]:
    """Entries of ``folder`` that hexatherm did not write, or that changed since.

    Returns
    -------
    list of (str, str)
        ``(relative path, reason)``, sorted; empty when replacing ``folder`` loses
        nothing but hexatherm's own unchanged output. A sub-folder is foreign unless
        the manifest lists it or it has a manifest of its own that vouches for all of it.
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
            elif (own := read_manifest(sub)) is not None:
                nested: list[tuple[str, str]] = []
                _foreign_walk(sub, "", own, nested)
                found.extend((f"{rel}/{name}", why) for name, why in nested)
            else:
                why = no_manifest if manifest is None else "a folder hexatherm did not write"
                found.append((rel + "/", why))
        elif not entry.is_file(follow_symlinks=False):
            found.append((rel, "not a regular file"))
        elif manifest is None:
            found.append((rel, no_manifest))
        elif rel not in manifest.files:
            found.append((rel, "not written by hexatherm"))
        elif _sha256_file(Path(entry.path)) not in manifest.files[rel]:
            found.append((rel, "changed since hexatherm wrote it"))


def _foreign_message(option: str, output: str, entries: list[tuple[str, str]]) -> str:
    named = ", ".join(f"{name} ({why})" for name, why in entries[:_NAMED])
    more = f" and {len(entries) - _NAMED} more" if len(entries) > _NAMED else ""
    return (
        f"{option} {output}: --overwrite replaces only what hexatherm wrote, and it holds "
        f"{named}{more}; move them away or choose another {option}"
    )


def _manifest_for_tree(folder: Path) -> Manifest:
    """A manifest of every file and folder under ``folder`` (a freshly written output)."""
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
            digest = _sha256_file(full)
            if digest is not None:
                manifest.record(rel, digest, full.lstat().st_size)
    manifest.folders = tuple(sorted(folders))
    return manifest


# --------------------------------------------------------------------------- checks


def _file_foreign(path: Path) -> str | None:
    """Why the existing file ``path`` is not hexatherm's to replace, or ``None``."""
    if path.is_symlink() or not path.is_file():
        return "not a regular file"
    manifest = read_manifest(path.parent)
    if manifest is None:
        return f"not written by hexatherm: no {MANIFEST_NAME} beside it"
    hashes = manifest.files.get(path.name)
    if hashes is None:
        return "not written by hexatherm"
    if _sha256_file(path) not in hashes:
        return "changed since hexatherm wrote it"
    return None


def check_output(
    output: PathLike,
    *,
    kind: Literal["folder", "file"],
    inputs: Iterable[PathLike] = (),
    overwrite: bool = False,
    option: str = "-o",
) -> Path:
    """Every check of an output, before any work is done.

    Parameters
    ----------
    output : path-like
        The output folder or file.
    kind : {'folder', 'file'}
        What the command writes there.
    inputs : iterable of path-like
        Every file and folder the run reads.
    overwrite : bool
        ``--overwrite`` was given.
    option : str
        The option the output came from, for messages.

    Returns
    -------
    Path
        The real path the output will be written to (links resolved).

    Raises
    ------
    OutputIsInputError
        The output is, contains or sits inside an input.
    OutputExistsError
        It exists and ``overwrite`` is false, or it is not of ``kind``.
    ForeignFilesError
        ``overwrite`` would replace something hexatherm did not write, or edited files.
    OutputWriteError
        A dangling link or a file where a folder is needed.
    """
    if kind not in ("folder", "file"):
        raise ValueError(f"kind must be 'folder' or 'file', got {kind!r}")
    given = os.fspath(output)
    inputs = list(inputs)
    check_not_input(given, inputs, option=option)
    target = resolve_output_path(given)
    check_not_input(target, inputs, option=option)
    if target.name == MANIFEST_NAME:
        raise OutputIsInputError(
            f"{option} {given}: {MANIFEST_NAME} is hexatherm's record of what it wrote; "
            f"choose another {option}",
            output=given,
            input=os.fspath(target),
        )
    if not os.path.lexists(target):
        return target
    if not overwrite:
        raise OutputExistsError(f"{given} exists; use --overwrite to replace it")
    if kind == "folder":
        if not target.is_dir():
            raise OutputExistsError(f"{given} exists and is not a folder")
        entries = foreign_entries(target)
    else:
        if target.is_dir():
            raise OutputExistsError(f"{given} exists and is a folder")
        why = _file_foreign(target)
        entries = [] if why is None else [(target.name, why)]
    if entries:
        raise ForeignFilesError(_foreign_message(option, given, entries), entries=entries)
    return target


# --------------------------------------------------------------------------- writes


def check_output_settled(
    output: PathLike,
    *,
    kind: Literal["folder", "file"],
    inputs: Iterable[PathLike] = (),
    overwrite: bool = False,
    option: str = "-o",
    lock_timeout_s: float = DEFAULT_LOCK_TIMEOUT_S,
    on_wait: Callable[[Path], None] | None = None,
) -> Path:
    """:func:`check_output`, looked at again under the output's lock when it finds foreign files.

    Without the lock, another run may be swapping the same folder while it is listed
    (entries vanish, files are replaced): what looks foreign then is only in flux. Every
    swap holds the lock, so a second look under it sees a settled folder; the answer of
    that look stands.
    """
    inputs = list(inputs)
    try:
        return check_output(output, kind=kind, inputs=inputs, overwrite=overwrite, option=option)
    except ForeignFilesError:
        if not Path(os.path.abspath(output)).parent.is_dir():
            raise
        with output_lock(output, timeout_s=lock_timeout_s, on_wait=on_wait):
            return check_output(
                output, kind=kind, inputs=inputs, overwrite=overwrite, option=option
            )


@contextlib.contextmanager
def output_dir(
    output: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    overwrite: bool = False,
    option: str = "-o",
    lock_timeout_s: float = DEFAULT_LOCK_TIMEOUT_S,
    on_wait: Callable[[Path], None] | None = None,
) -> Iterator[Path]:
    """Yield a temporary folder that becomes the output folder ``output`` if the block succeeds.

    Checks as :func:`check_output` before the block and again under the lock before
    the swap (another run may have written meanwhile); writes the manifest of what
    the block wrote into the folder; swaps it in (:func:`hexatherm.io.atomic.atomic_output_dir`).
    On any error nothing is left behind and ``output`` is as it was.

    Parameters
    ----------
    output, inputs, overwrite, option
        As :func:`check_output`.
    lock_timeout_s : float
        How long to wait for another run writing in the same folder.
    on_wait : callable, optional
        Called with the folder when waiting for another run (to tell the user).
    """
    inputs = list(inputs)
    given = os.fspath(output)
    check_output_settled(
        given,
        kind="folder",
        inputs=inputs,
        overwrite=overwrite,
        option=option,
        lock_timeout_s=lock_timeout_s,
        on_wait=on_wait,
    )

    def under_lock(target: Path, tmp: Path) -> None:
        check_not_input(target, inputs, option=option)
        if target.is_dir():
            entries = foreign_entries(target)
            if entries:
                raise ForeignFilesError(_foreign_message(option, given, entries), entries=entries)
        (tmp / MANIFEST_NAME).write_bytes(_manifest_for_tree(tmp).to_json())

    with atomic_output_dir(
        given,
        overwrite=overwrite,
        lock_timeout_s=lock_timeout_s,
        on_wait=on_wait,
        before_swap=under_lock,
    ) as tmp:
        yield tmp


def write_output_file(
    output: PathLike,
    data: str | bytes,
    *,
    inputs: Iterable[PathLike] = (),
    overwrite: bool = False,
    option: str = "-o",
    lock_timeout_s: float = DEFAULT_LOCK_TIMEOUT_S,
    on_wait: Callable[[Path], None] | None = None,
) -> Path:
    """Write the output file ``output`` and record it in its folder's manifest.

    ``str`` is written as UTF-8 without newline translation. The manifest first
    lists the new content beside the old one, then the file is replaced atomically,
    then the manifest lists the new content only: a kill at any point leaves a file
    the manifest vouches for. On an error the file and the manifest are as they were.

    Parameters
    ----------
    output, inputs, overwrite, option
        As :func:`check_output`.
    data : str or bytes
        The content.
    lock_timeout_s, on_wait
        As :func:`output_dir`.

    Returns
    -------
    Path
        The file written (links resolved).
    """
    inputs = list(inputs)
    given = os.fspath(output)
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    target = check_output(given, kind="file", inputs=inputs, overwrite=overwrite, option=option)
    created = make_parents(target)
    done = False
    try:
        with output_lock(target, timeout_s=lock_timeout_s, on_wait=on_wait):
            recover_output(target)
            target = check_output(
                given, kind="file", inputs=inputs, overwrite=overwrite, option=option
            )
            _write_recorded(target, payload)
        done = True
    finally:
        if not done:
            remove_created(created)
    return target


def _write_recorded(target: Path, payload: bytes) -> None:
    """Write ``target`` and its manifest entry (under the lock, checks done)."""
    manifest_path = target.parent / MANIFEST_NAME
    existed = os.path.lexists(manifest_path)
    try:
        before: bytes | None = _read_regular(manifest_path, MANIFEST_MAX_BYTES)
    except OSError:
        before = None  # missing, or unreadable: it vouched for nothing and is rewritten
    manifest = read_manifest(target.parent) or Manifest()
    for name in [n for n in manifest.files if "/" not in n]:
        if name != target.name and not (target.parent / name).is_file():
            del manifest.files[name]  # pruned: no longer there
    old = _sha256_file(target) if target.exists() else None
    new = hashlib.sha256(payload).hexdigest()
    manifest.record(target.name, new, len(payload), replaces=old if old != new else None)
    atomic_write_bytes(manifest_path, manifest.to_json())
    try:
        atomic_write_bytes(target, payload)
    except BaseException:
        with contextlib.suppress(OSError, HexathermError):
            if not existed:
                manifest_path.unlink()
            elif before is not None:
                atomic_write_bytes(manifest_path, before)
        raise
    manifest.record(target.name, new, len(payload))
    atomic_write_bytes(manifest_path, manifest.to_json())
