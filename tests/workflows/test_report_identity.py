"""Identification on every printed page (issue 25, item 1): the session file's
``identification:`` and a lab file (``--lab``) printed in the running header of the
process report and the calibration report, checked from the PDF headless Chromium
prints (as ``test_report_browser``), and the strict reading of the new fields.
"""

from __future__ import annotations

import hashlib
import html
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.errors import InputError
from hexatherm.io.config import read_session
from hexatherm.io.config.identity import read_lab
from tests.shipped import SHIPPED
from tests.workflows.test_report_browser import PAGE, WORD, print_pdf

ROOT = Path(__file__).resolve().parents[2]

LAB = """\
format: hexatherm-lab/1
lab: Hexapod Metrology Lab
address: 1 Example Road, Grenoble
operator: J. Doe
cmm: {make: Zeiss, model: PRISMO, serial: "CMM-4711", certificate: "DKD-K-0815-2026",
      mpe: "E0,MPE = 0.9 + L/350 um"}
signatures:
  - {role: Measured by, name: J. Doe}
  - {role: Approved by, name: A. Smith}
"""

IDENT = """
identification:
  customer: ACME Optics
  report_number: "HX-2026-017"
  operator: K. Lee
  hexapod: {model: H-850 demo, serial: "SN-0042"}
  ambient: {temperature_C: 20.1, humidity_percent: 45}
tolerances: {Tx_um: 5, Ty_um: 5, Tz_um: 5, Rx_urad: 50, Ry_urad: 50, Rz_urad: 50}
"""

#: every text the header must carry, on every page (operator: the session's wins)
EXPECTED = [
    "Hexapod Metrology Lab",
    "HX-2026-017",
    "ACME Optics",
    "K. Lee",
    "CMM-4711",
    "DKD-K-0815-2026",
    "E0,MPE = 0.9 + L/350 um",
    "Zeiss",
    "H-850 demo",
    "SN-0042",
    "20.1",
    "A. Smith (Approved by)",
]


def session_copy(name: str, tmp_path: Path, extra: str = IDENT) -> Path:
    folder = tmp_path / name
    shutil.copytree(SHIPPED / name, folder, ignore=shutil.ignore_patterns("expected"))
    with (folder / "session.yaml").open("a", encoding="utf-8") as f:
        f.write("\n" + extra)
    return folder


def pdf_pages(page: Path, folder: Path) -> list[str]:
    """The text of every page of ``page`` as Chromium prints it on A4."""
    text = print_pdf(page, folder / "page.pdf")
    pages = []
    for width, height, body in PAGE.findall(text):
        words = WORD.findall(body)
        for x0, y0, x1, y1, word in words:  # nothing off the paper
            assert 0 <= float(x0) and float(x1) <= float(width), word
            assert 0 <= float(y0) and float(y1) <= float(height), word
        pages.append(" ".join(html.unescape(w[4]) for w in words))
    return pages


def check_every_page(pages: list[str], expected: list[str]) -> None:
    assert len(pages) >= 2
    for n, text in enumerate(pages, 1):
        for item in expected:
            assert item in text, (n, item)
        assert f"page {n} of {len(pages)}" in text, n


