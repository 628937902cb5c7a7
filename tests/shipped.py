"""The shipped sessions as git tracks them: what the tests read of ``sessions/``.

A user who follows the README runs ``hexatherm process sessions/paper-zero-pose
--overwrite`` before the tests, and so leaves ``sessions/paper-zero-pose/results`` (and
maybe a ``report.html``, a ``diagnosis/``) beside the recorded files: a test that copies a
session folder, or lists its files, would read those too and fail for what lies there,
not for what the code does. So every test reads :data:`SHIPPED`: a copy, made once per
test process in a temporary folder, of the files of ``sessions/`` that git tracks
(``git ls-files``: committed or staged; a new session is seen once it is added), and of
nothing else, whatever else lies in the checkout.

Outside a git checkout (an unpacked source archive) the files that the repository's
``.gitignore`` does not ignore under ``sessions/`` are taken, the same set in a clean tree.
"""

from __future__ import annotations

import atexit
import fnmatch
import shutil
import subprocess
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _ignored_patterns() -> list[str]:
    """The ``.gitignore`` patterns of the repository that apply under ``sessions/``."""
    lines = (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()
    return [line.strip().rstrip("/") for line in lines if line.strip().startswith("sessions/")]


def tracked_files(folder: str = "sessions") -> list[str]:
    """The files under ``folder`` (relative to the repository) that git tracks, as paths
    relative to the repository, sorted."""
    try:
        out = subprocess.run(
            ["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--", folder],
            capture_output=True,
            check=True,
        ).stdout
        names = [n for n in out.decode("utf-8").split("\0") if n]
        # a file removed from the work tree but not yet from the index is not there to copy
        return sorted(n for n in names if (ROOT / n).is_file())
    except (OSError, subprocess.CalledProcessError):
        patterns = _ignored_patterns()
        found = []
        for path in sorted((ROOT / folder).rglob("*")):
            rel = path.relative_to(ROOT).as_posix()
            parts = rel.split("/")
            prefixes = ["/".join(parts[: i + 1]) for i in range(len(parts))]
            if path.is_file() and not any(
                fnmatch.fnmatchcase(p, pattern) for p in prefixes for pattern in patterns
            ):
                found.append(rel)
        return found


def _copy_tracked() -> Path:
    """A temporary folder holding the tracked files of ``sessions/`` (removed at exit)."""
    base = Path(tempfile.mkdtemp(prefix="hexatherm-shipped-"))
    atexit.register(shutil.rmtree, base, True)
    for name in tracked_files("sessions"):
        source, target = ROOT / name, base / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source, target)  # with its mode (a script's executable bit)
    root = base / "sessions"
    root.mkdir(exist_ok=True)
    return root


#: ``sessions/`` as git tracks it: read this, never ``ROOT / "sessions"``
SHIPPED = _copy_tracked()


def shipped_names() -> list[str]:
    """The shipped sessions' folder names (those with an ``expected/``), sorted."""
    return sorted(p.parent.name for p in SHIPPED.glob("*/expected"))
