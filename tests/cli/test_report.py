"""``hexatherm report``: writes one HTML file, never replaces one unasked, fails cleanly."""

from __future__ import annotations

import base64
import html
import re
import shutil

import pytest
from click.testing import CliRunner

import hexatherm.workflows.report.html
from hexatherm.cli import main
from hexatherm.io.manifest import read_manifest
from tests.shipped import SHIPPED

SESSION = SHIPPED / "paper-zero-pose"
IMG = re.compile(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"')


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def session(tmp_path):
    """A copy of the shipped session (the default output goes into the session folder)."""
    return session_copy(tmp_path)


def session_copy(tmp_path):
    folder = tmp_path / "paper"
    shutil.copytree(SESSION, folder, ignore=shutil.ignore_patterns("expected", "truth"))
    return folder


@pytest.fixture(scope="module")
def reported(tmp_path_factory):
    """``report SESSION`` of a fresh copy (processed first), rendered once for the tests
    that read it: the session folder, the command's result, the page it wrote."""
    session = session_copy(tmp_path_factory.mktemp("reported"))
    result = run("report", session)
    page = (session / "report.html").read_text(encoding="utf-8")
    return session, result, page


def test_report_writes_the_page_into_the_session_folder(reported):
    session, result, page = reported
    assert result.exit_code == 0, result.output
    images = IMG.findall(page)
    assert len(images) == 4
    assert all(base64.b64decode(data).startswith(b"\x89PNG\r\n\x1a\n") for data in images)
    assert "paper-zero-pose" in page and "<td>S10</td>" in page
    # the provenance of a command-line run: its command line and options
    # paths relative to the session folder, options as a person writes them (issue 33)
    assert "<td>hexatherm report .</td>" in page
    assert "(k = 2)" in page
    # (the text, not the figures' base64, where any four letters may occur)
    text = IMG.sub("", page)
    assert "coverage_factor = " not in text and "None" not in text
    assert str(session.parent) not in page  # no path of the lab's computer
    # and the results it rendered: process's provenance, with its SHA-256
    assert "results/provenance.json" in page and "results/poses.csv" in page
    assert f"wrote {session / 'report.html'}" in result.output
    # the one hidden file is hexatherm's record of what it wrote there, for --overwrite
    assert sorted(p.name for p in session.iterdir() if p.name.startswith(".")) == [
        ".hexatherm-manifest.json"
    ]
    # no results there: processed first, as process does (its results/), and said
    assert sorted(read_manifest(session).files) == ["report.html"]
    assert (session / "results" / "provenance.json").is_file()
    again = run("report", session, "--overwrite")
    assert again.exit_code == 0, again.output


def test_report_refuses_to_overwrite_unless_asked(session, tmp_path, monkeypatch):
    out = tmp_path / "out" / "r.html"
    out.parent.mkdir()
    out.write_text("keep me\n")
    again = run("report", session, "-o", out)
    assert again.exit_code == 1 and "use --overwrite" in again.output
    assert out.read_text() == "keep me\n"
    foreign = run("report", session, "-o", out, "--overwrite")
    assert foreign.exit_code == 1 and "r.html (not written by hexatherm" in foreign.output
    assert out.read_text() == "keep me\n"
    out.unlink()
    # the page itself is tested above; here that --overwrite replaces the file and that
    # process's options (recorded in its provenance.json) reach the report
    processed = run(
        "process",
        session,
        "--overwrite",
        "--interpolation",
        "before",
        "--mc",
        50,
        "--seed",
        3,
        "--quality-threshold",
        "registration_rms_um=1.5",
        "--tolerance",
        "Tx=20um",
        "--coverage-factor",
        "3",
    )
    assert processed.exit_code == 0, processed.output
    calls = []
    real = hexatherm.workflows.report.html.report_html

    def spy(result, uncertainty=None, quality=None, coverage_factor=2.0, **kwargs):
        calls.append(
            (
                result.interpolation,
                uncertainty.draws,
                uncertainty.seed,
                quality.thresholds.registration_rms_um,
                coverage_factor,
            )
        )
        return real(result, uncertainty, quality, coverage_factor, **kwargs)

    monkeypatch.setattr(hexatherm.workflows.report.html, "report_html", spy)
    replaced = run("report", session, "-o", out, "--overwrite")
    assert replaced.exit_code == 0, replaced.output
    assert calls[-1] == ("before", 50, 3, 1.5, 3.0)
    assert "<td>interpolation</td><td>before</td>" in out.read_text().replace("\n", "")
    assert sorted(p.name for p in out.parent.iterdir()) == [".hexatherm-manifest.json", "r.html"]


def test_report_of_a_bad_session_fails_cleanly_and_writes_nothing(session):
    lines = (session / "centres.csv").read_text().splitlines(keepends=True)
    (session / "centres.csv").write_text(
        "".join(line for line in lines if not line.startswith("S3,"))
    )
    result = run("report", session)
    assert result.exit_code == 1
    assert "step S3: not measured" in result.output and "Traceback" not in result.output
    assert not (session / "report.html").exists()
    assert not any(p.name.startswith(".") for p in session.iterdir())


def test_report_refuses_a_bad_quality_threshold(session):
    result = run("report", session, "--quality-threshold", "form=5")
    assert result.exit_code == 2  # a usage error: process's option, not report's
    assert "--quality-threshold is an option of process" in result.output
    assert not (session / "report.html").exists()


@pytest.mark.parametrize("k", ["nan", "0", "-1", "inf", "two"])
def test_report_refuses_a_bad_coverage_factor(session, k):
    result = run("report", session, "--coverage-factor", k)
    assert result.exit_code == 2 and "--coverage-factor" in result.output, result.output
    assert not (session / "report.html").exists()


def test_report_is_listed_by_help():
    result = run("--help")
    assert result.exit_code == 0 and "report" in result.output
    assert "Write the HTML report of a processed session's results." in result.output


def test_report_prints_the_pages_verdict(reported):
    _, result, page = reported  # the page as written, before any other test's --overwrite
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("Targets: 10;")
    deviation = next(line for line in lines if line.startswith("Largest corrected deviation"))
    text = deviation.split(": ", 1)[1]
    assert html.escape(text) in page  # the same words as the page's verdict block
