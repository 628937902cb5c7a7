"""No command writes into, around or onto its inputs (issue 12, item 1).

``process`` has its own tests (``test_process_outputs.py``); these are the other
commands that write: ``diagnose``, ``report``, ``fit-spheres``, ``register``,
``plan`` and ``simulate``. Every case is refused with one line naming the option,
before any work, and the whole tree of inputs is byte for byte as it was.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.manifest import read_manifest

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """format: hexatherm-scenario/1
hexapod: {hexapod}
balls: {balls}
plan: {{targets: [[0.5, 0, 0, 0, 0, 0]], reference_pose: [0, 0, 0, 0, 0, 0], cycles: 1}}
seed: 3
"""


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    """A lab's folder: two recorded sessions, the register sample and a scenario."""
    for name, to in [
        ("paper-zero-pose", "s"),
        ("paper-zero-pose-dmis", "d"),
        ("register-datums", "r"),
    ]:
        shutil.copytree(ROOT / "sessions" / name, tmp_path / to)
    (tmp_path / "scenario.yaml").write_text(
        SCENARIO.format(
            hexapod=tmp_path / "s" / "hexapod.yaml", balls=tmp_path / "s" / "balls.yaml"
        )
    )
    return tmp_path


def cases(lab: Path) -> dict[str, tuple[list[str], str]]:
    s, d, r = lab / "s", lab / "d", lab / "r"
    plan = ["plan", "--hexapod", s / "hexapod.yaml", "--balls", s / "balls.yaml"]
    plan += ["--grid", "2", "--box", "Tx=-1:1"]
    return {
        "diagnose into its session": (["diagnose", s, "-o", s], "contains the input"),
        "diagnose around two sessions": (["diagnose", s, "-o", lab], "contains the input"),
        "report onto the centres": (["report", s, "-o", s / "centres.csv"], "is the input"),
        "report onto the hexapod file": (["report", s, "-o", s / "hexapod.yaml"], "is the input"),
        "fit-spheres onto its points": (
            ["fit-spheres", d / "points.dmo", "-o", d / "points.dmo"],
            "is the input",
        ),
        "register onto its measurement": (
            ["register", r / "points.csv", "--datums", r / "datums.yaml", "-o", r / "points.csv"],
            "is the input",
        ),
        "register onto its datums": (
            ["register", r / "points.csv", "--datums", r / "datums.yaml", "-o", r / "datums.yaml"],
            "is the input",
        ),
        "plan onto the hexapod file": ([*plan, "-o", s / "hexapod.yaml"], "is the input"),
        "plan's DMIS onto the balls": (
            [*plan, "--origin-on-cmm", "450,320,210,0,0,15", "--dmis", s / "balls.yaml"],
            "is the input",
        ),
        "simulate onto a recorded session": (
            ["simulate", lab / "scenario.yaml", "-o", d],
            "not written by hexatherm",
        ),
        "simulate around its scenario": (
            ["simulate", lab / "scenario.yaml", "-o", lab],
            "contains the input",
        ),
    }


CASES = list(cases(Path("/lab")))


@pytest.mark.parametrize("case", CASES)
def test_an_output_onto_or_around_an_input_is_refused_with_overwrite(lab: Path, case: str) -> None:
    args, why = cases(lab)[case]
    before = snapshot(lab)
    result = CliRunner().invoke(main, [str(a) for a in [*args, "--overwrite"]])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and why in lines[0], result.output
    assert "Traceback" not in result.output
    assert snapshot(lab) == before


def test_dot_inside_a_session_is_a_clean_refusal(
    lab: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(lab / "s")
    before = snapshot(lab)
    for args in (["diagnose", ".", "-o", "."], ["simulate", lab / "scenario.yaml", "-o", "."]):
        result = CliRunner().invoke(main, [str(a) for a in [*args, "--overwrite"]])
        assert result.exit_code == 1 and "-o ." in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    assert snapshot(lab) == before


def test_a_single_file_output_is_replaced_only_while_hexatherm_vouches_for_it(lab: Path) -> None:
    d = lab / "d"
    out = lab / "out" / "centres.csv"
    run = ["fit-spheres", str(d / "points.dmo"), "-o", str(out)]
    assert CliRunner().invoke(main, run).exit_code == 0
    assert sorted(read_manifest(out.parent).files) == ["centres.csv"]
    first = out.read_bytes()
    assert CliRunner().invoke(main, [*run, "--overwrite"]).exit_code == 0
    assert out.read_bytes() == first
    out.write_bytes(first + b"# checked by J. Doe\n")  # the lab's edit: now it is theirs
    edited = CliRunner().invoke(main, [*run, "--overwrite"])
    assert edited.exit_code == 1 and "changed since hexatherm wrote it" in edited.output
    assert out.read_bytes().endswith(b"# checked by J. Doe\n")
