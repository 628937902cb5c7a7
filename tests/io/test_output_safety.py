"""Outputs never destroy recorded data (issue 12, items 1-4): inputs, manifest, modes, errors.

Every case checks that the inputs are byte-identical afterwards and that nothing is
left behind (no temporary file or folder, no old folder, no created parent).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import stat
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm import __version__
from hexatherm.errors import (
    ForeignFilesError,
    HexathermError,
    OutputExistsError,
    OutputIsInputError,
    OutputWriteError,
)
from hexatherm.io import atomic, outputs
from hexatherm.io.atomic import (
    atomic_output_dir,
    atomic_write_text,
    refuse_existing,
)
from hexatherm.io.manifest import MANIFEST_NAME, foreign_entries, read_manifest
from hexatherm.io.outputs import check_not_input, check_output, output_dir, write_output_file
from tests.conftest import REAL_FSYNC
from tests.waiting import SAFETY_S

SESSION_FILES = {
    "session.yaml": b"format: hexatherm-session/1\nname: s\n",
    "centres.csv": b"step,ball,x_mm,y_mm,z_mm\r\nO,B1,1.000,2.000,3.000\r\n",
    "temperatures.csv": b"time,leg1_C\n2019-12-02T09:35:50,20.5\n",
    "README.md": "Sesión grabada a mano\n".encode(),
    "expected/poses.csv": b"step,Tx_mm\nS1,0.001\n",
    "truth/legs.csv": b"t_s,dq_um\n0,0\n",
}
#: what hexatherm leaves while writing: .NAME.<pid>.<random>.tmp and .NAME.old.<pid>
LEFTOVER = re.compile(r"\..+\.\d+\.[A-Za-z0-9_]+\.tmp|\..+\.old\.\d+")


def make_tree(root: Path) -> dict[str, bytes]:
    """Two sessions sA, sB and a loose note under ``root``; returns every file's content."""
    files = {}
    for session in ("sA", "sB"):
        for rel, data in SESSION_FILES.items():
            path = root / session / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data + session.encode())
            files[f"{session}/{rel}"] = data + session.encode()
    (root / "notes.txt").write_bytes(b"lab notes\n")
    files["notes.txt"] = b"lab notes\n"
    return files


def session_inputs(root: Path, session: str = "sA") -> list[Path]:
    """The files a command processing ``session`` reads."""
    return [root / session / n for n in ("session.yaml", "centres.csv", "temperatures.csv")]


def snapshot(root: Path) -> dict[str, bytes]:
    """Every regular file under ``root`` (relative path -> content), links not followed."""
    found = {}
    for top, _dirs, files in os.walk(root):
        for name in files:
            path = Path(top) / name
            if path.is_file() and not path.is_symlink():
                found[path.relative_to(root).as_posix()] = path.read_bytes()
    return found


def assert_kept(root: Path, before: dict[str, bytes]) -> None:
    """Every file of ``before`` is still there with the same bytes."""
    now = snapshot(root)
    for rel, data in before.items():
        assert rel in now, f"{rel} was removed"
        assert now[rel] == data, f"{rel} was modified"


def leftovers(root: Path) -> list[str]:
    """Temporary files and folders, old folders, anywhere under ``root``."""
    found = []
    for top, dirs, files in os.walk(root):
        for name in dirs + files:
            if LEFTOVER.fullmatch(name):
                found.append(os.path.join(top, name))
    return found


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.fixture
def tree(tmp_path: Path) -> tuple[Path, dict[str, bytes]]:
    root = tmp_path / "root"
    root.mkdir()
    return root, make_tree(root)


def write_results(path: Path | str, content: str = "1", **kwargs: object) -> None:
    with output_dir(path, **kwargs) as tmp:  # type: ignore[arg-type]
        (tmp / "poses.csv").write_text(f"Tx_mm\n{content}\n")
        (tmp / "legs.csv").write_text(f"q1_mm\n{content}\n")


# --------------------------------------------------------------------------- 1. inputs


