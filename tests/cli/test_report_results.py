"""``report`` renders what ``process`` wrote (issue 34, item 1): the page's numbers are
poses.csv's, whatever options process had; stale or edited results are refused; process's
options are refused by report, naming process."""

from __future__ import annotations

import html
import re
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.csvout import RESOLUTION
from hexatherm.workflows.report import fixed
from tests.audit import session_copy

NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
UNITS = ("um",) * 3 + ("urad",) * 3


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def page_numbers(page: str) -> set[str]:
    """Every number printed in a table cell of the page."""
    cells = re.findall(r"<td[^>]*>(.*?)</td>", page, flags=re.S)
    return {html.unescape(n) for c in cells for n in re.findall(r"-?[0-9]+\.[0-9]+", c)}


@pytest.fixture(scope="module")
def smooth(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("smooth")
    # probed points; the smooth fit is used there (on paper-zero-pose it falls back to the
    # two neighbours, and the page could not tell smooth from linear)
    session = session_copy(tmp, "paper-zero-pose-dmis")
    result = run("process", session, "--interpolation", "smooth", "--mc", "20", "--seed", "3")
    assert result.exit_code == 0, result.output
    return session, session / "results"


def test_report_of_results_shows_poses_csv_numbers(smooth: tuple[Path, Path]) -> None:
    session, results = smooth
    out = session.parent / "page.html"
    result = run("report", results, "-o", out)
    assert result.exit_code == 0, result.output
    printed = page_numbers(out.read_text(encoding="utf-8"))
    poses = pd.read_csv(results / "poses.csv")
    for tag in ("conv", "corr"):
        for name, unit in zip(NAMES, UNITS, strict=True):
            for value in poses[f"d{name}_{tag}_{unit}"]:
                # the file is rounded to its resolution, the page to fewer digits: a value
                # half-way between two of the page's may print as either
                half = RESOLUTION[unit] / 2
                shown = {fixed(value + d, unit) for d in (-half, 0.0, half)}
                assert shown & printed, (tag, name, value)
    # the smooth interpolation's corrected poses differ from the linear ones: the page
    # is not the linear processing of the session
    other = session.parent / "linear"
    assert run("process", session, "-o", other).exit_code == 0
    lin = pd.read_csv(other / "poses.csv")
    differ = [
        fixed(v, "um")
        for v, w in zip(lin["dTx_corr_um"], poses["dTx_corr_um"], strict=True)
        if fixed(v, "um") != fixed(w, "um")
    ]
    assert len(differ) >= 5 and not set(differ) <= printed
    assert "Monte Carlo" in out.read_text(encoding="utf-8")  # process's --mc, not asked again


def test_the_page_names_the_results_it_rendered(smooth: tuple[Path, Path]) -> None:
    import hashlib

    session, results = smooth
    out = session.parent / "named.html"
    assert run("report", session, "-o", out).exit_code == 0  # a session: its results/
    page = out.read_text(encoding="utf-8")
    for name in ("poses.csv", "quality.csv", "provenance.json"):
        digest = hashlib.sha256((results / name).read_bytes()).hexdigest()
        assert digest in page, name


def test_stale_or_edited_results_are_refused(tmp_path: Path) -> None:
    session = session_copy(tmp_path, "paper-zero-pose")
    assert run("process", session).exit_code == 0
    poses = session / "results" / "poses.csv"
    text = poses.read_text()
    poses.write_text(text.replace("S1,", "S1,", 1)[:-2] + "9\n")
    edited = run("report", session)
    assert edited.exit_code == 1 and "poses.csv is not what process wrote" in edited.output
    poses.write_text(text)
    with (session / "temperatures.csv").open("a") as handle:
        handle.write("\n")
    stale = run("report", session)
    assert stale.exit_code == 1 and "are stale" in stale.output, stale.output
    assert "temperatures.csv changed" in stale.output
    assert not (session / "report.html").exists()


def test_a_session_without_results_is_processed_first_and_says_so(tmp_path: Path) -> None:
    session = session_copy(tmp_path, "paper-zero-pose")
    result = run("report", session)
    assert result.exit_code == 0, result.output
    assert "processed it first as 'hexatherm process" in result.output
    provenance = (session / "results" / "provenance.json").read_text()
    assert '"command": "process"' in provenance
    assert (session / "report.html").is_file()


@pytest.mark.parametrize(
    "option",
    [
        ["--interpolation", "smooth"],
        ["--mc", "10"],
        ["--fixed-diameter"],
        ["--tolerance", "Tx=2um"],
    ],
)
def test_process_options_given_to_report_are_refused_naming_process(
    tmp_path: Path, option: list[str]
) -> None:
    session = session_copy(tmp_path, "paper-zero-pose")
    result = run("report", session, *option)
    assert result.exit_code == 2
    assert f"{option[0]} is an option of process" in result.output
    assert not (session / "report.html").exists() and not (session / "results").exists()


def test_the_conformity_is_process_s_and_a_lab_s_own_tolerances_are_said(tmp_path: Path) -> None:
    # process judged Tx with a guarded rule: the page's decisions are poses.csv's, and its
    # rule; the lab file's Ty (not judged by process) is judged on the same numbers and
    # said; the lab's other decision rule is not used, with a warning
    session = session_copy(tmp_path, "paper-zero-pose")
    judged = run(
        "process", session, "--tolerance", "Tx=0.5um", "--decision-rule", "guarded-acceptance"
    )
    assert judged.exit_code == 0, judged.output
    lab = tmp_path / "lab.yaml"
    lab.write_text(
        "format: hexatherm-lab/1\nlab: L\n"
        "decision_rule:\n  rule: simple\ntolerances:\n  Ty_um: 50\n",
        encoding="utf-8",
    )
    out = tmp_path / "page.html"
    result = run("report", session, "--lab", lab, "-o", out)
    assert result.exit_code == 0, result.output
    assert "Ty_um judged against the lab file's tolerances" in result.output
    assert "decision_rule simple is not used" in result.output
    poses = pd.read_csv(session / "results" / "poses.csv")
    page = html.unescape(out.read_text(encoding="utf-8"))
    rows = {  # the conformity table's rows: with the probability of conforming (%)
        label: cells
        for label, cells in re.findall(r"<tr[^>]*><td>(S\d+)</td>(.*?)</tr>", page)
        if " %</td>" in cells
    }
    for label, decision in zip(poses["label"], poses["conformity_dTx"], strict=True):
        first = re.findall(r"<td>([a-z ]+)</td>", rows[label])[0]  # Tx's, then Ty's, overall
        assert first == decision.replace("_", " "), (label, decision, rows[label])
    assert "guarded acceptance" in page.lower()


def test_process_s_warnings_and_centres_basis_reach_the_page(tmp_path: Path) -> None:
    import json

    session = session_copy(tmp_path, "paper-zero-pose")
    assert run("process", session).exit_code == 0
    notes = json.loads((session / "results" / "provenance.json").read_text())["process"]
    assert notes["centres_uncertainty"].startswith("registration residuals pooled")
    out = tmp_path / "page.html"
    assert run("report", session, "-o", out).exit_code == 0
    page = html.unescape(out.read_text(encoding="utf-8"))
    assert f"ball centres: {notes['centres_uncertainty']}" in page
