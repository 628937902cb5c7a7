"""The parts every hexatherm HTML report shares: style, tables, figures, provenance, page.

``report`` (a processed session) and ``diagnose`` (where the twin and the data
disagree) write their pages from these: one style sheet that prints on A4
(:data:`STYLE`), escaped tables (:func:`html_table`), figures embedded as PNG data
URIs (:func:`figure_html`), the provenance block (:func:`provenance_html`: generation
time, version, command line and options, every input with size and SHA-256) and the
page around them (:func:`page_html`). No external resource, every text escaped.
"""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from hexatherm import __version__

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from hexatherm.io.provenance import RunFacts

STYLE = """
body { font-family: "DejaVu Sans", "Liberation Sans", sans-serif; margin: 1.5em auto;
  max-width: 1000px; color: #222; font-size: 11pt; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 8.5pt; margin: 0.5em 0; }
caption { caption-side: top; text-align: left; font-size: 9pt; color: #555; padding: 2px 0; }
th, td { border: 1px solid #ccc; padding: 1px 4px; vertical-align: top; }
th { background: #f0f0f0; font-weight: 600; }
td.num { text-align: right; white-space: nowrap; font-variant-numeric: tabular-nums;
  font-family: "DejaVu Sans Mono", "Liberation Mono", monospace; }
td.wrap { overflow-wrap: anywhere; word-break: break-all; }
td .u { display: block; color: #666; font-size: 0.85em; }
tr.fail td { background: #fdd; }
tr.total td { border-top: 2px solid #888; }
td.bad { color: #b00; font-weight: bold; }
table.meta td { overflow-wrap: anywhere; } table.meta td:first-child { white-space: nowrap; }
figure { margin: 0.5em 0; } figure img { max-width: 100%; }
figcaption, p.note { font-size: 0.85em; color: #555; }
pre { font-size: 0.75em; background: #f7f7f7; padding: 4px 8px; white-space: pre-wrap; }
p.missing { background: #fff3cd; border: 1px solid #e0c060; padding: 4px 8px; }
div.verdict { border: 2px solid #444; padding: 0.3em 1em; margin: 1em 0; }
div.verdict.failed { border-color: #b00; }
div.verdict li { margin: 0.2em 0; }
table.running { width: 100%; border-collapse: collapse; margin: 0; font-size: inherit; }
table.running > thead > tr > td, table.running > tbody > tr > td { border: none; padding: 0; }
div.running { font-size: 7pt; color: #333; border-bottom: 1px solid #888; padding-bottom: 2px;
  margin-bottom: 6px; line-height: 1.25; }
div.running b { font-weight: 600; }
div.running span { display: inline-block; max-width: 100%; margin-right: 0.8em; }
table.signatures td { height: 2.2em; min-width: 9em; }
@page { size: A4; margin: 14mm 15mm;
  @bottom-right { content: "page " counter(page) " of " counter(pages); font-size: 8pt; } }
@media print {
  table.running { font-size: inherit; }
  table.running > tbody > tr { break-inside: auto; page-break-inside: auto; }
  body { max-width: none; margin: 0; font-size: 9.5pt; }
  h2 { break-after: avoid; page-break-after: avoid; }
  table { font-size: 7.5pt; }
  thead { display: table-header-group; }
  tr, figure, div.verdict, caption { break-inside: avoid; page-break-inside: avoid; }
  img { max-width: 100%; }
}
""".strip()


def escape(value: object) -> str:
    """``value`` as escaped HTML text (quotes too)."""
    return html.escape(str(value), quote=True)


_e = escape

#: a cell: a text, or a value with its expanded uncertainty (printed one under the other)
Cell = str | tuple[str, str]


def _cell(cell: Cell, numeric: bool) -> str:
    if isinstance(cell, tuple):
        value, u = cell
        body = _e(value) + (f'<span class="u">\u00b1\u00a0{_e(u)}</span>' if u else "")
    else:
        body = _e(cell)
    return f'<td class="num">{body}</td>' if numeric else f"<td>{body}</td>"


