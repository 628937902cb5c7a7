"""Writing without half-written output: the mechanism under :mod:`hexatherm.io.outputs`.

A file is written to a temporary file beside it, fsynced, chmodded to the umask's
mode and renamed over the target; a folder is built as a temporary folder beside it
and swapped in. The policy (inputs are never outputs, ``--overwrite`` replaces only
what hexatherm wrote) lives in :mod:`hexatherm.io.outputs`, which commands call.

Names beside an output ``NAME`` (in its parent folder):

- ``.NAME.<pid>.<random>.tmp``: the temporary file or folder of process ``<pid>``;
- ``.NAME.old.<pid>``: the previous folder, between the two renames of a swap.

The swap of a folder ``results`` is ``results -> .results.old.<pid>``, then
``.results.<pid>.<random>.tmp -> results``, then the old folder is removed. A kill
between the two renames leaves no ``results``: :func:`recover_output` (run by every
later write of the same output, under the lock) puts the old folder back, removes old
folders left after a completed swap, and removes the temporary files and folders of
processes that no longer exist. Swaps and recoveries hold an exclusive ``flock`` on
the output's parent folder (:func:`output_lock`): concurrent runs wait their turn (or
are refused with :class:`OutputBusyError` after ``lock_timeout_s``). Every file and
folder of the new output is fsynced before the swap, the parent folder after each
rename.

Modes follow the umask (``0o666 & ~umask`` for files, ``0o777 & ~umask`` for folders),
not the 0600/0700 of :func:`tempfile.mkstemp`/:func:`tempfile.mkdtemp`.

Errors of the file system (disk full, read-only folder, permission denied, a dangling
symbolic link as the output or one of its parents) become :class:`OutputWriteError`,
one line naming the path; nothing is left behind (temporary files and the parent
folders the write created are removed).

Public API
----------
``atomic_write_text(path, text, *, encoding="utf-8")``, ``atomic_write_bytes(path, data)``
    Write a file atomically (no lock, no manifest: for files hexatherm rewrites as it
    goes, such as an acquisition's log).
``atomic_output_dir(path, overwrite=False, *, lock_timeout_s=..., on_wait=None, before_swap=None)``
    Context manager yielding a temporary folder that replaces ``path`` if the block
    succeeds.
``refuse_existing(path, overwrite)``
    :class:`~hexatherm.errors.OutputExistsError` when ``path`` exists and overwriting
    was not asked for.
``output_lock(path, *, timeout_s=..., on_wait=None)``, ``recover_output(path)``
    The lock and the recovery, for callers that compose their own writes.
``file_mode()``, ``folder_mode()``
    The modes the umask gives new files and folders.

>>> import tempfile, pathlib
>>> folder = pathlib.Path(tempfile.mkdtemp())
>>> atomic_write_text(folder / "a.txt", "hello\\n")
>>> (folder / "a.txt").read_text()
'hello\\n'
>>> with atomic_output_dir(folder / "results") as tmp:
...     _ = (tmp / "poses.csv").write_text("x\\n")
>>> sorted(p.name for p in folder.iterdir())
['a.txt', 'results']
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from hexatherm.errors import OutputBusyError, OutputExistsError, OutputWriteError

try:  # POSIX only; without it writes are not serialized
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

#: how long a write waits for another hexatherm run's swap of the same folder (s)
DEFAULT_LOCK_TIMEOUT_S = 600.0
#: poll interval while waiting for the lock (s)
_LOCK_POLL_S = 0.02

#: errno -> the words of the one-line message
_REASONS = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large for the file system or the process's limit",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.ENOTDIR: "a parent is not a folder",
    errno.EISDIR: "is a folder",
    errno.ENAMETOOLONG: "name too long",
    errno.ELOOP: "too many levels of symbolic links",
}
#: flock errors of file systems that cannot lock a folder (then writes are not serialized)
_NO_LOCKS = {errno.ENOLCK, errno.EBADF, errno.EINVAL, errno.EOPNOTSUPP, errno.ENOTSUP}
#: errors that can only come from writing, wherever they are raised
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


# --------------------------------------------------------------------------- modes


_umask_lock = threading.Lock()


def current_umask() -> int:
    """The process's umask, read without changing it where the system allows.

    Linux reports it in ``/proc/self/status``; elsewhere it is set and restored
    under a lock (which other threads creating files at that instant could see).
    """
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    with _umask_lock:  # pragma: no cover - systems without /proc
        mask = os.umask(0o022)
        os.umask(mask)
        return mask


def file_mode() -> int:
    """Mode of a new file under the current umask (``0o666 & ~umask``).

    >>> old = os.umask(0o027)
    >>> oct(file_mode()), oct(folder_mode())
    ('0o640', '0o750')
    >>> _ = os.umask(old)
    """
    return 0o666 & ~current_umask()


def folder_mode() -> int:
    """Mode of a new folder under the current umask (``0o777 & ~umask``)."""
    return 0o777 & ~current_umask()


# --------------------------------------------------------------------------- fsync


def fsync_dir(path: str | os.PathLike[str]) -> None:
    """fsync a folder, so that the renames and creations in it are on disk."""
    flags = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0)
    try:
        fd = os.open(path, flags)
    except OSError:  # pragma: no cover - systems that cannot open folders
        return
    try:
        with contextlib.suppress(OSError):  # some file systems refuse fsync on folders
            os.fsync(fd)
    finally:
        os.close(fd)


def fsync_tree(path: str | os.PathLike[str]) -> None:
    """fsync every regular file and every folder under ``path`` (and ``path``)."""
    for top, _dirs, files in os.walk(path, topdown=False):
        for name in files:
            full = os.path.join(top, name)
            if not os.path.islink(full) and os.path.isfile(full):
                fd = os.open(full, os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
        fsync_dir(top)


# --------------------------------------------------------------------------- errors


def _reason(exc: OSError) -> str:
    return _REASONS.get(exc.errno or 0, exc.strerror or str(exc))


def write_error(path: str | os.PathLike[str], exc: OSError) -> OutputWriteError:
    """The one-line :class:`OutputWriteError` for ``exc`` raised writing ``path``."""
    where = f" ({exc.filename})" if exc.filename and os.fspath(exc.filename) != path else ""
    return OutputWriteError(
        f"cannot write {os.fspath(path)}: {_reason(exc)}{where}; nothing was written",
        path=path,
        errno=exc.errno,
    )


def _is_output_error(exc: OSError, tmp: Path) -> bool:
    """Whether ``exc``, raised inside a block writing into ``tmp``, is about the output."""
    if exc.errno in _WRITE_ERRNOS:
        return True
    if exc.filename is None:
        return False
    try:
        return Path(os.path.abspath(exc.filename)).is_relative_to(tmp)
    except (TypeError, ValueError):
        return False


# --------------------------------------------------------------------------- paths


def resolve_output_path(path: str | os.PathLike[str]) -> Path:
    """The real path an output ``path`` will be written to; dangling links refused.

    Symbolic links are followed one component at a time, so that ``..`` after a
    link goes where the kernel goes (not where a lexical normalization would);
    a component that is a dangling link, or a file where a folder is needed, is
    refused with :class:`OutputWriteError` (writing there would create the link's
    missing target, or fail half-way).

    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> (root / "real").mkdir(); (root / "link").symlink_to(root / "gone")
    >>> resolve_output_path(root / "real" / ".." / "x") == root.resolve() / "x"
    True
    >>> try:
    ...     resolve_output_path(root / "link" / "x")
    ... except OutputWriteError as exc:
    ...     print(exc)
    cannot write .../link/x: .../link is a symbolic link to the missing .../gone; ...
    """
    given = os.fspath(path)
    absolute = Path(given if os.path.isabs(given) else os.path.join(os.getcwd(), given))
    parts = absolute.parts
    current = Path(os.path.realpath(parts[0]))
    for i, part in enumerate(parts[1:], start=1):
        if part == "..":
            current = current.parent
            continue
        step = current / part
        if step.is_symlink():
            if not step.exists():
                raise OutputWriteError(
                    f"cannot write {given}: {step} is a symbolic link to the missing "
                    f"{os.readlink(step)}; nothing was written",
                    path=given,
                )
            step = Path(os.path.realpath(step))
        elif i < len(parts) - 1 and os.path.lexists(step) and not step.is_dir():
            raise OutputWriteError(
                f"cannot write {given}: {step} is not a folder; nothing was written",
                path=given,
            )
        current = step
    return current


def make_parents(path: Path) -> list[Path]:
    """Create the missing parents of ``path`` (umask modes); the ones created, deepest last."""
    missing = []
    for parent in path.parents:
        if os.path.lexists(parent):
            break
        missing.append(parent)
    created = []
    try:
        for folder in reversed(missing):
            os.mkdir(folder)
            created.append(folder)
    except OSError as exc:
        remove_created(created)
        raise write_error(path, exc) from None
    for folder in created:
        fsync_dir(folder.parent)
    return created


def remove_created(created: list[Path]) -> None:
    """Remove the (empty) folders of ``created``, deepest first."""
    for folder in reversed(created):
        with contextlib.suppress(OSError):
            os.rmdir(folder)


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _tmp_pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf"\.{re.escape(name)}\.(\d+)\.[A-Za-z0-9_]+\.tmp")


def _old_pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf"\.{re.escape(name)}\.old\.(\d+)")


def _remove(path: Path) -> None:
    """Remove a file, link or folder tree (missing is fine)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _stale(folder: Path, pattern: re.Pattern[str]) -> list[tuple[Path, int]]:
    """Entries of ``folder`` matching ``pattern`` whose process is gone."""
    found = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            match = pattern.fullmatch(entry.name)
            if match and not _pid_alive(int(match.group(1))):
                found.append((Path(entry.path), int(match.group(1))))
    return found


