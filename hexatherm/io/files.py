"""Opening input files safely: regular files only, of a bounded size.

Every reader of hexatherm's inputs (YAML, CSV, DMIS) reads a file's bytes through
:func:`read_bytes`, which

* refuses what is not a regular file (a directory, a named pipe (FIFO), a device
  such as ``/dev/zero``, a socket) by :func:`os.stat` *before* opening it: opening a
  FIFO for reading would block until a writer comes;
* opens without blocking and checks the opened file again (a file swapped for a
  FIFO between the two checks is refused too, not waited on);
* refuses a file larger than a bound (:data:`MAX_MEASUREMENT_BYTES` by default,
  :data:`MAX_YAML_BYTES` for YAML), before reading it and while reading it (a
  file that grows, or a ``/proc`` file that claims size 0, stops at the bound);
* raises :class:`~hexatherm.errors.InputError` naming the file for all of these,
  and for a missing, dangling or unreadable one.

>>> import os, tempfile
>>> with tempfile.TemporaryDirectory() as folder:
...     os.mkfifo(os.path.join(folder, "pipe"))
...     for name in ("pipe", "."):
...         try:
...             read_bytes(os.path.join(folder, name))
...         except InputError as error:
...             print(error.message)
is a named pipe (FIFO), expected a regular file
is a directory, expected a file

Warnings about input that a reader drops on request (the last record of a file
cut short, an earlier group of records) are :class:`InputWarning`, issued with the
:mod:`warnings` module so that a command can show them.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import os
import stat
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, BinaryIO

from hexatherm.errors import InputError, InputWarning

__all__ = [
    "MAX_MEASUREMENT_BYTES",
    "MAX_YAML_BYTES",
    "InputWarning",
    "read_bytes",
    "open_bounded",
    "refusal",
    "refuse_utf16",
]

#: The largest measurement file (CSV, DMIS, serial log) hexatherm reads, bytes: 2 GiB
#: (a campaign of 1000 targets with probed points is about 30 MB)
MAX_MEASUREMENT_BYTES = 2 * 1024**3
#: The largest YAML file hexatherm reads, bytes: 16 MiB (a 2000-step plan is 0.2 MB)
MAX_YAML_BYTES = 16 * 1024**2

_CHUNK = 1 << 24


@dataclass(frozen=True)
class ReadOptions:
    """What the measurement and temperature readers may read past, when asked.

    Attributes
    ----------
    allow_truncated : bool
        A file cut short (a last line without a line break, a DMIS output without
        ``ENDFIL``) loses its last record, with an :class:`~hexatherm.errors.InputWarning`,
        instead of being refused.
    keep_later : bool
        A ball probed twice in one step (two groups of rows), or a DMIS point label
        seen twice: the later one is kept, with an :class:`~hexatherm.errors.InputWarning`,
        instead of the file being refused.
    """

    allow_truncated: bool = False
    keep_later: bool = False


#: read nothing past: the default of every reader
STRICT = ReadOptions()


def _kind_of(mode: int) -> str | None:
    """What a file that is not regular is, for messages (None: a regular file)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory, expected a file"
    if stat.S_ISFIFO(mode):
        return "is a named pipe (FIFO), expected a regular file"
    if stat.S_ISCHR(mode):
        return "is a character device, expected a regular file"
    if stat.S_ISBLK(mode):
        return "is a block device, expected a regular file"
    if stat.S_ISSOCK(mode):
        return "is a socket, expected a regular file"
    return "is not a regular file"


def _os_error(exc: OSError, path: str) -> InputError:
    if exc.errno in (errno.ENOENT, errno.ENOTDIR):
        if os.path.islink(path):
            return InputError(
                f"file not found (a dangling symbolic link to {os.readlink(path)!r})", path=path
            )
        return InputError("file not found", path=path)
    return InputError(f"cannot read: {exc.strerror or exc}", path=path)


def _too_large(size: int, limit: int, path: str, more: bool = False) -> InputError:
    what = f"more than {size:,} bytes" if more else f"{size:,} bytes"
    return InputError(
        f"the file is {what}, above the limit of {limit:,} bytes for this kind of file",
        path=path,
    )


