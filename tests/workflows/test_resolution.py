"""Result files at a documented resolution per unit (issue 16, item 2): read as text."""

from __future__ import annotations

import csv
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.io.csvout import RESOLUTION, column_unit, resolution_of
from hexatherm.workflows.process.outputs import fits_frame, legs_frame, poses_frame, write_results
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.quality import quality_checks
from hexatherm.workflows.process.uncertainty import PoseUncertainty, pose_uncertainty
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def processed(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[ProcessResult, PoseUncertainty, Path]:
    result = process_session(SHIPPED / "paper-zero-pose-dmis")
    uncertainty = pose_uncertainty(result)
    out = tmp_path_factory.mktemp("res") / "out"
    write_results(result, out, uncertainty=uncertainty, quality=quality_checks(result))
    return result, uncertainty, out


def _rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="", encoding="utf-8") as handle:
        header, *rows = list(csv.reader(handle))
    return header, rows


@pytest.mark.parametrize(
    "name", ["poses.csv", "legs.csv", "fits.csv", "quality.csv", "covariance.csv"]
)
def test_every_number_with_a_unit_is_a_whole_number_of_steps(
    processed: tuple[ProcessResult, PoseUncertainty, Path], name: str
) -> None:
    header, rows = _rows(processed[2] / name)
    rounded = 0
    for j, column in enumerate(header):
        cells = [row[j] for row in rows if row[j] != ""]
        step = resolution_of(column)
        if step is None:
            # text, flags, seconds and pure numbers: never a unit with a resolution
            assert column_unit(column) in ("", "s"), column
            continue
        decimals = round(-math.log10(step))
        pattern = re.compile(rf"-?[0-9]+\.[0-9]{{{decimals}}}")
        for cell in cells:
            # the text itself: fixed decimals, no exponent, hence k * step exactly
            assert pattern.fullmatch(cell), (name, column, cell)
            assert cell.lstrip("-0.") or not cell.startswith("-"), (name, column, cell)
        rounded += bool(cells)
    assert rounded >= 3  # the file has columns at a resolution


def test_poses_csv_has_no_unrounded_numeric_column(
    processed: tuple[ProcessResult, PoseUncertainty, Path],
) -> None:
    # a new column with a unit that has no resolution fails here: decide, then document
    header, _ = _rows(processed[2] / "poses.csv")
    unrounded = [c for c in header if resolution_of(c) is None]
    text = ["label", "time", "ref_before", "ref_after"]
    assert unrounded == [*text, "dt_before_s", "dt_after_s", "weight_after"]
    assert {"Tx_corr_mm", "Rz_corr_deg", "dTx_corr_um", "dRz_corr_urad"} < set(header)


@pytest.mark.parametrize("name", ["poses.csv", "legs.csv", "fits.csv"])
def test_written_numbers_are_within_half_a_step_of_the_results(
    processed: tuple[ProcessResult, PoseUncertainty, Path], name: str
) -> None:
    result, uncertainty, out = processed
    exact = {
        "poses.csv": lambda: poses_frame(result, uncertainty),
        "legs.csv": lambda: legs_frame(result),
        "fits.csv": lambda: fits_frame(result),
    }[name]()
    written = pd.read_csv(out / name)
    checked = 0
    for column in exact.columns:
        step = resolution_of(column)
        if step is None or not pd.api.types.is_float_dtype(exact[column]):
            continue
        x, y = exact[column].to_numpy(), written[column].to_numpy(dtype=float)
        assert np.array_equal(np.isnan(x), np.isnan(y)), column
        ok = ~np.isnan(x)
        # half a step, and the float error of the decimal text read back
        bound = step / 2 * (1 + 1e-9) + 1e-15 * np.abs(x[ok])
        assert np.all(np.abs(x[ok] - y[ok]) <= bound), column
        checked += int(ok.sum())
    assert checked > 50


def test_every_resolution_is_a_power_of_ten_and_its_unit_a_column_suffix() -> None:
    for unit, step in RESOLUTION.items():
        assert step == 10.0 ** round(math.log10(step)), unit
        assert column_unit(f"value_{unit}") == unit
