"""report.html of diagnose: the story of ``report.md`` as one page in the report's style.

The page is written from the same text as ``report.md`` (:func:`report_markdown`), read
back block by block in the small Markdown it uses (headings, paragraphs, ``-`` lists
two levels deep, ``**bold**``, ``code``, pipe tables, figure links), and laid out with
the parts every hexatherm report shares (:mod:`hexatherm.workflows.report.page`): the
style sheet that prints on A4, escaped tables, the figures embedded as PNG data URIs,
and the provenance block. Units are written µm, µrad, °C.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from hexatherm.workflows.diagnose.report.figures import report_figures
from hexatherm.workflows.diagnose.report.markdown import report_markdown
from hexatherm.workflows.diagnose.report.tables import FIGURE_DPI, FIGURE_FILES, REPORT_FILE
from hexatherm.workflows.report.figures import figure_png
from hexatherm.workflows.report.page import (
    escape,
    figure_html,
    html_table,
    page_html,
    provenance_html,
)

if TYPE_CHECKING:
    from hexatherm.io.provenance import RunFacts
    from hexatherm.workflows.diagnose.run import DiagnosisResult

#: the page's file name beside report.md
REPORT_HTML = "report.html"

_UNITS = (
    (re.compile(r"\burad\b"), "µrad"),
    (re.compile(r"\bum\b"), "µm"),
    (re.compile(r"\bdegC\b"), "°C"),
)
_HEADING = re.compile(r"(#{1,4}) (.*)")
_IMAGE = re.compile(r"!\[(.*)\]\((.*)\)")
_ITEM = re.compile(r"( *)- (.*)")
_PIPE = re.compile(r"(?<!\\)\|")


def units(text: str) -> str:
    """``text`` with its units as a reader writes them (``um`` -> ``µm``, ``degC`` -> ``°C``).

    >>> units("RMS 0.12 um, Rx in urad, 20 degC; umbrella")
    'RMS 0.12 µm, Rx in µrad, 20 °C; umbrella'
    """
    for pattern, unit in _UNITS:
        text = pattern.sub(unit, text)
    return text


#: a code span, or a backslash escape (CommonMark: ASCII punctuation made literal)
_LITERAL = re.compile(r"`([^`]+)`|\\([!-/:-@\[-`{-~])")
#: where a literal stands while the rest is formatted (private-use characters)
_SLOT = re.compile("\ue000([0-9]+)\ue001")


def inline(text: str) -> str:
    r"""One line of Markdown text as escaped HTML: ``**bold**``, ```code```, units, and
    backslash escapes (``\<`` is ``<``, text: how :func:`~.tables.md_text` writes a
    user's name).

    >>> inline("**NOT adequate** <1 um> in `a|b`")
    '<b>NOT adequate</b> &lt;1 µm&gt; in <code>a|b</code>'
    >>> inline(r"of \<i\>\*x\*\</i\>")
    'of &lt;i&gt;*x*&lt;/i&gt;'
    """
    literals: list[str] = []

    def keep(match: re.Match[str]) -> str:
        code, char = match[1], match[2]
        literals.append(f"<code>{escape(units(code))}</code>" if code else escape(char))
        return f"\ue000{len(literals) - 1}\ue001"

    out = escape(units(_LITERAL.sub(keep, text)))
    out = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", out)
    return _SLOT.sub(lambda m: literals[int(m[1])], out)


def _cells(line: str) -> list[str]:
    unescape = re.compile(r"\\([!-/:-@\[-`{-~])")
    return [unescape.sub(r"\1", c.strip()) for c in _PIPE.split(line.strip())[1:-1]]


def _table(lines: list[str]) -> str:
    headers = [units(c) for c in _cells(lines[0])]
    align = "".join("l" if c.startswith(":") else "r" for c in _cells(lines[1]))
    rows = [[units(c) for c in _cells(line)] for line in lines[2:]]
    return html_table([[(h, 1) for h in headers]], rows, align=align)


def _items(lines: list[str]) -> str:
    out, depth = [], 0
    for line in lines:
        match = _ITEM.fullmatch(line)
        assert match is not None
        level = 1 + len(match[1]) // 2
        if level > depth:
            out.append("<ul>" * (level - depth))
        elif level < depth:
            out.append("</li></ul>" * (depth - level) + "</li>")
        elif out:
            out.append("</li>")
        out.append(f"<li>{inline(match[2])}")
        depth = level
    out.append("</li></ul>" * depth)
    return "".join(out)


def markdown_html(markdown: str, figures: Mapping[str, bytes]) -> list[str]:
    """The blocks of ``markdown`` (the subset :func:`report_markdown` writes) as HTML.

    Parameters
    ----------
    markdown : str
    figures : mapping of str to bytes
        Link target (``residuals_time.png``) -> its PNG, embedded in place of the link;
        a link to anything else is left out.

    Returns
    -------
    list of str
        One HTML part per block; the level-1 heading is left out (the page has it).
    """
    parts = []
    for block in re.split(r"\n[ \t]*\n", markdown.strip("\n")):
        lines = [line for line in block.split("\n") if line.strip()]
        if not lines:
            continue
        heading = _HEADING.fullmatch(lines[0])
        image = _IMAGE.fullmatch(lines[0])
        if heading and len(lines) == 1:
            level = len(heading[1])
            if level > 1:
                parts.append(f"<h{level}>{inline(heading[2])}</h{level}>")
        elif image and len(lines) == 1:
            caption = units(image[1])
            parts.append(figure_html(figures.get(image[2]), caption, caption))
        elif all(line.startswith("|") for line in lines) and len(lines) >= 2:
            parts.append(_table(lines))
        elif all(_ITEM.fullmatch(line) for line in lines):
            parts.append(_items(lines))
        else:
            parts.append("<p>" + "<br>".join(inline(line) for line in lines) + "</p>")
    return parts


def report_html(
    result: DiagnosisResult,
    figures: Mapping[str, bytes],
    facts: RunFacts | None = None,
    generated: str | None = None,
) -> str:
    """The page ``report.html`` of a diagnosis.

    Parameters
    ----------
    result : DiagnosisResult
    figures : mapping of str to bytes
        Figure key (of :data:`FIGURE_FILES`) -> its PNG.
    facts : RunFacts, optional
        The command line's facts (default :func:`current_run`; none outside the
        command line, and the provenance block says so).
    generated : str, optional
        Generation time, ISO 8601 with UTC offset (default: now).
    """
    from hexatherm.io.provenance import current_run, now_iso

    names = {key: FIGURE_FILES[key] for key in figures}
    pngs = {FIGURE_FILES[key]: png for key, png in figures.items()}
    session = result.data.session
    parts = markdown_html(report_markdown(result, names), pngs)
    parts.append(
        provenance_html(
            current_run() if facts is None else facts,
            session.input_files(),
            session.path.parent,
            generated or now_iso(),
            extra=[("hexapod", result.data.hexapod_source)],
        )
    )
    return page_html(f"Diagnosis of {session.name}", parts)


def write_report_files(
    result: DiagnosisResult, out_dir: Path, *, dpi: int = FIGURE_DPI
) -> list[Path]:
    """Write ``report.md``, its PNG figures (:data:`FIGURE_FILES`) and ``report.html`` (the
    same story, figures embedded) into the folder ``out_dir``.

    The folder must exist; files of the same names are replaced. Returns the
    paths written, ``report.md`` first and ``report.html`` last.
    """
    out_dir = Path(out_dir)
    written = [out_dir / REPORT_FILE]
    pngs = {}
    for key, fig in report_figures(result).items():
        pngs[key] = figure_png(fig, dpi)
        path = out_dir / FIGURE_FILES[key]
        path.write_bytes(pngs[key])
        written.append(path)
    written[0].write_text(report_markdown(result, FIGURE_FILES), encoding="utf-8")
    page = out_dir / REPORT_HTML
    page.write_text(report_html(result, pngs), encoding="utf-8")
    return [*written, page]
