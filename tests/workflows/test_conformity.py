"""The conformity statement (issue 25, item 2): ISO 14253-1's decision rule on known
cases, ``--tolerance`` and ``tolerances:`` through ``process`` (``poses.csv``) and
``report`` (verdict and table), the decisions recomputed here from ``poses.csv``'s own
deviations and uncertainties."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.conformity import CONFORMS, DOES_NOT_CONFORM, NOT_DECIDABLE, combine, decide
from hexatherm.workflows.process.conformity import parse_tolerances
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "paper-zero-pose"


def test_decision_rule_on_known_cases():
    # T = 2: well inside; |d| + U exactly T (the acceptance limit, inclusive); U straddling
    # the upper limit; on the limit itself; |d| - U exactly T (still not decidable); outside
    # by more than U, both signs; an unknown U; U larger than T
    d = np.array([0.5, 1.0, 1.5, 2.0, 3.0, 3.5, -3.5, 0.1, 0.1])
    u = np.array([1.0, 1.0, 1.0, 0.5, 1.0, 1.0, 1.0, np.nan, 2.5])
    expected = [
        CONFORMS,
        CONFORMS,
        NOT_DECIDABLE,
        NOT_DECIDABLE,
        NOT_DECIDABLE,
        DOES_NOT_CONFORM,
        DOES_NOT_CONFORM,
        NOT_DECIDABLE,
        NOT_DECIDABLE,
    ]
    assert decide(d, u, 2.0).tolist() == expected
    assert combine([CONFORMS, CONFORMS]) == CONFORMS
    assert combine([CONFORMS, NOT_DECIDABLE]) == NOT_DECIDABLE
    assert combine([NOT_DECIDABLE, DOES_NOT_CONFORM, CONFORMS]) == DOES_NOT_CONFORM
    rows = combine([[CONFORMS, NOT_DECIDABLE], [CONFORMS, CONFORMS]], axis=1)
    assert rows.tolist() == [NOT_DECIDABLE, CONFORMS]


def test_parse_tolerances():
    got = parse_tolerances("Tx=2um, Tz=0.003mm,Rx=10urad,Rz=0.001deg")
    assert got == pytest.approx(
        {"Tx_um": 2.0, "Tz_um": 3.0, "Rx_urad": 10.0, "Rz_urad": np.pi / 180 * 1e3}
    )
    for bad in ("Tx=2", "Tx=2urad", "Qx=2um", "Tx=-1um", "Tx=2um,Tx=3um", "Rx=1mm", "Tx=1e999um"):
        with pytest.raises(ValueError):
            parse_tolerances(bad)
    # an asymmetric zone: LOWER..UPPER (issue 33)
    got = parse_tolerances("Tz=-1..3um,Rx=0..0.02mrad")
    assert got == {"Tz_um": (-1.0, 3.0), "Rx_urad": (0.0, 20.0)}
    for bad in ("Tz=3..-1um", "Tz=1..1um", "Tz=-1..um", "Tz=..3um"):
        with pytest.raises(ValueError):
            parse_tolerances(bad)


def expected_decisions(poses: pd.DataFrame, name: str, unit: str, limit: float, k: float):
    """ISO 14253-1 written out here, from poses.csv's own columns."""
    d = poses[f"d{name}_corr_{unit}"].abs()
    big_u = k * poses[f"u_d{name}_corr_{unit}"]
    return np.where(
        d + big_u <= limit, CONFORMS, np.where(d - big_u > limit, DOES_NOT_CONFORM, NOT_DECIDABLE)
    )


