"""Every shipped session's report, printed to A4 by headless Chromium (a script, not a test).

Run with ``.venv/bin/python bench/report_print.py``. For every folder of ``sessions/``
with a ``session.yaml`` it writes the report (``hexatherm report``, default options),
prints it to PDF with ``chromium --headless --print-to-pdf`` and reads the PDF back
with poppler's ``pdftotext -bbox``, then prints one line per session:

- pages, and whether every one is A4;
- the smallest margin between a word and the paper's edge (mm; negative: cut off);
- the title's scale (1.00: Chromium did not shrink the page to fit something wide);
- the type size of the tables' numbers (pt, from their word boxes);
- how many of the 12 pose column heads (6 commanded, 6 deviations, per table) and of
  the targets' corrected deviations (``expected/poses.csv``, formatted as the report
  does) are missing from the PDF's text.

``tests/workflows/test_report_browser.py`` checks the same on the widest session,
``with-hidden-effect``; this covers the others (about 5 s per session).
Needs ``apt-get install -y chromium poppler-utils``.
"""

from __future__ import annotations

import html
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
PT_PER_MM = 72 / 25.4
A4_PT = (595.28, 841.89)
#: a DejaVu word box is about this many em high
BOX_PER_EM = 1.164
#: the title's type: 1.5 x 9.5 pt in print
TITLE_PT = 14.25
WORD = re.compile(
    r'<word xMin="([\d.]+)" yMin="([\d.]+)" xMax="([\d.]+)" yMax="([\d.]+)">([^<]*)</word>'
)
PAGE = re.compile(r'<page width="([\d.]+)" height="([\d.]+)">(.*?)</page>', re.S)
HEADS = [f"{n}" for n in ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")]


def printed(session: Path, folder: Path, chromium: str) -> list[tuple[float, float, list]]:
    page = folder / f"{session.name}.html"
    pdf = folder / f"{session.name}.pdf"
    subprocess.run(
        [sys.executable, "-m", "hexatherm", "report", str(session), "-o", str(page)],
        check=True,
        capture_output=True,
    )
    subprocess.run(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--no-pdf-header-footer",
            f"--user-data-dir={folder / 'profile'}",
            f"--print-to-pdf={pdf}",
            page.as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
    text = subprocess.run(
        ["pdftotext", "-bbox", str(pdf), "-"], check=True, capture_output=True
    ).stdout.decode("utf-8")
    return [
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


def missing_deviations(session: Path, words: set[str]) -> int:
    poses = ROOT / "sessions" / session.name / "expected" / "poses.csv"
    if not poses.is_file():
        return -1
    frame = pd.read_csv(poses)
    missing = 0
    for name in HEADS:
        unit, decimals = ("um", 3) if name[0] == "T" else ("urad", 2)
        for value in frame[f"d{name}_corr_{unit}"]:
            text = f"{value:.{decimals}f}"
            text = text[1:] if text.startswith("-") and float(text) == 0 else text
            missing += text not in words
    return missing


def main() -> None:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None or shutil.which("pdftotext") is None:
        sys.exit("needs chromium and pdftotext: apt-get install -y chromium poppler-utils")
    print(
        f"{'session':<22} {'pages':>5} {'A4':>3} {'margin mm':>9} {'title':>5} "
        f"{'num pt':>6} {'heads':>5} {'devs':>5}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for yaml in sorted((ROOT / "sessions").glob("*/session.yaml")):
            session = yaml.parent
            pages = printed(session, Path(tmp), chromium)
            a4 = all(abs(w - A4_PT[0]) < 1 and abs(h - A4_PT[1]) < 1 for w, h, _ in pages)
            margin = min(
                min(x0, y0, w - x1, h - y1) for w, h, ws in pages for x0, y0, x1, y1, _ in ws
            )
            title = pages[0][2][0]
            scale = (title[3] - title[1]) / (BOX_PER_EM * TITLE_PT)
            heights = [
                y1 - y0
                for _, _, ws in pages
                for _, y0, _, y1, t in ws
                if re.fullmatch(r"-?\d+\.\d{3}", t)
            ]
            words = [t for _, _, ws in pages for *_, t in ws]
            heads = sum(words.count(n) < 2 for n in HEADS)
            print(
                f"{session.name:<22} {len(pages):>5} {'yes' if a4 else 'NO':>3} "
                f"{margin / PT_PER_MM:>9.1f} {scale:>5.2f} "
                f"{np.median(heights) / BOX_PER_EM:>6.2f} {heads:>5} "
                f"{missing_deviations(session, set(words)):>5}"
            )


if __name__ == "__main__":
    main()