def _link(root: Path) -> None:
    (root / "link").symlink_to(root / "sA", target_is_directory=True)


# (output relative to root, kind, inputs relative to root, fragment of the message)
INPUT_CASES = [
    ("sA", "folder", "sA/session.yaml", "folder contains the input"),
    ("sA/.", "folder", "sA/centres.csv", "folder contains the input"),
    (".", "folder", "sB/centres.csv", "folder contains the input"),
    ("sA/centres.csv", "file", "sA/centres.csv", "is the input"),
    ("sB/../sA/centres.csv", "file", "sA/centres.csv", "is the input"),
    ("link/centres.csv", "file", "sA/centres.csv", "is the input"),
    ("link", "folder", "sA/temperatures.csv", "folder contains the input"),
    ("sA/expected/poses.csv", "file", "sA/expected", "is inside the input folder"),
    ("sA/expected/new", "folder", "sA/expected", "is inside the input folder"),
    ("sA/centres.csv/x", "file", "sA/centres.csv", "is inside the input"),
    ("sA/truth", "folder", "sA/truth", "is the input"),
]


@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize(("out", "kind", "inp", "fragment"), INPUT_CASES)
def test_an_output_that_is_contains_or_sits_in_an_input_is_refused(
    tree, out, kind, inp, fragment, overwrite
):
    root, before = tree
    _link(root)
    with pytest.raises(OutputIsInputError) as caught:
        if kind == "folder":
            write_results(root / out, inputs=[root / inp], overwrite=overwrite, option="--out")
        else:
            write_output_file(root / out, "x", inputs=[root / inp], overwrite=overwrite)
    message = str(caught.value)
    assert fragment in message and str(root / inp) in message and "\n" not in message
    assert message.startswith("--out " if kind == "folder" else "-o ")
    assert caught.value.input == str(root / inp)
    assert_kept(root, before)
    assert leftovers(root) == []
    assert not (root / "sA" / MANIFEST_NAME).exists()


def test_dot_inside_a_session_is_a_clean_error(tree, monkeypatch):
    root, before = tree
    monkeypatch.chdir(root / "sA")
    inputs = [Path("session.yaml"), Path("centres.csv")]
    with pytest.raises(OutputIsInputError, match=r"^-o \.: the output folder contains"):
        write_results(".", inputs=inputs, overwrite=True)
    with pytest.raises(OutputIsInputError, match=r"^-o \.\.: the output folder contains"):
        check_output("..", kind="folder", inputs=inputs, overwrite=True)
    assert_kept(root, before)
    assert leftovers(root) == []


def test_a_hard_link_to_an_input_is_the_input(tree):
    root, before = tree
    os.link(root / "sA" / "centres.csv", root / "hard.csv")
    with pytest.raises(OutputIsInputError, match="is the input"):
        write_output_file(root / "hard.csv", "x", inputs=[root / "sA/centres.csv"], overwrite=True)
    assert_kept(root, before)


def test_outputs_beside_the_inputs_are_written(tree):
    """The control: the checks do not refuse the ordinary outputs."""
    root, before = tree
    inputs = session_inputs(root)
    write_results(root / "sA" / "results", inputs=inputs)
    page = write_output_file(root / "sA" / "report.html", "<html/>", inputs=inputs)
    check_not_input(root / "sA" / "results2", [root / "sB"])
    assert page == (root / "sA" / "report.html").resolve()
    assert (root / "sA" / "results" / "poses.csv").read_text() == "Tx_mm\n1\n"
    assert page.read_text() == "<html/>"
    assert_kept(root, before)
    assert leftovers(root) == []


# --------------------------------------------------------------------------- 2. manifest


def test_a_folder_output_records_what_it_holds(tree):
    root, _ = tree
    write_results(root / "sA" / "results", "7")
    doc = json.loads((root / "sA" / "results" / MANIFEST_NAME).read_text())
    assert doc["format"] == "hexatherm-manifest/1" and doc["hexatherm"] == __version__
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", doc["written_utc"])
    assert {name: e["sha256"] for name, e in doc["files"].items()} == {
        "poses.csv": sha256(b"Tx_mm\n7\n"),
        "legs.csv": sha256(b"q1_mm\n7\n"),
    }
    assert doc["files"]["poses.csv"]["bytes"] == len(b"Tx_mm\n7\n")
    assert foreign_entries(root / "sA" / "results") == []


