"""Where an output came from: ``provenance.json`` in every output folder.

The command line sets the run's facts once (:func:`run_context`: the command, its
arguments and options, the start time); every folder hexatherm writes through
:func:`hexatherm.io.outputs.output_dir` then gets a ``provenance.json`` beside its
manifest, with those facts, the end time, the versions of hexatherm and of the
libraries its numbers rest on, and every input file with its size and SHA-256. A run
outside the command line (a test, a script) sets none and writes none.

Times are ISO 8601 with the local UTC offset (``2026-11-25T13:02:11+01:00``).

>>> with run_context("process", ["process", "s"], {"mc": 0}):
...     facts = current_run()
>>> facts.command, facts.options, current_run() is None
('process', {'mc': 0}, True)
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import platform
import re
import shlex
import sys
from collections.abc import Iterable, Iterator, Mapping
from contextvars import ContextVar
from datetime import datetime
from pathlib import Path
from typing import Any

from hexatherm import __version__
from hexatherm.errors import InputError
from hexatherm.io.files import kept_digest

#: the file's name in every output folder
PROVENANCE_NAME = "provenance.json"
#: its format tag
PROVENANCE_FORMAT = "hexatherm-provenance/1"
#: the libraries whose versions are recorded
LIBRARIES = ("numpy", "scipy", "pandas")
_CHUNK = 1 << 20


@dataclasses.dataclass(frozen=True)
class RunFacts:
    """What the command line knows of a run.

    Attributes
    ----------
    command : str
        The command's name (``process``).
    argv : tuple of str
        Its arguments as given (after the command's name).
    options : dict
        Every parameter's value, defaults included, as JSON-ready values.
    started : str
        ISO 8601 time with offset.
    """

    command: str
    argv: tuple[str, ...]
    options: dict[str, Any]
    started: str


_current: ContextVar[RunFacts | None] = ContextVar("hexatherm_run", default=None)


def now_iso() -> str:
    """The local time, ISO 8601 to the second, with its UTC offset."""
    return datetime.now().astimezone().isoformat(timespec="seconds")


def json_ready(value: Any) -> Any:
    """``value`` with paths, tuples, dataclasses and non-finite floats made JSON values
    (``inf`` -> ``"inf"``)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return json_ready(dataclasses.asdict(value))
    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [json_ready(v) for v in value]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)


@contextlib.contextmanager
def run_context(command: str, argv: Iterable[str], options: Mapping[str, Any]) -> Iterator[None]:
    """Set the run's facts for the block (the command line does, once per command)."""
    facts = RunFacts(command, tuple(argv), json_ready(dict(options)), now_iso())
    token = _current.set(facts)
    try:
        yield
    finally:
        _current.reset(token)


def current_run() -> RunFacts | None:
    """The facts of the command running, or None outside the command line."""
    return _current.get()


def _sha256(path: Path) -> str:
    """The file's SHA-256: the one kept when the command read it (:func:`digests_kept`),
    or by reading it."""
    kept = kept_digest(path)
    if kept is not None:
        return kept
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while chunk := handle.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def _normalized(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def _version(name: str) -> str | None:
    """The installed version of the distribution ``name``, as ``importlib.metadata``
    gives it: the version in the name of the first ``<name>-<version>.dist-info`` folder
    along ``sys.path`` (the wheel's rule, PEP 427; pip installs them so), without
    loading ``importlib.metadata`` and the email parser it reads the metadata with
    (a fifth of the CPU of writing ``process``'s folder). A distribution without such
    a folder (an egg, a zip on the path) is looked up by ``importlib.metadata``."""
    wanted = _normalized(name)
    for entry in sys.path:
        try:
            names = os.listdir(entry or ".")
        except OSError:
            continue
        for found in names:
            if found.endswith(".dist-info"):
                project, _, version = found[: -len(".dist-info")].partition("-")
                if version and _normalized(project) == wanted:
                    return version
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def input_entries(inputs: Iterable[str | os.PathLike[str]]) -> list[dict[str, Any]]:
    """Every input once, in order: ``{"path", "bytes", "sha256"}`` for a file (the
    absolute path), ``{"path", "folder": True}`` for a folder, ``{"path"}`` for neither."""
    files = []
    for given in dict.fromkeys(os.path.abspath(p) for p in inputs):
        path = Path(given)
        entry: dict[str, Any] = {"path": given}
        if path.is_file():
            entry["bytes"] = path.stat().st_size
            try:
                entry["sha256"] = _sha256(path)
            except OSError as exc:  # unreadable: its mode, a failing disk or share
                raise InputError(f"cannot be read ({exc.strerror or exc})", path=given) from None
        elif path.is_dir():
            entry["folder"] = True
        files.append(entry)
    return files


#: the largest provenance.json read back (bytes): hexatherm writes a few kilobytes
PROVENANCE_MAX_BYTES = 16 * 2**20


def recorded_command(path: str | os.PathLike[str]) -> str | None:
    """The command a ``provenance.json`` says wrote its folder, or ``None`` when it is
    not one (unreadable, too large, not JSON, nested past the parser, not hexatherm's)."""
    try:
        with open(path, "rb") as handle:
            data = handle.read(PROVENANCE_MAX_BYTES + 1)
        if len(data) > PROVENANCE_MAX_BYTES:
            return None
        doc = json.loads(data.decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not isinstance(doc, dict) or doc.get("format") != PROVENANCE_FORMAT:
        return None
    command = doc.get("command")
    return command if isinstance(command, str) else None


def command_line(facts: RunFacts) -> str:
    """The run's command line quoted as a POSIX shell reads it, so that it runs as printed
    (a path with a space or a quote stays one argument; plain arguments are unchanged).

    >>> facts = RunFacts("report", ("Sessions 2026/s1", "-o", "out"), {}, "")
    >>> command_line(facts)
    "hexatherm report 'Sessions 2026/s1' -o out"
    """
    return shlex.join(["hexatherm", facts.command, *facts.argv])


def provenance_json(
    facts: RunFacts,
    inputs: Iterable[str | os.PathLike[str]],
    notes: Mapping[str, Any] | None = None,
) -> str:
    """The content of ``provenance.json`` for a run that read ``inputs``; ``notes``, what
    the command found that a later reader of its outputs needs (``process``: its warnings),
    under the command's name."""
    files = input_entries(inputs)
    doc = {
        "format": PROVENANCE_FORMAT,
        "hexatherm": __version__,
        "command": facts.command,
        "command_line": command_line(facts),
        "argv": list(facts.argv),
        "options": facts.options,
        "started": facts.started,
        "finished": now_iso(),
        "inputs": files,
        "python": platform.python_version(),
        "libraries": {name: _version(name) for name in LIBRARIES},
    }
    if notes is not None:
        doc[facts.command] = json_ready(dict(notes))
    return json.dumps(doc, indent=1, allow_nan=False) + "\n"
