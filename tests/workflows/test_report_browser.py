"""The report as a browser prints it: headless Chromium to an A4 PDF, read back with poppler.

The report of the widest shipped session (``with-hidden-effect``: 40 targets, every
commanded column) is printed with ``chromium --headless --print-to-pdf``; the PDF's
words and their boxes come from ``pdftotext -bbox`` and its images from ``pdfimages
-list`` (poppler-utils, no Python dependency). The truths are independent of the
report's code: ``expected/poses.csv`` (every corrected deviation, formatted here), the
input files hashed here, and the figures' PNGs as embedded in the HTML.

Skipped only where no Chromium exists (Debian: ``apt-get install -y chromium
poppler-utils``); a Chromium without poppler fails, naming what is missing.
One PDF for all the tests here (building the page ~1.5 s, printing it ~3 s).
"""

from __future__ import annotations

import base64
import hashlib
import html
import re
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.io.csvout import RESOLUTION
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.report import build_report
from tests.shipped import SHIPPED
from tests.waiting import SAFETY_S

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "with-hidden-effect"
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
A4_PT = (595.28, 841.89)
IMG = re.compile(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"')
WORD = re.compile(
    r'<word xMin="([\d.]+)" yMin="([\d.]+)" xMax="([\d.]+)" yMax="([\d.]+)">([^<]*)</word>'
)
PAGE = re.compile(r'<page width="([\d.]+)" height="([\d.]+)">(.*?)</page>', re.S)


def browser() -> str | None:
    for name in BROWSERS:
        if path := shutil.which(name):
            return path
    return None


def poppler(tool: str) -> str:
    path = shutil.which(tool)
    if path is None:
        pytest.fail(f"{tool} not found: install poppler-utils (apt-get install -y poppler-utils)")
    return path


@pytest.fixture(scope="module")
def printed(tmp_path_factory):
    """(page HTML, [(width, height, [(x0, y0, x1, y1, word)])] per PDF page, pdfimages list)."""
    return print_report(SESSION, tmp_path_factory.mktemp("browser"))


def print_pdf(page: Path, pdf: Path) -> str:
    """Print the HTML file ``page`` to ``pdf`` on A4 with headless Chromium (its profile
    beside ``pdf``) and return the PDF's words with their boxes (``pdftotext -bbox``);
    skip where no Chromium is installed."""
    chromium = browser()
    if chromium is None:
        pytest.skip("no Chromium (apt-get install -y chromium poppler-utils)")
    subprocess.run(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-pdf-header-footer",
            f"--user-data-dir={pdf.parent / 'profile'}",
            f"--print-to-pdf={pdf}",
            page.as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=SAFETY_S,
    )
    return subprocess.run(
        [poppler("pdftotext"), "-bbox", str(pdf), "-"], check=True, capture_output=True
    ).stdout.decode("utf-8")


def print_report(session: Path, folder: Path):
    """The report of ``session`` printed by Chromium: as :func:`printed`."""
    if browser() is None:
        pytest.skip("no Chromium (apt-get install -y chromium poppler-utils)")
    page = build_report(process_session(session))
    (folder / "report.html").write_text(page, encoding="utf-8")
    pdf = folder / "report.pdf"
    text = print_pdf(folder / "report.html", pdf)
    pages = [
        (
            float(w),
            float(h),
            [
                (float(a), float(b), float(c), float(d), html.unescape(t))
                for a, b, c, d, t in WORD.findall(body)
            ],
        )
        for w, h, body in PAGE.findall(text)
    ]
    images = subprocess.run(
        [poppler("pdfimages"), "-list", str(pdf)], check=True, capture_output=True, text=True
    ).stdout
    return page, pages, images


def test_every_page_is_a4_unshrunk_and_no_word_leaves_it(printed):
    _, pages, _ = printed
    assert len(pages) >= 3
    for width, height, words in pages:
        assert (width, height) == pytest.approx(A4_PT, abs=1.0)
        assert words
        for x0, y0, x1, y1, word in words:
            assert 0 <= x0 and x1 <= width and 0 <= y0 and y1 <= height, word
    # Chromium shrinks the whole page to fit content wider than the paper: the title's
    # type (1.5 x 9.5 pt; a DejaVu word box is ~1.16 em high) shows it was not
    # (the largest type of the first page; the running header above it is smaller)
    title = max(pages[0][2], key=lambda w: w[3] - w[1])
    assert title[4] in ("Measurement", "report") and title[3] - title[1] >= 0.97 * 1.164 * 14.25
    # and the tables' numbers print at a readable size (>= 7 pt type)
    heights = [
        y1 - y0
        for _, _, words in pages
        for _, y0, _, y1, word in words
        if re.fullmatch(r"-?\d+\.\d{3}", word)
    ]
    assert len(heights) > 40 * 12 and np.median(heights) >= 1.164 * 7.0


def test_every_pose_column_is_on_the_page(printed):
    _, pages, _ = printed
    words = [w[4] for _, _, page in pages for w in page]
    text = " ".join(words)
    # both tables, every column head: 6 commanded (mm, °) and 6 deviations (µm, µrad)
    for which in ("conventional", "corrected"):
        assert f"{which} − commanded" in text
    for name in ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz"):
        assert words.count(name) >= 4, name  # commanded and deviation, in each table
    assert words.count("(µm)") >= 6 and words.count("(µrad)") >= 6
    assert words.count("(mm)") >= 6 and words.count("(°)") >= 6
    # every corrected deviation of every target, from poses.csv, down to the last column
    poses = pd.read_csv(SESSION / "expected" / "poses.csv")
    present = set(words)
    for name, decimals in (("Tx", 3), ("Tz", 3), ("Ry", 2), ("Rz", 2)):
        unit = "um" if name[0] == "T" else "urad"
        values = poses[f"d{name}_corr_{unit}"].to_numpy()
        missing = [v for v in values if not shown(v, decimals, unit) & present]
        assert not missing, (name, missing)
    assert np.isfinite(values).all()


def test_verdict_and_provenance_are_printed(printed):
    _, pages, _ = printed
    first = " ".join(w[4] for w in pages[0][2])
    assert "Verdict" in first and "targets failed a quality check" in first
    assert "U = k·u" in first
    words = {w[4] for _, _, page in pages for w in page}
    assert "Provenance" in words
    for name in ("session.yaml", "centres.csv", "temperatures.csv"):
        digest = hashlib.sha256((SESSION / name).read_bytes()).hexdigest()
        assert digest in words, name


def test_every_figure_is_embedded_with_data_and_printed(printed):
    page, _, images = printed
    pngs = [base64.b64decode(data, validate=True) for data in IMG.findall(page)]
    assert len(pngs) == 4  # poses, temperatures, growth, registration
    sizes = []
    for png in pngs:
        assert png.startswith(b"\x89PNG\r\n\x1a\n")
        width, height = struct.unpack(">II", png[16:24])
        assert width >= 1300 and height >= 500  # 150 dpi
        sizes.append((width, height))
    rows = [line.split() for line in images.splitlines()[2:] if line.strip()]
    printed_sizes = [(int(r[3]), int(r[4])) for r in rows if r[2] == "image"]
    assert sorted(printed_sizes) == sorted(sizes)


def shown(value: float, decimals: int, unit: str) -> set[str]:
    """The texts the page may show for a value that poses.csv holds to half a step of
    ``unit``: the page rounds the exact value, so near a boundary either neighbour."""
    half = RESOLUTION[unit] / 2
    texts = {f"{v:.{decimals}f}" for v in (value - half, value, value + half)}
    return {t[1:] if t.startswith("-") and float(t) == 0 else t for t in texts}


OTHER_SESSIONS = sorted(
    p.parent.name for p in (SHIPPED).glob("*/expected") if p.parent.name != SESSION.name
)


@pytest.mark.parametrize("name", OTHER_SESSIONS)
def test_every_shipped_sessions_report_prints_its_pose_columns_on_a4(name, tmp_path):
    """The other shipped sessions, lighter: A4, nothing off the paper, every pose column
    head of both tables and every corrected Tx of poses.csv in the PDF's text."""
    _, pages, _ = print_report(SHIPPED / name, tmp_path)
    words = [w[4] for _, _, page in pages for w in page]
    for width, height, page_words in pages:
        assert (width, height) == pytest.approx(A4_PT, abs=1.0)
        for x0, y0, x1, y1, word in page_words:
            assert 0 <= x0 and x1 <= width and 0 <= y0 and y1 <= height, word
    text = " ".join(words)
    for which in ("conventional", "corrected"):
        assert f"{which} − commanded" in text
    for axis in ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz"):
        assert words.count(axis) >= 2, axis  # a deviation column in each table
    poses = pd.read_csv(SHIPPED / name / "expected" / "poses.csv")
    assert not [v for v in poses["dTx_corr_um"] if not shown(v, 3, "um") & set(words)]