def test_overwrite_replaces_hexatherms_own_folder(tree):
    root, before = tree
    out = root / "sA" / "results"
    write_results(out, "1")
    with pytest.raises(OutputExistsError, match="use --overwrite"):
        write_results(out, "2")
    write_results(out, "2", overwrite=True)
    assert (out / "poses.csv").read_text() == "Tx_mm\n2\n"
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "legs.csv", "poses.csv"]
    assert_kept(root, before)
    assert leftovers(root) == []


@pytest.mark.parametrize(
    ("spoil", "named"),
    [
        (
            lambda out: (out / "notes.txt").write_text("mine"),
            "notes.txt (not written by hexatherm)",
        ),
        (
            lambda out: (out / "poses.csv").write_text("Tx_mm\n1.5\n"),
            "poses.csv (changed since hexatherm wrote it)",
        ),
        (lambda out: (out / MANIFEST_NAME).write_text("{"), "no .hexatherm-manifest.json"),
        (
            lambda out: (out / MANIFEST_NAME).unlink(),
            "legs.csv (not written by hexatherm: no .hexatherm",
        ),
        (lambda out: (out / "raw").mkdir(), "raw/ (a folder hexatherm did not write)"),
        (lambda out: (out / "l").symlink_to(out / "poses.csv"), "l (a symbolic link"),
        (lambda out: os.mkfifo(out / "pipe"), "pipe (not a regular file)"),
    ],
)
def test_overwrite_refuses_a_folder_with_foreign_or_edited_files(tree, spoil, named):
    root, _ = tree
    out = root / "sA" / "results"
    write_results(out, "1")
    spoil(out)
    before = snapshot(root)
    with pytest.raises(ForeignFilesError) as caught:
        write_results(out, "2", overwrite=True)
    message = str(caught.value)
    assert named in message and message.startswith(f"-o {out}: --overwrite replaces only")
    assert "\n" not in message
    assert_kept(root, before)
    assert snapshot(root) == before
    assert leftovers(root) == []


def test_overwrite_refuses_a_session_folder_even_without_declared_inputs(tree):
    root, before = tree
    for target, named in ((root / "sA", "centres.csv"), (root, "sA/")):
        with pytest.raises(ForeignFilesError, match=f"{named} \\(not written by hexatherm: no"):
            write_results(target, overwrite=True)
    assert_kept(root, before)
    assert leftovers(root) == []


