"""The leg thermal model against hand computation."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.thermal import LegThermalModel

SEGMENTS = [("body", "aluminium", 23.1e-6, 148.0), ("screw", "steel", 11.5e-6, None)]


def test_growth_by_hand():
    model = LegThermalModel.uniform(SEGMENTS, reference_temperature_C=20.0)
    q = np.array([240.0, 245.0, 250.0, 255.0, 260.0, 265.0])
    temp = np.array([20.0, 21.0, 22.0, 23.0, 24.0, 25.0])
    expected = (23.1e-6 * 148.0 + 11.5e-6 * (q - 148.0)) * (temp - 20.0)
    np.testing.assert_allclose(model.growth_mm(q, temp), expected, rtol=1e-14)


def test_per_segment_temperatures_by_hand():
    model = LegThermalModel.uniform(SEGMENTS)
    q = np.full(6, 250.0)
    temp = np.tile([[22.0, 25.0]], (6, 1))  # body at 22, screw at 25
    expected = 23.1e-6 * 148.0 * 2.0 + 11.5e-6 * 102.0 * 5.0
    np.testing.assert_allclose(model.growth_mm(q, temp, per_segment=True), expected, rtol=1e-14)


def test_scaling_is_exact_for_uniform_heating():
    model = LegThermalModel.uniform(SEGMENTS)
    q_r, q_s = np.full(6, 230.0), np.linspace(240, 270, 6)
    d_t = np.array([0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    growth_r = model.growth_mm(q_r, 20.0 + d_t)
    np.testing.assert_allclose(
        model.scale_growth(growth_r, q_r, q_s), model.growth_mm(q_s, 20.0 + d_t), rtol=1e-13
    )


def test_legs_may_differ_and_pad():
    per_leg = [SEGMENTS] * 5 + [
        [("a", "al", 23e-6, 50.0), ("b", "al", 23e-6, 90.0), ("c", "st", 12e-6, None)]
    ]
    model = LegThermalModel.from_segments(per_leg)
    assert model.cte_per_K.shape == (6, 3)
    np.testing.assert_allclose(model.total_fixed_length_mm, [148.0] * 5 + [140.0])
    s = model.sensitivity_mm_per_K(np.full(6, 250.0))
    assert s[5] == pytest.approx(23e-6 * 140 + 12e-6 * 110, rel=1e-14)


def test_exactly_one_variable_segment():
    with pytest.raises(ValueError, match="leg 1 must have exactly one variable segment, has 2"):
        LegThermalModel.uniform([("a", "s", 1e-5, None), ("b", "s", 1e-5, None)])
    with pytest.raises(ValueError, match="length must be positive"):
        LegThermalModel.uniform([("a", "s", 1e-5, -3.0), ("b", "s", 1e-5, None)])
