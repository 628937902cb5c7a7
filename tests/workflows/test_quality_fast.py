"""The quality checks' fast paths against the loops they replace: the diameter of every
step and ball (each cell once: set at once), the checks' ran/failed flags (lists, not
Series.map)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from hexatherm.session import QualityLimits
from hexatherm.workflows.process.measured import nominal_fit_diameter_mm
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.quality import CHECKS, DETAILS, NA, QualityReport, _ball_values
from tests.workflows.test_quality import session


def loop_diameters(result) -> np.ndarray:
    """_ball_values' diameters as its loop makes them, record by record, cell by cell."""
    plan, balls = result.session.plan, result.session.balls
    step_index = {label: i for i, label in enumerate(plan.labels)}
    step_index.update({label: step_index[kept] for label, kept in result.repeat_of.items()})
    ball_index = {name: j for j, name in enumerate(balls.names)}
    nominal_mm = nominal_fit_diameter_mm(balls)
    diameter = np.full((len(plan.labels), len(balls.names)), np.nan)
    for rec in result.records:
        for label, ball, d in zip(rec.label, rec.ball, rec.diameter_mm, strict=True):
            i, j = step_index[label], ball_index[ball]
            value = (d - nominal_mm[j]) * 1e3
            if not abs(diameter[i, j]) >= abs(value):
                diameter[i, j] = value
    return diameter


def test_diameters_as_the_loop_makes_them(tmp_path):
    result = process_session(session(tmp_path / "s"))
    _, diameter = _ball_values(result)
    np.testing.assert_array_equal(diameter, loop_diameters(result))
    assert not np.isnan(diameter).any()
    # every cell twice (the records of two files): the loop keeps the larger deviation
    rec = result.records[0]
    bigger = dataclasses.replace(
        rec, diameter_mm=rec.diameter_mm + np.linspace(-2e-3, 2e-3, len(rec))
    )
    twice = dataclasses.replace(result, records=(rec, bigger))
    _, diameter = _ball_values(twice)
    np.testing.assert_array_equal(diameter, loop_diameters(twice))
    assert not np.array_equal(diameter, _ball_values(result)[1])
    # a NaN diameter in the file's records: as the loop leaves it
    nan = rec.diameter_mm.copy()
    nan[::3] = np.nan
    holed = dataclasses.replace(result, records=(dataclasses.replace(rec, diameter_mm=nan),))
    np.testing.assert_array_equal(_ball_values(holed)[1], loop_diameters(holed))


def test_ran_and_failing_as_series_map():
    values = [True, False, NA, np.True_, np.False_, "", None, 0, 1.0]
    frame = pd.DataFrame(
        {
            "label": [f"S{i}" for i in range(len(values))],
            "ok_form": pd.Series(values, dtype=object),
        },
        index=np.arange(3, 3 + len(values)),
    )
    report = QualityReport(frame, QualityLimits())
    column = frame["ok_form"]
    pd.testing.assert_series_equal(
        report.failing("form"), column.map(lambda ok: ok is False).astype(bool)
    )
    pd.testing.assert_series_equal(
        report.ran("form"), column.map(lambda ok: isinstance(ok, bool | np.bool_)).astype(bool)
    )


def _former_failing_texts(report: QualityReport, check: str) -> list[str]:
    """``QualityReport.failing_texts`` as it was: the whole frame's failing rows taken."""
    rows = report.frame.loc[report.failing(check)]
    labels = rows["label"].astype(str).tolist()
    if check not in DETAILS:
        return labels
    column, text = DETAILS[check]
    return [
        f"{label} ({text.format(where)})" if where != "" else label
        for label, where in zip(labels, rows[column].tolist(), strict=True)
    ]


def test_failing_texts_from_two_columns_are_the_former_rows_texts():
    # issue 37 (write10k): the failing steps' labels and legs from the two columns named,
    # not the whole frame's rows; random flags (True, False, NA, numpy bools), legs given
    # as text, whole numbers or "" (no leg), labels that look like numbers
    rng = np.random.default_rng(37)
    for n in (0, 1, 7, 200):
        flags = np.array([True, False, NA, np.True_, np.False_], dtype=object)
        legs = np.array(["", "3", 4, "6", 0], dtype=object)
        data = {"label": [f"S{i}" if i % 5 else str(i) for i in range(n)], "kind": ["target"] * n}
        for check, (column, _, _) in CHECKS.items():
            data[column] = rng.normal(size=n)
            data[f"ok_{check}"] = list(rng.choice(flags, n))
        for column, _ in DETAILS.values():
            data[column] = list(rng.choice(legs, n))
        data["failed"] = [""] * n
        report = QualityReport(pd.DataFrame(data), QualityLimits())
        for check in CHECKS:
            assert report.failing_texts(check) == _former_failing_texts(report, check)


def test_ok_cells_and_file_flags_are_the_former_loops():
    # issue 37 (io10k): a check's ok_ cells made by numpy, and quality.csv's flags from
    # them, against the former list comprehensions, on random and edge masks
    from hexatherm.workflows.process.outputs import quality_file_frame
    from hexatherm.workflows.process.quality import ok_cells

    rng = np.random.default_rng(3737)
    for n in (0, 1, 2, 7, 500):
        for p_bad, p_missing in ((0.5, 0.3), (0.0, 0.0), (1.0, 0.0), (0.2, 1.0)):
            bad = rng.random(n) < p_bad
            missing = rng.random(n) < p_missing
            bad &= ~missing
            former = [NA if m else not b for m, b in zip(missing, bad, strict=True)]
            cells = ok_cells(bad, missing)
            assert cells == former
            assert [type(c) for c in cells] == [type(c) for c in former]
    # quality.csv's flags: NA (could not run: passes) or the cell's truth
    cells = [True, False, NA, np.True_, np.False_, 1, 0, "", "x", np.nan, 2.5]
    frame = pd.DataFrame({"ok_form": cells, "ok_time_gap": cells[::-1]})
    frame["growth_leg"] = frame["warming_leg"] = ["", "3"] * 5 + [""]
    frame["failed"] = ""
    written = quality_file_frame(QualityReport(frame, QualityLimits()))
    for column in ("ok_form", "ok_time_gap"):
        values = frame[column].tolist()
        former = np.array([v is NA or v == NA or bool(v) for v in values])
        assert written[column].dtype == former.dtype
        np.testing.assert_array_equal(written[column].to_numpy(), former)
