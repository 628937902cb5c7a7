"""Same numbers (issue 32): a simulated session written as QIF 3 results the way CMM
software writes them (centres; probed points) processes to the poses of hexatherm's own
centres and points CSVs, to the resolution of poses.csv (1e-7 mm, 1e-7 deg)."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.csvout import RESOLUTION, column_unit
from hexatherm.io.qifschema import check_document
from tests.io.qifwriter import results_qif
from tests.sessions import make_session


def process(session, out):
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    return pd.read_csv(out / "poses.csv"), result.output


def qif_session(session, target, qif: bytes, names: dict | None = None):
    """A copy of ``session`` that reads ``results.qif`` (and a feature_names map)."""
    shutil.copytree(session, target, ignore=shutil.ignore_patterns("results", "truth"))
    (target / "results.qif").write_bytes(qif)
    check_document(target / "results.qif")  # what the test writes is valid QIF 3
    text = (target / "session.yaml").read_text()
    text = text.replace("centres.csv", "results.qif").replace("points.csv", "results.qif")
    if names:
        lines = "".join(f'  "{key}": {value}\n' for key, value in names.items())
        text += f"feature_names:\n{lines}"
    (target / "session.yaml").write_text(text)
    return target


def assert_same_poses(a: pd.DataFrame, b: pd.DataFrame) -> None:
    assert list(a.columns) == list(b.columns) and len(a) == len(b)
    numeric = [c for c in a.columns if c.endswith(("_mm", "_deg", "_um", "_urad"))]
    steps = np.array([RESOLUTION[column_unit(c)] for c in numeric])
    difference = np.abs(a[numeric].to_numpy(float) - b[numeric].to_numpy(float))
    assert np.all((difference <= steps) | (np.isnan(difference) & a[numeric].isna().to_numpy()))
    assert (a["label"] == b["label"]).all() and (a["time"] == b["time"]).all()


@pytest.mark.parametrize("unit", ["mm", "inch"])
def test_centres_from_qif_give_the_poses_of_the_centres_csv(tmp_path, unit):
    make_session(tmp_path / "s", output="centres", n_targets=3, noise_mm=1e-3)
    expected, _ = process(tmp_path / "s", tmp_path / "a")
    centres = read_measurement_csv(tmp_path / "s" / "centres.csv")
    names = None
    kwargs = {}
    if unit == "inch":  # a German lab's names, mapped in session.yaml
        kwargs["names"] = lambda step, ball: f"Kugel {ball[1:]} Pos {step}"
        names = {
            f"Kugel {b[1:]} Pos {s}": f"{s}_{b}"
            for s, b in zip(centres.label, centres.ball, strict=True)
        }
    qif = results_qif(centres, unit=unit, **kwargs)
    session = qif_session(tmp_path / "s", tmp_path / "q", qif, names)
    got, _ = process(session, tmp_path / "b")
    assert_same_poses(expected, got)
    if unit == "mm":  # the same doubles in, the same file out
        assert (tmp_path / "a" / "poses.csv").read_bytes() == (
            tmp_path / "b" / "poses.csv"
        ).read_bytes()


def test_points_from_qif_are_fitted_as_the_points_csv(tmp_path):
    make_session(tmp_path / "s", output="points", n_targets=2, point_noise_mm=1e-3)
    points = read_measurement_csv(tmp_path / "s" / "points.csv")
    # each ball's time is the mean of its points' (hexatherm's rule), which a CMM stamps
    # its feature with here; the CMM's own centre (Location) is moved 0.5 mm off: unused
    qif = results_qif(points, unit="inch", location_offset_mm=0.5)
    session = qif_session(tmp_path / "s", tmp_path / "q", qif)
    expected, _ = process(tmp_path / "s", tmp_path / "a")
    got, _ = process(session, tmp_path / "b")
    assert_same_poses(expected, got)
    fits_a = pd.read_csv(tmp_path / "a" / "fits.csv")
    fits_b = pd.read_csv(tmp_path / "b" / "fits.csv")
    assert (fits_b["source"] == "points").all() and (fits_a["n"] == fits_b["n"]).all()


def test_a_bad_feature_names_map_is_refused_at_its_key(tmp_path):
    make_session(tmp_path / "s", output="centres", n_targets=1)
    centres = read_measurement_csv(tmp_path / "s" / "centres.csv")
    session = qif_session(tmp_path / "s", tmp_path / "q", results_qif(centres), {"Ball 1": "S1B1"})
    result = CliRunner().invoke(main, ["process", str(session)])
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert "field 'feature_names.Ball 1': expected <step>_<ball>" in result.output
    assert len(result.output.strip().splitlines()) == 1