def html_table(
    header_rows: Sequence[Sequence[tuple[str, int]]],
    rows: Iterable[Sequence[Cell]],
    numeric_from: int = 1,
    row_classes: Sequence[str] | None = None,
    caption: str = "",
    align: str = "",
    css: str = "",
) -> str:
    """An escaped HTML table.

    Parameters
    ----------
    header_rows : sequence of sequence of (text, colspan)
    rows : iterable of sequence of Cell
        Cell texts (escaped here); a ``(value, U)`` pair prints U under the value.
    numeric_from : int
        Cells from this column on are right-aligned numbers.
    row_classes : sequence of str, optional
        CSS class of each body row (``"fail"`` highlights it).
    caption : str
        The table's caption (escaped).
    align : str, optional
        ``"l"`` or ``"r"`` per column (``"r"``: a number); overrides ``numeric_from``.
    css : str, optional
        The table's CSS class (``"meta"``: a field/value table).
    """
    out = [f'<table class="{_e(css)}">' if css else "<table>"]
    if caption:
        out.append(f"<caption>{_e(caption)}</caption>")
    out.append("<thead>")
    for header in header_rows:
        cells = "".join(
            f'<th colspan="{span}">{_e(text)}</th>' if span > 1 else f"<th>{_e(text)}</th>"
            for text, span in header
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("</thead><tbody>")
    for i, row in enumerate(rows):
        cls = row_classes[i] if row_classes is not None else ""
        cells = "".join(
            _cell(c, align[k] == "r" if align else k >= numeric_from) for k, c in enumerate(row)
        )
        out.append(f'<tr class="{_e(cls)}">{cells}</tr>' if cls else f"<tr>{cells}</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def figure_html(figure: Figure | bytes | None, alt: str, caption: str, dpi: int = 150) -> str:
    """A figure (a matplotlib figure, drawn at ``dpi``, or PNG bytes) embedded as a data URI,
    with its caption; empty for None."""
    if figure is None:
        return ""
    if not isinstance(figure, bytes):
        from hexatherm.workflows.report.figures import figure_png

        figure = figure_png(figure, dpi)
    data = base64.b64encode(figure).decode("ascii")
    return (
        f'<figure><img src="data:image/png;base64,{data}" alt="{_e(alt)}">'
        f"<figcaption>{_e(caption)}</figcaption></figure>"
    )


def provenance_html(
    facts: RunFacts | None,
    inputs: Iterable[str | os.PathLike[str]],
    folder: Path,
    generated: str,
    extra: Sequence[tuple[str, str]] = (),
) -> str:
    """The provenance block: when, by what, how (``extra`` rows: limits ...), and from which
    files (size, SHA-256; paths relative to ``folder`` where they lie inside it)."""
    from hexatherm.io.provenance import input_entries

    if facts is None:
        command = options = "not run from the command line"
    else:
        command = " ".join(["hexatherm", facts.command, *facts.argv])
        options = "; ".join(f"{key} = {value}" for key, value in facts.options.items())
    rows: list[Sequence[Cell]] = [
        ["generated", generated],
        ["hexatherm", __version__],
        ["command line", command],
        ["options", options],
        *[list(row) for row in extra],
    ]
    if facts is not None:
        rows.append(["started", facts.started])
    files: list[Sequence[Cell]] = []
    base = folder.resolve()
    for entry in input_entries(inputs):
        path = Path(entry["path"])
        shown = os.path.relpath(path, base) if path.is_relative_to(base) else str(path)
        size = str(entry["bytes"]) if "bytes" in entry else "folder"
        files.append([shown, size, entry.get("sha256", "")])
    return "\n".join(
        [
            "<h2>Provenance</h2>",
            html_table([[("field", 1), ("value", 1)]], rows, numeric_from=99, css="meta"),
            html_table(
                [[("input file", 1), ("bytes", 1), ("SHA-256", 1)]],
                files,
                numeric_from=1,
                caption=f"Input files, relative to {base}",
            ),
        ]
    )


def running_header_html(rows: Sequence[tuple[str, str]]) -> str:
    """The running header: ``(name, text)`` pairs (escaped) in one small block, which
    :func:`page_html` repeats at the top of every printed page."""
    items = " ".join(f"<span><b>{_e(name)}:</b> {_e(text)}</span>" for name, text in rows)
    return f'<div class="running">{items}</div>'


def signature_html(signatures: Sequence[tuple[str, str]]) -> str:
    """The signature block: one row per ``(role, name)``, with room to sign and date."""
    if not signatures:
        return ""
    rows: list[Sequence[Cell]] = [[role, name, "", ""] for role, name in signatures]
    return "<h2>Signatures</h2>" + html_table(
        [[("role", 1), ("name", 1), ("signature", 1), ("date", 1)]],
        rows,
        numeric_from=99,
        css="signatures",
    )


def page_html(title: str, parts: Iterable[str], header: str = "") -> str:
    """The self-contained page: ``title`` (escaped) as its title and heading, the ``parts``
    (HTML) in order, and a last line naming the version.

    ``header`` (HTML, :func:`running_header_html`) is repeated at the top of every printed
    page: the page is one table whose head it is (browsers repeat a table's head on every
    page it spans); every page's foot says "page x of y" (CSS page margin box).
    """
    head = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{_e(title)}</title>",
        f"<style>\n{STYLE}\n</style></head><body>",
    ]
    if header:
        head.append(
            f'<table class="running"><thead><tr><td>{header}</td></tr></thead><tbody><tr><td>'
        )
    head.append(f"<h1>{_e(title)}</h1>")
    tail = [f'<p class="note">Made by hexatherm {_e(__version__)}.</p>']
    if header:
        tail.append("</td></tr></tbody></table>")
    tail.append("</body></html>")
    return "\n".join([*head, *parts, *tail]) + "\n"
