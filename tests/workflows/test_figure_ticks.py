"""The figures' ticks, for ``report``, ``calibrate`` and ``diagnose`` (issue 37, item 3).

Every numbered axis shows at least three ticks at nice steps (1, 2, 2.5 or 5 times a
power of ten), each labelled with its own value (the label read back as a number), and
its locator gives no tick outside the view (matplotlib makes a tick object for every
location given and draws those in the view only). The locator's ticks are MaxNLocator's
own, those in the view: compared over random ranges.
"""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from matplotlib.ticker import FixedLocator, MaxNLocator

from hexatherm.workflows.report.figures import (
    MIN_TICKS,
    TICK_INTERVALS,
    TICK_STEPS,
    WIDE_TICK_INTERVALS,
    in_view_locator,
)
from tests.shipped import SHIPPED


@pytest.mark.parametrize("nbins", [TICK_INTERVALS, WIDE_TICK_INTERVALS])
def test_the_ticks_are_maxnlocators_in_the_view(nbins: int) -> None:
    rng = np.random.default_rng(37)
    plain = MaxNLocator(nbins=nbins, steps=list(TICK_STEPS), min_n_ticks=MIN_TICKS)
    ours = in_view_locator(nbins)
    for _ in range(2000):
        scale = 10.0 ** rng.uniform(-6, 6)
        low = rng.uniform(-3, 3) * scale
        high = low + rng.uniform(1e-3, 5) * scale
        expected = [
            t
            for t in plain.tick_values(low, high)
            if low <= t <= high
            or math.isclose(t, low, rel_tol=1e-12, abs_tol=1e-12 * scale)
            or math.isclose(t, high, rel_tol=1e-12, abs_tol=1e-12 * scale)
        ]
        np.testing.assert_array_equal(ours.tick_values(low, high), expected)
        assert len(expected) >= MIN_TICKS


def _number(text: str) -> float:
    return float(text.replace("\u2212", "-"))


def _check_axis(axis: object, where: str) -> int:
    """The checks of the module's docstring on one drawn axis; its labelled ticks."""
    locs = np.asarray(axis.get_majorticklocs())  # type: ignore[attr-defined]
    low, high = sorted(axis.get_view_interval())  # type: ignore[attr-defined]
    slack = 1e-9 * max(high - low, abs(low), abs(high))
    assert ((locs >= low - slack) & (locs <= high + slack)).all(), (where, locs, low, high)
    assert len(locs) >= MIN_TICKS, (where, locs)
    steps = np.diff(locs)
    np.testing.assert_allclose(steps, steps[0], rtol=1e-9, err_msg=where)
    mantissa = steps[0] / 10.0 ** math.floor(math.log10(steps[0]) + 1e-12)
    assert any(math.isclose(mantissa, s) for s in (1.0, 2.0, 2.5, 5.0)), (where, steps)
    assert axis.major.formatter.get_offset() == "", where  # type: ignore[attr-defined]
    labelled = 0
    for tick, loc in zip(axis.get_major_ticks(len(locs)), locs, strict=True):  # type: ignore[attr-defined]
        # the label left or below (label1), or right or above (label2: a colour bar's)
        label = tick.label1 if tick.label1.get_visible() else tick.label2
        if label.get_visible() and label.get_text():
            assert math.isclose(_number(label.get_text()), loc, abs_tol=slack), where
            labelled += 1
    return labelled


def _check_figure(fig: object, name: str) -> int:
    """Draw ``fig`` and check every numbered axis; the axes checked."""
    fig.savefig(io.BytesIO(), format="rgba", dpi=40)  # type: ignore[attr-defined]
    checked = 0
    for k, ax in enumerate(fig.axes):  # type: ignore[attr-defined]
        for axis in (ax.xaxis, ax.yaxis):
            shown = axis.get_visible() and any(
                t.tick1line.get_visible() or t.tick2line.get_visible()
                for t in axis.get_major_ticks()
            )
            locator = axis.get_major_locator()
            if not shown or axis.get_scale() != "linear" or isinstance(locator, FixedLocator):
                continue  # hidden, logarithmic, or the targets' or parameters' names
            labelled = _check_axis(axis, f"{name}, axes {k}, {axis.axis_name}")
            # a shared axis is labelled on the outer panel only
            shared = ax.get_shared_x_axes() if axis.axis_name == "x" else ax.get_shared_y_axes()
            if len(shared.get_siblings(ax)) == 1:
                assert labelled >= MIN_TICKS, (name, k, axis.axis_name)
            checked += 1
    return checked


def test_diagnose_figures() -> None:
    import tempfile
    from pathlib import Path

    from hexatherm.core.effects import make_effect
    from hexatherm.workflows.diagnose.report import figures as dfig
    from hexatherm.workflows.diagnose.run import read_for_diagnosis, run_diagnosis
    from hexatherm.workflows.simulate.campaigns import diagnosis_campaign
    from hexatherm.workflows.simulate.twinsession import write_twin_session

    with tempfile.TemporaryDirectory() as tmp:
        spec = diagnosis_campaign(
            [make_effect("leg_thermal_lag", {"tau_s": 1500.0})], seed=1, n_targets=6
        )
        write_twin_session(spec, Path(tmp) / "s")
        result = run_diagnosis(read_for_diagnosis(Path(tmp) / "s"))
    figures = dfig.report_figures(result)
    # 12 + 12 panels of x and y, the centre figure's x, y and temperature, 6 panels
    counts = {key: _check_figure(fig, key) for key, fig in figures.items()}
    assert counts == {"pose_time": 24, "legs_time": 24, "centre_rms": 3, "temperature": 12}


def test_report_figures() -> None:
    from hexatherm.workflows.process.pipeline import process_session
    from hexatherm.workflows.report import figures as rfig

    result = process_session(SHIPPED / "with-hidden-effect")
    pose = rfig.pose_figure(result)
    assert _check_figure(pose, "pose") == 6  # y of the 6 panels; x: the targets' names
    temperature = rfig.temperature_figure(result)
    assert temperature is not None
    for fig, name in (
        (temperature, "temperature"),
        (rfig.growth_figure(result), "growth"),
        (rfig.registration_figure(result), "registration"),
    ):
        assert _check_figure(fig, name) == 2, name


def test_calibrate_figures() -> None:
    from hexatherm.workflows.calibrate import report as cal
    from hexatherm.workflows.calibrate.run import calibrate, read_campaign

    run = calibrate(read_campaign([SHIPPED / "calibration-geometry"]), "joints")
    stroke = cal.stroke_map(run)
    # the map's x, y and colour bar; the residuals' shared targets axis (y: logarithmic);
    # the workspace's two x, their shared y and the colour bar; the correlations' colour bar
    assert _check_figure(cal._map_figure(stroke, run.campaign.commanded), "map") == 3
    assert _check_figure(cal._residual_figure(run), "residuals") == 2
    assert _check_figure(cal._workspace_figure(run), "workspace") == 5
    assert _check_figure(cal._correlation_figure(run), "correlation") == 1