def recover_output(path: str | os.PathLike[str]) -> list[str]:
    """Repair what a killed write of ``path`` left; call under :func:`output_lock`.

    - ``path`` missing and an old folder ``.NAME.old.<pid>`` of a dead process there
      (a kill between the two renames of a swap): the old folder is renamed back;
    - old folders of dead processes beside an existing ``path`` (a kill after the
      swap, during the removal): removed;
    - temporary files and folders ``.NAME.<pid>.<random>.tmp`` of dead processes:
      removed (they were never committed).

    Returns
    -------
    list of str
        One sentence per repair (empty when there was nothing to do).
    """
    path = Path(os.path.abspath(path))
    folder, name = path.parent, path.name
    done = []
    olds = sorted(_stale(folder, _old_pattern(name)), key=lambda e: e[0].stat().st_mtime)
    if olds and not os.path.lexists(path):
        newest = olds.pop()[0]
        os.replace(newest, path)
        fsync_dir(folder)
        done.append(f"restored {path} from {newest.name} (a swap was interrupted)")
    for old, _pid in olds:
        _remove(old)
        done.append(f"removed {old} (left by an interrupted swap)")
    for tmp, _pid in _stale(folder, _tmp_pattern(name)):
        _remove(tmp)
        done.append(f"removed {tmp} (left by an interrupted write)")
    if done:
        fsync_dir(folder)
    return done


