"""The parts every hexatherm HTML report shares, as data the templates print.

``report`` (a processed session), ``calibrate`` and ``diagnose`` (where the twin and the
data disagree) write their pages from templates (:mod:`~hexatherm.workflows.report.render`:
one style sheet that prints on A4, the running header, the signature block); what they
print comes from here: tables (:func:`table`, a :class:`~.render.Table`), figures
embedded as PNG data URIs (:func:`figure`), the provenance block (:func:`provenance`:
generation time, version, command line and options, every input with size and SHA-256)
and the signature block (:func:`signature_table`). No external resource, every text
escaped by the templates.
"""

from __future__ import annotations

import html
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from hexatherm import __version__
from hexatherm.workflows.report.render import PACKAGE_TEMPLATES, Figure, Table

if TYPE_CHECKING:
    from matplotlib.figure import Figure as MplFigure

    from hexatherm.io.provenance import RunFacts

#: the style sheet of every page (``templates/style.css``)
STYLE = (PACKAGE_TEMPLATES / "style.css").read_text(encoding="utf-8").strip()


def escape(value: object) -> str:
    """``value`` as escaped HTML text (quotes too)."""
    return html.escape(str(value), quote=True)


#: a cell: a text, or a value with its expanded uncertainty (printed one under the other)
Cell = str | tuple[str, str]


def table(
    header_rows: Sequence[Sequence[tuple[str, int]]],
    rows: Iterable[Sequence[Cell]],
    numeric_from: int = 1,
    row_classes: Sequence[str] | None = None,
    caption: str = "",
    align: str = "",
    css: str = "",
) -> Table:
    """A table as the templates print it (escaped).

    Parameters
    ----------
    header_rows : sequence of sequence of (text, colspan)
    rows : iterable of sequence of Cell
        Cell texts; a ``(value, U)`` pair prints U under the value.
    numeric_from : int
        Cells from this column on are right-aligned numbers.
    row_classes : sequence of str, optional
        CSS class of each body row (``"fail"`` highlights it).
    caption : str
        The table's caption.
    align : str, optional
        ``"l"`` or ``"r"`` per column (``"r"``: a number); overrides ``numeric_from``.
    css : str, optional
        The table's CSS class (``"meta"``: a field/value table).
    """
    return Table(
        [list(h) for h in header_rows],
        [list(r) for r in rows],
        numeric_from,
        None if row_classes is None else list(row_classes),
        caption,
        align,
        css,
    )


def figure(fig: MplFigure | bytes | None, alt: str, caption: str, dpi: int = 150) -> Figure | None:
    """A figure (a matplotlib figure, drawn at ``dpi``, or PNG bytes) to embed, with its
    caption; None for None."""
    if fig is None:
        return None
    if not isinstance(fig, bytes):
        from hexatherm.workflows.report.figures import figure_png

        fig = figure_png(fig, dpi)
    return Figure(fig, alt, caption)


def provenance(
    facts: RunFacts | None,
    inputs: Iterable[str | os.PathLike[str]],
    folder: Path,
    generated: str,
    extra: Sequence[tuple[str, str]] = (),
) -> dict[str, Table]:
    """The provenance block's two tables: when, by what, how (``extra`` rows: limits ...),
    and from which files (size, SHA-256; paths relative to ``folder`` where they lie
    inside it)."""
    from hexatherm.io.provenance import command_line, input_entries

    if facts is None:
        command = options = "not run from the command line"
    else:
        command = command_line(facts)  # quoted: it runs as printed
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
    return {
        "run": table([[("field", 1), ("value", 1)]], rows, numeric_from=99, css="meta"),
        "files": table(
            [[("input file", 1), ("bytes", 1), ("SHA-256", 1)]],
            files,
            numeric_from=1,
            caption=f"Input files, relative to {base}",
        ),
    }


def signature_table(signatures: Sequence[tuple[str, str]]) -> Table | None:
    """The signature block: one row per ``(role, name)``, with room to sign and date."""
    if not signatures:
        return None
    rows: list[Sequence[Cell]] = [[role, name, "", ""] for role, name in signatures]
    return table(
        [[("role", 1), ("name", 1), ("signature", 1), ("date", 1)]],
        rows,
        numeric_from=99,
        css="signatures",
    )
