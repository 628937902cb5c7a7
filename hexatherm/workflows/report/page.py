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
import shlex
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

from hexatherm import __version__
from hexatherm.workflows.report.render import PACKAGE_TEMPLATES, Drawing, Figure, Table

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


#: what makes a matplotlib figure (None: there is none, not to be given to :func:`figure`)
Maker = Callable[[], "MplFigure | None"]


@overload
def figure(fig: Maker, alt: str, caption: str, dpi: int = 150) -> Drawing: ...
@overload
def figure(
    fig: MplFigure | bytes | None, alt: str, caption: str, dpi: int = 150
) -> Figure | None: ...
def figure(
    fig: MplFigure | bytes | Maker | None, alt: str, caption: str, dpi: int = 150
) -> Figure | Drawing | None:
    """A figure (a matplotlib figure, drawn at ``dpi``, or PNG bytes) to embed, with its
    caption; None for None. A function making the matplotlib figure (where there is one)
    gives a :class:`~.render.Drawing`: made and drawn by :func:`~.render.render_page`,
    after the rest of the page."""
    from hexatherm.workflows.report.figures import figure_png

    if callable(fig):
        make = fig

        def draw() -> bytes:
            made = make()
            assert made is not None, f"{alt}: a Drawing is given where there is a figure"
            return figure_png(made, dpi)

        return Drawing(draw, alt, caption)
    if fig is None:
        return None
    if not isinstance(fig, bytes):
        fig = figure_png(fig, dpi)
    return Figure(fig, alt, caption)


def provenance(
    facts: RunFacts | None,
    inputs: Iterable[str | os.PathLike[str]],
    folder: Path,
    generated: str,
    extra: Sequence[tuple[str, str]] = (),
    folder_name: str = "the session's folder",
    number: str | None = None,
) -> dict[str, Table]:
    """The provenance block's two tables: the document's ``number``, when, by what, how
    (``extra`` rows: limits ...), and from which files (size, SHA-256). Paths, in the files and
    in the command line and options, are relative to ``folder`` (``folder_name`` says
    which): a customer's document carries no path of the lab's computer."""
    from hexatherm.io.provenance import input_entries

    base = folder.resolve()
    if facts is None:
        command = options = "not run from the command line"
    else:
        command = command_text(facts.command, facts.argv, base)  # quoted: it runs as printed
        options = options_text(facts.options, base) or "none"
    rows: list[Sequence[Cell]] = [
        *([["report number", number or "none assigned"]] if number is not None else []),
        ["generated", generated],
        ["hexatherm", __version__],
        [f"command line (paths relative to {folder_name})", command],
        ["options in effect", options],
        *[list(row) for row in extra],
    ]
    if facts is not None:
        rows.append(["started", facts.started])
    files: list[Sequence[Cell]] = []
    for entry in input_entries(inputs):
        size = str(entry["bytes"]) if "bytes" in entry else "folder"
        files.append([relative(entry["path"], base), size, entry.get("sha256", "")])
    return {
        "run": table([[("field", 1), ("value", 1)]], rows, numeric_from=99, css="meta"),
        "files": table(
            [[("input file", 1), ("bytes", 1), ("SHA-256", 1)]],
            files,
            numeric_from=1,
            caption=f"Input files, relative to {folder_name} ({base.name})",
        ),
    }


def signature_table(signatures: Sequence[tuple[str, str]], date: str = "") -> Table | None:
    """The signature block: one row per ``(role, name)``, with room to sign, dated
    ``date`` (the date of issue: a document is signed when it is issued)."""
    if not signatures:
        return None
    rows: list[Sequence[Cell]] = [[role, name, "", date] for role, name in signatures]
    return table(
        [[("role", 1), ("name", 1), ("signature", 1), ("date", 1)]],
        rows,
        numeric_from=99,
        css="signatures",
    )


def relative(path: str | os.PathLike[str], base: Path) -> str:
    """``path`` relative to ``base`` (``..`` where it lies outside), never absolute."""
    try:
        return os.path.relpath(Path(path).resolve(), base.resolve())
    except ValueError:  # another drive (Windows): its name only
        return Path(path).name


#: parameters that are arguments (in the command line), not options
_ARGUMENTS = ("session", "sessions", "sessions_dir", "source")
#: options whose parameter is named otherwise than their flag
_FLAGS = {"tolerances": "--tolerance", "quality_thresholds": "--quality-threshold", "out": "-o"}


def options_text(options: Mapping[str, Any], base: Path) -> str:
    """The options as a person writes them: ``--coverage-factor 2 --mc 0``; flags given
    by their name, tolerances as ``Tx=2um``, paths relative to ``base``, options not given
    left out."""
    words: list[str] = []
    for key, value in options.items():
        flag = _FLAGS.get(key, "--" + key.replace("_", "-"))
        empty = isinstance(value, list | tuple | Mapping | str) and not value
        if key in _ARGUMENTS or value is None or value is False or empty:
            continue
        if value is True:
            words.append(flag)
        elif isinstance(value, Mapping) and all(isinstance(v, bool) for v in value.values()):
            words += ["--" + k.replace("_", "-") for k, v in value.items() if v]
        elif isinstance(value, Mapping):
            words += [flag, ",".join(_item(k, v) for k, v in value.items())]
        elif isinstance(value, list | tuple):
            for item in value:
                words += [flag, _word(item, base)]
        else:
            words += [flag, _word(value, base)]
    return shlex.join(words)


def _item(key: str, value: object) -> str:
    """A mapping's item as the command line takes it: ``Tx_um: 2`` -> ``Tx=2um``,
    ``(-1, 3)`` -> ``Tx=-1..3um``."""
    name, _, unit = key.partition("_")
    if unit in ("um", "urad"):
        limits = value if isinstance(value, list | tuple) else [value]
        return f"{name}=" + "..".join(f"{float(str(v)):g}" for v in limits) + unit
    return f"{key}={value}"


def _word(value: object, base: Path) -> str:
    text = str(value)
    return relative(text, base) if os.path.isabs(text) else text


def command_text(command: str, argv: Sequence[str], base: Path) -> str:
    """The command line with every absolute path relative to ``base``."""
    return shlex.join(["hexatherm", command, *(_word(a, base) for a in argv)])
