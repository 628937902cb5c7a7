"""Issue 37: what a scanning probe's session needs of the readers, each fast path checked
against the straightforward method it replaces (a second method, on random input)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hexatherm.io.csvcolumns import ISO_TIME, _iso_layout
from hexatherm.io.records import Records
from hexatherm.workflows.process.measured import point_groups


def _groups_by_sorting(records: Records) -> tuple[np.ndarray, np.ndarray]:
    """The ``(label, ball)`` groups numbered in file order, by sorting every key (the
    method before issue 37)."""
    keys = np.char.add(np.char.add(records.label.astype(str), "\x1f"), records.ball.astype(str))
    _, first, groups = np.unique(keys, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[groups.reshape(-1)], first[order]


@pytest.mark.parametrize("seed", range(20))
def test_point_groups_agree_with_sorting_every_key(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_runs = int(rng.integers(1, 40))
    # runs of random keys from a small set, so that keys come back in later runs (records
    # of several files joined) and neighbours share a label or a ball
    labels = rng.choice(["O", "R0", "S1", "S10", "R1"], n_runs)
    balls = rng.choice(["B1", "B2", "B3"], n_runs)
    sizes = rng.integers(1, 6, n_runs)
    rec = Records(
        "p.csv",
        "points",
        np.repeat(labels, sizes),
        np.repeat(balls, sizes),
        np.zeros((sizes.sum(), 3)),
        np.zeros(sizes.sum()),
        "seconds",
        np.arange(sizes.sum()) + 2,
    )
    groups, first = point_groups(rec)
    expected_groups, expected_first = _groups_by_sorting(rec)
    np.testing.assert_array_equal(groups, expected_groups)
    np.testing.assert_array_equal(first, expected_first)


def _layout_by_text(values: np.ndarray) -> bool | None:
    """:func:`_iso_layout` the way it was before issue 37: the times joined into one text."""
    width = len(values[0])
    data = "\n".join(values).encode("utf-8", "replace") + b"\n"
    if len(data) != values.size * (width + 1):
        return None
    codes = np.frombuffer(data, dtype=np.uint8).reshape(values.size, width + 1)
    digit = (codes >= 48) & (codes <= 57)
    shape = np.where(digit, np.uint8(48), codes)
    if not (shape == shape[0]).all():
        return None
    match = ISO_TIME.fullmatch(shape[0, :width].tobytes().decode("ascii", "replace"))
    return None if match is None else match.group("offset") is not None


GOOD = "2024-03-05T07:30:00.015000"
VARIANTS = [
    [GOOD, "2024-03-05T07:30:01.025000"],
    [GOOD, "2024-03-05T07:30:01.0250001"],  # one longer
    [GOOD, "2024-03-05T07:30:01.02500"],  # one shorter
    [GOOD, "2024-03-05T07:30:01.02500Z"],  # as long, another layout
    [GOOD, "2024-03-05T07:30:01.0250é0"],  # beyond ASCII
    [GOOD + "Z", "2024-03-05T07:30:01.025000Z"],
    ["2024-03-05T07:30+01:00", "2024-03-05T07:31+01:00"],
    ["2024-03-05 07:30:00", "2024-03-05T07:30:00"],  # another separator
    ["2024-3-5T7:30", "2024-3-5T7:31"],  # not two-digit fields
    ["1709623800", "1709623801"],  # numbers
    ["", ""],
    ["", "2024-03-05T07:30:00"],
]


@pytest.mark.parametrize("times", VARIANTS)
def test_iso_layout_agrees_with_the_joined_text(times: list[str]) -> None:
    values = np.array(times, dtype=object)
    if times[0] == "":
        assert _iso_layout(values) is None
        return
    assert _iso_layout(values) == _layout_by_text(values)


def test_iso_layout_on_a_long_column_and_a_shifted_last_row() -> None:
    stamps = pd.date_range("2024-03-05T07:30", periods=5000, freq="10ms")
    values = np.array(stamps.strftime("%Y-%m-%dT%H:%M:%S.%f"), dtype=object)
    assert _iso_layout(values) is False
    values[-1] = "2024-03-05T07:30:50 000000"
    assert _iso_layout(values) is None


def _spheres(rng: np.random.Generator, n_spheres: int) -> tuple[np.ndarray, np.ndarray]:
    """Probed points on random 70 deg caps of random 20-40 mm spheres, 0.5 um noise."""
    sizes = rng.integers(5, 60, n_spheres)
    groups = np.repeat(np.arange(n_spheres), sizes)
    theta = np.radians(rng.uniform(0, 70, groups.size))
    phi = rng.uniform(0, 2 * np.pi, groups.size)
    u = np.c_[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]
    centres = rng.uniform(-500, 500, (n_spheres, 3))
    radii = rng.uniform(10, 20, n_spheres)
    points = centres[groups] + radii[groups, None] * u + rng.normal(0, 5e-4, u.shape)
    return points, groups


@pytest.mark.parametrize("block_points", [7, 64, 500])
def test_spheres_fitted_in_blocks_agree_with_all_at_once(
    block_points: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from hexatherm.core import spherefit

    points, groups = _spheres(np.random.default_rng(block_points), 40)
    whole = spherefit.fit_spheres(points, groups)
    monkeypatch.setattr(spherefit, "BLOCK_POINTS", block_points)
    blocks = spherefit.fit_spheres(points, groups)
    for name in ("centre_mm", "radius_mm", "cov_centre_mm2", "form_um", "residuals_mm"):
        np.testing.assert_allclose(getattr(blocks, name), getattr(whole, name), rtol=1e-12)
    np.testing.assert_array_equal(blocks.iterations, whole.iterations)
    np.testing.assert_allclose(blocks.cap_half_angle_deg, whole.cap_half_angle_deg, rtol=1e-12)


def test_a_sphere_that_fails_in_a_later_block_is_named_as_all_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from hexatherm.core import spherefit
    from hexatherm.errors import FitError

    points, groups = _spheres(np.random.default_rng(3), 30)
    for bad in (7, 25):  # coplanar points: degenerate
        points[groups == bad, 2] = 1.0
    with pytest.raises(FitError) as whole:
        spherefit.fit_spheres(points, groups)
    monkeypatch.setattr(spherefit, "BLOCK_POINTS", 50)
    with pytest.raises(FitError) as blocks:
        spherefit.fit_spheres(points, groups)
    assert str(blocks.value) == str(whole.value)
    assert "sphere 7" in str(blocks.value) and "25" in str(blocks.value)
