"""The page system of every hexatherm report: Jinja2 templates, and a lab's own over them.

The reports (``report``, ``calibrate``, ``diagnose``) are written from templates shipped
in the package (``hexatherm/templates``): ``base.html.j2`` (the page, its style sheet,
the running header every printed page repeats, "page x of y", the signature block),
which ``process.html.j2``, ``calibration.html.j2`` and ``diagnosis.html.j2`` extend,
``letterhead.html.j2`` (what the running header shows), ``closing.html.j2`` (the lab's
wording after the report) and ``macros.html.j2`` (tables, figures, provenance).

A lab overrides any of them with a template of the same name in its own folder
(``--template-dir DIR``, or ``templates:`` in the lab file): that folder is searched
first. Its templates may embed files of the folder (a logo) with ``asset("logo.svg")``,
a data URI: the page stays self-contained. Autoescape is on: every value the data
gives is escaped, whatever the template.

A template that cannot be read, has a syntax error or fails while rendering raises
:class:`~hexatherm.errors.InputError` naming its file and line; nothing is written. So
does one that runs too long or makes too much (:mod:`hexatherm.workflows.report.sandbox`).
Templates and assets are read by one rule: files of the folder (no ``..``, no link out
of it, of at most :data:`ASSET_MAX_BYTES`), each named by a constant so that the
provenance lists every file a page is made of (:func:`named_files`).

>>> environment().from_string("<p>{{ x }}</p>").render(x='<script a="1">')
'<p>&lt;script a=&quot;1&quot;&gt;</p>'
"""

from __future__ import annotations

import base64
import html
import os
import re
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import jinja2
from jinja2 import nodes
from jinja2.loaders import split_template_path
from markupsafe import Markup

from hexatherm import __version__
from hexatherm.errors import InputError
from hexatherm.io.files import read_bytes
from hexatherm.workflows.report.sandbox import BoundedEnvironment, render_bounds, spend

#: the package's own templates
PACKAGE_TEMPLATES = Path(__file__).resolve().parents[2] / "templates"
#: MIME type of an asset, by suffix
ASSET_TYPES = {
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".gif": "image/gif",
    ".webp": "image/webp",
}
#: the largest asset embedded (a logo, a stamp, a signature: a larger file is a mistake,
#: and would make a page no browser prints)
ASSET_MAX_BYTES = 10 * 2**20
#: the largest template read (the same bound: a template may hold an inline image)
TEMPLATE_MAX_BYTES = ASSET_MAX_BYTES


#: a text cell with a run of more characters than this that a browser may not break (no
#: space, no hyphen: a long target label, a path) may break anywhere (class ``long``): the
#: browser would shrink the whole printed page to fit a table wider than the paper
UNBROKEN_CHARS = 24
_BREAKS = re.compile(r"[\s-]+")


def _unbroken(value: object) -> bool:
    return any(len(word) > UNBROKEN_CHARS for word in _BREAKS.split(str(value)))


@dataclass(frozen=True)
class TableCell:
    """One cell as the table macro prints it: its CSS class, its text, and an expanded
    uncertainty printed under it (empty: none)."""

    css: str
    value: str
    u: str = ""


@dataclass
class Table:
    """A table as data, which ``macros.html.j2``'s ``table`` prints (escaped).

    Attributes
    ----------
    header_rows : list of list of (text, colspan)
    rows : list of list of Cell
        Cell texts; a ``(value, U)`` pair prints U under the value.
    numeric_from : int
        Cells from this column on are right-aligned numbers (class ``num``).
    row_classes : list of str, optional
        CSS class of each body row (``"fail"`` highlights it).
    caption : str
    align : str
        ``"l"`` or ``"r"`` per column; overrides ``numeric_from``.
    css : str
        The table's CSS class (``"meta"``: a field/value table).
    cell_classes : list of list of str, optional
        The CSS class of every cell, overriding ``align`` and ``numeric_from``.
    """

    header_rows: list[list[tuple[str, int]]]
    rows: list[list[str | tuple[str, str]]]
    numeric_from: int = 1
    row_classes: list[str] | None = None
    caption: str = ""
    align: str = ""
    css: str = ""
    cell_classes: list[list[str]] | None = field(default=None)

    def body(self) -> Iterator[tuple[str, list[TableCell]]]:
        """``(row class, cells)`` of every body row."""
        for i, row in enumerate(self.rows):
            cells = []
            for k, cell in enumerate(row):
                if self.cell_classes is not None:
                    css = self.cell_classes[i][k]
                else:
                    numeric = self.align[k] == "r" if self.align else k >= self.numeric_from
                    css = "num" if numeric else ""
                value, u = cell if isinstance(cell, tuple) else (cell, "")
                if not css and self.css != "meta" and _unbroken(value):
                    css = "long"  # may break anywhere, or the browser shrinks the whole page
                cells.append(TableCell(css, value, u))
            yield (self.row_classes[i] if self.row_classes is not None else ""), cells


