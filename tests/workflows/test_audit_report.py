"""A hostile-input audit of ``report`` and of the pages ``diagnose`` writes (session 10).

A lab's templates that are not UTF-8, include or extend themselves, or ask ``asset()``
for what is not an image of their folder; a template folder that is the session or
the output folder; labels too long for the figures. Each is refused in one line naming
file and line (exit status 1, no traceback, nothing written, no input touched) or
printed as the reader needs it.
"""

from __future__ import annotations

import base64
import hashlib
import os
import re
import shutil
from pathlib import Path
from unittest import mock

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.errors import InputError
from hexatherm.workflows.report.render import Drawing, render_page
from tests.audit import hashes, refusal, session_copy
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "paper-zero-pose"


def templates(folder: Path, files: dict[str, str | bytes]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        data = text.encode("utf-8") if isinstance(text, str) else text
        (folder / name).write_bytes(data)
    return folder


def report_refused(tmp_path: Path, folder: Path) -> str:
    """``report`` of a copy of paper-zero-pose with the lab's templates ``folder``:
    refused before any figure is drawn, nothing written, no input changed; its one line."""
    from hexatherm.workflows.report import figures

    session = session_copy(tmp_path)
    before = hashes(session, folder)
    out = tmp_path / "out" / "report.html"
    drawn = []
    real = figures.figure_png
    with mock.patch.object(figures, "figure_png", lambda *a, **k: drawn.append(a) or real(*a, **k)):
        result = CliRunner().invoke(
            main, ["report", str(session), "--template-dir", str(folder), "-o", str(out)]
        )
    line = refusal(result)
    assert drawn == [], line  # fails fast: a bad template costs no figure
    assert not out.exists() and not out.parent.exists()
    assert hashes(session, folder) == before
    return line


# ------------------------------------------------------------------ templates


def test_a_template_that_is_not_utf8_is_refused_naming_its_file_and_line(tmp_path):
    folder = templates(tmp_path / "t", {"closing.html.j2": b"<p>\nCaf\xe9 du Lac</p>\n"})
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'closing.html.j2'}:2: template: not UTF-8"), line


def test_a_style_sheet_that_is_not_utf8_is_refused_too(tmp_path):
    # style.css is a template too (base.html.j2 includes it), though not a .j2 file
    folder = templates(tmp_path / "t", {"style.css": b"body { color: red; }\n/* \xff */\n"})
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'style.css'}:2: template: not UTF-8"), line


@pytest.mark.parametrize(
    ("files", "where", "line_no"),
    [
        # a template that includes itself
        ({"closing.html.j2": '<p>\n{% include "closing.html.j2" %}\n'}, "closing.html.j2", 2),
        # two that include each other
        (
            {
                "closing.html.j2": '{% include "words.html.j2" %}\n',
                "words.html.j2": '<p>\n\n{% include "closing.html.j2" %}\n',
            },
            "words.html.j2",
            3,
        ),
        # the page extends the report that extends it
        ({"base.html.j2": '{% extends "process.html.j2" %}\n'}, "base.html.j2", 1),
        # the style sheet includes the page
        ({"style.css": 'body {}\n{% include "base.html.j2" %}\n'}, "style.css", 2),
    ],
)
def test_an_endless_include_or_extends_loop_is_refused_naming_file_and_line(
    tmp_path, files, where, line_no
):
    folder = templates(tmp_path / "t", files)
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / where}:{line_no}: template: "), line
    assert "loop" in line, line


def test_a_loop_only_rendering_finds_is_refused_naming_the_template(tmp_path):
    # the name comes from a variable: no reading of the templates can see the loop
    folder = templates(
        tmp_path / "t",
        {"closing.html.j2": '{% set me = "closing" %}\n{% include me ~ ".html.j2" %}\n'},
    )
    with pytest.raises(InputError, match=r"closing\.html\.j2:2: template: .*loop") as caught:
        render_page("closing.html.j2", folder.resolve(), title="t", header_rows=[])
    assert str(folder.resolve() / "closing.html.j2") in str(caught.value)


