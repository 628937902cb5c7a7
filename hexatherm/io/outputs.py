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
   since, or a sub-folder the manifest lists, whole (:func:`foreign_entries`; a nested
   folder with a manifest of its own is another output, and foreign), and when it holds
   no session (``session.yaml`` anywhere in it: only ``simulate``, whose outputs are
   sessions, replaces one; :func:`session_entries`). A single-file output is replaced only when the
   manifest of its folder lists it with its current SHA-256. Anything else is refused
   with :class:`ForeignFilesError`, naming the files.

   And only what the *same command* wrote: each file's entry names the command that
   wrote it (``provenance.json`` says it for a folder whose manifest does not), and
   ``report -o plan.yaml``, ``diagnose -o SESSION/results`` or ``process -o`` a
   diagnosis refuse another command's output, as they refuse a file with no such
   record (:func:`other_commands`). A run outside the command line (a script) is a
   command of its own: it replaces only what such a run wrote.

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
``check_not_input(output, inputs, *, option="-o")``; ``foreign_entries(folder)`` and
``read_manifest(folder)`` in :mod:`hexatherm.io.manifest`
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
>>> from hexatherm.io.manifest import read_manifest
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
import os
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

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
from hexatherm.io.manifest import (
    MANIFEST_MAX_BYTES,
    MANIFEST_NAME,
    Manifest,
    foreign_entries,
    manifest_for_tree,
    read_manifest,
    read_regular_bytes,
    sha256_file,
)
from hexatherm.io.provenance import (
    PROVENANCE_NAME,
    current_run,
    provenance_json,
    recorded_command,
)

__all__ = [
    "SESSION_FILE",
    "check_not_input",
    "check_output",
    "check_output_settled",
    "hexatherms_own",
    "other_commands",
    "output_dir",
    "session_entries",
    "write_output_file",
]

#: how many foreign entries a message names
_NAMED = 5

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


#: the file that makes a folder a session
SESSION_FILE = "session.yaml"


def session_entries(folder: PathLike) -> list[tuple[str, str]]:
    """The ``session.yaml`` files in ``folder``'s tree (links not followed), as foreign entries.

    A folder that holds a session holds recorded data: only a command whose output is a
    session (``simulate``) may replace it, and no recording command writes into it.

    >>> import tempfile
    >>> top = Path(tempfile.mkdtemp())
    >>> (top / "a").mkdir(); _ = (top / "a" / "session.yaml").write_text("name: a\\n")
    >>> session_entries(top)
    [('a/session.yaml', 'a session')]
    """
    top = Path(folder)
    found = []
    for where, dirs, files in os.walk(top):
        dirs.sort()
        if SESSION_FILE in files and not os.path.islink(os.path.join(where, SESSION_FILE)):
            rel = Path(where, SESSION_FILE).relative_to(top).as_posix()
            found.append((rel, "a session"))
    return sorted(found)


def _writer() -> str | None:
    """The command writing now (``None`` outside a command line)."""
    facts = current_run()
    return None if facts is None else facts.command


def _written_by(folder: Path, manifest: Manifest, name: str) -> str | None:
    """The command that wrote ``name`` of ``folder``: its manifest entry's, else the one
    ``provenance.json`` names when the manifest vouches for it (a folder written whole)."""
    command = manifest.commands.get(name)
    if command is None and PROVENANCE_NAME in manifest.files:
        path = folder / PROVENANCE_NAME
        if sha256_file(path) in manifest.files[PROVENANCE_NAME]:
            command = recorded_command(path)
    return command


def _not_by(command: str | None, writer: str | None) -> str:
    if command is None:
        return "written by hexatherm with no record of its command"
    if writer is None:
        return f"written by hexatherm {command}"
    return f"written by hexatherm {command}, not {writer}"