@dataclass(frozen=True)
class Figure:
    """A figure: its PNG (embedded as a data URI), alternative text and caption."""

    png: bytes
    alt: str
    caption: str

    @property
    def uri(self) -> str:
        return "data:image/png;base64," + base64.b64encode(self.png).decode("ascii")


@dataclass(frozen=True)
class Drawing:
    """A figure not drawn yet: ``draw()`` gives its PNG. :func:`render_page` draws it
    once a lab's templates have rendered the page without it (the costly part last: a
    template that fails while rendering is refused before any figure is drawn)."""

    draw: Callable[[], bytes]
    alt: str
    caption: str

    def drawn(self) -> Figure:
        return Figure(self.draw(), self.alt, self.caption)

    def undrawn(self) -> Figure:
        """The figure without its pixels (an empty PNG): what the rehearsal renders."""
        return Figure(b"", self.alt, self.caption)


def _inside(folder: Path, name: str) -> bool:
    """Whether ``folder / name`` is in ``folder``, links resolved: the one rule of the
    templates and the assets (no ``..``, absolute path or link out of the folder)."""
    path = folder / name
    return folder.resolve() in path.resolve().parents


def _asset(env: jinja2.Environment, folders: tuple[Path, ...], name: str) -> str:
    """A file of the lab's template folder (or the package's) as a data URI: an image,
    inside the folder (no ``..``, absolute path or link out of it), of at most
    :data:`ASSET_MAX_BYTES`; read once per page, and counted in the page's size."""
    kind = ASSET_TYPES.get(Path(name).suffix.lower())
    if kind is None:
        raise jinja2.TemplateRuntimeError(
            f"asset {name!r}: not an image ({', '.join(sorted(ASSET_TYPES))})"
        )
    outside = False
    for folder in folders:
        path = folder / name
        try:
            inside = _inside(folder, name)
            found = inside and path.is_file()
        except (OSError, ValueError):
            raise jinja2.TemplateRuntimeError(f"asset {name!r}: not a file name") from None
        outside = outside or not inside
        if not found:
            continue
        try:
            size = path.stat().st_size
            if size > ASSET_MAX_BYTES:
                raise jinja2.TemplateRuntimeError(
                    f"asset {name!r}: {size} bytes; an embedded image may have at most "
                    f"{ASSET_MAX_BYTES} ({ASSET_MAX_BYTES // 2**20} MiB)"
                )
            data = read_bytes(path, limit=ASSET_MAX_BYTES)
        except OSError as exc:
            raise jinja2.TemplateRuntimeError(
                f"asset {name!r}: cannot be read ({exc.strerror})"
            ) from None
        except InputError as exc:
            raise jinja2.TemplateRuntimeError(f"asset {name!r}: {exc.message}") from None
        _read_files(env).add(path.resolve())
        uri = f"data:{kind};base64," + base64.b64encode(data).decode("ascii")
        spend(len(uri))
        return uri
    if outside:
        raise jinja2.TemplateRuntimeError(
            f"asset {name!r}: outside the template folder (an image in it: no '..', "
            "absolute path or link out of it)"
        )
    raise jinja2.TemplateRuntimeError(
        f"asset {name!r} not found in {', '.join(str(f) for f in folders)}"
    )


def _escaped(value: object) -> Markup:
    """Every value printed, escaped as :func:`html.escape` does (``&quot;``, ``&#x27;``):
    autoescape leaves markup as it is; counted in the page's size."""
    if not isinstance(value, Markup):
        value = Markup(html.escape(str(value), quote=True))
    spend(len(value))
    return value


def _read_files(env: jinja2.Environment) -> set[Path]:
    """Every file the environment ``env`` read (templates and assets, links resolved)."""
    assert isinstance(env, BoundedEnvironment)
    return env.hexatherm_read


