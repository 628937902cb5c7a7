"""The HTML report: embedded figures, and figures that plot the session's numbers.

The plotted values are compared with the shipped ``expected/`` tables and the raw
``temperatures.csv`` (read here with pandas), not with the report's own helpers.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm import __version__
from hexatherm.io.csvout import RESOLUTION
from hexatherm.session import QualityLimits
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.quality import quality_checks
from hexatherm.workflows.process.uncertainty import pose_uncertainty
from hexatherm.workflows.report import (
    FIGURE_DPI,
    build_report,
    figure_png,
    growth_figure,
    pose_figure,
    registration_figure,
    report_html,
    temperature_figure,
)
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSIONS = SHIPPED
IMG = re.compile(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"')
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
URAD_PER_DEG = np.pi / 180 * 1e6
NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


@pytest.fixture(scope="module")
def paper():
    return process_session(SESSIONS / "paper-zero-pose")


@pytest.fixture(scope="module")
def hidden():
    return process_session(SESSIONS / "with-hidden-effect")


def expected(session: str, name: str) -> pd.DataFrame:
    return pd.read_csv(SESSIONS / session / "expected" / name)


def expected_deviations(poses: pd.DataFrame, tag: str) -> np.ndarray:
    """``tag`` pose minus commanded pose, um and urad, from the poses.csv columns."""
    cols = []
    for name in NAMES:
        unit, scale = ("mm", 1e3) if name[0] == "T" else ("deg", URAD_PER_DEG)
        cols.append((poses[f"{name}_{tag}_{unit}"] - poses[f"{name}_cmd_{unit}"]) * scale)
    return np.column_stack(cols)


def labelled_lines(ax, prefix: str) -> dict:
    return {line.get_label(): line for line in ax.lines if line.get_label().startswith(prefix)}


def test_report_embeds_every_figure_as_a_png(hidden):
    page = build_report(hidden)
    images = IMG.findall(page)
    assert len(images) == 4  # poses, temperatures, growth, registration
    for data in images:
        png = base64.b64decode(data, validate=True)
        assert png.startswith(PNG_SIGNATURE)
        width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
        assert width > 500 and height > 300
    # self-contained: no external resource
    assert not re.search(r'(src|href)="(?!data:)', page)
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    # metadata
    for text in (
        "with-hidden-effect",
        "centres.csv",
        "temperatures.csv",
        "symetrie-like",
        "82: 1 origin, 41 references, 40 targets",
        "linear",
        __version__,
        "leg1, leg2, leg3, leg4, leg5, leg6, air",
    ):
        assert text in page, text
    # every target in the poses table, with its uncertainty; the quality table
    for label in ("S1", "S20", "S40"):
        assert f"<td>{label}</td>" in page
    # a value and its expanded uncertainty (k = 2 by default) in every deviation cell of
    # the conventional and the corrected tables
    assert len(re.findall(r'\d<span class="u">±\xa0\d', page)) == 40 * 12
    assert "expanded uncertainty U (k = 2)" in page
    assert "Uncertainty: linear propagation (GUM)" in page
    assert "<th>registration RMS (µm)</th>" in page and "<td>R40</td>" in page
    assert "not available" not in page
    # units as a reader writes them, not as the files' column names
    assert "µrad" in page and "°C" in page
    assert not re.search(r"\((um|urad|degC)\)", page)


def _pixels(png: bytes) -> np.ndarray:
    from PIL import Image  # matplotlib's own PNG codec

    with Image.open(io.BytesIO(png)) as image:
        return np.asarray(image)


def _zlib_level_class(png: bytes) -> int:
    """FLEVEL of the zlib stream of the PNG's first IDAT chunk (RFC 1950): 0 for zlib levels
    0-1, 1 for 2-5, 2 for the default (6), 3 for 7-9."""
    data = png.index(b"IDAT") + 4
    return png[data + 1] >> 6


def test_figure_png_has_the_pixels_of_a_plain_savefig(hidden):
    # figure_png writes RGB at a faster zlib level than savefig's RGBA at its default:
    # other bytes, the same pixels (each figure drawn fresh): the same colours, and
    # savefig's alpha, the channel left out, opaque everywhere
    png = figure_png(pose_figure(hidden))
    plain = io.BytesIO()
    pose_figure(hidden).savefig(plain, format="png", dpi=FIGURE_DPI)
    fast_pixels, plain_pixels = _pixels(png), _pixels(plain.getvalue())
    assert fast_pixels.shape == (round(6.2 * FIGURE_DPI), round(9.5 * FIGURE_DPI), 3)
    np.testing.assert_array_equal(fast_pixels, plain_pixels[..., :3])
    assert (plain_pixels[..., 3] == 255).all()
    assert (_zlib_level_class(png), _zlib_level_class(plain.getvalue())) == (1, 2)


def test_figure_png_keeps_the_alpha_of_a_see_through_figure():
    # a figure whose face lets the background through is written RGBA, its alpha kept
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    def made() -> Figure:
        fig = Figure(figsize=(2.0, 1.0))
        FigureCanvasAgg(fig)
        fig.patch.set_alpha(0.0)
        fig.subplots().plot([0.0, 1.0], [1.0, 0.0])
        return fig

    plain = io.BytesIO()
    made().savefig(plain, format="png", dpi=50)
    fast_pixels, plain_pixels = _pixels(figure_png(made(), 50)), _pixels(plain.getvalue())
    assert fast_pixels.shape == (50, 100, 4) and plain_pixels[..., 3].min() == 0
    np.testing.assert_array_equal(fast_pixels, plain_pixels)


def test_pose_figure_plots_every_trial_conventional_and_corrected(paper):
    poses = expected("paper-zero-pose", "poses.csv")
    conventional = expected_deviations(poses, "conv")
    corrected = expected_deviations(poses, "corr")
    fig = pose_figure(paper)
    assert len(fig.axes) == 6
    for j, ax in enumerate(fig.axes):
        assert ax.get_title() == f"{NAMES[j]} ({'µm' if j < 3 else 'µrad'})"
        containers = {c.get_label(): c for c in ax.containers}
        assert set(containers) == {"conventional", "corrected"}
        for name, values in (("conventional", conventional), ("corrected", corrected)):
            x, y = containers[name].lines[0].get_data()
            assert len(y) == len(poses) == 10
            np.testing.assert_allclose(np.round(x), np.arange(1, 11))
            # poses.csv holds the pose and the commanded pose each to half a step
            step = 1e3 * RESOLUTION["mm"] if j < 3 else URAD_PER_DEG * RESOLUTION["deg"]
            np.testing.assert_allclose(y, values[:, j], atol=step * 1.001, rtol=0)
            assert not containers[name].has_yerr
    # the thermal drift is there and the correction takes it off (Tx, Tz)
    for j in (0, 2):
        assert np.ptp(conventional[:, j]) > 10 * np.ptp(corrected[:, j]) / 2


def test_pose_figure_error_bars_are_the_expanded_uncertainties(paper):
    u = pose_uncertainty(paper)
    assert np.all(u.corrected_u > 0)
    k = 2.5
    fig = pose_figure(paper, u, coverage_factor=k)
    assert "k = 2.5" in fig.get_suptitle()
    for j, ax in enumerate(fig.axes):
        scale = 1e3 if j < 3 else URAD_PER_DEG
        for c in ax.containers:
            u_mm_deg = u.conventional_u if c.get_label() == "conventional" else u.corrected_u
            segments = c.lines[2][0].get_segments()
            half = np.array([abs(s[1, 1] - s[0, 1]) / 2 for s in segments])
            np.testing.assert_allclose(half, k * u_mm_deg[:, j] * scale, rtol=1e-9)
            centre = np.array([(s[1, 1] + s[0, 1]) / 2 for s in segments])
            np.testing.assert_allclose(centre, c.lines[0].get_ydata(), atol=1e-9)


def test_temperature_figure_plots_the_log(hidden):
    log = pd.read_csv(SESSIONS / "with-hidden-effect" / "temperatures.csv")
    stamps = pd.to_datetime(log["time"]).dt.tz_localize("UTC")  # session: utc_offset "+00:00"
    # the log starts before the first step here, so the x origin is its first sample
    assert stamps[0] <= pd.to_datetime(expected("with-hidden-effect", "legs.csv")["time"]).min()
    hours = (stamps - stamps[0]).dt.total_seconds().to_numpy() / 3600
    ax = temperature_figure(hidden).axes[0]
    lines = labelled_lines(ax, "")
    assert set(lines) >= {f"leg {i}" for i in range(1, 7)} | {"air"}
    for name, column in [(f"leg {i}", f"leg{i}") for i in range(1, 7)] + [("air", "air")]:
        x, y = lines[name].get_data()
        assert len(x) == len(log) == 466
        np.testing.assert_allclose(x, hours, atol=1e-9)
        np.testing.assert_allclose(y, log[column])
    assert ax.get_xlim()[1] > 3.5  # a 3.9 h session


def test_no_leg_hides_another_in_the_temperature_figure(hidden):
    # legs 1 and 4 lie on each other in this log: each leg needs its own line style and
    # marker, and markers at its own samples, to be seen under another
    log = pd.read_csv(SESSIONS / "with-hidden-effect" / "temperatures.csv")
    assert np.max(np.abs(log["leg1"] - log["leg4"])) < 0.5
    lines = labelled_lines(temperature_figure(hidden).axes[0], "leg ")
    styles = {(str(line.get_linestyle()), str(line.get_marker())) for line in lines.values()}
    assert len(styles) == 6
    marked = []
    for line in lines.values():
        start, step = line.get_markevery()
        marked.append(set(range(start, len(line.get_xdata()), step)))
    assert all(not (a & b) for i, a in enumerate(marked) for b in marked[i + 1 :])
    assert all(len(m) >= 10 for m in marked)


def test_growth_figure_plots_the_growth_at_every_reference(paper):
    legs = expected("paper-zero-pose", "legs.csv")
    refs = legs[legs["kind"] == "reference"]
    ax = growth_figure(paper).axes[0]
    lines = labelled_lines(ax, "leg ")
    assert len(lines) == 6
    for leg in range(1, 7):
        x, y = lines[f"leg {leg}"].get_data()
        assert len(y) == len(refs) == 11
        assert np.all(np.diff(x) > 0)
        np.testing.assert_allclose(y, refs[f"dq_leg{leg}_um"], atol=RESOLUTION["um"] / 2 * 1.001)
    assert lines["leg 5"].get_ydata()[-1] > 20  # leg 5 is heated most


def test_registration_figure_plots_every_step(hidden):
    legs = expected("with-hidden-effect", "legs.csv")
    ax = registration_figure(hidden).axes[0]
    lines = {line.get_label(): line for line in ax.lines}
    assert set(lines) == {"origin", "reference", "target"}
    for kind, line in lines.items():
        rows = legs[legs["kind"] == kind]
        assert len(line.get_ydata()) == len(rows)
        np.testing.assert_allclose(
            line.get_ydata(), rows["registration_rms_um"], atol=RESOLUTION["um"] / 2 * 1.001
        )
    assert sum(len(line.get_ydata()) for line in lines.values()) == len(legs) == 82


def test_report_escapes_text_says_what_is_missing_and_flags_failures(paper):
    # one page for three things (a page takes ~1 s): no temperature log and no
    # uncertainty, text to escape, quality flags with failing rows
    legs = expected("paper-zero-pose", "legs.csv")
    limit_um = 0.5
    failing = legs.loc[legs["registration_rms_um"] > limit_um, "label"].tolist()
    assert 0 < len(failing) < len(legs)
    quality = quality_checks(
        paper, QualityLimits(registration_rms_um=limit_um, temperature_change_C=np.inf)
    )
    session = dataclasses.replace(paper.session, name='<script>alert("x")</script>&')
    result = dataclasses.replace(
        paper, session=session, temperatures=None, warnings=("step <S1>: too far",)
    )
    assert temperature_figure(result) is None
    page = report_html(result, quality=quality)
    assert len(IMG.findall(page)) == 3
    assert "no temperature log" in page and "uncertainty not available" in page
    assert "<script>" not in page
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;&amp;" in page
    assert "step &lt;S1&gt;: too far" in page
    assert "quality checks not available" not in page
    assert f"{len(failing)} step(s) failing a check" in page
    # the quality table's failing rows, marked; the verdict names them (not targets
    # only: the origin and references failing are listed apart)
    highlighted = re.findall(r'<tr class="fail"><td>([^<]*) \u2717</td><td>', page)
    assert highlighted == failing
    assert page.count('class="num bad"') == len(failing)
    assert "<td>registration RMS (µm)</td>" in page and "≤ 0.5" in page
    assert "uncertainty not available" in page and "Uncertainty:</b> not available" in page
