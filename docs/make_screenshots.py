"""Screenshots of the shipped sessions' reports, for docs/report.md: ``docs/report-<session>.png``.

Each session's report is written by the command line (``python -m hexatherm report
SESSION -o TMP/report.html``, so its provenance block shows a real command line) into a
temporary folder, rendered by headless Chromium at a desktop window's size, and the
top of the page (title, verdict, the paper's Figure 6 and the start of the pose table)
is saved as a 256-colour PNG (well under 300 kB).

Usage::

    python docs/make_screenshots.py                 # paper-zero-pose, with-hidden-effect
    python docs/make_screenshots.py --all           # every shipped session with a session.yaml
    python docs/make_screenshots.py calibration-campaign --height 2400

Needs Chromium (Debian: ``apt-get install -y chromium``) and Pillow (matplotlib's).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

DOCS = Path(__file__).resolve().parent
SESSIONS = DOCS.parent / "sessions"
DEFAULT = ("paper-zero-pose", "with-hidden-effect")
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
WIDTH_PX = 1100


def browser() -> str:
    for name in BROWSERS:
        if path := shutil.which(name):
            return path
    sys.exit("no Chromium found: apt-get install -y chromium")


def screenshot(session: Path, out: Path, height_px: int, chromium: str) -> None:
    """Write the report of ``session`` and its screenshot ``out`` (256 colours)."""
    from PIL import Image

    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "report.html"
        subprocess.run(
            [sys.executable, "-m", "hexatherm", "report", str(session), "-o", str(page)],
            check=True,
        )
        shot = Path(tmp) / "shot.png"
        subprocess.run(
            [
                chromium,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--hide-scrollbars",
                f"--user-data-dir={Path(tmp) / 'profile'}",
                f"--window-size={WIDTH_PX},{height_px}",
                f"--screenshot={shot}",
                page.as_uri(),
            ],
            check=True,
            capture_output=True,
            timeout=120,
        )
        with Image.open(shot) as image:
            small = image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
            small.save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} kB)")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sessions", nargs="*", help=f"session names [default: {DEFAULT}]")
    parser.add_argument("--all", action="store_true", help="every shipped session")
    parser.add_argument("--height", type=int, default=1500, help="window height, px")
    args = parser.parse_args(argv)
    if args.all:
        names = sorted(p.parent.name for p in SESSIONS.glob("*/session.yaml"))
    else:
        names = args.sessions or list(DEFAULT)
    chromium = browser()
    for name in names:
        screenshot(SESSIONS / name, DOCS / f"report-{name}.png", args.height, chromium)


if __name__ == "__main__":
    main()
