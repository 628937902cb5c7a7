"""``provenance.json`` in every output folder a command writes (issue 16, item 2): the
command line, every option, every input with its SHA-256, start and end times with
their UTC offset, the versions; none for a run outside the command line."""

from __future__ import annotations

import hashlib
import json
import shutil
from datetime import datetime
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm import __version__
from hexatherm.cli import main
from hexatherm.io.manifest import read_manifest
from hexatherm.io.outputs import output_dir
from hexatherm.io.provenance import PROVENANCE_NAME, json_ready
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def session(tmp_path: Path) -> Path:
    return Path(shutil.copytree(SHIPPED / "paper-zero-pose", tmp_path / "s"))


def test_process_records_its_command_options_and_inputs(session: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ["process", str(session), "-o", str(out), "--mc", "20", "--seed", "7"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    doc = json.loads((out / PROVENANCE_NAME).read_text())
    assert doc["format"] == "hexatherm-provenance/1" and doc["hexatherm"] == __version__
    assert doc["command_line"] == "hexatherm " + " ".join(args)  # plain arguments as typed
    assert doc["options"]["mc"] == 20 and doc["options"]["seed"] == 7
    assert doc["options"]["interpolation"] == "linear"  # defaults too
    inputs = {Path(entry["path"]).name: entry for entry in doc["inputs"]}
    assert set(inputs) == {
        "session.yaml",
        "hexapod.yaml",
        "balls.yaml",
        "plan.yaml",
        "centres.csv",
        "temperatures.csv",
    }
    for name, entry in inputs.items():
        assert entry["sha256"] == sha256(session / name)
        assert entry["bytes"] == (session / name).stat().st_size
    started = datetime.fromisoformat(doc["started"])
    finished = datetime.fromisoformat(doc["finished"])
    assert started.utcoffset() is not None and started <= finished
    assert set(doc["libraries"]) == {"numpy", "scipy", "pandas"}
    # hexatherm wrote it: listed in the manifest, so --overwrite replaces it
    assert PROVENANCE_NAME in read_manifest(out).files
    again = CliRunner().invoke(main, [*args, "--overwrite"])
    assert again.exit_code == 0, again.output


def test_a_run_outside_the_command_line_writes_none(tmp_path: Path) -> None:
    with output_dir(tmp_path / "out") as folder:
        (folder / "poses.csv").write_text("Tx_mm\n0\n")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        ".hexatherm-manifest.json",
        "poses.csv",
    ]


def test_values_are_made_json() -> None:
    assert json_ready({"a": (Path("x"), float("inf")), "b": None}) == {
        "a": ["x", "inf"],
        "b": None,
    }


def test_the_command_line_of_a_path_with_a_space_runs_as_written(tmp_path: Path) -> None:
    # provenance.json's command_line is quoted as the report's page quotes it: a shell
    # splits it back into the arguments the run was given (space-joined, a path with a
    # space came back as two arguments)
    import shlex

    session = Path(shutil.copytree(SHIPPED / "paper-zero-pose", tmp_path / "my s"))
    out = tmp_path / "out 'a'"
    args = ["process", str(session), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    doc = json.loads((out / PROVENANCE_NAME).read_text())
    assert shlex.split(doc["command_line"]) == ["hexatherm", *args]
    assert doc["argv"] == args[1:]


def test_digests_of_the_bytes_read_are_the_files_and_follow_a_change(tmp_path, monkeypatch):
    """Within ``digests_kept`` the provenance digest of a file read whole is taken from the
    bytes read (no second read), equal to the file's SHA-256; a file changed since (same
    size, new content) is read and hashed again; outside the block nothing is kept."""
    import os

    from hexatherm.io import files, provenance

    path = tmp_path / "points.csv"
    path.write_bytes(b"label,ball,x,y,z,time\nO,B1,1,2,3,0\n")
    opened: list[object] = []
    real_open = open
    monkeypatch.setattr(
        provenance, "open", lambda *a, **k: opened.append(a[0]) or real_open(*a, **k), raising=False
    )
    with files.digests_kept():
        files.read_bytes(path)
        (entry,) = provenance.input_entries([path])
        assert entry["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
        assert opened == []  # from the bytes read
        stat = path.stat()
        path.write_bytes(b"label,ball,x,y,z,time\nO,B1,9,2,3,0\n")
        os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
        (entry,) = provenance.input_entries([path])
        assert entry["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
        assert opened == [path]  # changed since it was read: read again
    files.read_bytes(path)
    assert files.kept_digest(path) is None


def test_former_results_are_hashed_once_per_version(tmp_path, monkeypatch):
    """issue 37 (io10k): within ``digests_kept`` (``process``), ``sha256_file`` of a file
    it hashed before (the former results, looked at before the work, before writing and
    under the lock) is the kept digest, read once; a file changed since (new content, a
    later time) or replaced (another inode) is read again; every digest is the file's
    SHA-256 (hashlib of its bytes), and outside the block each call reads the file."""
    import os

    from hexatherm.io import files, manifest

    path = tmp_path / "poses.csv"
    path.write_bytes(b"label,Tx_mm\nS1,0.1000000\n")
    reads: list[int] = []
    real_read = os.read
    monkeypatch.setattr(manifest.os, "read", lambda fd, n: reads.append(fd) or real_read(fd, n))

    def digest() -> str | None:
        reads.clear()
        return manifest.sha256_file(path)

    def truth() -> str:
        return hashlib.sha256(path.read_bytes()).hexdigest()

    with files.digests_kept():
        assert digest() == truth() and reads
        for _ in range(2):
            assert digest() == truth() and not reads  # kept
        stat = path.stat()
        path.write_bytes(b"label,Tx_mm\nS1,0.2000000\n")  # same size
        os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))
        assert digest() == truth() and reads  # changed: read again
        assert digest() == truth() and not reads
        replaced = tmp_path / "new.csv"
        replaced.write_bytes(b"label,Tx_mm\nS2,0.3000000\n")
        os.replace(replaced, path)
        assert digest() == truth() and reads  # another file: read
    for _ in range(2):
        assert digest() == truth() and reads  # nothing kept outside the block
    assert manifest.sha256_file(tmp_path) is None and manifest.sha256_file(tmp_path / "x") is None
