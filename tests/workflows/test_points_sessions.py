"""Sessions of probed points (CSV and DMIS): fitted centres, fits.csv, and the checks."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.registration import check_distances
from hexatherm.io.csvout import RESOLUTION, column_unit
from hexatherm.session import Balls
from tests.sessions import BALLS, make_session


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def poses(folder):
    return pd.read_csv(folder / "poses.csv")


def centres_session_from(points_session, centres_csv, target):
    """A copy of a session that reads the given centres file instead of its points."""
    shutil.copytree(points_session, target, ignore=shutil.ignore_patterns("results"))
    shutil.copy(centres_csv, target / "centres.csv")
    text = (target / "session.yaml").read_text()
    for name in ("points.csv", "points.dmo"):
        text = text.replace(name, "centres.csv")
    (target / "session.yaml").write_text(text)
    return target


@pytest.mark.parametrize("output", ["points", "dmis"])
def test_points_session_equals_the_centres_it_fits(tmp_path, output):
    session = tmp_path / "pts"
    make_session(session, output=output, point_noise_mm=1.5e-3, n_targets=3)
    points_file = session / ("points.csv" if output == "points" else "points.dmo")
    assert run("process", session, "-o", tmp_path / "a").exit_code == 0
    fitted = run("fit-spheres", points_file, "-o", tmp_path / "centres.csv")
    assert fitted.exit_code == 0, fitted.output
    other = centres_session_from(session, tmp_path / "centres.csv", tmp_path / "ctr")
    result = run("process", other, "-o", tmp_path / "b")
    assert result.exit_code == 0, result.output
    a, b = poses(tmp_path / "a"), poses(tmp_path / "b")
    # the uncertainties differ: a points session has each fit's full covariance, a
    # centres file one u_um per centre (the fit is looser along the cap's axis)
    # through files at 1e-7 mm and 1e-7 deg (the centres, then the poses): half a step
    # of each pose and the centres' own rounding carried through, within two steps
    numeric = [c for c in a.columns if c.endswith(("_mm", "_deg")) and not c.startswith("u_")]
    steps = np.array([RESOLUTION[column_unit(c)] for c in numeric])
    assert np.all(np.abs(a[numeric].to_numpy() - b[numeric].to_numpy()) <= 2 * steps)
    assert (a["time"] == b["time"]).all()


def test_noise_free_points_fit_exactly_and_report_quality(tmp_path):
    make_session(tmp_path / "s", output="points", n_targets=2)
    assert run("process", tmp_path / "s").exit_code == 0
    fits = pd.read_csv(tmp_path / "s" / "results" / "fits.csv")
    assert len(fits) == 6 * 3 and (fits["source"] == "points").all()
    assert (fits["n"] == 25).all()
    np.testing.assert_allclose(fits["diameter_dev_um"], 0.0, atol=1e-6)
    assert fits["form_um"].max() < 1e-6
    np.testing.assert_allclose(fits["cap_deg"], 70.0, atol=2.0)  # spiral covers ~the cap
    truth = pd.read_csv(tmp_path / "s" / "truth" / "steps.csv").set_index("label")
    got = poses(tmp_path / "s" / "results")
    np.testing.assert_allclose(got["Tx_conv_mm"], truth.loc[got["label"], "Tx_true_mm"], atol=1e-9)


def test_uncompensated_points_fit_ball_plus_tip(tmp_path):
    balls = Balls(BALLS.names, BALLS.centres_mm, BALLS.diameters_mm, False, 2.0)
    make_session(tmp_path / "s", output="points", balls=balls, n_targets=1)
    assert run("process", tmp_path / "s", "--fixed-diameter").exit_code == 0
    fits = pd.read_csv(tmp_path / "s" / "results" / "fits.csv")
    np.testing.assert_allclose(fits["diameter_mm"], 25.4 + 2.0, atol=1e-12)
    np.testing.assert_allclose(fits["diameter_dev_um"], 0.0, atol=1e-9)
    assert fits["form_um"].max() < 1e-6  # the fixed radius is the right one


def test_fit_spheres_fixed_diameter_and_stdout(tmp_path):
    make_session(tmp_path / "s", output="points", n_targets=1, point_noise_mm=1e-3)
    result = run("fit-spheres", tmp_path / "s" / "points.csv", "--diameter-mm", "25.4")
    assert result.exit_code == 0
    table = pd.read_csv(__import__("io").StringIO(result.stdout))
    assert list(table.columns) == [
        "label",
        "ball",
        "x",
        "y",
        "z",
        "time",
        "diameter",
        "form_um",
        "n",
        "u_um",
        "u_x_um",
        "u_y_um",
        "u_z_um",
        "r_xy",
        "r_xz",
        "r_yz",
    ]
    assert (table["diameter"] == 25.4).all() and len(table) == 4 * 3
    # u_um is the per-axis u's root mean square (to the 1e-4 um they are written at)
    axes = table[["u_x_um", "u_y_um", "u_z_um"]].to_numpy()
    np.testing.assert_allclose(table["u_um"], np.sqrt((axes**2).mean(axis=1)), atol=2e-4)


def test_fit_spheres_refuses_to_overwrite(tmp_path):
    make_session(tmp_path / "s", output="points", n_targets=1)
    out = tmp_path / "c.csv"
    out.write_text("keep")
    result = run("fit-spheres", tmp_path / "s" / "points.csv", "-o", out)
    assert result.exit_code == 1 and "--overwrite" in result.output
    assert out.read_text() == "keep"


def test_too_few_points_names_step_ball_file_and_line(tmp_path):
    make_session(tmp_path / "s", output="points", n_targets=1)
    path = tmp_path / "s" / "points.csv"
    lines = path.read_text().splitlines(keepends=True)
    kept = [ln for ln in lines if not ln.startswith("R1,B2,")] + [
        ln for ln in lines if ln.startswith("R1,B2,")
    ][:3]
    path.write_text("".join(kept))
    result = run("process", tmp_path / "s")
    assert result.exit_code == 1
    line = len(kept) - 2
    assert f"points.csv:{line}: step R1 ball B2: sphere fit:" in result.output, result.output
    assert "4" in result.output
    assert not (tmp_path / "s" / "results").exists()


def swap_labels(path, step, a, b):
    text = (
        path.read_text()
        .replace(f"\n{step},{a},", "\nTMP,")
        .replace(f"\n{step},{b},", f"\n{step},{a},")
        .replace("\nTMP,", f"\n{step},{b},")
    )
    path.write_text(text)


def test_swapped_balls_are_named(tmp_path):
    make_session(tmp_path / "s")
    swap_labels(tmp_path / "s" / "centres.csv", "S2", "B1", "B3")
    result = run("process", tmp_path / "s")
    assert result.exit_code == 1
    assert "step S2: balls B1 and B3 look swapped" in result.output


def test_inch_mm_mixup_is_named():
    centres = BALLS.centres_mm / 25.4 + [100.0, 0.0, 0.0]
    check = check_distances(centres, BALLS.centres_mm, BALLS.names)
    assert "inch values read as millimetres" in check.diagnosis[0]
    check = check_distances(BALLS.centres_mm * 25.4, BALLS.centres_mm, BALLS.names)
    assert "millimetre values read as inches" in check.diagnosis[0]


def test_one_bad_ball_is_named():
    centres = BALLS.centres_mm.copy()
    centres[1] += [0.2, 0.0, 0.0]
    check = check_distances(centres, BALLS.centres_mm, BALLS.names)
    assert "ball B2 is the likeliest culprit" in check.diagnosis[0]
    assert check.worst_mm[0] > 0.1


def test_registration_residual_warns_or_fails(tmp_path):
    make_session(tmp_path / "s")
    path = tmp_path / "s" / "centres.csv"
    frame = pd.read_csv(path)
    row = frame.index[(frame.label == "S1") & (frame.ball == "B2")][0]
    # move B2 45 um away from the balls' centroid, in their plane: the distances
    # change by < 50 um (passes) but the registration residual is ~21 um RMS
    others = frame[(frame.label == "S1")][["x", "y", "z"]].to_numpy()
    away = others[1] - others.mean(axis=0)
    frame.loc[row, ["x", "y", "z"]] = others[1] + 0.045 * away / np.linalg.norm(away)
    frame.to_csv(path, index=False)
    result = run("process", tmp_path / "s")
    assert result.exit_code == 0
    assert "warning: step S1: registration residual" in result.output
    result = run("process", tmp_path / "s", "--overwrite", "--strict-registration")
    assert result.exit_code == 1 and "step S1: registration residual" in result.output


def test_inspect_lists_the_real_dmis_samples():
    from tests.io.test_dmis import SAMPLES

    for name, count in (("Example1.dmo", 6), ("Example2.dmo", 9), ("impeller-part-1.dmo", 162)):
        result = run("inspect", SAMPLES / name, "--csv")
        assert result.exit_code == 0, result.output
        table = pd.read_csv(__import__("io").StringIO(result.stdout))
        assert len(table) == count
    table = pd.read_csv(
        __import__("io").StringIO(run("inspect", SAMPLES / "Example1.dmo", "--csv").stdout)
    )
    sphere = table[table.type == "SPHERE"].iloc[0]
    assert (sphere.x_mm, sphere.y_mm, sphere.z_mm, sphere.size_mm) == (
        74.8580,
        58.0652,
        3.7478,
        27.8511,
    )


def test_inspect_csv_and_errors(tmp_path):
    make_session(tmp_path / "s", n_targets=1)
    result = run("inspect", tmp_path / "s" / "centres.csv")
    assert result.exit_code == 0 and "R1_B3" in result.stdout and "SPHERE" in result.stdout
    bad = tmp_path / "bad.dmo"
    bad.write_text(
        "DMISMN/'x',04.0\nDATE=2020/01/01\nTIME=10:00:00\nFA(S1_B1_1)=FEAT/POINT,CART,1,2,abc\n"
    )
    result = run("inspect", bad)
    assert result.exit_code == 1 and "bad.dmo:4" in result.output


def test_fit_spheres_shows_a_progress_bar_on_the_general_dmis_reader(tmp_path):
    make_session(tmp_path / "s", output="dmis", n_targets=1, point_noise_mm=1e-3)
    dmo = tmp_path / "s" / "points.dmo"
    fast = run("fit-spheres", dmo, "-o", tmp_path / "fast.csv")
    assert fast.exit_code == 0 and "reading points.dmo" not in fast.output
    lines = dmo.read_text().splitlines(keepends=True)
    dmo.write_text("".join(lines[:2] + ["$$ a comment: the general reader\n"] + lines[2:]))
    slow = run("fit-spheres", dmo, "-o", tmp_path / "slow.csv")
    assert slow.exit_code == 0 and "reading points.dmo" in slow.stderr
    assert (tmp_path / "slow.csv").read_text() == (tmp_path / "fast.csv").read_text()


def test_fit_spheres_old_option_name_still_reads_with_a_warning(tmp_path):
    make_session(tmp_path / "s", output="points", n_targets=1, point_noise_mm=1e-3)
    new = run("fit-spheres", tmp_path / "s" / "points.csv", "--diameter-mm", "25.4")
    old = run("fit-spheres", tmp_path / "s" / "points.csv", "--fixed-diameter", "25.4")
    assert old.exit_code == 0 and "now --diameter-mm" in old.output
    assert old.stdout == new.stdout
    both = run(
        "fit-spheres",
        tmp_path / "s" / "points.csv",
        "--diameter-mm",
        "25.4",
        "--fixed-diameter",
        "25.4",
    )
    assert both.exit_code == 2