class _Loader(jinja2.FileSystemLoader):
    """A folder of templates, read by the rule of the assets (no link out of the folder, a
    regular file of at most :data:`TEMPLATE_MAX_BYTES`); a file that is not UTF-8 is a
    syntax error naming its line, one that cannot be read an :class:`InputError` naming it;
    every file read is recorded (:func:`_read_files`)."""

    def get_source(self, environment: jinja2.Environment, template: str) -> tuple[str, str, Any]:
        pieces = split_template_path(template)  # no '..'
        folder = Path(self.searchpath[0])
        path = os.path.join(folder, *pieces)
        if not os.path.lexists(path):
            raise jinja2.TemplateNotFound(template)
        try:
            inside = _inside(folder, "/".join(pieces))
        except (OSError, ValueError):
            raise jinja2.TemplateNotFound(template) from None
        if not inside:
            raise InputError(
                "template: a link out of the template folder (templates and assets are "
                "files of the folder)",
                path=path,
            )
        if not os.path.isfile(path):
            raise jinja2.TemplateNotFound(template)
        data = read_bytes(path, limit=TEMPLATE_MAX_BYTES)
        try:
            source = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = data.count(b"\n", 0, exc.start) + 1
            column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
            raise jinja2.TemplateSyntaxError(
                f"not UTF-8 text: byte 0x{data[exc.start]:02x} at column {column}",
                line,
                template,
                path,
            ) from None
        _read_files(environment).add(Path(path).resolve())
        mtime = os.path.getmtime(path)

        def uptodate() -> bool:
            try:
                return os.path.getmtime(path) == mtime
            except OSError:
                return False

        return source, path, uptodate


@cache
def environment(template_dir: Path | None = None) -> jinja2.Environment:
    """The templates: ``template_dir``'s first (a lab's), then the package's; sandboxed (a
    template prints the data it is given, and cannot reach Python's internals: ``__class__``,
    ``__globals__`` ... are refused, a lab's folder is data, not a program); without the
    ``safe`` filter (a value given by the data is never printed as markup)."""
    folders = (PACKAGE_TEMPLATES,) if template_dir is None else (template_dir, PACKAGE_TEMPLATES)
    env = BoundedEnvironment(
        loader=jinja2.ChoiceLoader([_Loader(str(f)) for f in folders]),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
        finalize=_escaped,
    )
    # every value the data gives prints as text: no template marks it as markup
    del env.filters["safe"]
    env.globals["asset"] = lambda name: _asset(env, folders, str(name))
    env.globals["version"] = __version__
    return env


def check_template_dir(template_dir: str | os.PathLike[str] | None) -> Path | None:
    """``template_dir`` resolved, every template in it compiled, with every template they
    and the package's pages name (``style.css`` too): a syntax error, a file that is not
    UTF-8, a template named but found nowhere or a loop of includes or extends is an
    :class:`InputError` naming the file and line, before any work is done."""
    if template_dir is None:
        return None
    folder = Path(template_dir).resolve()
    if not folder.is_dir():
        raise InputError("not a folder of templates", path=template_dir)
    env = environment(folder)
    try:
        _check_references(env, _pages(folder), folder)
    except jinja2.TemplateError as exc:
        raise template_error(exc, env) from None
    return folder


def _pages(folder: Path) -> list[str]:
    """The templates a page may start from: the lab's ``.j2`` files in ``folder``, then
    the package's."""
    names = [n for n in sorted(os.listdir(folder)) if n.endswith(".j2") and (folder / n).is_file()]
    return names + sorted(n for n in os.listdir(PACKAGE_TEMPLATES) if n.endswith(".j2"))


#: the statements that name another template
_NAMING = (nodes.Extends, nodes.Include, nodes.Import, nodes.FromImport)


def _names_in(tree: nodes.Template) -> Iterator[tuple[nodes.Node, str]]:
    """Each statement of ``tree`` that names another template by a constant, with that
    name, in order (a name computed while rendering is left out: render_page stops a
    loop of those)."""
    for node in tree.find_all(_NAMING):
        target = getattr(node, "template", None)  # each of _NAMING has one
        if isinstance(target, nodes.Const) and isinstance(target.value, str):
            yield node, target.value


