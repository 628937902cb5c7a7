"""report.md, the tables and the figures of ``hexatherm diagnose``.

(hexatherm.workflows.diagnose.report)

One small simulated campaign with a hidden leg thermal lag is diagnosed once for
the module; the figures' data are compared with the residual arrays and the
session's own times and temperatures, the tables with numbers computed here.
"""

from __future__ import annotations

import base64
import dataclasses
import hashlib
import io
import re
from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.effects import make_effect
from hexatherm.workflows.diagnose import report as dr
from hexatherm.workflows.diagnose.run import DiagnosisResult, read_for_diagnosis, run_diagnosis
from hexatherm.workflows.simulate.campaigns import diagnosis_campaign

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> DiagnosisResult:
    from hexatherm.workflows.simulate.twinsession import write_twin_session

    folder = tmp_path_factory.mktemp("diag") / "session"
    spec = diagnosis_campaign(
        [make_effect("leg_thermal_lag", {"tau_s": 1500.0})], seed=1, n_targets=6
    )
    write_twin_session(spec, folder)
    return run_diagnosis(read_for_diagnosis(folder))


@pytest.fixture(scope="module")
def written(result: DiagnosisResult, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("out")
    return dr.write_report_files(result, out, dpi=50)  # small: fast


#: the page's figures, by FIGURE_FILES key, and what makes each
BUILDERS = (
    ("pose_time", dr.pose_time_figure),
    ("legs_time", dr.legs_time_figure),
    ("centre_rms", dr.centre_rms_figure),
    ("temperature", dr.temperature_figure),
)


@pytest.fixture(scope="module")
def built(result: DiagnosisResult) -> dict:
    """Each figure built afresh once (not the ones written): the tests read their data
    and draw them, neither changes them."""
    return {key: build(result) for key, build in BUILDERS}


def _hours(result: DiagnosisResult) -> tuple[np.ndarray, np.ndarray]:
    obs = result.data.observations
    order = np.argsort(obs.times_s, kind="stable")
    start = min(obs.log.t0_s, obs.times_s.min())
    return order, (obs.times_s[order] - start) / 3600.0


def _line(ax: object, label: str) -> object:
    lines = [ln for ln in ax.get_lines() if ln.get_label() == label]  # type: ignore[attr-defined]
    assert len(lines) == 1, [ln.get_label() for ln in ax.get_lines()]  # type: ignore[attr-defined]
    return lines[0]


# ------------------------------------------------------------------ report.md
def test_report_tells_the_story(result: DiagnosisResult, written: list[Path]) -> None:
    text = written[0].read_text(encoding="utf-8")
    assert written[0].name == "report.md"
    added = result.diagnosis.added
    assert [a.effect.name for a in added] == ["leg_thermal_lag"]
    tau = added[0].effect.values["tau_s"]
    se = added[0].std_errors["tau_s"]
    assert abs(tau - 1500.0) < 150.0
    assert f"{tau:.0f} ± {se:.0f} s" in text
    assert f"{added[0].delta_bic:.1f}" in text
    d = result.diagnosis
    for value in (
        d.baseline_rms_um,
        d.final_rms_um,
        d.baseline_heldout_rms_um,
        d.final_heldout_rms_um,
    ):
        assert f"{value:.2f}" in text
    headline = text.split("## Session")[0]
    assert "leg_thermal_lag" in headline and f"{tau:.0f}" in headline


def test_report_lists_every_candidate_of_every_round(
    result: DiagnosisResult, written: list[Path]
) -> None:
    text = written[0].read_text(encoding="utf-8")
    section = text.split("## Candidates")[1].split("## Where")[0]
    rounds = section.split("### Round ")[1:]
    assert len(rounds) == len(result.diagnosis.rounds) >= 2
    for block, candidates in zip(rounds, result.diagnosis.rounds, strict=True):
        rows = [ln for ln in block.splitlines() if ln.startswith("| ") and "candidate" not in ln]
        assert [r.split("|")[1].strip() for r in rows] == [c.name for c in candidates]
        for row, c in zip(rows, candidates, strict=True):
            cells = [x.strip() for x in row.split("|")[1:-1]]
            assert cells[2] == f"{c.delta_bic:.1f}"
            assert cells[4] == f"{c.heldout_rms_um:.2f}"
            assert cells[5].startswith("yes") == c.passes
    assert "yes, added" in rounds[0]
    assert "Flagged alternatives" in text


def test_report_links_pngs_that_exist(written: list[Path]) -> None:
    from matplotlib.image import imread

    text = written[0].read_text(encoding="utf-8")
    links = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert sorted(links) == sorted(dr.FIGURE_FILES.values())
    folder = written[0].parent
    assert sorted(p.name for p in written[1:-1]) == sorted(links)
    assert written[-1].name == "report.html"
    for link in links:
        path = folder / link
        assert not Path(link).is_absolute() and path.is_file()
        assert path.read_bytes()[:8] == PNG_SIGNATURE
        image = imread(path)
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 400


def test_report_html_is_the_same_story_with_the_figures_embedded(
    result: DiagnosisResult, written: list[Path]
) -> None:
    page = written[-1].read_text(encoding="utf-8")
    text = written[0].read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert not re.search(r'(src|href)="(?!data:)', page)  # self-contained
    # every figure: the very PNG written beside it
    embedded = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    pngs = [p.read_bytes() for p in written[1:-1]]
    assert sorted(base64.b64decode(d) for d in embedded) == sorted(pngs)
    # every table of report.md (a header line followed by its alignment line), plus the
    # provenance block's two and the running header's (the page every report shares)
    md_tables = len(re.findall(r"^\|.*\|\n\|[:-]", text, flags=re.M))
    assert md_tables >= 5 and page.count("<table") == md_tables + 3
    assert page.count('<table class="running">') == 1
    # the story's numbers, in µm
    added = result.diagnosis.added[0]
    tau, se = added.effect.values["tau_s"], added.std_errors["tau_s"]
    assert f"{tau:.0f} ± {se:.0f} s" in page and f"{added.delta_bic:.1f}" in page
    assert "µm" in page and not re.search(r"\b(um|urad)\b", re.sub(r"<[^>]+>", "", page))
    # its provenance: the session's files, hashed here
    session = result.data.session
    for path in session.input_files():
        digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        assert f'<td class="num">{digest}</td>' in page, path
    assert "not run from the command line" in page


# -------------------------------------------------------------------- figures
def test_written_figures_have_the_pixels_of_a_plain_savefig(
    built: dict, written: list[Path]
) -> None:
    # the PNG written (figure_png: RGB, a faster zlib level) and a plain savefig of the
    # same figure built afresh decode to the same pixels: the same colours, and savefig's
    # alpha, the one channel left out, opaque everywhere
    from PIL import Image

    folder = written[0].parent
    # (the legs' figure is written from the pose's, its lines refilled: report_pngs)
    for key, _ in BUILDERS:
        plain = io.BytesIO()
        built[key].savefig(plain, format="png", dpi=50)  # the fixture's dpi
        with (
            Image.open(folder / dr.FIGURE_FILES[key]) as fast,
            Image.open(plain) as slow,
        ):
            assert fast.size == slow.size and (fast.mode, slow.mode) == ("RGB", "RGBA")
            slow_pixels = np.asarray(slow)
            np.testing.assert_array_equal(np.asarray(fast), slow_pixels[..., :3])
            assert (slow_pixels[..., 3] == 255).all()


def test_pose_and_leg_figures_hold_the_residuals(result: DiagnosisResult, built: dict) -> None:
    order, hours = _hours(result)
    for fig, attr in (
        (built["pose_time"], "pose_um"),
        (built["legs_time"], "legs_um"),
    ):
        axes = np.array(fig.axes).reshape(6, 2)
        for c, (state, res) in enumerate((("before", result.before), ("after", result.after))):
            values = getattr(res, attr)
            for j in range(6):
                line = _line(axes[j, c], state)
                np.testing.assert_allclose(line.get_xdata(), hours)
                np.testing.assert_allclose(line.get_ydata(), values[order, j])


def test_centre_and_temperature_figures(result: DiagnosisResult, built: dict) -> None:
    order, hours = _hours(result)
    obs = result.data.observations
    fig = built["centre_rms"]
    ax, temp_ax = fig.axes
    for label, fit in (("before", result.diagnosis.baseline), ("after", result.diagnosis.final)):
        line = [ln for ln in ax.get_lines() if ln.get_label().startswith(label + ":")][0]
        step_rms = np.sqrt(np.mean(fit.residual_mm**2, axis=(1, 2))) * 1e3
        np.testing.assert_allclose(line.get_ydata(), step_rms[order])
        np.testing.assert_allclose(line.get_xdata(), hours)
    mean_temp = np.array(
        [
            np.mean([np.interp(t, obs.log.times_s, obs.log.legs_C[:, i]) for i in range(6)])
            for t in obs.times_s[order]
        ]
    )
    np.testing.assert_allclose(_line(temp_ax, "mean leg temperature").get_ydata(), mean_temp)

    fig = built["temperature"]
    assert len(fig.axes) == 6
    for j, ax in enumerate(fig.axes):
        for state, res in (("before", result.before), ("after", result.after)):
            line = _line(ax, state)
            np.testing.assert_allclose(line.get_xdata(), mean_temp)
            np.testing.assert_allclose(line.get_ydata(), res.pose_um[order, j])


# --------------------------------------------------------------------- tables
def _rows(text: str, title_start: str) -> dict[str, list[str]]:
    block = text.split(title_start)[1].split("\n\n")[0].splitlines()[3:]
    return {ln.split()[0]: ln.split()[1:] for ln in block}


def test_terminal_tables_before_and_after(result: DiagnosisResult) -> None:
    text = dr.terminal_tables(result)
    comp = _rows(text, "Pose residuals by component")
    for j, name in enumerate(("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")):
        before = np.sqrt(np.mean(result.before.pose_um[:, j] ** 2))
        after = np.sqrt(np.mean(result.after.pose_um[:, j] ** 2))
        assert comp[name][1:3] == [f"{before:.2f}", f"{after:.2f}"]
    legs = _rows(text, "Leg-space residuals")
    for j in range(6):
        before = np.sqrt(np.mean(result.before.legs_um[:, j] ** 2))
        assert legs[f"leg{j + 1}"][0] == f"{before:.2f}"
    kinds = _rows(text, "Centre residuals by step kind")
    assert kinds["all"][1:] == [
        f"{result.diagnosis.baseline_rms_um:.2f}",
        f"{result.diagnosis.final_rms_um:.2f}",
    ]
    plan_kinds = np.array(result.data.observations.plan.kinds)
    assert kinds["reference"][0] == str(int(np.sum(plan_kinds == "reference")))
    worst = _rows(text, "Worst steps before")
    top = int(np.argmax(result.before.centre_rms_um))
    assert worst["1"][0] == result.data.observations.plan.labels[top]
    assert "Whiteness and trend before" in text and "Whiteness and trend after" in text
    # the headers carry the units; each table's rule is as wide as its header
    for block in text.strip().split("\n\n"):
        lines = block.splitlines()
        assert len(lines[2]) == max(len(ln) for ln in lines[1:])
    assert "RMS before (um)" in text


def test_the_lag_is_what_made_the_residuals_structured(result: DiagnosisResult) -> None:
    before, after = dr.summaries(result)
    white_before = sum(t.whiteness.white() for t in before.leg_tests)
    white_after = sum(t.whiteness.white() for t in after.leg_tests)
    assert white_before <= 2 and white_after >= 5


def test_nothing_added(result: DiagnosisResult, tmp_path: Path) -> None:
    d = result.diagnosis
    nothing = dataclasses.replace(
        result,
        after=result.before,
        diagnosis=dataclasses.replace(
            d,
            final=d.baseline,
            added=(),
            rounds=d.rounds[:1],
            final_heldout_rms_um=d.baseline_heldout_rms_um,
        ),
    )
    text = dr.report_markdown(nothing, {"pose_time": "p.png"})
    assert "Nothing added" in text and "RMS after" not in text
    assert re.findall(r"\]\(([^)]+)\)", text) == ["p.png"]
    fig = dr.pose_time_figure(nothing)
    assert len(fig.axes) == 6
    np.testing.assert_allclose(
        _line(fig.axes[2], "before").get_ydata(), result.before.pose_um[_hours(result)[0], 2]
    )
    assert "after" not in dr.terminal_tables(nothing, tests=False)


def test_the_candidates_table_lines_up_with_long_effect_names() -> None:
    from hexatherm.core.diagnosis.model import Candidate
    from hexatherm.workflows.diagnose.outputs import candidates_table

    rows = [
        Candidate("ball_plate_expansion", None, -6.6, 6.089, 6.101, False, "a note"),
        Candidate("leg_offset", None, 4248.2, 0.341, 0.353, True),
    ]
    lines = candidates_table(tuple(rows)).splitlines()
    # every column ends where the header's does, whatever the names' lengths
    expected = {
        "dBIC": ["4248.2", "-6.6"],
        "RMS_um": ["0.341", "6.089"],
        "heldout_um": ["0.353", "6.101"],
    }
    for title, values in expected.items():
        end = lines[0].index(title) + len(title)
        assert [line[:end].split()[-1] for line in lines[1:]] == values, title
        assert all(line[end] == " " for line in lines[1:]), title


# ------------------------------------------------------------------ hostile names
# Issue 22, "Also": report.md copied the session's name raw into Markdown (``<script>``,
# ``</table>``: HTML for any Markdown viewer). Checked with an independent CommonMark
# parser (markdown-it-py): no raw HTML, and the text read back is the name as it is.
HOSTILE = "x <script>alert(1)</script></table> | **b** `c` _d_ [e](f) &amp; ~g~ \\ #"


def _hostile(result: DiagnosisResult, path: Path | None = None) -> DiagnosisResult:
    data = result.data
    session = dataclasses.replace(data.session, name=HOSTILE, path=path or data.session.path)
    hexapod = dataclasses.replace(data.hexapod, name=HOSTILE)
    data = dataclasses.replace(data, session=session, hexapod=hexapod, hexapod_source=HOSTILE)
    return dataclasses.replace(result, data=data)


def _commonmark_text(inline: object) -> str:
    """The text a CommonMark viewer shows for an inline token; raw HTML refused."""
    out = []
    for child in inline.children:  # type: ignore[attr-defined]
        assert child.type not in ("html_inline", "html_block"), child
        if child.type in ("text", "code_inline"):
            out.append(child.content)
        elif child.type == "softbreak":
            out.append("\n")
    return "".join(out)


def test_report_md_escapes_the_sessions_name_path_and_hexapod(
    result: DiagnosisResult, tmp_path: Path
) -> None:
    from markdown_it import MarkdownIt

    path = tmp_path / "a`b <i>c</i>" / "session.yaml"
    md = dr.report_markdown(_hostile(result, path))
    tokens = MarkdownIt("commonmark").enable("table").parse(md)
    assert not [t for t in tokens if t.type == "html_block"]
    texts = [_commonmark_text(t) for t in tokens if t.type == "inline"]
    assert texts[0] == f"Diagnosis of {HOSTILE}"
    assert f"session: {path}" in texts
    assert f"hexapod: {HOSTILE} ({HOSTILE})" in texts
    heading = [t.tag for t in tokens if t.type == "heading_open"]
    assert heading.count("h1") == 1  # the name did not make or end a heading


def test_report_html_escapes_them_too(result: DiagnosisResult) -> None:
    import html

    page = dr.report_html(_hostile(result), {}, generated="2026-01-01T00:00:00+00:00")
    assert "<script>" not in page and page.count("</table>") == page.count("<table")
    title = html.escape(f"Diagnosis of {HOSTILE}", quote=True)
    assert f"<title>{title}</title>" in page and f"<h1>{title}</h1>" in page
    item = next(li for li in page.split("<li>") if li.startswith("hexapod: "))
    shown = html.unescape(re.sub(r"<[^>]+>", "", item))
    assert shown.strip() == f"hexapod: {HOSTILE} ({HOSTILE})"


def test_a_table_cell_is_text_too() -> None:
    """A step label or ball name in a table: no HTML, no cell boundary, as it is."""
    from markdown_it import MarkdownIt

    cell = "S1 <script>x</script> | `y` *z* & \\"
    md = dr.render_markdown(dr.Table("T", ("label",), ((cell,),), "l"))
    tokens = MarkdownIt("commonmark").enable("table").parse(md)
    cells = [_commonmark_text(t) for t in tokens if t.type == "inline"][1:]
    assert cells == ["label", cell]
    html = dr.markdown_html(md, {})[-1]
    assert "<script>" not in html and "&lt;script&gt;x&lt;/script&gt; | `y` *z* &amp; \\" in html


def test_report_html_writes_units_in_its_own_text_only(result: DiagnosisResult) -> None:
    # "um" is German for "at" and a folder's name: the page turned a user's "um", "urad",
    # "degC" into µm, µrad, °C, printing a path or a hexapod's name that is not theirs
    import html

    user = "Messung um 10 Uhr (urad, degC)"
    path = Path("/data/um/urad") / "session.yaml"
    data = result.data
    session = dataclasses.replace(data.session, name=user, path=path)
    hexapod = dataclasses.replace(data.hexapod, name=user)
    data = dataclasses.replace(data, session=session, hexapod=hexapod, hexapod_source=user)
    page = dr.report_html(dataclasses.replace(result, data=data), {}, generated="2026-01-01")
    text = html.unescape(re.sub(r"<[^>]+>", "", page))
    assert f"session: {path}" in text
    assert f"hexapod: {user} ({user})" in text
    # hexatherm's own text keeps its units as a reader writes them
    assert "RMS (µm)" in text and "RMS (um)" not in text