# --------------------------------------------------------------------------- lock


@contextlib.contextmanager
def output_lock(
    path: str | os.PathLike[str],
    *,
    timeout_s: float = DEFAULT_LOCK_TIMEOUT_S,
    on_wait: Callable[[Path], None] | None = None,
) -> Iterator[None]:
    """Hold an exclusive lock on the folder that holds ``path`` (``flock`` on the folder).

    The lock is the folder itself, so that nothing is left behind. Not re-entrant:
    a process holding it must not take it again.

    On a file system that cannot lock a folder (some NFS mounts answer ``ENOLCK``
    or ``EBADF``) the block runs unlocked: the swap and its recovery still work,
    but concurrent runs are not serialized there.

    Parameters
    ----------
    path : path-like
        The output; its parent folder must exist.
    timeout_s : float
        Give up after this many seconds (0: do not wait).
    on_wait : callable, optional
        Called once with the locked folder when the lock is taken by another run.

    Raises
    ------
    OutputBusyError
        The lock was not free within ``timeout_s``.
    """
    if not timeout_s >= 0:
        raise ValueError(f"timeout_s must be >= 0, got {timeout_s}")
    folder = Path(os.path.abspath(path)).parent
    if fcntl is None:  # pragma: no cover - Windows
        yield
        return
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError as exc:
        raise write_error(path, exc) from None
    try:
        deadline = time.monotonic() + timeout_s
        waited = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as exc:
                if exc.errno in _NO_LOCKS:
                    break  # a file system without flock on folders (NFS): unserialized
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise write_error(path, exc) from None
                if time.monotonic() >= deadline:
                    raise OutputBusyError(
                        f"cannot write {os.fspath(path)}: another hexatherm run is writing "
                        f"in {folder} (waited {timeout_s:g} s); try again when it is done"
                    ) from None
                if not waited and on_wait is not None:
                    on_wait(folder)
                waited = True
                time.sleep(_LOCK_POLL_S)
        yield
    finally:
        os.close(fd)  # closing the descriptor releases the lock


# --------------------------------------------------------------------------- files