def _named(env: jinja2.Environment, name: str) -> tuple[str, list[tuple[str, int]]]:
    """The file of the template ``name`` (compiled), and the templates it names by a
    constant: ``(name, line)``, in order (``include ... ignore missing`` left out when
    the template does not exist)."""
    assert env.loader is not None
    source, filename, _ = env.loader.get_source(env, name)
    env.get_template(name)  # compiles: a syntax error names its file and line
    tree = env.parse(source, name, filename)
    found = []
    for node, target in _names_in(tree):
        if isinstance(node, nodes.Include) and node.ignore_missing:
            try:
                env.loader.get_source(env, target)
            except jinja2.TemplateNotFound:
                continue
        found.append((target, node.lineno))
    return filename or name, found


def named_files(template_dir: Path) -> list[Path]:
    """The files of the lab's folder ``template_dir`` (checked by :func:`check_template_dir`)
    that its pages are made from, as the templates name them by a constant: every template
    reached from the lab's and the package's pages, every ``asset("...")``; sub-folders
    too (a folder's other files are not read: a lab's ``.git``, its archive)."""
    env = environment(template_dir)
    assert env.loader is not None
    top = template_dir.resolve()
    names = _pages(top)
    seen: set[str] = set()
    found: set[Path] = set()
    while names:
        name = names.pop()
        if name in seen:
            continue
        seen.add(name)
        try:
            source, filename, _ = env.loader.get_source(env, name)
        except jinja2.TemplateNotFound:
            continue
        if filename is not None and Path(filename).resolve().is_relative_to(top):
            found.add(Path(filename))
        tree = env.parse(source, name, filename)
        names += [target for _, target in _names_in(tree)]
        for call in tree.find_all(nodes.Call):
            first = call.args[0] if call.args else None
            if (
                isinstance(call.node, nodes.Name)
                and call.node.name == "asset"
                and isinstance(first, nodes.Const)
                and isinstance(first.value, str)
            ):
                path = template_dir / first.value
                try:
                    if not (top in path.resolve().parents and path.is_file()):
                        continue  # refused when the page is rendered
                    size = path.stat().st_size
                except (OSError, ValueError):
                    continue  # refused when the page is rendered
                if size > ASSET_MAX_BYTES:  # before anything reads or hashes it
                    raise InputError(
                        f"template: asset {first.value!r}: {size} bytes; an embedded image "
                        f"may have at most {ASSET_MAX_BYTES} ({ASSET_MAX_BYTES // 2**20} MiB)",
                        path=filename or name,
                        line=call.lineno,
                    )
                found.add(path)
    return sorted(found)


def _check_references(env: jinja2.Environment, roots: list[str], folder: Path) -> None:
    """Every template reachable from ``roots`` compiled; a name found nowhere or a loop is
    a :class:`InputError` at the statement that names it (a loop: a statement of the
    lab's ``folder`` when one is on it, the last one)."""
    files: dict[str, str] = {}
    edges: dict[str, list[tuple[str, int]]] = {}
    done: set[str] = set()

    def visit(name: str, path: list[tuple[str, str, int]]) -> None:
        # path: (template, its file, line of the statement naming the next one)
        if name not in edges:
            files[name], edges[name] = _named(env, name)
        for target, line in edges[name]:
            here = [*path, (name, files[name], line)]
            on_path = [step[0] for step in here]
            if target in on_path:
                loop = here[on_path.index(target) :]
                culprit = next((s for s in reversed(loop) if Path(s[1]).parent == folder), loop[-1])
                chain = " -> ".join([*(s[0] for s in loop), target])
                raise InputError(
                    f"template: endless loop of includes/extends: {chain}",
                    path=culprit[1],
                    line=culprit[2],
                )
            if target in done:
                continue
            try:
                visit(target, here)
            except jinja2.TemplateNotFound:
                if target in files:
                    raise
                raise InputError(
                    f"template: {target!r} not found in {_folders(env)}",
                    path=files[name],
                    line=line,
                ) from None
        done.add(name)

    for root in roots:
        if root not in done:
            visit(root, [])


def template_error(exc: jinja2.TemplateError, env: jinja2.Environment) -> InputError:
    """``exc`` as an :class:`InputError` naming the template's file and line."""
    message = str(exc.message if exc.message is not None else exc).splitlines()[0]
    if message.startswith("No filter named 'safe'"):
        message += " (hexatherm prints every value of the data as text, never as markup)"
    if isinstance(exc, jinja2.TemplateSyntaxError) and exc.filename:
        return InputError(f"template: {message}", path=exc.filename, line=exc.lineno)
    if isinstance(exc, jinja2.TemplateNotFound):
        return InputError(f"template {exc.name!r} not found", path=_folders(env))
    return _in_template(f"template: {message}", exc, env)


