"""A lab's own templates (issue 25, item 4): the example lab template set
(``docs/examples/lab-templates``: letterhead with logo and address, closing wording) on
every printed A4 page of a process report and a calibration report, as headless Chromium
prints them (``test_report_browser.print_pdf``); escaping whatever the template; a bad
template refused in one line naming file and line, nothing written.
"""

from __future__ import annotations

import base64
import re
import shutil
from pathlib import Path

from click.testing import CliRunner

from hexatherm.cli import main
from tests.workflows.test_report_identity import (
    EXPECTED,
    IDENT,
    LAB,
    check_every_page,
    pdf_pages,
    session_copy,
)

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "docs" / "examples" / "lab-templates"
#: the example letterhead prints the lab file's (LAB's) name and address, and the logo's
#: text (in the SVG), on every page; it names no lab of its own (issue 33)
LETTERHEAD = ["Hexapod Metrology Lab", "1 Example Road, Grenoble", "LOGO"]
CLOSING = "shall not be reproduced except in full"


def lab_with_templates(tmp_path: Path) -> Path:
    """LAB with ``templates: lab-templates`` (relative to the lab file), the example there."""
    shutil.copytree(EXAMPLE, tmp_path / "lab-templates")
    lab = tmp_path / "lab.yaml"
    lab.write_text(LAB + "templates: lab-templates\n", encoding="utf-8")
    return lab


def test_the_example_letterhead_is_on_every_page_of_a_process_and_a_calibration_report(
    tmp_path,
):
    # the process report: the templates from --template-dir
    session = session_copy("paper-zero-pose", tmp_path)
    (tmp_path / "lab.yaml").write_text(LAB, encoding="utf-8")
    out = tmp_path / "report.html"
    args = ["report", str(session), "--lab", str(tmp_path / "lab.yaml")]
    result = CliRunner().invoke(main, [*args, "--template-dir", str(EXAMPLE), "-o", str(out)])
    assert result.exit_code == 0, result.output
    page = out.read_text(encoding="utf-8")
    # the logo, embedded: the very file of the example
    logo = base64.b64encode((EXAMPLE / "logo.svg").read_bytes()).decode("ascii")
    assert f'src="data:image/svg+xml;base64,{logo}"' in page
    assert not re.search(r'(src|href)="(?!data:)', page)  # still one self-contained file
    pages = pdf_pages(out, tmp_path / "process")
    check_every_page(pages, [*LETTERHEAD, *EXPECTED])
    assert CLOSING in " ".join(pages) and "Signatures" in " ".join(pages)
    assert "written approval of Hexapod Metrology Lab" in " ".join(pages)
    assert "Example Metrology" not in " ".join(pages)
    # the lab's templates are inputs of the page: in its provenance
    assert "letterhead.html.j2" in " ".join(pages)

    # the calibration report: the templates from the lab file's templates:
    (tmp_path / "cal").mkdir()
    lab = lab_with_templates(tmp_path / "cal")
    session = session_copy("calibration-geometry", tmp_path / "cal")
    out = tmp_path / "cal" / "out"
    result = CliRunner().invoke(
        main,
        ["calibrate", str(session), "--level", "joints", "--lab", str(lab), "-o", str(out)],
    )
    assert result.exit_code == 0, result.output
    pages = pdf_pages(out / "report.html", tmp_path / "cal")
    check_every_page(pages, [*LETTERHEAD, *EXPECTED, "calibration-geometry"])
    assert CLOSING in " ".join(pages)


HOSTILE = '<script>alert("x")</script>'


def test_every_field_is_escaped_whatever_the_template(tmp_path):
    session = session_copy(
        "paper-zero-pose", tmp_path, IDENT.replace("ACME Optics", f"ACME {HOSTILE}")
    )
    (tmp_path / "lab.yaml").write_text(
        LAB.replace("Hexapod Metrology Lab", "Lab <b>bold</b> & co"), encoding="utf-8"
    )
    out = tmp_path / "report.html"
    result = CliRunner().invoke(
        main,
        [
            "report",
            str(session),
            "--lab",
            str(tmp_path / "lab.yaml"),
            "--template-dir",
            str(EXAMPLE),
            "-o",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    page = out.read_text(encoding="utf-8")
    assert "<script>" not in page and "<b>bold</b>" not in page
    escaped = "ACME &lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;"
    # in the lab's letterhead (the running header) and the signature-free identification
    letterhead = page.split('<table class="running"><thead>')[1].split("</thead>")[0]
    assert escaped in letterhead and "Lab &lt;b&gt;bold&lt;/b&gt; &amp; co" in letterhead
    assert "Example Metrology Laboratory" not in page


def refused(tmp_path: Path, templates: dict[str, str], *extra: str) -> tuple[str, Path]:
    """Run ``report`` with a template folder holding ``templates``; its one-line error
    (exit status not 0) and the output it must not have written."""
    folder = tmp_path / "templates"
    folder.mkdir(parents=True)
    for name, text in templates.items():
        (folder / name).write_text(text, encoding="utf-8")
    out = tmp_path / "report.html"
    # a copy: report processes a session without results into it (and takes that back
    # on refusal), which must not happen in the shipped tree while other tests read it
    session = session_copy("paper-zero-pose", tmp_path)
    before = sorted(session.rglob("*"))
    result = CliRunner().invoke(
        main, ["report", str(session), "--template-dir", str(folder), *extra, "-o", str(out)]
    )
    assert result.exit_code != 0
    assert not out.exists()
    assert sorted(session.rglob("*")) == before  # nothing left in the session either
    lines = [line for line in result.output.splitlines() if line.strip()]
    return lines[-1], folder


def test_a_bad_template_is_refused_naming_file_and_line(tmp_path):
    # a syntax error: before any processing
    line, folder = refused(
        tmp_path / "a",
        {"letterhead.html.j2": "<div>\n{% for name, text in header_rows %}\n{{ name }\n</div>\n"},
    )
    assert f"{folder / 'letterhead.html.j2'}:3:" in line, line
    # an error while rendering: a field the page does not give, an asset not in the folder
    line, folder = refused(tmp_path / "b", {"closing.html.j2": "<p>\n{{ lab_name }}</p>\n"})
    assert f"{folder / 'closing.html.j2'}:2:" in line and "lab_name" in line, line
    line, folder = refused(
        tmp_path / "c", {"closing.html.j2": "\n\n<img src=\"{{ asset('x.png') }}\">"}
    )
    assert f"{folder / 'closing.html.j2'}:3:" in line and "x.png" in line, line
    # a lab file's templates: that is not a folder
    lab = tmp_path / "lab.yaml"
    lab.write_text(LAB + "templates: nowhere\n", encoding="utf-8")
    out = tmp_path / "r.html"
    session = session_copy("paper-zero-pose", tmp_path)
    result = CliRunner().invoke(main, ["report", str(session), "--lab", str(lab), "-o", str(out)])
    assert result.exit_code != 0 and not out.exists()
    assert f"lab.yaml:{LAB.count(chr(10)) + 1}: field 'templates'" in result.output