def test_the_message_names_five_foreign_entries_and_counts_the_rest(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    for i in range(8):
        (out / f"f{i}.csv").write_text("x")
    with pytest.raises(ForeignFilesError) as caught:
        write_results(out, overwrite=True)
    assert "f4.csv" in str(caught.value) and "f5.csv" not in str(caught.value)
    assert str(caught.value).count("and 3 more") == 1
    assert len(caught.value.entries) == 8


def test_an_empty_folder_may_be_replaced_but_never_a_nested_output(tree):
    """A nested output (its own manifest) is another run's: foreign (issue 22, item 2)."""
    root, before = tree
    out = root / "sA" / "results"
    out.mkdir()
    write_results(out, "1", overwrite=True)
    write_results(out / "sim", "9")  # a nested output with its own manifest
    (root / "sA" / "results" / "deep").mkdir()
    with output_dir(out / "deep" / "run", overwrite=True) as tmp:
        (tmp / "sub").mkdir()
        (tmp / "sub" / "a.csv").write_text("a\n")
    assert foreign_entries(out) == [
        ("deep/", "a folder hexatherm did not write"),
        ("sim/", "another output, not listed by this folder's manifest"),
    ]
    with pytest.raises(ForeignFilesError, match="sim/"):
        write_results(out, "2", overwrite=True)
    assert (out / "sim" / "poses.csv").read_text() == "Tx_mm\n9\n"
    shutil.rmtree(out / "deep")
    shutil.rmtree(out / "sim")
    write_results(out, "2", overwrite=True)
    assert sorted(p.name for p in out.iterdir()) == [MANIFEST_NAME, "legs.csv", "poses.csv"]
    assert_kept(root, before)


def test_a_sub_folder_written_by_the_block_is_hexatherms(tmp_path):
    out = tmp_path / "sim"
    with output_dir(out) as tmp:
        (tmp / "truth").mkdir()
        (tmp / "truth" / "legs.csv").write_text("t\n")
    assert read_manifest(out).folders == ("truth",)  # type: ignore[union-attr]
    assert "truth/legs.csv" in read_manifest(out).files  # type: ignore[union-attr]
    (out / "truth" / "legs.csv").write_text("edited\n")
    assert foreign_entries(out) == [("truth/legs.csv", "changed since hexatherm wrote it")]


def test_a_single_file_is_recorded_beside_it_and_replaced_only_unchanged(tree):
    root, before = tree
    page = root / "sA" / "report.html"
    write_output_file(page, "<p>1</p>")
    entry = json.loads((root / "sA" / MANIFEST_NAME).read_text())["files"]["report.html"]
    assert entry["sha256"] == sha256(b"<p>1</p>") and "replaces_sha256" not in entry
    with pytest.raises(OutputExistsError, match="use --overwrite"):
        write_output_file(page, "<p>2</p>")
    write_output_file(page, b"<p>2</p>", overwrite=True)
    assert page.read_bytes() == b"<p>2</p>"
    page.write_text("<p>2</p><!-- my note -->")
    with pytest.raises(
        ForeignFilesError, match=r"report.html \(changed since hexatherm wrote it\)"
    ):
        write_output_file(page, "<p>3</p>", overwrite=True)
    assert page.read_text() == "<p>2</p><!-- my note -->"
    assert_kept(root, before)
    assert leftovers(root) == []


@pytest.mark.parametrize("name", ["centres.csv", "README.md", "notes.txt"])
def test_overwrite_never_replaces_a_file_hexatherm_did_not_write(tree, name):
    root, before = tree
    target = root / name if name == "notes.txt" else root / "sA" / name
    write_output_file(root / "sA" / "plan.yaml", "a: 1\n")  # the folder has a manifest now
    with pytest.raises(ForeignFilesError, match=f"{name} \\(not written by hexatherm"):
        write_output_file(target, "x", overwrite=True)
    with pytest.raises(ForeignFilesError):
        check_output(target, kind="file", overwrite=True)
    assert_kept(root, before)
    assert leftovers(root) == []


def test_the_manifest_itself_is_never_an_output(tree):
    root, _ = tree
    write_output_file(root / "sA" / "plan.yaml", "a: 1\n")
    before = snapshot(root)
    with pytest.raises(OutputIsInputError, match="record of what it wrote"):
        write_output_file(root / "sA" / MANIFEST_NAME, "{}", overwrite=True)
    assert snapshot(root) == before


def test_kinds_do_not_mix(tree):
    root, before = tree
    with pytest.raises(OutputExistsError, match="is not a folder"):
        write_results(root / "notes.txt", overwrite=True)
    with pytest.raises(OutputExistsError, match="is a folder"):
        write_output_file(root / "sA", "x", overwrite=True)
    with pytest.raises(ValueError, match="kind"):
        check_output(root / "x", kind="dir")  # type: ignore[arg-type]
    assert_kept(root, before)


def test_a_failed_write_leaves_the_manifest_as_it_was(tree, monkeypatch):
    root, _ = tree
    write_output_file(root / "sA" / "a.csv", "1\n")
    before = snapshot(root)
    real = atomic.atomic_write_bytes

    def failing(path, data):
        if Path(path).name == "b.csv":
            raise OutputWriteError("cannot write b.csv: no space left", path=path)
        return real(path, data)

    monkeypatch.setattr(outputs, "atomic_write_bytes", failing)
    with pytest.raises(OutputWriteError):
        write_output_file(root / "sA" / "b.csv", "2\n")
    with pytest.raises(OutputWriteError):
        write_output_file(root / "new" / "b.csv", "2\n")
    assert snapshot(root) == before
    assert not (root / "new").exists()


def test_legacy_functions_keep_their_behaviour(tmp_path):
    out = tmp_path / "results"
    with atomic_output_dir(out) as tmp:
        (tmp / "a.csv").write_text("1\n")
    with pytest.raises(OutputExistsError, match="use --overwrite"):
        refuse_existing(out, False)
    refuse_existing(out, True)
    with atomic_output_dir(out, overwrite=True) as tmp:
        (tmp / "b.csv").write_text("2\n")
    assert sorted(p.name for p in out.iterdir()) == ["b.csv"]  # no manifest: the mechanism only
    atomic_write_text(tmp_path / "new" / "x.txt", "é\r\n")
    assert (tmp_path / "new" / "x.txt").read_bytes() == "é\r\n".encode()
    assert leftovers(tmp_path) == []


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc")
def test_files_and_folders_are_fsynced_before_the_swap_and_the_parent_after(tmp_path, monkeypatch):
    synced: list[str] = []
    real = REAL_FSYNC  # the disk flush itself (tests/conftest.py flushes nothing elsewhere)

    def spy(fd: int) -> None:
        synced.append(os.readlink(f"/proc/self/fd/{fd}"))
        real(fd)

    monkeypatch.setattr(os, "fsync", spy)
    write_results(tmp_path / "results", "1")
    write_results(tmp_path / "results", "2", overwrite=True)
    folder = str(tmp_path)
    swaps = [i for i, p in enumerate(synced) if p == folder]
    for run in (synced[: swaps[0]], synced[swaps[0] + 1 : swaps[-1]]):
        tmps = {Path(p).name for p in run if Path(p).parent == tmp_path}
        assert len(tmps) == 1 and LEFTOVER.fullmatch(tmps.pop())  # the temporary folder itself
        names = {Path(p).name for p in run if Path(p).parent.parent == tmp_path}
        assert {"poses.csv", "legs.csv", MANIFEST_NAME} <= names
    assert synced[-1] == folder  # after the old folder went
    synced.clear()
    write_output_file(tmp_path / "report.html", "x")
    assert synced[-1] == folder and any(LEFTOVER.fullmatch(Path(p).name) for p in synced)


@pytest.mark.parametrize(("code", "works"), [(errno.ENOLCK, True), (errno.EIO, False)])
def test_a_file_system_without_folder_locks_still_writes(tmp_path, monkeypatch, code, works):
    """NFS may refuse flock on a folder (ENOLCK): the write goes on, unserialized."""
    fcntl = pytest.importorskip("fcntl")

    def no_lock(fd: int, operation: int) -> None:
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(fcntl, "flock", no_lock)
    if works:
        write_results(tmp_path / "results", "1")
        write_output_file(tmp_path / "report.html", "x")
        assert (tmp_path / "results" / "poses.csv").read_text() == "Tx_mm\n1\n"
    else:
        with pytest.raises(OutputWriteError, match="cannot write"):
            write_results(tmp_path / "results", "1")
        assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- 3. modes


@contextlib.contextmanager
def umask(mask: int) -> Iterator[None]:
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


@pytest.mark.parametrize(("mask", "dmode", "fmode"), [(0o022, 0o755, 0o644), (0o077, 0o700, 0o600)])
def test_modes_follow_the_umask(tmp_path, mask, dmode, fmode):
    with umask(mask):
        write_results(tmp_path / "a" / "results")
        write_output_file(tmp_path / "b" / "report.html", "x")
        atomic_write_text(tmp_path / "c.txt", "x")

    def mode(rel: str) -> int:
        return stat.S_IMODE((tmp_path / rel).stat().st_mode)

    assert mode("a") == dmode and mode("a/results") == dmode and mode("b") == dmode
    for rel in ("a/results/poses.csv", f"a/results/{MANIFEST_NAME}", "b/report.html"):
        assert mode(rel) == fmode, rel
    assert mode(f"b/{MANIFEST_NAME}") == fmode and mode("c.txt") == fmode
    with umask(0o027):
        assert atomic.current_umask() == 0o027
        assert (atomic.file_mode(), atomic.folder_mode()) == (0o640, 0o750)


# --------------------------------------------------------------------------- 4. errors


def _fail_under(root: Path, code: int, monkeypatch, name: str = "write") -> None:
    """Make ``os.<name>`` fail with ``code`` for descriptors of files under ``root``."""
    real = getattr(os, name)

    def fake(fd, *args):
        try:
            where = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            where = ""
        if where.startswith(str(root)):
            if name == "write" and args and len(args[0]) > 3:
                real(fd, bytes(args[0])[:3])  # a partial write first, as a full disk does
            raise OSError(code, os.strerror(code))
        return real(fd, *args)

    monkeypatch.setattr(os, name, fake)


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc")
@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT, errno.EIO])
def test_a_full_disk_leaves_nothing_behind(tree, monkeypatch, code):
    root, _ = tree
    write_output_file(root / "sA" / "report.html", "<p>old</p>")
    write_results(root / "sA" / "results", "old")
    before = snapshot(root)
    _fail_under(root, code, monkeypatch, "write")
    with pytest.raises(OutputWriteError) as caught:
        write_output_file(root / "sA" / "report.html", "<p>new</p>" * 100, overwrite=True)
    assert "\n" not in str(caught.value) and caught.value.errno == code
    assert str(caught.value).startswith("cannot write ") and "nothing was written" in str(
        caught.value
    )
    with pytest.raises(OutputWriteError):
        write_output_file(root / "sB" / "deep" / "report.html", "x" * 100)
    monkeypatch.undo()
    _fail_under(root, code, monkeypatch, "fsync")  # delayed allocation: the error at fsync
    with pytest.raises(OutputWriteError, match=os.strerror(code) if code == errno.EIO else "disk"):
        write_results(root / "sA" / "results", "new", overwrite=True)
    with pytest.raises(OutputWriteError):
        write_results(root / "sB" / "x" / "y" / "results", "new")
    monkeypatch.undo()
    assert snapshot(root) == before
    assert not (root / "sB" / "deep").exists() and not (root / "sB" / "x").exists()
    assert leftovers(root) == []