def test_a_pages_figures_are_drawn_once_the_labs_templates_rendered_without_them(tmp_path):
    # a template that fails while rendering costs no figure (fail fast); a good one gets
    # the figure drawn once, its pixels in the page
    drawn = []

    def draw() -> bytes:
        drawn.append(1)
        return b"\x89PNG drawn"

    page = '<p>\n<img src="{{ f.uri }}" alt="{{ f.alt }}">{{ more }}\n'
    folder = templates(tmp_path / "t", {"page.html.j2": page})
    with pytest.raises(InputError, match=r"page\.html\.j2:2: template: .*'more'"):
        render_page("page.html.j2", folder.resolve(), f=Drawing(draw, "a figure", "c"))
    assert drawn == []
    html = render_page("page.html.j2", folder.resolve(), f=Drawing(draw, "a fig", "c"), more=1)
    assert drawn == [1]
    uri = base64.b64encode(b"\x89PNG drawn").decode("ascii")
    assert f'src="data:image/png;base64,{uri}"' in html
    assert 'alt="a fig"' in html


@pytest.mark.parametrize(
    ("name", "why"),
    [
        ("../secret.svg", "outside the template folder"),
        ("/SECRET", "outside the template folder"),
        ("link.svg", "outside the template folder"),
        ("a\x00.png", "not a file name"),
    ],
)
def test_an_asset_outside_the_folder_is_refused_as_such(tmp_path, name, why):
    secret = tmp_path / "secret.svg"
    secret.write_text("<svg>secret</svg>", encoding="utf-8")
    name = name.replace("/SECRET", str(secret))
    call = "asset('" + name.replace("\x00", "\\x00") + "')"
    folder = templates(tmp_path / "t", {"closing.html.j2": '<p>\n<img src="{{ ' + call + ' }}">\n'})
    (folder / "link.svg").symlink_to(secret)
    (folder / "logo.svg").write_text("<svg/>", encoding="utf-8")
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'closing.html.j2'}:2: template: asset "), line
    assert why in line, line


