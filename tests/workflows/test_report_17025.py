"""A certificate a lab signs as it comes out (issue 33): the items of ISO/IEC 17025:2017
clause 7.8.2.1 in the process report and the calibration report, read from the PDF that
headless Chromium prints (as ``test_report_identity``), made with the example lab's
templates (``docs/examples/lab-templates``) and a lab file naming another lab: that lab
on every page, the example's nowhere; each document its own number, on every page.
"""

from __future__ import annotations

import html
import re
import shutil
from pathlib import Path

import pandas as pd
from click.testing import CliRunner

from hexatherm.cli import main
from tests.workflows.test_report_browser import PAGE, WORD, print_pdf
from tests.workflows.test_report_identity import session_copy

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "docs" / "examples" / "lab-templates"

OTHER_LAB = """\
format: hexatherm-lab/1
lab: Laboratoire Precision Sud
address: 3 rue des Mesures, 34000 Montpellier, France
contact: +33 4 00 00 00 00
accreditation: COFRAC 2-9999
place: measuring room B, 20 +- 0.3 degC
procedure: "LPS-PO-12 rev. 2"
cmm: {make: Zeiss, model: PRISMO, serial: "CMM-4711"}
signatures:
  - {role: Measured by, name: J. Doe}
  - {role: Approved by, name: B. Martin}
numbering: "LPS-{session}-{doc}"
titles: {report: Calibration certificate, calibrate: Geometry calibration certificate}
decision_rule: {rule: guarded-acceptance, guard_factor: 1}
templates: lab-templates
"""

IDENT = """
identification:
  customer: ACME Optics
  customer_address: 5 Optics Park, Grenoble
  report_number: "HX-2026-017"
  received: "2019-12-18"
  deviations: "ambient 0.4 degC above the procedure's 20 +- 0.3 degC during S7-S10"
  hexapod: {model: H-850 demo, serial: "SN-0042", condition: "as received, no damage"}
tolerances: {Tx_um: 5, Ty_um: [-3, 8], Rz_urad: 50}
"""

#: what every page carries: the lab of the lab file, the page count (the number is added)
EVERY_PAGE = ["Laboratoire Precision Sud", "3 rue des Mesures, 34000 Montpellier, France"]

#: 7.8.2.1 item -> a text the document must hold somewhere
ITEMS = {
    "a title": "Calibration certificate",
    "b lab and address": "Laboratoire Precision Sud, 3 rue des Mesures",
    "c place": "Place of measurement measuring room B",
    "e customer": "Customer ACME Optics, 5 Optics Park, Grenoble",
    "f method": 'Kalas, A. Vissière, O. Company, S. Krut, P. Noiré, T. Roux, F. Pierrot, "Thermal '
    'deflection decoupled 6-DOF pose measurement of hexapods"',
    "f procedure": "Procedure LPS-PO-12 rev. 2",
    "g item": "serial SN-0042; condition: as received, no damage",
    "h receipt": "Date of receipt 2019-12-18",
    "j issue": "Date of issue",
    "k sampling": "Sampling not applicable",
    "l relates only": "The results relate only to the item measured",
    "n deviations": "Deviations from the method ambient 0.4 degC above",
    "o authorised": "Authorised by J. Doe (Measured by), B. Martin (Approved by)",
    "p external": "Results from external providers none",
    "end": "End of report",
}


def pdf_pages(page: Path, folder: Path) -> list[str]:
    """The text of every printed page, its words in lines as a reader reads them (by
    height on the page, then left to right: a table's row is one line)."""
    text = print_pdf(page, folder / "page.pdf")
    pages = []
    for _, _, body in PAGE.findall(text):
        words = [(float(y1), float(x0), w) for x0, _, _, y1, w in WORD.findall(body)]
        lines: list[list[tuple[float, float, str]]] = []
        for word in sorted(words):
            if lines and abs(lines[-1][0][0] - word[0]) < 2.0:  # the same baseline
                lines[-1].append(word)
            else:
                lines.append([word])
        pages.append(
            " ".join(
                " ".join(html.unescape(w) for _, _, w in sorted(ln, key=lambda t: t[1]))
                for ln in lines
            )
        )
    return pages


def lab_folder(tmp_path: Path) -> Path:
    shutil.copytree(EXAMPLE, tmp_path / "lab-templates")
    (tmp_path / "lab-templates" / "lab.yaml").unlink()  # the example's, not used here
    lab = tmp_path / "lab.yaml"
    lab.write_text(OTHER_LAB, encoding="utf-8")
    return lab