def other_commands(folder: PathLike, writer: str | None) -> list[tuple[str, str]]:
    """The files of ``folder`` its manifest lists that another command than ``writer``
    wrote (or with no record of which), as foreign entries: ``--overwrite`` replaces
    only an output of the same command (``report -o plan.yaml``, ``diagnose -o``
    process's results are refused).

    >>> import tempfile
    >>> from hexatherm.io.provenance import run_context
    >>> top = Path(tempfile.mkdtemp())
    >>> with run_context("process", [], {}), output_dir(top / "results") as tmp:
    ...     _ = (tmp / "poses.csv").write_text("Tx_mm\\n")
    >>> other_commands(top / "results", "diagnose")
    [('poses.csv', 'written by hexatherm process, not diagnose'), \
('provenance.json', 'written by hexatherm process, not diagnose')]
    >>> other_commands(top / "results", "process")
    []
    """
    top = Path(folder)
    manifest = read_manifest(top)
    if manifest is None:
        return []  # nothing vouched for: foreign_entries names it
    found = []
    for name in sorted(manifest.files):
        if not os.path.lexists(top / name):
            continue
        command = _written_by(top, manifest, name)
        if command != writer:
            found.append((name, _not_by(command, writer)))
    return found


def _replace_entries(target: Path, sessions: bool) -> list[tuple[str, str]]:
    """What keeps ``--overwrite`` from replacing the folder ``target``: foreign entries,
    a session (unless the output is one), the files a recording command recorded there,
    another command's output."""
    found = set(foreign_entries(target))
    if not sessions:
        found |= set(session_entries(target))
    manifest = read_manifest(target)
    if manifest is not None and manifest.recorder is not None:
        why = f"recorded by hexatherm {manifest.recorder}"
        found |= {(name, why) for name in manifest.recorded} or {(MANIFEST_NAME, why)}
        return sorted(found)
    named = {name for name, _ in found}
    others = [e for e in other_commands(target, _writer()) if e[0] not in named]
    return sorted(found) + others  # what is not hexatherm's first, then another's output


def _foreign_message(option: str, output: str, entries: list[tuple[str, str]]) -> str:
    """The refusal's line: the first :data:`_NAMED` entries, another command's files
    together (``a.csv, b.csv (written by hexatherm process, not diagnose)``)."""
    groups: dict[str, list[str]] = {}
    for name, why in entries[:_NAMED]:
        key = why if why.startswith("written by hexatherm") else f"{name}\0{why}"
        groups.setdefault(key, []).append(name)
    named = ", ".join(
        f"{', '.join(names)} ({key.rpartition(chr(0))[2]})" for key, names in groups.items()
    )
    more = f" and {len(entries) - _NAMED} more" if len(entries) > _NAMED else ""
    return (
        f"{option} {output}: --overwrite replaces only what hexatherm wrote, and it holds "
        f"{named}{more}; move them away or choose another {option}"
    )


# --------------------------------------------------------------------------- checks


def _file_foreign(path: Path, same_command: bool = False) -> str | None:
    """Why the existing file ``path`` is not hexatherm's to replace, or ``None``; nor the
    command's writing now (``same_command``)."""
    if path.is_symlink() or not path.is_file():
        return "not a regular file"
    manifest = read_manifest(path.parent)
    if manifest is None:
        return f"not written by hexatherm: no {MANIFEST_NAME} beside it"
    hashes = manifest.files.get(path.name)
    if hashes is None:
        return "not written by hexatherm"
    if manifest.recorder is not None and path.name in manifest.recorded:
        return f"recorded by hexatherm {manifest.recorder}"
    if sha256_file(path) not in hashes:
        return "changed since hexatherm wrote it"
    if same_command:
        writer = _writer()
        command = _written_by(path.parent, manifest, path.name)
        if command != writer:
            return _not_by(command, writer)
    return None


def hexatherms_own(path: PathLike) -> bool:
    """Whether the file ``path`` is an output hexatherm wrote there, unchanged since (not a
    file a recording command recorded), or the manifest that records them: not an input
    of a later run that reads its folder (a lab's templates beside the report)."""
    path = Path(path)
    if path.name == MANIFEST_NAME:
        return path.is_file() and not path.is_symlink()
    return os.path.lexists(path) and _file_foreign(path) is None