def _in_template(message: str, exc: BaseException, env: jinja2.Environment) -> InputError:
    """An :class:`InputError` with ``message``, naming the file and line of the innermost
    template (a ``.j2`` file, or any other file the templates include: ``style.css``)
    that ``exc`` passed through: the innermost of the lab's when the lab has templates
    (the line to fix), with hexatherm's file and line where it failed, if deeper."""
    frames = [
        frame
        for frame in traceback.extract_tb(exc.__traceback__)
        if not frame.filename.endswith(".py") and not frame.filename.startswith("<")
    ]
    if not frames:
        return InputError(message, path=_folders(env))
    package = str(PACKAGE_TEMPLATES) + os.sep
    labs = [f for f in frames if not f.filename.startswith(package)]
    where = labs[-1] if labs else frames[-1]
    if where is not frames[-1]:
        message += f" (in hexatherm's {Path(frames[-1].filename).name}:{frames[-1].lineno})"
    return InputError(message, path=where.filename, line=where.lineno)


def _folders(env: jinja2.Environment) -> str:
    loader = env.loader
    assert isinstance(loader, jinja2.ChoiceLoader)
    return ", ".join(
        str(path)
        for sub in loader.loaders
        if isinstance(sub, jinja2.FileSystemLoader)
        for path in sub.searchpath
    )


def render_page(name: str, template_dir: Path | None = None, **context: Any) -> str:
    """The template ``name`` rendered with ``context``, within the bounds of
    :mod:`~hexatherm.workflows.report.sandbox`; a template's failure, or a bound
    exceeded, is an :class:`InputError` naming its file and line, and so is a file of the
    lab's folder read by a name computed while rendering (the provenance lists the files
    named by a constant, :func:`named_files`).

    The figures of ``context`` given as :class:`Drawing` are drawn after the rest: with a
    lab's templates (``template_dir``), the page is first rendered with them undrawn, so
    that a template failing while rendering (a field the page does not give, an asset out
    of the folder, an unsafe attribute) is refused before the figures cost their time;
    the page written is the one rendered with the figures drawn."""
    drawings = {key: value for key, value in context.items() if isinstance(value, Drawing)}
    if drawings and template_dir is not None:
        _render(name, template_dir, {**context, **{k: d.undrawn() for k, d in drawings.items()}})
    return _render(name, template_dir, {**context, **{k: d.drawn() for k, d in drawings.items()}})


def _render(name: str, template_dir: Path | None, context: dict[str, Any]) -> str:
    """:func:`render_page` of figures drawn or undrawn."""
    env = environment(template_dir)
    try:
        with render_bounds():
            page = env.get_template(name).render(**context)
    except jinja2.TemplateError as exc:
        raise template_error(exc, env) from None
    except RecursionError as exc:  # a loop of includes whose names are computed
        raise _in_template(
            "template: endless loop of includes/extends (names computed while rendering)",
            exc,
            env,
        ) from None
    except MemoryError as exc:
        raise _in_template("template: the page needs too much memory", exc, env) from None
    except Exception as exc:  # a lab's template fails (1/0, int('x'*5000)): its line
        if template_dir is None:
            raise  # hexatherm's own templates: a bug, with its traceback
        raise _in_template(f"template: {type(exc).__name__}: {exc}", exc, env) from None
    if template_dir is not None:
        _check_read(env, template_dir)
    return page


def _check_read(env: jinja2.Environment, template_dir: Path) -> None:
    """Refuse a file of the lab's folder the page read that :func:`named_files` does not
    list (a name computed while rendering): the provenance would not list it."""
    top = template_dir.resolve()
    named = {p.resolve() for p in named_files(template_dir)}
    unnamed = sorted(p for p in _read_files(env) if p.is_relative_to(top) and p not in named)
    if unnamed:
        raise InputError(
            "template: read by a name computed while rendering; name it by a constant "
            '(include "...", asset("...")) so that the provenance lists it',
            path=os.fspath(unnamed[0]),
        )


def render_macro(name: str, *args: Any) -> str:
    """One macro of the package's ``macros.html.j2`` (a table, a figure) as HTML."""
    module = environment(None).get_template("macros.html.j2").module
    return str(getattr(module, name)(*args))


__all__ = [
    "Drawing",
    "Figure",
    "Markup",
    "Table",
    "TableCell",
    "check_template_dir",
    "named_files",
    "environment",
    "render_macro",
    "render_page",
    "template_error",
]