def check_document(pages: list[str], number: str, title: str) -> str:
    """Every page: the other lab, the number, page x of y; the items somewhere; the
    example lab nowhere. The whole text, for more checks."""
    assert len(pages) >= 2
    for n, text in enumerate(pages, 1):
        for item in [*EVERY_PAGE, f"Report number: {number}"]:
            assert item in text, (n, item)
        assert f"page {n} of {len(pages)}" in text, n
    text = " ".join(pages)
    squeezed = "".join(text.split())  # a cell's text wraps where the browser breaks it
    for name, item in {**ITEMS, "a title": title}.items():
        assert "".join(item.split()) in squeezed, name
    assert "Example Metrology" not in text and "Musterstrasse" not in text
    assert f"End of report {number}" in pages[-1]
    return text


def test_both_reports_carry_the_items_of_17025_7_8_2_1(tmp_path):
    lab = lab_folder(tmp_path)
    session = session_copy("paper-zero-pose", tmp_path, IDENT)
    # the CMM's clock: local time at +01:00 (the shipped session says +00:00)
    spec = session / "session.yaml"
    spec.write_text(spec.read_text().replace('utc_offset: "+00:00"', 'utc_offset: "+01:00"'))
    out = tmp_path / "report.html"
    result = CliRunner().invoke(main, ["report", str(session), "--lab", str(lab), "-o", str(out)])
    assert result.exit_code == 0, result.output
    pages = pdf_pages(out, tmp_path / "p")
    number = "LPS-HX-2026-017-R"  # the lab's pattern: its own number, not the session's
    text = check_document(pages, number, "Calibration certificate")
    # i: the dates measured with their UTC offset: the CMM's local times (the first
    # step's: the mean of its balls' times in the centres file, read here) at +01:00
    centres = pd.read_csv(session / "centres.csv")
    first = pd.to_datetime(centres["time"][centres["label"] == "O"]).mean()
    assert f"Date(s) of measurement {first.isoformat(timespec='seconds')}+01:00 to" in text
    assert "µm" in text and "µrad" in text
    # a correction smaller than its U is said to be so (item 10): Rz on this session
    assert "Not significant: the thermal correction is smaller than its U on Rz" in text
    # the decision rule and the risk it carries (JCGM 106: 1 - Phi(2) at k = 2)
    assert "guarded acceptance, ILAC-G8:09/2019 4.2.2 (w = U)" in text
    assert "acceptance limit 2.28 %" in text and "Ty: T = [-3, 8] µm" in text
    # the number in the provenance too; the signatures dated with the date of issue
    issue = re.search(r"Date of issue (\d{4}-\d{2}-\d{2})", text).group(1)
    assert f"report number {number}" in text
    assert f"Approved by B. Martin {issue}" in text

    # the calibration report: its own number, not the session's nor the process report's
    (tmp_path / "cal").mkdir()
    cal_lab = lab_folder(tmp_path / "cal")
    session = session_copy("calibration-geometry", tmp_path / "cal", IDENT)
    out = tmp_path / "cal" / "out"
    args = ["calibrate", str(session), "--level", "joints", "--lab", str(cal_lab), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    pages = pdf_pages(out / "report.html", tmp_path / "cal")
    text = check_document(pages, "LPS-HX-2026-017-C", "Geometry calibration certificate")
    assert "Report number: HX-2026-017 " not in text  # the session's number is not its own
    # (compared without blanks: the PDF's text may break the line at the number's hyphen)
    squeezed = "".join(text.split())
    assert "thesessions'ownreports:calibration-geometry(reportHX-2026-017)" in squeezed


def test_the_report_number_option_wins_and_titles_are_the_labs(tmp_path):
    lab = lab_folder(tmp_path)
    session = session_copy("paper-zero-pose", tmp_path, IDENT)
    out = tmp_path / "report.html"
    args = ["report", str(session), "--lab", str(lab), "-o", str(out)]
    result = CliRunner().invoke(
        main, [*args, "--report-number", "2026/0815", "--title", "Test report"]
    )
    assert result.exit_code == 0, result.output
    page = out.read_text(encoding="utf-8")
    assert "<h1>Test report</h1>" in page and "<title>Test report 2026/0815</title>" in page
    assert "End of report 2026/0815" in page and "LPS-HX" not in page
    # the letterhead and the closing print the lab file's lab, the base template keeps
    # its page numbering and signatures
    assert "written approval of Laboratoire Precision Sud" in page
    assert 'counter(page) " of " counter(pages)' in page and "<h2>Signatures</h2>" in page


def test_a_bad_numbering_pattern_names_the_lab_file_line_and_field(tmp_path):
    lab = lab_folder(tmp_path)
    lab.write_text(OTHER_LAB.replace("LPS-{session}-{doc}", "LPS-{serial}"), encoding="utf-8")
    session = session_copy("paper-zero-pose", tmp_path, IDENT)
    out = tmp_path / "report.html"
    result = CliRunner().invoke(main, ["report", str(session), "--lab", str(lab), "-o", str(out)])
    assert result.exit_code == 1 and not out.exists()
    line = OTHER_LAB.splitlines().index('numbering: "LPS-{session}-{doc}"') + 1
    assert f"lab.yaml:{line}: field 'numbering'" in result.output and "{serial}" in result.output