def refusal(
    path: str | os.PathLike[str], *, limit: int = MAX_MEASUREMENT_BYTES
) -> InputError | None:
    """Why :func:`read_bytes` would refuse a file before opening it, or None.

    Parameters
    ----------
    path : str or path-like
        The file (symbolic links are followed).
    limit : int, optional
        The largest size accepted, bytes.

    Returns
    -------
    InputError or None
        The error naming the file: missing, dangling link, not a regular file, too large.
    """
    where = os.fspath(path)
    try:
        info = os.stat(where)
    except OSError as exc:
        return _os_error(exc, where)
    kind = _kind_of(info.st_mode)
    if kind is not None:
        return InputError(kind, path=where)
    if info.st_size > limit:
        return _too_large(info.st_size, limit, where)
    return None


def _open_regular(where: str, limit: int) -> tuple[int, os.stat_result]:
    """A descriptor of the regular file ``where`` of at most ``limit`` bytes, opened
    without blocking, and its status: checked before opening (:func:`refusal`) and on
    the opened file (a file swapped for a FIFO between the two); InputError else."""
    refused = refusal(where, limit=limit)
    if refused is not None:
        raise refused
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    flags |= getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(where, flags)
    except OSError as exc:
        raise _os_error(exc, where) from None
    try:
        info = os.fstat(fd)
        kind = _kind_of(info.st_mode)
        if kind is not None:  # swapped after the first look
            raise InputError(kind, path=where)
        if info.st_size > limit:
            raise _too_large(info.st_size, limit, where)
    except BaseException:
        os.close(fd)
        raise
    return fd, info