def test_process_writes_the_decisions_to_poses_csv(tmp_path):
    out = tmp_path / "out"
    k = 0.25
    result = CliRunner().invoke(
        main,
        [
            "process",
            str(SESSION),
            "-o",
            str(out),
            "--tolerance",
            "Tx=1um",
            "--tolerance",
            "Rx=0.03mrad",
            "--coverage-factor",
            str(k),
        ],
    )
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(out / "poses.csv")
    tx = expected_decisions(poses, "Tx", "um", 1.0, k)
    rx = expected_decisions(poses, "Rx", "urad", 30.0, k)
    # the chosen tolerance puts targets in all three classes
    assert set(tx) == {CONFORMS, NOT_DECIDABLE, DOES_NOT_CONFORM}
    assert poses["conformity_dTx"].tolist() == tx.tolist()
    assert poses["conformity_dRx"].tolist() == rx.tolist()
    assert (poses["tol_upper_dTx_um"] == 1.0).all() and (poses["tol_upper_dRx_urad"] == 30.0).all()
    assert (poses["tol_lower_dTx_um"] == -1.0).all()
    assert (poses["decision_rule"] == "iso14253").all()
    np.testing.assert_allclose(poses["U_dTx_corr_um"], k * poses["u_dTx_corr_um"], atol=1e-4)
    assert (poses["coverage_factor"] == k).all()
    overall = [combine(row) for row in zip(tx, rx, strict=True)]
    assert poses["conformity"].tolist() == [str(o) for o in overall]
    assert "conformity" in result.output and "DOES NOT CONFORM" in result.output
    # the untoleranced components get no columns; the spec's columns are untouched
    assert "conformity_dTy" not in poses
    expected = pd.read_csv(SESSION / "expected" / "poses.csv")
    pd.testing.assert_frame_equal(poses[expected.columns], expected)


def test_session_tolerances_and_report_verdict(tmp_path):
    session = tmp_path / "s"
    shutil.copytree(SESSION, session, ignore=shutil.ignore_patterns("expected"))
    with (session / "session.yaml").open("a") as f:
        f.write("\ntolerances: {Tx_um: 5.0, Ty_um: 5.0, Tz_um: 5.0}\n")
    out = tmp_path / "report.html"
    # the session's tolerances are judged where the numbers are made, and the report
    # renders that judgement (issue 34)
    assert CliRunner().invoke(main, ["process", str(session)]).exit_code == 0
    result = CliRunner().invoke(main, ["report", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(SESSION / "expected" / "poses.csv")
    decisions = np.array(
        [expected_decisions(poses, n, "um", 5.0, 2.0) for n in ("Tx", "Ty", "Tz")]
    ).T
    overall = str(combine(decisions))
    words = {CONFORMS: "CONFORMS", NOT_DECIDABLE: "NOT DECIDABLE", DOES_NOT_CONFORM: "DOES NOT"}
    assert f"Conformity: {words[overall]}" in result.output
    page = out.read_text()
    assert "ISO 14253-1 (guard band w = U)" in page and "Tx: T = ±5 µm" in page
    # the risk the rule carries at its acceptance limit: 1 - Phi(2) for w = U, k = 2
    assert "acceptance limit 2.28 %" in page
    assert page.count("<td>conforms</td>") >= int(np.sum(decisions == CONFORMS))
    # process's --tolerance wins over the session's, key by key
    processed = CliRunner().invoke(
        main, ["process", str(session), "--overwrite", "--tolerance", "Tx=0.01um"]
    )
    assert processed.exit_code == 0, processed.output
    again = CliRunner().invoke(main, ["report", str(session), "-o", str(out), "--overwrite"])
    assert again.exit_code == 0, again.output
    decisions[:, 0] = expected_decisions(poses, "Tx", "um", 0.01, 2.0)
    # with U ~1.3 um nothing can conform to 0.01 um: where |d| - U > T it does not, else
    # U straddles the limit (both occur on this session)
    assert set(decisions[:, 0]) == {NOT_DECIDABLE, DOES_NOT_CONFORM}
    overall = str(combine(decisions))
    assert f"Conformity: {words[overall]}" in again.output
    assert "Tx ±0.01 um, Ty ±5 um" in again.output


@pytest.mark.parametrize("bad", ["Tx=2", "Tx=2urad", "Tq=1um"])
def test_a_bad_tolerance_is_a_usage_error(tmp_path, bad):
    result = CliRunner().invoke(
        main, ["process", str(SESSION), "-o", str(tmp_path / "o"), "--tolerance", bad]
    )
    assert result.exit_code == 2 and "--tolerance" in result.output
    assert not (tmp_path / "o").exists()


def test_a_bad_tolerances_mapping_names_file_line_field(tmp_path):
    session = tmp_path / "s"
    shutil.copytree(SESSION, session, ignore=shutil.ignore_patterns("expected"))
    with (session / "session.yaml").open("a") as f:
        f.write("\ntolerances:\n  Tx_um: -2\n")
    result = CliRunner().invoke(main, ["process", str(session), "-o", str(tmp_path / "o")])
    assert result.exit_code != 0
    line = (session / "session.yaml").read_text().splitlines().index("  Tx_um: -2") + 1
    assert f"session.yaml:{line}: field 'tolerances.Tx_um'" in result.output
