"""report.html of diagnose: the story of ``report.md`` as one page in the report's style.

The page is written from the same text as ``report.md`` (:func:`report_markdown`), parsed
by markdown-it-py (CommonMark and pipe tables, raw HTML off: a user's text stays text),
its units written as a reader writes them (µm, µrad, °C) and its figure links replaced
by the figures, embedded as PNG data URIs; the template ``diagnosis.html.j2``
(:mod:`hexatherm.workflows.report.render`, a lab may override it) lays it out with the
parts every hexatherm report shares: the style sheet that prints on A4, the running
header and the provenance block.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from hexatherm.workflows.diagnose.report.figures import report_pngs
from hexatherm.workflows.diagnose.report.markdown import report_markdown
from hexatherm.workflows.diagnose.report.tables import FIGURE_DPI, FIGURE_FILES, REPORT_FILE
from hexatherm.workflows.report.document import document, template_variables
from hexatherm.workflows.report.figures import figure_png
from hexatherm.workflows.report.page import figure, provenance
from hexatherm.workflows.report.render import Markup, render_macro, render_page

if TYPE_CHECKING:
    from markdown_it.token import Token

    from hexatherm.io.provenance import RunFacts
    from hexatherm.workflows.diagnose.run import DiagnosisResult

#: the page's file name beside report.md
REPORT_HTML = "report.html"

#: a unit as hexatherm's text writes it -> as a reader does
_UNITS = {"urad": "µrad", "um": "µm", "degC": "°C"}
_UNIT_WORDS = re.compile(r"\b(?:urad|um|degC)\b")


def units(text: str, keep: Collection[str] = ()) -> str:
    """``text`` with its units as a reader writes them (``um`` -> ``µm``, ``degC`` -> ``°C``),
    but in the texts ``keep`` (a user's: a name, a path, a label), printed as they are.

    >>> units("RMS 0.12 um, Rx in urad, 20 degC; umbrella")
    'RMS 0.12 µm, Rx in µrad, 20 °C; umbrella'
    >>> units("hexapod: Messung um 10 (um); Bum", keep=["Messung um 10", "B"])
    'hexapod: Messung um 10 (µm); Bum'
    """
    return _units(text, _kept_pattern(keep))


def _kept_pattern(keep: Collection[str]) -> re.Pattern[str] | None:
    """The pattern of the texts ``keep`` for :func:`_units`, longest first (None: none)."""
    kept = sorted({k for k in keep if k}, key=len, reverse=True)
    return re.compile("|".join(map(re.escape, kept))) if kept else None


def _units(text: str, kept: re.Pattern[str] | None) -> str:
    """:func:`units` with the kept texts' pattern made once (a page asks for hundreds)."""
    if _UNIT_WORDS.search(text) is None:
        return text
    spans = [] if kept is None else [m.span() for m in kept.finditer(text)]

    def unit(match: re.Match[str]) -> str:
        if any(a <= match.start() < b for a, b in spans):
            return match.group(0)
        return _UNITS[match.group(0)]

    return _UNIT_WORDS.sub(unit, text)


def _text(token: Token) -> str:
    return "".join(c.content for c in token.children or () if c.type in ("text", "code_inline"))


def _figure_token(
    inline: Token, figures: Mapping[str, bytes], kept: re.Pattern[str] | None = None
) -> Token | None:
    """An ``html_block`` token holding the figure a paragraph of one image links to."""
    from markdown_it.token import Token

    children = inline.children or []
    if len(children) != 1 or children[0].type != "image":
        return None
    image = children[0]
    caption = _units(_text(image), kept)
    png = figures.get(str(image.attrGet("src")))
    html = "" if png is None else render_macro("figure", figure(png, caption, caption)) + "\n"
    return Token("html_block", "", 0, content=html, block=True)


def markdown_html(
    markdown: str, figures: Mapping[str, bytes], keep: Collection[str] = ()
) -> list[str]:
    r"""``markdown`` (as :func:`report_markdown` writes it) as HTML, by markdown-it-py.

    Parameters
    ----------
    markdown : str
    figures : mapping of str to bytes
        Link target (``residuals_time.png``) -> its PNG, embedded in place of a paragraph
        that is that one image link; a link to anything else is left out.
    keep : collection of str
        A user's texts (names, paths, labels): printed as they are, their ``um`` not
        turned into ``µm`` (:func:`units`).

    Returns
    -------
    list of str
        The HTML, one part; the level-1 heading is left out (the page has it).

    >>> md = "# T\n\n**NOT adequate** <1 um>, `a|b`\n\n| a (um) |\n|--:|\n| 1 |"
    >>> print(markdown_html(md, {})[0].replace("\n", "").replace("</p>", "</p>\n"))
    <p><strong>NOT adequate</strong> &lt;1 µm&gt;, <code>a|b</code></p>
    <table><thead><tr><th>a (µm)</th></tr></thead><tbody><tr><td class="num">1</td></tr>...
    """
    from markdown_it import MarkdownIt

    parser = MarkdownIt("commonmark", {"html": False, "breaks": True}).enable("table")
    tokens = parser.parse(markdown)
    kept = _kept_pattern(keep)
    out: list[Token] = []
    k = 0
    while k < len(tokens):
        token = tokens[k]
        if token.type == "heading_open" and token.tag == "h1":
            k += 3  # open, inline, close: the page's title
            continue
        if token.type == "paragraph_open" and not token.hidden:
            replaced = _figure_token(tokens[k + 1], figures, kept)
            if replaced is not None:
                out.append(replaced)
                k += 3
                continue
        if token.type in ("th_open", "td_open"):
            right = token.attrGet("style") != "text-align:left"
            token.attrs.pop("style", None)
            if right and token.type == "td_open":
                token.attrSet("class", "num")
        for child in token.children or ():
            if child.type in ("text", "code_inline"):
                child.content = _units(child.content, kept)
        out.append(token)
        k += 1
    return [parser.renderer.render(out, parser.options, {})]


def report_html(
    result: DiagnosisResult,
    figures: Mapping[str, bytes],
    facts: RunFacts | None = None,
    generated: str | None = None,
    template_dir: Path | None = None,
    extra_inputs: Sequence[Path] = (),
    markdown: str | None = None,
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
    template_dir : Path, optional
        A lab's templates, over the package's.
    extra_inputs : sequence of Path
        Further files the page was made from, listed in its provenance after the
        session's (the ``--hexapod`` model, the lab's template files).
    markdown : str, optional
        The story, if made already: :func:`report_markdown` of ``result`` with the
        figures' file names (made here otherwise).
    """
    from hexatherm.io.provenance import current_run, now_iso

    names = {key: FIGURE_FILES[key] for key in figures}
    pngs = {FIGURE_FILES[key]: png for key, png in figures.items()}
    session = result.data.session
    issued = generated or now_iso()
    number = session.identification.get("report_number")
    doc = document(
        "diagnose",
        issued,
        {},
        [None if number is None else str(number)],
        [session.name],
    )
    title = f"Diagnosis of {session.name}"
    keep = [  # a user's texts, printed as they are
        session.name,
        str(session.path),
        result.data.hexapod.name,
        result.data.hexapod_source,
        *session.plan.labels,
        *session.balls.names,
    ]
    return render_page(
        "diagnosis.html.j2",
        template_dir,
        title=title,
        subtitle="",
        **template_variables(doc, dict(session.identification)),
        ident_block=None,
        header_rows=[
            ("Report number", doc.number or "none assigned"),
            ("Report", title),
            ("Date of issue", doc.issue_date),
            ("Hexapod", f"{result.data.hexapod.name} ({result.data.hexapod_source})"),
        ],
        signatures=None,
        story=Markup(
            "".join(markdown_html(markdown or report_markdown(result, names), pngs, keep))
        ),
        provenance=provenance(
            current_run() if facts is None else facts,
            [*session.input_files(), *extra_inputs],
            session.path.parent,
            issued,
            extra=[("hexapod", result.data.hexapod_source)],
            number=doc.number,
        ),
    )


def write_report_files(
    result: DiagnosisResult,
    out_dir: Path,
    *,
    dpi: int = FIGURE_DPI,
    template_dir: Path | None = None,
    extra_inputs: Sequence[Path] = (),
) -> list[Path]:
    """Write ``report.md``, its PNG figures (:data:`FIGURE_FILES`) and ``report.html`` (the
    same story, figures embedded; ``template_dir``: a lab's templates; ``extra_inputs``: as
    :func:`report_html`) into the folder ``out_dir``.

    The folder must exist; files of the same names are replaced. Returns the
    paths written, ``report.md`` first and ``report.html`` last.
    """
    out_dir = Path(out_dir)
    written = [out_dir / REPORT_FILE]
    pngs = report_pngs(result, lambda fig: figure_png(fig, dpi))
    for key, data in pngs.items():
        path = out_dir / FIGURE_FILES[key]
        path.write_bytes(data)
        written.append(path)
    names = {key: FIGURE_FILES[key] for key in pngs}  # all of them: report.md's links
    markdown = report_markdown(result, names)
    written[0].write_text(markdown, encoding="utf-8")
    page = out_dir / REPORT_HTML
    html = report_html(
        result, pngs, template_dir=template_dir, extra_inputs=extra_inputs, markdown=markdown
    )
    page.write_text(html, encoding="utf-8")
    return [*written, page]