def read_bytes(path: str | os.PathLike[str], *, limit: int = MAX_MEASUREMENT_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes.

    Parameters
    ----------
    path : str or path-like
        The file (symbolic links are followed).
    limit : int, optional
        The largest size accepted, bytes (:data:`MAX_MEASUREMENT_BYTES` by default;
        :data:`MAX_YAML_BYTES` for YAML).

    Returns
    -------
    bytes

    Raises
    ------
    InputError
        Naming the file: missing (or a dangling link), not a regular file (checked
        before opening, so a FIFO never blocks, and again on the opened file), larger
        than ``limit`` (checked before and while reading), or unreadable.
    """
    if limit < 0:
        raise ValueError(f"limit must be >= 0, got {limit}")
    where = os.fspath(path)
    fd, info = _open_regular(where, limit)
    try:
        parts: list[bytes] = []
        total = 0
        # one read of the whole file for a file that does not change (its one part is
        # returned as it is: no copy by the join), then parts of _CHUNK
        want = max(info.st_size + 1, 65536)
        while True:
            chunk = os.read(fd, max(1, min(want, limit + 1 - total)))
            if not chunk:
                break
            parts.append(chunk)
            total += len(chunk)
            if total > limit:
                raise _too_large(limit, limit, where, more=True)
            want = _CHUNK
        data = b"".join(parts)
        kept = _kept.get()
        if kept is not None and _identity(os.fstat(fd)) == _identity(info):
            kept[_identity(info)] = hashlib.sha256(data).hexdigest()
    except OSError as exc:
        raise _os_error(exc, where) from None
    finally:
        os.close(fd)
    return data


#: SHA-256 digests of the files :func:`read_bytes` read while :func:`digests_kept` is on,
#: by the file's identity (:func:`_identity`) when it was read
_kept: ContextVar[dict[tuple[int, ...], str] | None] = ContextVar("kept", default=None)


def _identity(info: os.stat_result) -> tuple[int, ...]:
    """What tells a file's version apart: device, inode, size, modification time (ns)."""
    return (info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns)


@contextlib.contextmanager
def digests_kept() -> Iterator[None]:
    """Within the block, :func:`read_bytes` keeps the SHA-256 of every file it reads
    (of the bytes read, while they are in memory) for :func:`kept_digest`: a command
    that records its inputs' digests (``provenance.json``) need not read them again."""
    token = _kept.set({})
    try:
        yield
    finally:
        _kept.reset(token)


def kept_digest(path: str | os.PathLike[str]) -> str | None:
    """The SHA-256 (hex) of ``path`` kept by :func:`digests_kept` when it was read, if the
    file is still the version read (same device, inode, size and modification time);
    None otherwise."""
    kept = _kept.get()
    if not kept:
        return None
    try:
        return kept.get(_identity(os.stat(path)))
    except OSError:
        return None


def digest_of(fd: int, info: os.stat_result, compute: Callable[[], str]) -> str:
    """The SHA-256 of the open file ``fd`` (status ``info``): kept by :func:`digests_kept`
    for its identity, else ``compute()``, kept when on and the file did not change while
    read. ``--overwrite`` looks at the former results three times (before the work,
    before writing, under the lock): a file of one identity is hashed once."""
    kept = _kept.get()
    key = _identity(info)
    if kept is not None and key in kept:
        return kept[key]
    digest = compute()
    if kept is not None and _identity(os.fstat(fd)) == key:
        kept[key] = digest
    return digest


class _BoundedReader(io.RawIOBase):
    """A regular file's bytes, read in order, refusing more than ``limit`` (see
    :func:`open_bounded`)."""

    def __init__(self, fd: int, path: str, limit: int) -> None:
        self._fd, self._path, self._limit, self._total = fd, path, limit, 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        view = memoryview(buffer).cast("B")
        want = max(1, min(len(view), self._limit + 1 - self._total))
        try:
            chunk = os.read(self._fd, want)
        except OSError as exc:
            raise _os_error(exc, self._path) from None
        self._total += len(chunk)
        if self._total > self._limit:
            raise _too_large(self._limit, self._limit, self._path, more=True)
        view[: len(chunk)] = chunk
        return len(chunk)

    def close(self) -> None:
        if not self.closed:
            os.close(self._fd)
        super().close()


def open_bounded(path: str | os.PathLike[str], *, limit: int = MAX_MEASUREMENT_BYTES) -> BinaryIO:
    """A regular file of at most ``limit`` bytes, opened for reading in a stream (for the
    readers that parse as they read, such as QIF's): the checks of :func:`read_bytes`
    before opening and on the opened file, and the bound again while reading (an
    :class:`~hexatherm.errors.InputError` from ``read``). Close it (``with``).

    >>> import tempfile
    >>> with tempfile.NamedTemporaryFile() as file:
    ...     _ = file.write(b"12345"); file.flush()
    ...     with open_bounded(file.name) as stream:
    ...         stream.read()
    ...     try:
    ...         open_bounded(file.name, limit=4)
    ...     except InputError as error:
    ...         print(error.message)
    b'12345'
    the file is 5 bytes, above the limit of 4 bytes for this kind of file
    """
    where = os.fspath(path)
    fd, _ = _open_regular(where, limit)
    return io.BufferedReader(_BoundedReader(fd, where, limit), buffer_size=1 << 16)


_UTF16_BOMS = {
    b"\xff\xfe\x00\x00": "UTF-32",
    b"\x00\x00\xfe\xff": "UTF-32",
    b"\xff\xfe": "UTF-16",
    b"\xfe\xff": "UTF-16",
}


def refuse_utf16(data: bytes, path: str | os.PathLike[str]) -> None:
    """InputError when ``data`` is UTF-16 or UTF-32 text (which the UTF-8 readers would
    call 'not UTF-8' or, without a byte order mark, 'NUL byte'): says so, and how to fix it.

    >>> try:
    ...     refuse_utf16("label,ball".encode("utf-16-le"), "c.csv")
    ... except InputError as error:
    ...     print(error)
    c.csv:1: looks like UTF-16 text (every other byte is NUL): save the file as UTF-8
    >>> refuse_utf16(b"label,ball", "c.csv")
    """
    for bom, name in _UTF16_BOMS.items():
        if data.startswith(bom):
            raise InputError(
                f"{name} text (byte order mark {bom.hex(' ')}): save the file as UTF-8",
                path=path,
                line=1,
            )
    head = data[:64]
    if len(head) >= 4 and len(head) % 2 == 0:
        even, odd = head[0::2], head[1::2]
        if (odd.count(0) == len(odd) and even.count(0) == 0) or (
            even.count(0) == len(even) and odd.count(0) == 0
        ):
            raise InputError(
                "looks like UTF-16 text (every other byte is NUL): save the file as UTF-8",
                path=path,
                line=1,
            )
