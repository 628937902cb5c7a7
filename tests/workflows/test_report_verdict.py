"""The report as a deliverable: its verdict, provenance and tables, against independent truths.

The truths are the shipped ``expected/poses.csv`` and ``expected/quality.csv`` (written by
``process``, read here with pandas), the input files hashed here with hashlib, and
the plan's commanded values as the plan file writes them.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm import __version__
from hexatherm.io.csvout import RESOLUTION
from hexatherm.io.provenance import RunFacts
from hexatherm.workflows.process.outputs import poses_frame
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.quality import quality_checks
from hexatherm.workflows.process.uncertainty import pose_uncertainty
from hexatherm.workflows.report import (
    FIGURE_DPI,
    exact,
    fixed,
    pose_figure,
    poses_table_html,
    report_html,
    verdict,
)
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSIONS = SHIPPED
T_NAMES, R_NAMES = ("Tx", "Ty", "Tz"), ("Rx", "Ry", "Rz")


@pytest.fixture(scope="module")
def hidden():
    result = process_session(SESSIONS / "with-hidden-effect")
    return result, pose_uncertainty(result), quality_checks(result)


STAMP = "2026-11-25T14:00:00+01:00"


@pytest.fixture(scope="module")
def pages(hidden) -> dict[float, str]:
    """The report page of the session with k = 2 (the default) and k = 3, each rendered
    once (its figures are most of a report's time) and read by every test below; no
    facts (not run from the command line)."""
    result, u, quality = hidden
    return {
        2.0: report_html(result, u, quality, generated=STAMP),
        3.0: report_html(result, u, quality, coverage_factor=3.0, generated=STAMP),
    }


def expected(name: str) -> pd.DataFrame:
    return pd.read_csv(SESSIONS / "with-hidden-effect" / "expected" / name)


def largest(poses: pd.DataFrame, names, tag: str, unit: str):
    """(|value|, label, name, u) of the largest |d<name>_<tag>_<unit>| over the targets."""
    block = np.abs(poses[[f"d{n}_{tag}_{unit}" for n in names]].to_numpy())
    i, j = np.unravel_index(np.argmax(block), block.shape)
    return block[i, j], poses["label"][i], names[j], poses[f"u_d{names[j]}_{tag}_{unit}"][i]


@pytest.mark.parametrize("k", [2.0, 3.0])
def test_verdict_is_the_largest_deviation_of_poses_csv_with_k_times_u(hidden, k):
    result, u, quality = hidden
    poses = expected("poses.csv")
    summary = verdict(result, u, quality, coverage_factor=k)
    assert summary.targets == len(poses) == 40
    for extreme, names, unit in (
        (summary.deviation_um, T_NAMES, "um"),
        (summary.deviation_urad, R_NAMES, "urad"),
    ):
        value, label, name, u_std = largest(poses, names, "corr", unit)
        assert (extreme.target, extreme.parameter) == (label, name)
        # poses.csv holds them to half a step of their unit
        half = RESOLUTION[unit] / 2 * 1.001
        assert abs(extreme.value) == pytest.approx(value, abs=max(1e-4, half))
        assert extreme.expanded_u == pytest.approx(k * u_std, abs=k * half)
    # the thermal correction: largest |corrected - conventional|
    for extreme, names, unit in (
        (summary.correction_um, T_NAMES, "um"),
        (summary.correction_urad, R_NAMES, "urad"),
    ):
        diff = np.column_stack(
            [poses[f"d{n}_corr_{unit}"] - poses[f"d{n}_conv_{unit}"] for n in names]
        )
        assert abs(extreme.value) == pytest.approx(
            np.abs(diff).max(), abs=max(1e-4, RESOLUTION[unit] * 1.001)
        )
        assert abs(extreme.value) > 10  # the thermal drift is there (35 um, 76 urad)
    # the failing targets: quality.csv's, with their checks
    table = expected("quality.csv")
    failing = table[(table["failed"] != "none") & (table["kind"] == "target")]
    assert [label for label, _ in summary.failing_targets] == failing["label"].tolist()
    assert len(summary.failing_targets) == 3
    assert summary.basis == "linear propagation (GUM)"
    with pytest.raises(ValueError, match="must be > 0"):
        verdict(result, u, quality, coverage_factor=float("nan"))


def test_page_starts_with_the_verdict_and_states_k_wherever_u_appears(hidden, pages):
    result, u, quality = hidden
    # the poses.csv table in memory: the page's 3 decimals of the exact numbers (the file's
    # 4 decimals, rounded again, may differ in the last digit)
    poses = poses_frame(result, u)
    page = pages[3.0]
    body = page[page.index("<body>") :]
    assert body.index("Verdict") < body.index("<figure>")
    value, label, name, u_std = largest(poses, T_NAMES, "corr", "um")
    dev = f"{fixed(value, 'um').lstrip('-')} µm ({name} of {label}), U = {3 * u_std:.3f} µm (k = 3)"
    assert dev in page.replace("-", "")
    assert "3 of 40 targets failed a quality check" in page
    assert page.count("(k = 3)") >= 4  # translation, rotation, and both pose tables
    assert "Error bars: expanded uncertainty U = k·u, k = 3." in page
    assert "k = 2" not in page and "k = 1" not in page


def test_provenance_block_names_the_run_and_hashes_every_input(hidden, pages):
    result, u, quality = hidden
    facts = RunFacts(
        "report", ("sessions/with-hidden-effect", "--mc", "0"), {"mc": 0, "seed": 0}, "x"
    )
    stamp = STAMP
    page = report_html(result, u, quality, facts=facts, generated=stamp)
    block = page[page.index("<h2>Provenance</h2>") :]
    assert f"<td>{stamp}</td>" in block and f"<td>{__version__}</td>" in block
    assert "<td>hexatherm report sessions/with-hidden-effect --mc 0</td>" in block
    assert "<td>--mc 0 --seed 0</td>" in block  # as a person writes them
    assert "form ≤ 10 µm" in block and "Jacobian rcond ≥ 0.01" in block
    files = sorted(
        p for p in (SESSIONS / "with-hidden-effect").iterdir() if p.suffix in (".yaml", ".csv")
    )
    assert len(files) == 6
    for path in files:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        row = f'<td>{path.name}</td><td class="num">{path.stat().st_size}</td>'
        assert f'{row}<td class="num">{digest}</td>' in block, path.name
    outside = pages[2.0]
    assert f"<td>{stamp}</td>" in outside
    assert outside.count("not run from the command line") == 2  # command line, options


def test_pose_tables_print_exact_commanded_values_and_fixed_decimals(hidden, pages):
    result, u, quality = hidden
    plan = (SESSIONS / "with-hidden-effect" / "plan.yaml").read_text()
    page = pages[2.0]
    # the commanded values as the plan file writes them (-16.441, not -16.44)
    for text in ("-16.441", "-13.004", "14.19", "-0.051"):
        assert re.search(rf"(?<![\d.]){re.escape(text)}(?![\d])", plan), text
        assert f'<td class="num">{text}</td>' in page, text
    # deviations: 3 decimals in um, 2 in urad, in both tables; U likewise
    table = poses_table_html(result, u, "corrected", 2.0)
    rows = re.findall(r"<tr(?: class=\"\w+\")?><td>S\d+[^<]*</td>(.*?)</tr>", table)
    assert len(rows) == 40
    for row in rows:
        cells = re.findall(r'<td class="num">([^<]*)(?:<span class="u">±\xa0([^<]*)</span>)?', row)
        devs = cells[-6:]
        for j, (value, expanded) in enumerate(devs):
            pattern = r"-?\d+\.\d{3}" if j < 3 else r"-?\d+\.\d{2}"
            assert re.fullmatch(pattern, value) and re.fullmatch(pattern, expanded), (value, j)


def test_zero_commanded_columns_are_dropped():
    paper = process_session(SESSIONS / "paper-zero-pose")
    table = poses_table_html(paper, None, "conventional")
    assert "commanded Tx, Ty, Tz, Rx, Ry, Rz = 0 at every target" in table
    assert "(mm)" not in table and 'colspan="6">conventional − commanded' in table


def test_failing_targets_are_marked_in_every_table_and_the_pose_figure(hidden, pages):
    result, u, quality = hidden
    page = pages[2.0]
    for label in ("S2", "S14", "S25"):
        # conventional, corrected and quality tables
        assert page.count(f'<tr class="fail"><td>{label} ✗</td>') == 3, label
    assert page.count("✗</td>") == 3 * 3
    # shaded bands at exactly their trial positions (S2 is trial 2)
    fig = pose_figure(result, u, failing={"S2": "temperature", "S25": "temperature"})
    for ax in fig.axes:
        bands = [p for p in ax.patches if p.get_gid() == "failed"]
        centres = sorted(round(float(np.mean(b.get_x() + b.get_width() / 2))) for b in bands)
        assert centres == [2, 25]
    assert "failed a check" in [t.get_text() for t in fig.legends[0].get_texts()]


@pytest.mark.parametrize("failing", [{}, {"S2": "temperature", "S25": "temperature"}])
def test_the_pose_figure_legend_hides_no_title(hidden, failing):
    """Figure 6's legend above the panels takes two rows with the failed checks' band
    (four entries in three columns): measured by matplotlib's renderer at the dpi the
    report draws it, its box meets neither a panel's title nor the figure's."""
    result, u, _ = hidden
    fig = pose_figure(result, u, failing=failing)
    fig.set_dpi(FIGURE_DPI)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(renderer)
    assert len(fig.legends[0].get_texts()) == (4 if failing else 3)
    titles = [ax.title for ax in fig.axes] + [fig._suptitle]
    assert [t.get_text()[:2] for t in titles[:6]] == ["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]
    for title in titles:
        box = title.get_window_extent(renderer)
        assert box.height > 0 and not box.overlaps(legend), title.get_text()
    # one row of legend: the panels' top as it was
    assert failing or fig.subplotpars.top == pytest.approx(0.84)


def test_numbers_text():
    assert [fixed(-0.0004, "um"), fixed(1.005, "urad"), exact(-16.441)] == [
        "0.000",
        "1.00",  # 1.005 is 1.00499999... in binary
        "-16.441",
    ]
    assert float(exact(0.1 + 0.2)) == 0.1 + 0.2  # shortest text that reads back


@pytest.mark.parametrize("k", [2.0, 3.0])
def test_the_common_and_own_parts_are_those_of_poses_csv_times_k(pages, k):
    page = pages[k]
    poses = expected("poses.csv")
    start = page.rindex("<table", 0, page.index("part of U"))
    table = page[start : page.index("</table>", start)]
    for part, row_name in (("common", "common to all targets"), ("own", "own (the target")):
        row = table[table.index(row_name) :]
        cells = re.findall(r'<td class="num">([^<]*)</td>', row)[:6]
        for j, name in enumerate(T_NAMES + R_NAMES):
            unit = "um" if name in T_NAMES else "urad"
            column = poses[f"u_{part}_d{name}_corr_{unit}"].to_numpy()
            rms = k * float(np.sqrt(np.mean(column**2)))
            # the page rounds the unrounded RMS, poses.csv holds u rounded (1e-4 um, 1e-3
            # urad): half a step of the page's last digit plus k times half the file's
            step, written = (1e-3, 1e-4) if unit == "um" else (1e-2, 1e-3)
            assert abs(float(cells[j]) - rms) <= step / 2 + k * written / 2 + 1e-12, (
                part,
                name,
                cells[j],
                rms,
            )
    assert f"(k = {exact(k)})" in table