def test_a_full_disk_inside_the_block_is_an_output_error(tree):
    root, _ = tree
    before = snapshot(root)
    with pytest.raises(OutputWriteError, match="no space left on the device"):
        with output_dir(root / "sA" / "results") as tmp:
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp / "poses.csv"))
    with pytest.raises(FileNotFoundError):  # an input that cannot be read stays what it is
        with output_dir(root / "sA" / "results"):
            (root / "sA" / "missing.csv").read_text()
    assert snapshot(root) == before
    assert leftovers(root) == [] and not (root / "sA" / "results").exists()


def test_a_file_size_limit_is_a_one_line_error(tmp_path):
    """A real kernel refusal (EFBIG from RLIMIT_FSIZE) in a child process."""
    out = tmp_path / "out"
    code = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))\n"
        "from hexatherm.errors import HexathermError\n"
        "from hexatherm.io.outputs import output_dir, write_output_file\n"
        "try:\n"
        "    if sys.argv[2] == 'file':\n"
        "        write_output_file(sys.argv[1] + '/big.csv', 'x' * 100000)\n"
        "    else:\n"
        "        with output_dir(sys.argv[1] + '/results') as tmp:\n"
        "            (tmp / 'big.csv').write_text('x' * 100000)\n"
        "except HexathermError as exc:\n"
        "    print(exc, file=sys.stderr)\n"
        "    sys.exit(1)\n"
    )
    out.mkdir()
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    for kind in ("file", "folder"):
        done = subprocess.run(
            [os.sys.executable, "-c", code, str(out), kind],  # type: ignore[attr-defined]
            capture_output=True,
            text=True,
            env=env,
            timeout=SAFETY_S,
        )
        assert done.returncode == 1, done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and "file too large" in lines[0], done.stderr
        assert list(out.iterdir()) == []


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[None]:
    """Make ``folder`` unwritable for this process (chmod; chattr +i for root)."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield
        finally:
            folder.chmod(0o755)
        return
    if shutil.which("chattr") is None:
        pytest.skip("root without chattr: cannot make a folder read-only")
    made = subprocess.run(["chattr", "+i", str(folder)], capture_output=True)
    if made.returncode != 0:
        pytest.skip("chattr +i refused (no CAP_LINUX_IMMUTABLE)")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(folder)], check=True)


def test_a_read_only_folder_is_a_one_line_error(tree):
    root, _ = tree
    write_output_file(root / "sA" / "report.html", "old")
    write_results(root / "sB" / "results", "old")
    before = snapshot(root)
    with read_only(root / "sA"), read_only(root / "sB"):
        for attempt in (
            lambda: write_output_file(root / "sA" / "report.html", "new", overwrite=True),
            lambda: write_output_file(root / "sA" / "new.html", "new"),
            lambda: write_results(root / "sA" / "results"),
            lambda: write_results(root / "sA" / "a" / "b"),
            lambda: write_results(root / "sB" / "results", "new", overwrite=True),
        ):
            with pytest.raises(OutputWriteError) as caught:
                attempt()
            assert re.search(r"permission denied|operation not permitted", str(caught.value))
            assert "\n" not in str(caught.value)
    assert snapshot(root) == before
    assert leftovers(root) == []


def test_a_read_only_file_system_is_a_one_line_error(tree, monkeypatch):
    root, _ = tree
    before = snapshot(root)

    def erofs(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system", kwargs.get("dir"))

    monkeypatch.setattr(tempfile, "mkstemp", erofs)
    monkeypatch.setattr(tempfile, "mkdtemp", erofs)
    with pytest.raises(OutputWriteError, match="read-only file system"):
        write_output_file(root / "sA" / "x" / "report.html", "new")
    with pytest.raises(OutputWriteError, match="read-only file system"):
        write_results(root / "sA" / "y" / "results")
    assert snapshot(root) == before
    assert sorted(p.name for p in (root / "sA").iterdir()) == sorted(
        {Path(r).parts[0] for r in SESSION_FILES}
    )


@pytest.mark.parametrize("kind", ["file", "folder"])
@pytest.mark.parametrize("where", ["output", "parent", "grandparent"])
def test_a_dangling_symlink_as_output_or_parent_is_a_one_line_error(tree, kind, where):
    root, _ = tree
    link = root / "sA" / "gone"
    link.symlink_to(root / "unmounted" / "disk")
    out = {"output": link, "parent": link / "results", "grandparent": link / "a" / "results"}[where]
    before = snapshot(root)
    with pytest.raises(OutputWriteError) as caught:
        if kind == "file":
            write_output_file(out, "x", overwrite=True)
        else:
            write_results(out, overwrite=True)
    message = str(caught.value)
    assert (
        "\n" not in message and "symbolic link to the missing" in message and str(link) in message
    )
    assert link.is_symlink() and not (root / "unmounted").exists()
    assert snapshot(root) == before
    assert leftovers(root) == []


def test_a_live_symlink_as_output_writes_through_it(tree):
    root, before = tree
    (root / "store").mkdir()
    (root / "sA" / "out").symlink_to(root / "store", target_is_directory=True)
    write_results(root / "sA" / "out" / "results", "1")
    (root / "sA" / "res").symlink_to(root / "store" / "results", target_is_directory=True)
    write_results(root / "sA" / "res", "2", overwrite=True)
    assert (root / "sA" / "res").is_symlink()
    assert (root / "store" / "results" / "poses.csv").read_text() == "Tx_mm\n2\n"
    assert_kept(root, before)
    assert leftovers(root) == []


def test_a_file_as_a_parent_is_a_one_line_error(tree):
    root, _ = tree
    before = snapshot(root)
    with pytest.raises(OutputWriteError, match="is not a folder"):
        write_results(root / "notes.txt" / "results")
    with pytest.raises(OutputWriteError, match="is not a folder"):
        atomic_write_text(root / "notes.txt" / "a" / "b.txt", "x")
    assert snapshot(root) == before


# --------------------------------------------------------------------------- property

TARGETS = [
    ".",
    "sA",
    "sA/.",
    "sA/..",
    "sA/results",
    "sA/results/sub",
    "sA/results/poses.csv",
    "sA/centres.csv",
    "sA/session.yaml",
    "sA/expected",
    "sA/expected/poses.csv",
    "sA/truth",
    "sA/report.html",
    "sB/results",
    "sB/../sA/centres.csv",
    "sB/report.html",
    "link",
    "link/results",
    "link/centres.csv",
    "dangling",
    "dangling/results",
    "notes.txt",
    "notes.txt/x",
    "out",
    "out/report.html",
]
OPERATIONS = st.lists(
    st.tuples(
        st.sampled_from(["folder", "file"]),
        st.sampled_from(TARGETS),
        st.sampled_from(["none", "sA", "sB", "sA-folder", "all", "written", "written-folders"]),
        st.booleans(),
        st.sampled_from(["cwd-root", "cwd-sA", "absolute"]),
    ),
    min_size=1,
    max_size=7,
)


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(OPERATIONS)
def test_no_sequence_of_writes_ever_modifies_or_removes_an_input(monkeypatch, operations):
    monkeypatch.setattr(os, "fsync", lambda fd: None)  # durability is tested apart; speed here
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp).resolve()
        originals = make_tree(root)
        _link(root)
        (root / "dangling").symlink_to(root / "nowhere")
        declared = {
            "none": [],
            "sA": session_inputs(root, "sA"),
            "sB": session_inputs(root, "sB"),
            "sA-folder": [root / "sA"],
            "all": session_inputs(root, "sA") + session_inputs(root, "sB"),
        }
        written: list[Path] = []  # what earlier writes made: inputs of later commands
        for number, (kind, target, inputs, overwrite, base) in enumerate(operations):
            declared["written"] = [p for p in written if p.is_file()]
            declared["written-folders"] = [p.parent for p in declared["written"]]
            inputs_before = {
                f: f.read_bytes()
                for p in declared[inputs]
                for f in ([p] if p.is_file() else p.rglob("*"))
                if f.is_file() and not f.is_symlink()
            }
            if base == "absolute":
                out = str(root / target)
            else:
                cwd = root if base == "cwd-root" else root / "sA"
                monkeypatch.chdir(cwd)
                out = os.path.relpath(root / target, cwd) if base == "cwd-sA" else target
            content = f"run {number}\n"
            try:
                if kind == "folder":
                    with output_dir(out, inputs=declared[inputs], overwrite=overwrite) as folder:
                        (folder / "poses.csv").write_text(content)
                else:
                    write_output_file(out, content, inputs=declared[inputs], overwrite=overwrite)
            except HexathermError as exc:
                assert "\n" not in str(exc)
            else:
                made = Path(out) / "poses.csv" if kind == "folder" else Path(out)
                assert made.read_text() == content
                written.append(made.resolve())
            assert_kept(root, originals)
            for path, data in inputs_before.items():
                assert path.is_file() and path.read_bytes() == data, f"input {path} changed"
        assert leftovers(root) == []
        assert not (root / "nowhere").exists()


def test_the_suites_fsync_still_refuses_a_bad_descriptor(tmp_path):
    """tests/conftest.py leaves out the flush to disk, not fsync's checks: the product's
    calls on a closed descriptor fail here as they would for real."""
    assert os.fsync is not REAL_FSYNC
    fd = os.open(tmp_path, os.O_RDONLY)
    os.close(fd)
    with pytest.raises(OSError):
        os.fsync(fd)
    with open(tmp_path / "x", "w") as handle:
        os.fsync(handle)
        os.fsync(handle.fileno())