def test_process_report_prints_identification_on_every_page(tmp_path):
    session = session_copy("paper-zero-pose", tmp_path)
    (tmp_path / "lab.yaml").write_text(LAB, encoding="utf-8")
    out = tmp_path / "report.html"
    result = CliRunner().invoke(
        main, ["report", str(session), "--lab", str(tmp_path / "lab.yaml"), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    pages = pdf_pages(out, tmp_path)
    # the session's dates, from its centres file (an independent reading)
    times = [line.split(",")[-1][:10] for line in (session / "centres.csv").read_text().split()[1:]]
    dates = sorted(set(times))
    check_every_page(pages, [*EXPECTED, dates[0]])
    assert "J. Doe (Measured by)" in pages[0]
    # the signature block, once, with both signatories
    assert "Signatures" in pages[-1] or "Signatures" in pages[-2]
    # the session's operator wins over the lab's
    assert "Operator: K. Lee" in pages[0] and "Operator: J. Doe" not in pages[0]
    # the lab file is an input of the page: in the provenance with its SHA-256
    digest = hashlib.sha256((tmp_path / "lab.yaml").read_bytes()).hexdigest()
    assert digest in " ".join(pages)
    # the conformity statement, in the verdict on the first page, and its table
    assert "Conformity:" in pages[0]
    assert "Rz: T = ±50 µrad" in " ".join(pages)


def test_identification_fields_are_read_strictly(tmp_path):
    session = session_copy("paper-zero-pose", tmp_path, "identification:\n  report_number: 17\n")
    with pytest.raises(InputError) as err:
        read_session(session)
    text = str(err.value)
    line = (session / "session.yaml").read_text().splitlines().index("  report_number: 17") + 1
    assert f"session.yaml:{line}:" in text and "field 'identification.report_number'" in text
    assert "'17'" in text  # the hint: quote it
    bad = {
        "cmm: {serial: [1, 2]}\n": "identification.cmm.serial",
        "ambient: {humidity_percent: 140}\n": "identification.ambient.humidity_percent",
        "ambient: {temperature_C: warm}\n": "identification.ambient.temperature_C",
        "signatures: [{role: Approved by}]\n": "identification.signatures[0].name",
        "hexapod: {colour: red}\n": "identification.hexapod.colour",
        "labs: X\n": "identification.labs",
    }
    for k, (line, field) in enumerate(bad.items()):
        folder = session_copy("paper-zero-pose", tmp_path / str(k), "identification:\n  " + line)
        with pytest.raises(InputError) as err:
            read_session(folder)
        assert f"field '{field}'" in str(err.value), str(err.value)
        line = (folder / "session.yaml").read_text().splitlines().index("  " + line.strip()) + 1
        assert f"session.yaml:{line}: " in str(err.value)
    (tmp_path / "lab.yaml").write_text(LAB.replace('"CMM-4711"', "4711"), encoding="utf-8")
    with pytest.raises(InputError) as err:
        read_lab(tmp_path / "lab.yaml")
    assert "lab.yaml:5: field 'cmm.serial'" in str(err.value)


def test_cli_refuses_a_bad_lab_file_in_one_line(tmp_path):
    (tmp_path / "lab.yaml").write_text("format: hexatherm-lab/1\nlab: [1]\n", encoding="utf-8")
    out = tmp_path / "report.html"
    result = CliRunner().invoke(
        main,
        [
            "report",
            str(SHIPPED / "paper-zero-pose"),
            "--lab",
            str(tmp_path / "lab.yaml"),
            "-o",
            str(out),
        ],
    )
    assert result.exit_code != 0
    assert "lab.yaml:2: field 'lab'" in result.output
    assert not out.exists()


def test_calibration_report_names_hexapod_dates_and_identification_on_every_page(tmp_path):
    session = session_copy("calibration-geometry", tmp_path)
    (tmp_path / "lab.yaml").write_text(LAB, encoding="utf-8")
    out = tmp_path / "cal"
    result = CliRunner().invoke(
        main,
        [
            "calibrate",
            str(session),
            "--level",
            "joints",
            "--lab",
            str(tmp_path / "lab.yaml"),
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    hexapod = (session / "hexapod.yaml").read_text().split("name:")[1].split()[0]
    times = [line.split(",")[-1][:10] for line in (session / "centres.csv").read_text().split()[1:]]
    pages = pdf_pages(out / "report.html", tmp_path)
    check_every_page(pages, [*EXPECTED, hexapod, min(times), "calibration-geometry"])
    text = " ".join(pages)
    assert "Signatures" in text and f"Hexapod {hexapod} (hexapod.yaml); sessions" in text


def test_a_serial_number_with_leading_zeros_is_quoted_as_written(tmp_path):
    """``serial: 007`` reads as the number 7: the hint says to quote '007', not '7'."""
    session = session_copy("paper-zero-pose", tmp_path, "identification:\n  cmm: {serial: 007}\n")
    with pytest.raises(InputError, match=r"quote it: '007'\)"):
        read_session(session)
