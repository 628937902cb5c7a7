"""The shipped datum measurement (sessions/register-datums): register recovers the truth."""

from __future__ import annotations

import importlib.util
import io
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.config import read_balls
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = SHIPPED / "register-datums"


def register_sample(out: Path) -> None:
    """``hexatherm register`` of the sample's points and datums into ``out`` (succeeds)."""
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


def test_register_recovers_the_true_balls_from_the_sample(tmp_path: Path) -> None:
    before = {p: p.read_bytes() for p in SAMPLE.rglob("*") if p.is_file()}
    out = tmp_path / "balls.yaml"
    register_sample(out)
    got, truth = read_balls(out), read_balls(SAMPLE / "truth" / "balls.yaml")
    assert got.names == truth.names
    error_um = np.linalg.norm(got.centres_mm - truth.centres_mm, axis=1) * 1e3
    # 1 um noise per point: a 25-point cap fits to about 1 um, the frame adds about as much
    assert np.all(error_um < 5.0), error_um
    assert {p: p.read_bytes() for p in SAMPLE.rglob("*") if p.is_file()} == before


def test_the_sample_is_what_its_script_makes() -> None:
    spec = importlib.util.spec_from_file_location(
        "make_register_datums", SHIPPED / "make_register_datums.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = io.StringIO()
    module.measurement().to_csv(text, index=False, lineterminator="\n")
    assert text.getvalue() == (SAMPLE / "points.csv").read_text()
    assert (SAMPLE / "datums.yaml").read_text() == module.DATUMS


def test_balls_yaml_carries_each_centres_uncertainty_at_sane_digits(tmp_path: Path) -> None:
    """Issue 25, item 3: u_centre_um per ball (the sphere fit's covariance turned into the
    platform frame), centres at 1e-7 mm; the trace of a covariance does not change with
    the frame, so the sum of u^2 equals the fit's in the CMM frame, computed here."""
    import re

    import pandas as pd
    import yaml

    from hexatherm.core.spherefit import fit_spheres

    out = tmp_path / "balls.yaml"
    register_sample(out)
    text = out.read_text()
    doc = yaml.safe_load(text)
    records = pd.read_csv(SAMPLE / "points.csv")
    for name, ball in doc["balls"].items():
        u = np.array(ball["u_centre_um"])
        assert u.shape == (3,) and np.all(u > 0) and np.all(u < 5)
        points = records.loc[records["ball"] == name, ["x", "y", "z"]].to_numpy(float)
        fit = fit_spheres(points, np.zeros(len(points), dtype=int))
        trace_um2 = np.trace(fit.cov_centre_mm2[0]) * 1e6
        assert np.sum(u**2) == pytest.approx(trace_um2, rel=1e-3, abs=1e-6)
    for number in re.findall(r"-?\d+\.\d+", text):
        assert len(number.split(".")[1]) <= 7, number
    assert read_balls(out).names == tuple(doc["balls"])  # the reader takes the new key
