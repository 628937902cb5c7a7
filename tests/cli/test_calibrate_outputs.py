"""calibrate's deliverables (issue 25, items 3 and 7): parameters.csv at the documented
resolution per unit with U = k u (--coverage-factor), the report's rotation residuals
and correlation heatmap, and -o's default."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "calibration-geometry"


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    root = tmp_path_factory.mktemp("cal")
    session = root / "s"
    shutil.copytree(SESSION, session, ignore=shutil.ignore_patterns("expected"))
    result = CliRunner().invoke(
        main, ["calibrate", str(session), "--level", "joints+gains", "--coverage-factor", "3"]
    )
    assert result.exit_code == 0, result.output
    return session / "calibration", result  # the default output folder


def test_default_output_folder_is_the_sessions_calibration(calibrated):
    out, result = calibrated
    assert (out / "parameters.csv").is_file() and (out / "report.html").is_file()
    assert f"wrote {out / 'parameters.csv'}" in result.output


def test_parameters_csv_has_u_at_k_and_the_documented_resolution(calibrated):
    out, _ = calibrated
    params = pd.read_csv(out / "parameters.csv")
    assert params["coverage_factor"].eq(3.0).all()
    for column in ("nominal", "calibrated", "u", "U", "U_um", "U_ppm", "max_abs_correlation"):
        assert params[column].dtype == np.float64, column
    mm = params["unit"] == "mm"
    gain = params["unit"] == "mm/mm"
    assert mm.sum() == 42 and gain.sum() == 6
    # U = k u to the resolution of each (both rounded to half a step)
    assert np.all(np.abs(params["U"][mm] - 3 * params["u"][mm]) <= 4 * 0.5e-7 + 1e-12)
    assert np.all(np.abs(params["U"][gain] - 3 * params["u"][gain]) <= 4 * 0.5e-10 + 1e-15)
    assert np.all(np.abs(params["U_um"][mm] - 3 * params["u_um"][mm]) <= 4 * 0.5e-4 + 1e-9)
    assert np.all(np.abs(params["U_ppm"][gain] - 3 * params["u_ppm"][gain]) <= 4 * 0.5e-4 + 1e-9)
    assert np.all(np.abs(params["U_um"][mm] - 1e3 * params["U"][mm]) <= 0.5e-4 + 1e3 * 0.5e-7)
    assert params["U_um"][gain].isna().all() and params["U_ppm"][mm].isna().all()
    # the text: 7 decimals for mm, 10 for mm/mm, 4 for um, ppm and correlations
    lines = (out / "parameters.csv").read_text().splitlines()
    head = lines[0].split(",")
    decimals = {"nominal": None, "calibrated": None, "u": None, "U": None}
    fixed = {"U_um": 4, "U_ppm": 4, "u_um": 4, "change_um": 4, "max_abs_correlation": 4}
    for line in lines[1:]:
        cells = dict(zip(head, line.split(","), strict=True))
        want = 7 if cells["unit"] == "mm" else 10
        for column in decimals:
            assert re.fullmatch(rf"-?\d+\.\d{{{want}}}", cells[column]), (column, cells[column])
        for column, n in fixed.items():
            assert cells[column] == "" or re.fullmatch(rf"-?\d+\.\d{{{n}}}", cells[column])


def test_report_has_rotation_residuals_and_the_correlation_heatmap(calibrated):
    out, _ = calibrated
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == 4  # map, residuals (2), correlations
    assert "<h2>Correlations</h2>" in page and "U (k = 3)" in page


def test_the_figures_hold_the_residuals_and_the_correlations():
    from hexatherm.workflows.calibrate.report import (
        _correlation_figure,
        _residual_figure,
        _workspace_figure,
    )
    from hexatherm.workflows.calibrate.run import calibrate, read_campaign

    run = calibrate(read_campaign([SESSION]), "joints")
    fig = _correlation_figure(run)
    shown = np.asarray(fig.axes[0].images[0].get_array())
    # the correlation from the covariance, computed here
    index = [i for i, m in enumerate(run.fit.model.mask) if m]
    cov = run.fit.covariance[np.ix_(index, index)]
    sd = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        expected = cov / np.outer(sd, sd)
    np.testing.assert_allclose(shown, expected, atol=1e-12)
    residuals = _residual_figure(run)
    rotation = residuals.axes[1].get_lines()
    np.testing.assert_allclose(
        rotation[0].get_ydata(), np.linalg.norm(run.residuals_before_um_urad[:, 3:], axis=1)
    )
    np.testing.assert_allclose(
        rotation[1].get_ydata(), np.linalg.norm(run.residuals_after_um_urad[:, 3:], axis=1)
    )
    assert "rotation" in residuals.axes[1].get_ylabel()
    workspace = _workspace_figure(run)
    before, after = (ax.collections[0] for ax in workspace.axes[:2])
    np.testing.assert_allclose(before.get_offsets(), run.campaign.commanded[:, :2])
    np.testing.assert_allclose(
        before.get_array(), np.linalg.norm(run.residuals_before_um_urad[:, :3], axis=1)
    )
    np.testing.assert_allclose(
        after.get_array(), np.linalg.norm(run.residuals_after_um_urad[:, :3], axis=1)
    )
    assert before.get_clim() == after.get_clim()  # one colour scale