def test_an_asset_too_large_to_embed_is_refused(tmp_path):
    from hexatherm.workflows.report.render import ASSET_MAX_BYTES

    folder = templates(
        tmp_path / "t", {"closing.html.j2": "\n<img src=\"{{ asset('big.png') }}\">"}
    )
    with (folder / "big.png").open("wb") as f:
        f.truncate(ASSET_MAX_BYTES + 1)  # sparse: no disk used
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'closing.html.j2'}:2: template: asset 'big.png': "), (
        line
    )
    assert f"{ASSET_MAX_BYTES + 1} bytes" in line, line
    # one byte less is embedded, whole
    (folder / "big.png").write_bytes(b"\x89PNG" + bytes(ASSET_MAX_BYTES - 4))
    out = tmp_path / "ok.html"
    session = session_copy(tmp_path / "s")  # report processes it first: its results/
    result = CliRunner().invoke(
        main, ["report", str(session), "--template-dir", str(folder), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    page = out.read_text(encoding="utf-8")
    uri = page.rsplit('<img src="data:image/png;base64,', 1)[1].split('"', 1)[0]  # the closing's
    assert base64.b64decode(uri) == (folder / "big.png").read_bytes()


def test_a_template_named_but_found_nowhere_is_refused_where_it_is_named(tmp_path):
    text = '{% include "words.html.j2" ignore missing %}\n{% include "nowhere.j2" %}\n'
    folder = templates(tmp_path / "t", {"closing.html.j2": text})
    line = report_refused(tmp_path, folder)
    assert line.startswith(
        f"Error: {folder / 'closing.html.j2'}:2: template: 'nowhere.j2' not found"
    ), line


def test_diagnose_refuses_a_template_loop_before_any_work(tmp_path):
    session = session_copy(tmp_path, "with-hidden-effect")
    folder = templates(tmp_path / "t", {"diagnosis.html.j2": '{% extends "diagnosis.html.j2" %}\n'})
    before = hashes(session, folder)
    out = tmp_path / "diag"
    result = CliRunner().invoke(
        main, ["diagnose", str(session), "--template-dir", str(folder), "-o", str(out)]
    )
    line = refusal(result)
    assert line.startswith(f"Error: {folder / 'diagnosis.html.j2'}:1: template: endless loop"), line
    assert "diagnosing" not in result.output  # refused before the diagnosis ran
    assert not out.exists() and hashes(session, folder) == before


# ------------------------------------------- a template folder that is the session or output folder


def provenance_files(page: Path) -> list[str]:
    """The input files the page's provenance lists, as shown."""
    text = page.read_text(encoding="utf-8")
    files = text.split("Input files, relative to", 1)[1].split("</tbody>", 1)[0]
    return re.findall(r"<tr><td[^>]*>([^<]*)</td>", files)


@pytest.mark.parametrize("where", ["session", "separate"])
def test_a_template_folder_that_holds_the_report_is_replaced_with_overwrite(tmp_path, where):
    session = session_copy(tmp_path)
    folder = session if where == "session" else templates(tmp_path / "t", {"closing.html.j2": "x"})
    out = folder / "report.html"
    assert CliRunner().invoke(main, ["process", str(session)]).exit_code == 0
    inputs = hashes(session, folder)
    args = ["report", str(session), "--template-dir", str(folder), "-o", str(out)]
    first = CliRunner().invoke(main, args)
    assert first.exit_code == 0, first.output
    written = out.read_bytes()
    # hexatherm's own report (and its record of it) are not inputs of the next page:
    # --overwrite replaces them
    again = CliRunner().invoke(main, [*args, "--overwrite"])
    assert again.exit_code == 0, again.output
    shown = provenance_files(out)
    assert "report.html" not in shown and ".hexatherm-manifest.json" not in shown, shown
    assert len(shown) == len(set(shown)), shown  # every input once
    assert "session.yaml" in shown or str(session / "session.yaml") in shown
    after = hashes(session, folder)
    for name in ("report.html", ".hexatherm-manifest.json"):
        after.pop(str(folder / name))
    assert after == inputs
    # a report edited since is the user's: an input, never replaced
    out.write_bytes(written + b"<!-- checked, J. Doe -->")
    edited = CliRunner().invoke(main, [*args, "--overwrite"])
    line = refusal(edited)
    assert str(out) in line, line
    assert out.read_bytes() == written + b"<!-- checked, J. Doe -->"


# ------------------------------------------------------------------ labels in the figures


def relabelled(tmp_path: Path, rename: dict[str, str]) -> Path:
    """A copy of paper-zero-pose with targets renamed (plan and centres)."""
    session = session_copy(tmp_path)
    for name in ("plan.yaml", "centres.csv"):
        text = (session / name).read_text(encoding="utf-8")
        for old, new in rename.items():
            text = re.sub(rf"(?<![\w-]){old}(?![\w-])", new, text)
        (session / name).write_text(text, encoding="utf-8")
    return session


def drawn_ticks(fig) -> tuple[list[str], list, object]:
    """The pose figure drawn: its bottom panels' tick texts and extents, and the x labels'."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    bottom = fig.axes[3:6]
    texts = [t.get_text() for t in bottom[0].get_xticklabels()]
    boxes = [t.get_window_extent(renderer) for ax in bottom for t in ax.get_xticklabels()]
    boxes += [ax.xaxis.label.get_window_extent(renderer) for ax in bottom]
    return texts, boxes, fig.bbox


@pytest.mark.parametrize(
    "tail", ["-MW", "-WORKSPACE-CORNER-MWMW", "-" + "very-long-target-label-" * 8]
)
def test_long_target_labels_stay_on_the_pose_figure_and_tell_the_targets_apart(tmp_path, tail):
    from hexatherm.workflows.process.pipeline import Checks, process_session
    from hexatherm.workflows.report import pose_figure

    labels = {f"S{i}": f"S{i}{tail}" for i in range(10, 0, -1)}
    result = process_session(relabelled(tmp_path, labels), "linear", None, Checks())
    texts, boxes, page = drawn_ticks(pose_figure(result))
    for box in boxes:  # every tick label and the axis' title inside the figure
        assert box.y0 >= 0 and box.x0 >= 0 and box.x1 <= page.x1, box
    assert len(set(texts)) == 10  # each target told apart
    for k, text in enumerate(texts):
        full = labels[f"S{k + 1}"]
        assert text == full or (text[:5] == full[:5] and text.endswith(full[-6:]) and "…" in text)


def test_short_labels_keep_the_figure_as_it_was(tmp_path):
    # the shipped sessions' labels (S1 .. S10): the layout of before, to the pixel
    from hexatherm.workflows.process.pipeline import Checks, process_session
    from hexatherm.workflows.report import pose_figure

    fig = pose_figure(process_session(SESSION, "linear", None, Checks()))
    assert fig.subplotpars.bottom == 0.1
    texts, boxes, _ = drawn_ticks(fig)
    assert texts == [f"S{i}" for i in range(1, 11)]
    # the top row's ticks are the bottom row's (shared x; labelled at the bottom only)
    for ax in fig.axes[:6]:
        assert list(ax.get_xticks()) == list(range(1, 11)) and ax.get_xlim() == (0.4, 10.6)


def test_a_long_unbroken_name_or_label_does_not_shrink_the_printed_page(tmp_path):
    # a word wider than the paper (a session name, a target label without a hyphen)
    # made Chromium shrink every page to fit it: the tables' numbers printed at ~5 pt
    from tests.workflows.test_report_browser import A4_PT, PAGE, WORD, browser, print_pdf

    if browser() is None:
        pytest.skip("no Chromium (apt-get install -y chromium poppler-utils)")
    session = relabelled(tmp_path, {f"S{i}": f"S{i}" + "X" * 60 for i in range(10, 0, -1)})
    text = (session / "session.yaml").read_text(encoding="utf-8")
    name = "N" * 120
    (session / "session.yaml").write_text(text.replace("paper-zero-pose", name), encoding="utf-8")
    out = tmp_path / "report.html"
    result = CliRunner().invoke(main, ["report", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    pages = PAGE.findall(print_pdf(out, tmp_path / "report.pdf"))
    heights = []
    for width, height, body in pages:
        assert (float(width), float(height)) == pytest.approx(A4_PT, abs=1.0)
        for x0, y0, x1, y1, word in WORD.findall(body):
            assert 0 <= float(x0) and float(x1) <= float(width), word
            if re.fullmatch(r"-?\d+\.\d{3}", word):
                heights.append(float(y1) - float(y0))
    # the tables' numbers at their 7.5 pt (a DejaVu word box is ~1.16 em high), not shrunk
    assert len(heights) > 100 and sorted(heights)[len(heights) // 2] >= 1.164 * 7.0
    # the name and every label printed whole, in pieces
    words = "".join(w[4] for _, _, body in pages for w in WORD.findall(body))
    assert name in words
    assert all(f"S{i}" + "X" * 60 in words for i in range(1, 11))


def test_one_target_shows_its_common_band(tmp_path):
    # a band over trials 1..M has no width when M = 1: the legend named a band not drawn
    from hexatherm.core.geometry import to_um_urad
    from hexatherm.workflows.process.pipeline import Checks, process_session
    from hexatherm.workflows.process.uncertainty import pose_uncertainty
    from hexatherm.workflows.report import pose_figure

    session = session_copy(tmp_path)
    plan = (session / "plan.yaml").read_text(encoding="utf-8").splitlines(keepends=True)
    cut = [line for line in plan if not re.search(r"label: [SR]([2-9]|10)\b", line)]
    (session / "plan.yaml").write_text("".join(cut), encoding="utf-8")
    centres = (session / "centres.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    keep = [line for line in centres if not re.match(r"[SR]([2-9]|10),", line)]
    (session / "centres.csv").write_text("".join(keep), encoding="utf-8")
    result = process_session(session, "linear", None, Checks())
    assert len(result.correction.target_index) == 1
    uncertainty = pose_uncertainty(result)
    assert uncertainty.common_u is not None
    expected = 2.0 * to_um_urad(uncertainty.common_u[:, 6:12])[0]
    fig = pose_figure(result, uncertainty, 2.0)
    for j, ax in enumerate(fig.axes[:6]):
        (band,) = [c for c in ax.collections if c.get_gid() == "common"]
        xs, ys = band.get_paths()[0].vertices.T
        assert xs.min() < 1.0 - 0.2 and xs.max() > 1.0 + 0.2, j  # wide enough to see
        assert ys.max() == pytest.approx(expected[j]) and ys.min() == pytest.approx(-expected[j])


# ------------------------------------------------------------------ a template is not a program


@pytest.mark.parametrize(
    "expression",
    [
        "''.__class__.__mro__[1].__subclasses__()",
        "asset.__globals__",
        "header_rows.__class__.__init__.__globals__",
    ],
)
def test_a_template_cannot_reach_python_internals(tmp_path, expression):
    # the lab's templates are data: a folder passed around between labs must not run code
    folder = templates(tmp_path / "t", {"closing.html.j2": "<p>\n{{ " + expression + " }}</p>\n"})
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'closing.html.j2'}:2: template: "), line
    assert "unsafe" in line, line


def test_a_mistake_that_fails_inside_hexatherms_macro_names_the_labs_line(tmp_path):
    # the lab calls hexatherm's table macro with a text: it fails in macros.html.j2,
    # a file the lab did not write; the line to fix is the lab's
    text = '{% import "macros.html.j2" as m %}\n<p>x</p>\n{{ m.table(title) }}\n'
    folder = templates(tmp_path / "t", {"closing.html.j2": text})
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'closing.html.j2'}:3: template: "), line
    assert "has no attribute 'css'" in line and "hexatherm's macros.html.j2:" in line, line


def test_a_template_or_image_in_a_sub_folder_is_listed_in_the_provenance(tmp_path):
    # the page is made from them: a signed report names every file it came from (the
    # files of sub-folders its templates name: a folder's other files are not read)
    folder = templates(
        tmp_path / "t",
        {
            "closing.html.j2": '{% include "parts/words.html.j2" %}\n',
            "letterhead.html.j2": "<img src=\"{{ asset('img/logo.svg') }}\">\n",
        },
    )
    templates(folder / "parts", {"words.html.j2": "<p>Not to be reproduced.</p>\n"})
    templates(folder / "img", {"logo.svg": "<svg>EML</svg>"})
    templates(folder / ".git", {"HEAD": "ref: refs/heads/main\n"})  # a lab's own history
    templates(folder / "archive", {"old.html.j2": "<p>2019</p>\n"})  # not named: not read
    out = tmp_path / "report.html"
    session = session_copy(tmp_path / "s")  # report processes it first: its results/
    result = CliRunner().invoke(
        main, ["report", str(session), "--template-dir", str(folder), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    page = out.read_text(encoding="utf-8")
    assert "Not to be reproduced." in page
    files = page.split("Input files, relative to", 1)[1].split("</tbody>", 1)[0]
    rows = dict(
        (path, sha)
        for path, sha in re.findall(r"<tr><td[^>]*>([^<]*)</td>.*?<td[^>]*>([0-9a-f]{64})<", files)
    )
    for name in ("closing.html.j2", "letterhead.html.j2", "parts/words.html.j2", "img/logo.svg"):
        shown = os.path.relpath(folder / name, session)  # relative to the session (issue 33)
        assert rows[shown] == hashlib.sha256((folder / name).read_bytes()).hexdigest()
    assert not any(".git" in path or "archive" in path for path in rows)


# ------------------------------------------------------------------ provenance


def test_the_command_line_in_the_provenance_runs_as_printed(tmp_path):
    # a folder with a space (and a quote) in its name: printed joined by spaces, the
    # command line named two arguments where there was one
    import html
    import shlex

    session = session_copy(tmp_path / "Sessions 2026 'Zürich'")
    out = tmp_path / "the report.html"
    processed = CliRunner().invoke(main, ["process", str(session), "--tolerance", "Tx=2um"])
    assert processed.exit_code == 0, processed.output
    args = ["report", str(session), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    page = out.read_text(encoding="utf-8")
    row = re.search(r"<tr><td>command line[^<]*</td><td>([^<]*)</td>", page)
    assert row is not None
    # paths relative to the session folder (no path of the lab's computer, issue 33): it
    # runs as printed from there, each path still one argument
    relative = ["report", ".", "-o", os.path.relpath(out, session)]
    assert shlex.split(html.unescape(row.group(1))) == ["hexatherm", *relative]
    assert (session / relative[3]).resolve() == out.resolve()


# ------------------------------------------------------------------ -o


@pytest.mark.parametrize(("given", "why"), [("new/", "a folder"), ("", "empty")])
def test_an_output_that_is_no_file_name_is_a_usage_error(tmp_path, monkeypatch, given, why):
    # "-o new/" wrote a file named "new"; "-o ''" was refused as "-o ." (the current folder)
    monkeypatch.chdir(tmp_path)
    session = session_copy(tmp_path)
    before = hashes(tmp_path)
    result = CliRunner().invoke(main, ["report", str(session), "-o", given])
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit)
    assert "'-o'" in result.output and why in result.output, result.output
    assert hashes(tmp_path) == before and sorted(p.name for p in tmp_path.iterdir()) == [
        "paper-zero-pose"
    ]


@pytest.mark.parametrize(
    "text",
    ["{{ text|safe }}", "{% filter safe %}{{ text }}{% endfilter %}"],
)
def test_a_template_cannot_print_the_data_as_markup(tmp_path, text):
    # '|safe' let a session's "<script>" into the page through a lab's letterhead
    letterhead = (
        "<div>\n{% for name, text in header_rows %}<span>" + text + "</span>{% endfor %}</div>\n"
    )
    folder = templates(tmp_path / "t", {"letterhead.html.j2": letterhead})
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'letterhead.html.j2'}:2: template: "), line
    assert "safe" in line, line


# ------------------------------------------------------------------ a user's text in a figure


@pytest.mark.parametrize(
    "column", ["$\\notacommand{$ probe", "$x^2$ air", "_spare", "cost $5 and $6"]
)
def test_a_temperature_columns_name_is_printed_in_the_legend_as_it_is(tmp_path, column):
    # matplotlib reads "$...$" as mathematics (a traceback, or x² for "$x^2$") and hides
    # a label that starts with "_": the legend must name the column as the file does
    from hexatherm.workflows.process.pipeline import Checks, process_session
    from hexatherm.workflows.report import temperature_figure

    session = session_copy(tmp_path)
    lines = (session / "temperatures.csv").read_text(encoding="utf-8").splitlines()
    lines = [lines[0] + "," + column] + [line + ",20.5" for line in lines[1:]]
    (session / "temperatures.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    out = tmp_path / "report.html"
    result = CliRunner().invoke(main, ["report", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output
    fig = temperature_figure(process_session(session, "linear", None, Checks()))
    fig.canvas.draw()
    legend = fig.axes[0].get_legend()
    shown = {t.get_text(): t for t in legend.get_texts()}
    assert "air" in shown and len(shown) == 8
    (text,) = [t for t in legend.get_texts() if t.get_text() not in {"air"}][6:]
    # what a reader sees: the name's characters, no mathematics
    from matplotlib import cbook

    renderer = fig.canvas.get_renderer()
    assert not cbook.is_math_text(text.get_text())
    assert text.get_text().replace("\\$", "$") == column
    assert text.get_window_extent(renderer).width > 0


def test_only_a_run_no_browser_breaks_may_break_anywhere():
    # a path that breaks at its hyphens keeps its cell (and its print) as before; one
    # without a space or hyphen over 24 characters may break anywhere
    from hexatherm.workflows.report import table

    cells = [
        "/srv/hexapod-lab/lab-templates/logo.svg",
        "/home/jdoe/labdata/sessions/campaign2026/centres.csv",
        "S1" + "X" * 60,
        "S10",
    ]
    t = table([[("file", 1)]], [[c] for c in cells], numeric_from=9)
    assert [cs[0].css for _, cs in t.body()] == ["", "long", "long", ""]
    meta = table([[("file", 1)]], [[c] for c in cells], numeric_from=9, css="meta")
    assert {cs[0].css for _, cs in meta.body()} == {""}  # meta tables wrap anyway


def test_a_long_path_in_the_provenance_does_not_shrink_the_printed_page(tmp_path):
    # a lab file in a folder whose path has no hyphen: listed whole in the provenance,
    # wider than its column, it made Chromium shrink every page
    from tests.workflows.test_report_browser import A4_PT, PAGE, WORD, browser, print_pdf

    if browser() is None:
        pytest.skip("no Chromium (apt-get install -y chromium poppler-utils)")
    deep = tmp_path / "labdata" / "qualitymanagement" / "templatesandforms" / "hexapodlab2026"
    deep.mkdir(parents=True)
    (deep / "laboratoryfile.yaml").write_text(
        "format: hexatherm-lab/1\nlab: Example Lab\n", encoding="utf-8"
    )
    out = tmp_path / "report.html"
    session = session_copy(tmp_path / "s")  # report processes it first: its results/
    args = ["report", str(session), "--lab", str(deep / "laboratoryfile.yaml"), "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    pages = PAGE.findall(print_pdf(out, tmp_path / "report.pdf"))
    title = max(
        (float(y1) - float(y0), w) for _, _, b in pages[:1] for _, y0, _, y1, w in WORD.findall(b)
    )
    assert title[0] >= 0.97 * 1.164 * 14.25, title  # the title's 14.25 pt, not shrunk
    for width, height, _ in pages:
        assert (float(width), float(height)) == pytest.approx(A4_PT, abs=1.0)


@pytest.mark.parametrize(
    "target",
    ["centres.csv", "session.yaml", "plan.yaml", "temperatures.csv", "lab.yaml", "t/logo.svg"],
)
def test_report_onto_an_input_is_refused_whatever_the_overwrite(tmp_path, target):
    # (found fine: kept as a guard) every file the page is made from, the lab's too
    session = session_copy(tmp_path)
    closing = "<p>closing <img src=\"{{ asset('logo.svg') }}\"></p>\n"
    folder = templates(session / "t", {"closing.html.j2": closing})
    (folder / "logo.svg").write_text("<svg/>", encoding="utf-8")
    (session / "lab.yaml").write_text("format: hexatherm-lab/1\nlab: L\n", encoding="utf-8")
    before = hashes(session)
    out = session / target
    for extra in ([], ["--overwrite"]):
        args = ["report", str(session), "--lab", str(session / "lab.yaml")]
        args += ["--template-dir", str(folder), "-o", str(out), *extra]
        line = refusal(CliRunner().invoke(main, args))
        assert "the output is the input" in line, line
    assert hashes(session) == before and not (session / ".hexatherm-manifest.json").exists()


@pytest.mark.parametrize("target", ["/proc/self/mem", "/proc/self/environ"])
def test_a_file_of_the_template_folder_that_cannot_be_read_is_one_line(tmp_path, target):
    # /proc/self/mem reads as an I/O error (as an unreadable file or a failing share
    # does; root reads any mode), /proc/self/environ as the process's environment; a
    # template linked to either is a link out of the folder, refused before it is read
    # (issue 36 item 6); a file nothing reads is not read (item 7:
    # tests/cli/test_audit_round3.py)
    if not Path(target).is_file():
        pytest.skip(f"no {target}")
    folder = templates(tmp_path / "t", {"letterhead.html.j2": "<div>{{ title }}</div>\n"})
    (folder / "closing.html.j2").symlink_to(target)
    line = report_refused(tmp_path, folder)
    assert line.startswith(f"Error: {folder / 'closing.html.j2'}: "), line
    assert "a link out of the template folder" in line, line


def test_diagnoses_page_lists_the_labs_templates_and_the_hexapod_file_it_was_made_from(
    tmp_path,
):
    # its provenance.json did; the page (what a reader signs) listed the session's alone
    session = session_copy(tmp_path, "with-hidden-effect")
    folder = templates(tmp_path / "t", {"closing.html.j2": "<p>Not to be reproduced.</p>\n"})
    model = tmp_path / "model" / "hexapod.yaml"
    model.parent.mkdir()
    shutil.copy(session / "hexapod.yaml", model)
    out = tmp_path / "diag"
    args = ["diagnose", str(session), "--template-dir", str(folder), "--hexapod", str(model)]
    result = CliRunner().invoke(main, [*args, "-o", str(out)])
    assert result.exit_code == 0, result.output
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "Not to be reproduced." in page
    files = page.split("Input files, relative to", 1)[1].split("</tbody>", 1)[0]
    rows = dict(re.findall(r"<tr><td[^>]*>([^<]*)</td>.*?<td[^>]*>([0-9a-f]{64})<", files))
    for path in (folder / "closing.html.j2", model, session / "centres.csv"):
        shown = os.path.relpath(path, session)  # relative to the session (issue 33)
        assert rows[shown] == hashlib.sha256(path.read_bytes()).hexdigest(), shown
