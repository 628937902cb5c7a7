"""hexatherm works from a built wheel, away from the source tree.

The wheel is built from this checkout and installed (without dependencies: they are
this environment's) into a temporary folder; a fresh interpreter, started in another
folder with ``-P`` (no current folder on ``sys.path``) and that folder first on its
path, must import hexatherm from the wheel, read its package data (the campaigns'
hexapod file) and run ``diagnose`` on a shipped session. A module that reads files
relative to the source tree, or package data missing from the wheel, fails here.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import yaml

from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("git") is None:
        pytest.skip("git is needed to copy the checkout")
    work = tmp_path_factory.mktemp("wheel")
    # build from a copy of the tracked files only (no results/, caches or venvs)
    src = work / "src"
    files = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        check=True,
    ).stdout.split(b"\0")
    for name in filter(None, files):
        rel = Path(os.fsdecode(name))
        if rel.parts[0] not in {"hexatherm", "pyproject.toml", "README.md"}:
            continue
        if not (ROOT / rel).is_file():
            continue
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, src / rel)
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(work / "dist"), "."],
        cwd=src,
        capture_output=True,
        text=True,
    )
    if build.returncode != 0:
        pytest.fail(f"the wheel does not build:\n{build.stderr[-2000:]}")
    (wheel,) = (work / "dist").glob("hexatherm-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "hexatherm/data/symetrie-like.yaml" in names
    assert "hexatherm/py.typed" in names
    target = work / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target), wheel],
        check=True,
        capture_output=True,
    )
    return target


def _run(target: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(target)}
    return subprocess.run(
        [sys.executable, "-P", *args], cwd=cwd, env=env, capture_output=True, text=True
    )


def test_the_wheel_imports_from_itself_and_reads_its_data(installed: Path, tmp_path: Path) -> None:
    code = (
        "import hexatherm, pathlib;"
        "from hexatherm.workflows.simulate.campaigns import hexapod_text;"
        "print(pathlib.Path(hexatherm.__file__).parent);"
        "print(len(hexapod_text()))"
    )
    done = _run(installed, tmp_path, "-c", code)
    assert done.returncode == 0, done.stderr
    where, size = done.stdout.split()
    assert Path(where).parent == installed
    assert int(size) == len((ROOT / "configs" / "symetrie-like.yaml").read_text("utf-8"))


def test_the_shipped_hexapod_data_is_the_configs_file() -> None:
    packaged = ROOT / "hexatherm" / "data" / "symetrie-like.yaml"
    assert packaged.read_bytes() == (ROOT / "configs" / "symetrie-like.yaml").read_bytes()


def test_diagnose_runs_from_the_wheel_on_a_shipped_session(installed: Path, tmp_path: Path) -> None:
    session = tmp_path / "session"
    shutil.copytree(SHIPPED / "with-hidden-effect", session)
    out = tmp_path / "diagnosis"
    done = _run(installed, tmp_path, "-m", "hexatherm", "diagnose", str(session), "-o", str(out))
    assert done.returncode == 0, done.stderr
    diagnosis = json.loads((out / "diagnosis.json").read_text("utf-8"))
    truth = yaml.safe_load((session / "truth" / "effects.yaml").read_text("utf-8"))
    # the session's hidden effect (its truth) is the one diagnose names first
    assert diagnosis["added"][0]["effect"] == truth["effects"][0]["name"]


def test_the_wheel_carries_the_qif_schema_and_compiles_it(installed: Path, tmp_path: Path) -> None:
    code = (
        "from hexatherm.io.qifschema import SCHEMA_DIR, schema; schema(); print(SCHEMA_DIR);"
        "print(sorted(p.name for p in SCHEMA_DIR.iterdir()))"
    )
    done = _run(installed, tmp_path, "-c", code)
    assert done.returncode == 0, done.stderr
    where, listing = done.stdout.splitlines()
    assert Path(where).is_relative_to(installed)
    for name in ("LICENSE-QIF.md", "LICENSE-W3C-xmldsig.txt", "QIFApplications", "QIFLibrary"):
        assert name in listing
