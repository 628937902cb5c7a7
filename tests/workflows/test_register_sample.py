"""The shipped datum measurement (sessions/register-datums): register recovers the truth."""

from __future__ import annotations

import importlib.util
import io
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.config import read_balls

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sessions" / "register-datums"


def test_register_recovers_the_true_balls_from_the_sample(tmp_path: Path) -> None:
    before = {p: p.read_bytes() for p in SAMPLE.rglob("*") if p.is_file()}
    out = tmp_path / "balls.yaml"
    result = CliRunner().invoke(
        main,
        [
            "register",
            str(SAMPLE / "points.csv"),
            "--datums",
            str(SAMPLE / "datums.yaml"),
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    got, truth = read_balls(out), read_balls(SAMPLE / "truth" / "balls.yaml")
    assert got.names == truth.names
    error_um = np.linalg.norm(got.centres_mm - truth.centres_mm, axis=1) * 1e3
    # 1 um noise per point: a 25-point cap fits to about 1 um, the frame adds about as much
    assert np.all(error_um < 5.0), error_um
    assert {p: p.read_bytes() for p in SAMPLE.rglob("*") if p.is_file()} == before


def test_the_sample_is_what_its_script_makes() -> None:
    spec = importlib.util.spec_from_file_location(
        "make_register_datums", ROOT / "sessions" / "make_register_datums.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = io.StringIO()
    module.measurement().to_csv(text, index=False, lineterminator="\n")
    assert text.getvalue() == (SAMPLE / "points.csv").read_text()
    assert (SAMPLE / "datums.yaml").read_text() == module.DATUMS
