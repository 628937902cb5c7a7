"""Result files that pandas reads without cleaning (issue 34, item 5): one dtype per column
whatever the session, every check passing or some failing, centres or probed points,
one reference per target or two.

Every CSV file ``process`` writes is read with a plain ``pandas.read_csv`` and each
column's dtype is held to one rule, by the column's name: a number with a unit
(``_mm``, ``_um``, ``_s`` ...) or a ratio is a float, a count or a leg a whole number,
a flag (``ok_*``) a boolean, a label or a name text; the same column has the same dtype
in every run."""

from __future__ import annotations

import collections
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.csvout import column_unit
from tests.audit import session_copy
from tests.shipped import SHIPPED

#: whole-number columns
INTEGERS = {"n", "growth_leg", "warming_leg"}
#: text columns (labels, names, verdicts)
TEXTS = {
    "label",
    "label_a",
    "label_b",
    "kind",
    "ball",
    "source",
    "file",
    "ref_before",
    "ref_after",
    "interpolation",
    "failed",
    "decision_rule",
}
#: float columns without a unit (ratios)
RATIOS = {"weight_after", "jacobian_rcond", "coverage_factor", "guard_factor"}


def expected_kind(column: str) -> str:
    """The dtype kind a column must read as: ``f`` float, ``i`` integer, ``b`` bool, ``O``
    text."""
    if column in INTEGERS:
        return "i"
    if column.startswith("ok_"):
        return "b"
    if column in TEXTS or column.startswith("conformity"):
        return "O"
    if column in RATIOS or column.startswith("p_conform_") or column_unit(column):
        return "f"
    raise AssertionError(f"a result column no rule names: {column} (decide, then add it here)")


def kind_of(series: pd.Series) -> str:
    """``f``, ``i``, ``b`` or ``O`` (text, whatever pandas' string dtype)."""
    if pd.api.types.is_bool_dtype(series):
        return "b"
    if pd.api.types.is_integer_dtype(series):
        return "i"
    if pd.api.types.is_float_dtype(series):
        return "f"
    assert series.map(type).eq(str).all(), series.tolist()
    return "O"


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``process``'s results of sessions that pass every check and that fail some, of
    centres and of probed points, with two references per target and with one."""
    tmp = tmp_path_factory.mktemp("dtypes")
    runs = {
        "passing": ("paper-zero-pose", ["--tolerance", "Tx=2um"]),
        "points": ("paper-zero-pose-dmis", ["--interpolation", "smooth"]),
        "failing": ("with-hidden-effect", ["--interpolation", "before"]),
        "serial": ("serial-capture", ["--quality-threshold", "form_um=0.1"]),
    }
    out = {}
    for key, (name, options) in runs.items():
        session = session_copy(tmp, name)
        folder = tmp / f"{key}-results"
        result = CliRunner().invoke(main, ["process", str(session), "-o", str(folder), *options])
        assert result.exit_code == 0, result.output
        out[key] = folder
    return out


def test_the_runs_cover_passing_and_failing_checks(results: dict[str, Path]) -> None:
    failed = {key: pd.read_csv(folder / "quality.csv")["failed"] for key, folder in results.items()}
    assert failed["passing"].eq("none").all()
    assert not failed["failing"].eq("none").all() and not failed["serial"].eq("none").all()
    one_side = pd.read_csv(results["failing"] / "poses.csv")
    assert one_side["ref_after"].eq("none").all()


def test_every_result_column_reads_with_one_dtype_whatever_the_session(
    results: dict[str, Path],
) -> None:
    seen: dict[tuple[str, str], set[str]] = collections.defaultdict(set)
    for folder in results.values():
        files = sorted(folder.glob("*.csv"))
        assert {"poses.csv", "legs.csv", "fits.csv", "quality.csv"} <= {f.name for f in files}
        for path in files:
            frame = pd.read_csv(path)
            for column in frame.columns:
                kind = kind_of(frame[column])
                seen[(path.name, column)].add(kind)
                if column == "time":  # ISO text or seconds, as the session's files give it
                    continue
                assert kind == expected_kind(column), (path.name, column, frame[column].dtype)
    mixed = {key: kinds for key, kinds in seen.items() if len(kinds) > 1}
    assert mixed == {}
    assert ("quality.csv", "ok_form") in seen and ("covariance.csv", "label_a") in seen


def test_quality_flags_are_false_exactly_where_a_check_failed(results: dict[str, Path]) -> None:
    for folder in results.values():
        frame = pd.read_csv(folder / "quality.csv")
        flags = [c for c in frame.columns if c.startswith("ok_")]
        assert len(flags) == 9
        named = frame["failed"].map(lambda t: set() if t == "none" else set(t.split(";")))
        for column in flags:
            check = column.removeprefix("ok_")
            failing = named.map(lambda names, c=check: c in names)
            assert (~frame[column]).tolist() == failing.tolist(), column
        legs = frame[["growth_leg", "warming_leg"]].to_numpy()
        assert np.isin(legs, range(7)).all()


def test_jacobian_rcond_is_written_to_a_millionth(results: dict[str, Path]) -> None:
    text = (results["passing"] / "quality.csv").read_text().splitlines()
    column = text[0].split(",").index("jacobian_rcond")
    cells = [row.split(",")[column] for row in text[1:]]
    written = [c for c in cells if c]
    assert written and all(len(c.split(".")[1]) == 6 for c in written), written


def test_the_shipped_expected_files_hold_the_same_rules() -> None:
    """What replay holds every version to (``sessions/*/expected``) follows the rules too."""
    for path in sorted(SHIPPED.glob("*/expected/*.csv")):
        if path.name not in ("poses.csv", "legs.csv", "fits.csv", "quality.csv"):
            continue
        frame = pd.read_csv(path)
        for column in frame.columns:
            if column != "time":
                assert kind_of(frame[column]) == expected_kind(column), (path, column)