def check_output(
    output: PathLike,
    *,
    kind: Literal["folder", "file"],
    inputs: Iterable[PathLike] = (),
    overwrite: bool = False,
    option: str = "-o",
    sessions: bool = False,
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
    sessions : bool
        The output is a session (``simulate``): ``--overwrite`` may replace a folder
        that holds one (when its manifest vouches for it).

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
        entries = _replace_entries(target, sessions)
    else:
        if target.is_dir():
            raise OutputExistsError(f"{given} exists and is a folder")
        why = _file_foreign(target, same_command=True)
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
    sessions: bool = False,
) -> Path:
    """:func:`check_output`, looked at again under the output's lock when it finds foreign files.

    Without the lock, another run may be swapping the same folder while it is listed
    (entries vanish, files are replaced): what looks foreign then is only in flux. Every
    swap holds the lock, so a second look under it sees a settled folder; the answer of
    that look stands.
    """
    inputs = list(inputs)

    def check() -> Path:
        return check_output(
            output, kind=kind, inputs=inputs, overwrite=overwrite, option=option, sessions=sessions
        )

    try:
        return check()
    except ForeignFilesError:
        if not Path(os.path.abspath(output)).parent.is_dir():
            raise
        with output_lock(output, timeout_s=lock_timeout_s, on_wait=on_wait):
            return check()


@contextlib.contextmanager
def output_dir(
    output: PathLike,
    *,
    inputs: Iterable[PathLike] = (),
    overwrite: bool = False,
    option: str = "-o",
    lock_timeout_s: float = DEFAULT_LOCK_TIMEOUT_S,
    on_wait: Callable[[Path], None] | None = None,
    sessions: bool = False,
    notes: Mapping[str, Any] | None = None,
) -> Iterator[Path]:
    """Yield a temporary folder that becomes the output folder ``output`` if the block succeeds.

    Checks as :func:`check_output` before the block and again under the lock before
    the swap (another run may have written meanwhile); writes the manifest of what
    the block wrote into the folder, and (in a command line's run) ``provenance.json``
    (:mod:`hexatherm.io.provenance`, with ``notes``); swaps it in
    (:func:`hexatherm.io.atomic.atomic_output_dir`). On any error nothing is left behind.

    Parameters
    ----------
    output, inputs, overwrite, option, sessions
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
        sessions=sessions,
    )

    def under_lock(target: Path, tmp: Path) -> None:
        check_not_input(target, inputs, option=option)
        if target.is_dir():
            entries = _replace_entries(target, sessions)
            if entries:
                raise ForeignFilesError(_foreign_message(option, given, entries), entries=entries)
        facts = current_run()
        if facts is not None:  # a command line's run: where the folder came from
            (tmp / PROVENANCE_NAME).write_text(provenance_json(facts, inputs, notes), "utf-8")
        (tmp / MANIFEST_NAME).write_bytes(manifest_for_tree(tmp, _writer()).to_json())

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
        before: bytes | None = read_regular_bytes(manifest_path, MANIFEST_MAX_BYTES)
    except OSError:
        before = None  # missing, or unreadable: it vouched for nothing and is rewritten
    manifest = read_manifest(target.parent) or Manifest()
    for name in [n for n in manifest.files if "/" not in n]:
        if name != target.name and not (target.parent / name).is_file():
            del manifest.files[name]  # pruned: no longer there
    old = sha256_file(target) if target.exists() else None
    new = hashlib.sha256(payload).hexdigest()
    writer = _writer()
    manifest.record(
        target.name, new, len(payload), replaces=old if old != new else None, command=writer
    )
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
    manifest.record(target.name, new, len(payload), command=writer)
    atomic_write_bytes(manifest_path, manifest.to_json())