def refuse_existing(path: str | os.PathLike[str], overwrite: bool) -> None:
    """Raise :class:`OutputExistsError` when ``path`` exists and overwriting was not asked."""
    if os.path.lexists(path) and not overwrite:
        raise OutputExistsError(f"{os.fspath(path)} exists; use --overwrite to replace it")


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file beside it and a rename.

    The file gets the umask's mode, is fsynced before the rename and the folder
    after it; temporary files of dead processes for the same name are removed.
    A symbolic link as ``path`` is followed (its target is replaced).

    Returns
    -------
    Path
        The file written (absolute, links resolved).

    Raises
    ------
    OutputWriteError
        The file system refused (nothing is left behind).
    """
    target = resolve_output_path(Path(path))
    if target.is_dir():
        raise OutputWriteError(
            f"cannot write {os.fspath(path)}: is a folder; nothing was written", path=path
        )
    created = make_parents(target)
    tmp: str | None = None
    done = False
    try:
        for stale, _pid in _stale(target.parent, _tmp_pattern(target.name)):
            _remove(stale)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp", dir=target.parent
        )
        try:
            if hasattr(os, "fchmod"):  # not on Windows before Python 3.13
                os.fchmod(fd, file_mode())
            _write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, target)
        done = True
        fsync_dir(target.parent)
    except OSError as exc:
        raise write_error(path, exc) from None
    finally:
        if not done:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
            remove_created(created)
    return target


def atomic_write_text(path: str | os.PathLike[str], text: str, *, encoding: str = "utf-8") -> None:
    """Write ``text`` (no newline translation) as :func:`atomic_write_bytes` does."""
    atomic_write_bytes(path, text.encode(encoding))


# --------------------------------------------------------------------------- folders


def _swap(target: Path, tmp: Path) -> None:
    """Put ``tmp`` in place of ``target`` (which may exist); call under the lock."""
    folder = target.parent
    old = None
    if os.path.lexists(target):
        old = folder / f".{target.name}.old.{os.getpid()}"
        _remove(old)  # our own pid's leftover, if the pid was reused
        os.replace(target, old)
        fsync_dir(folder)
    try:
        os.replace(tmp, target)
    except BaseException:
        if old is not None:
            os.replace(old, target)
        raise
    fsync_dir(folder)
    if old is not None:
        _remove(old)
        fsync_dir(folder)


@contextlib.contextmanager
def atomic_output_dir(
    path: str | os.PathLike[str],
    overwrite: bool = False,
    *,
    lock_timeout_s: float = DEFAULT_LOCK_TIMEOUT_S,
    on_wait: Callable[[Path], None] | None = None,
    before_swap: Callable[[Path, Path], None] | None = None,
) -> Iterator[Path]:
    """Yield a temporary folder that replaces ``path`` only if the block succeeds.

    Parameters
    ----------
    path : path-like
        The output folder (a symbolic link to a folder is followed).
    overwrite : bool
        Replace an existing ``path``; without it :class:`OutputExistsError` is raised
        before anything is written (and again at the swap, if another run created
        ``path`` meanwhile).
    lock_timeout_s : float
        How long the swap waits for another run's swap in the same folder
        (:class:`OutputBusyError` after that).
    on_wait : callable, optional
        Called with the locked folder when the swap has to wait.
    before_swap : callable, optional
        ``before_swap(target, tmp)`` is called under the lock right before the swap,
        with the recovered state of ``target`` (a policy check, a manifest to add).
        Files it writes into ``tmp`` are fsynced with the rest.

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``overwrite`` is false, or ``path`` is not a folder.
    OutputWriteError
        The file system refused (disk full, read-only, dangling link, ...).
    OutputBusyError
        Another run kept the folder locked for ``lock_timeout_s``.

    On any error the temporary folder (and the parents this call created) is
    removed and ``path`` is left as it was.
    """
    target = resolve_output_path(Path(path))
    refuse_existing(path, overwrite)
    if target.exists() and not target.is_dir():
        raise OutputExistsError(f"{os.fspath(path)} exists and is not a folder")
    created = make_parents(target)
    try:
        tmp = Path(
            tempfile.mkdtemp(
                prefix=f".{target.name}.{os.getpid()}.", suffix=".tmp", dir=target.parent
            )
        )
        os.chmod(tmp, folder_mode())
    except OSError as exc:
        remove_created(created)
        raise write_error(path, exc) from None
    try:
        try:
            yield tmp
        except OSError as exc:
            if _is_output_error(exc, tmp):
                raise write_error(path, exc) from None
            raise
        try:
            fsync_tree(tmp)
            with output_lock(target, timeout_s=lock_timeout_s, on_wait=on_wait):
                recover_output(target)
                refuse_existing(target, overwrite)
                if target.exists() and not target.is_dir():
                    raise OutputExistsError(f"{os.fspath(path)} exists and is not a folder")
                if before_swap is not None:
                    before_swap(target, tmp)
                    fsync_tree(tmp)
                _swap(target, tmp)
        except OSError as exc:
            raise write_error(path, exc) from None
    except BaseException:
        _remove(tmp)
        remove_created(created)
        raise
