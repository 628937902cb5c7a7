"""Summaries and tests of residual series (hexatherm.core.residuals), against independent truths."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from hexatherm.core.residuals import (
    PoseResiduals,
    autocorrelation,
    default_lags,
    linear_trend,
    ljung_box,
    spearman,
    summarize,
)


# ------------------------------------------------------------------ Ljung-Box
def test_ljung_box_equals_hand_computation() -> None:
    # x = [2, -1, 0, 3, 1]: mean 1, deviations [1, -2, -1, 2, 0], sum of squares 10
    # r1 = (1*-2 + -2*-1 + -1*2 + 2*0) / 10 = -0.2 ; r2 = (1*-1 + -2*2 + -1*0) / 10 = -0.5
    # Q = 5 * 7 * (0.04 / 4 + 0.25 / 3); chi-square with 2 dof: p = exp(-Q / 2)
    q = 35.0 * (0.01 + 0.25 / 3.0)
    result = ljung_box([2.0, -1.0, 0.0, 3.0, 1.0], lags=2)
    np.testing.assert_allclose(autocorrelation([2.0, -1.0, 0.0, 3.0, 1.0], 2), [-0.2, -0.5])
    assert result.lags == 2
    assert result.q == pytest.approx(q, rel=1e-12)
    assert result.p_value == pytest.approx(np.exp(-q / 2.0), rel=1e-12)


def test_white_noise_passes_at_the_expected_rate() -> None:
    rng = np.random.default_rng(20240611)
    p = np.array([ljung_box(rng.standard_normal(100)).p_value for _ in range(200)])
    rate = float(np.mean(p < 0.05))
    assert 0.02 <= rate <= 0.09, rate
    # the p-values of a true null are (about) uniform
    assert stats.kstest(p, "uniform").pvalue > 0.01


def test_autocorrelated_series_are_flagged() -> None:
    rng = np.random.default_rng(5)
    for _ in range(20):
        e = rng.standard_normal(100)
        ar = np.zeros(100)
        for i in range(1, 100):
            ar[i] = 0.8 * ar[i - 1] + e[i]
        assert not ljung_box(ar).white()
        assert ljung_box(ar).p_value < 1e-3
        assert not ljung_box(np.cumsum(rng.standard_normal(100))).white()


def test_ljung_box_degenerate_and_default_lags() -> None:
    assert np.isnan(ljung_box(np.ones(20)).q)
    assert np.isnan(ljung_box([1.0, 2.0]).p_value)
    assert [default_lags(n) for n in (4, 26, 50, 51, 1000)] == [1, 5, 10, 10, 10]
    assert ljung_box(np.arange(30.0) % 3).lags == 6


# --------------------------------------------------------------------- trend
def test_known_linear_trend_is_recovered() -> None:
    rng = np.random.default_rng(11)
    t_s = np.sort(rng.uniform(0.0, 10 * 3600.0, 200))
    sigma = 0.2
    y = 3.0 + 0.5 * t_s / 3600.0 + sigma * rng.standard_normal(t_s.size)
    tr = linear_trend(t_s, y)
    hours = t_s / 3600.0
    expected_se = sigma / np.sqrt(np.sum((hours - hours.mean()) ** 2))
    assert abs(tr.slope_per_h - 0.5) < 4 * expected_se
    assert tr.std_error_per_h == pytest.approx(expected_se, rel=0.2)
    assert tr.t == pytest.approx(tr.slope_per_h / tr.std_error_per_h)
    assert tr.significant()
    ref = stats.linregress(hours, y)
    assert tr.slope_per_h == pytest.approx(ref.slope, rel=1e-10)
    assert tr.std_error_per_h == pytest.approx(ref.stderr, rel=1e-10)
    assert tr.p_value == pytest.approx(ref.pvalue, rel=1e-6, abs=1e-300)


def test_no_trend_in_white_noise_and_degenerate_times() -> None:
    rng = np.random.default_rng(3)
    p = [linear_trend(np.arange(50) * 60.0, rng.standard_normal(50)).p_value for _ in range(200)]
    assert 0.02 <= np.mean(np.array(p) < 0.05) <= 0.09
    assert np.isnan(linear_trend(np.full(5, 7.0), np.arange(5.0)).slope_per_h)


# ------------------------------------------------------------------ Spearman
def test_spearman() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert spearman(x, np.exp(x)).rho == pytest.approx(1.0)
    assert spearman(x, -(x**3)).rho == pytest.approx(-1.0)
    assert np.isnan(spearman(x, np.ones(5)).rho)
    # rank correlation = Pearson correlation of the ranks
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal(30), rng.standard_normal(30)
    ranks = np.corrcoef(np.argsort(np.argsort(a)), np.argsort(np.argsort(b)))[0, 1]
    assert spearman(a, b).rho == pytest.approx(ranks)


# ------------------------------------------------------------------- summary
def _residuals(pose: np.ndarray, legs: np.ndarray, step_rms: np.ndarray) -> PoseResiduals:
    return PoseResiduals(pose, legs, step_rms)


def test_summary_values() -> None:
    rng = np.random.default_rng(8)
    n = 40
    pose = rng.standard_normal((n, 6)) * [1, 2, 3, 4, 5, 6] + [0.5, 0, 0, 0, 0, -1]
    legs = rng.standard_normal((n, 6))
    step_rms = rng.uniform(0.1, 1.0, n)
    step_rms[17] = 9.0
    step_rms[3] = 8.0
    kinds = ["origin"] + ["reference", "target"] * ((n - 1) // 2) + ["reference"]
    labels = [f"S{i}" for i in range(n)]
    times = np.arange(n) * 200.0 + 1e9
    temps = 20.0 + rng.uniform(0, 5, (n, 6))
    s = summarize(_residuals(pose, legs, step_rms), labels, kinds, times, temps, n_worst=3)

    for j in range(6):
        assert s.component_rms[j] == pytest.approx(np.sqrt(np.sum(pose[:, j] ** 2) / n))
        assert s.component_mean[j] == pytest.approx(np.sum(pose[:, j]) / n)
        assert s.leg_rms_um[j] == pytest.approx(np.linalg.norm(legs[:, j]) / np.sqrt(n))
    assert s.kind_count == {"origin": 1, "reference": 20, "target": 19}
    target = [i for i in range(n) if kinds[i] == "target"]
    assert s.kind_rms_um["target"] == pytest.approx(
        np.linalg.norm(step_rms[target]) / np.sqrt(len(target))
    )
    assert s.kind_rms_um["origin"] == pytest.approx(step_rms[0])
    assert s.centre_rms_um == pytest.approx(np.linalg.norm(step_rms) / np.sqrt(n))
    assert [w.label for w in s.worst] == ["S17", "S3", labels[int(np.argsort(step_rms)[-3])]]
    assert s.worst[0].time_s == times[17] and s.worst[0].kind == kinds[17]
    # quarters of 10 steps each
    np.testing.assert_allclose(
        s.part_rms_um, [np.sqrt(np.mean(step_rms[10 * b : 10 * b + 10] ** 2)) for b in range(4)]
    )
    np.testing.assert_allclose(s.part_span_s[:, 0], times[[0, 10, 20, 30]])
    assert [t.name for t in s.tests] == [
        "Tx",
        "Ty",
        "Tz",
        "Rx",
        "Ry",
        "Rz",
        "leg1",
        "leg2",
        "leg3",
        "leg4",
        "leg5",
        "leg6",
    ]
    assert [t.unit for t in s.pose_tests] == ["um"] * 3 + ["urad"] * 3
    assert len(s.leg_tests) == 6


def test_summary_tests_follow_time_and_temperature() -> None:
    n = 50
    rng = np.random.default_rng(4)
    times = rng.permutation(n) * 120.0  # steps not stored in time order
    temps = np.column_stack([20.0 + np.sin(times / 2000.0 + j) for j in range(6)])
    pose = 0.01 * rng.standard_normal((n, 6))
    pose[:, 0] = 2.0 * times / 3600.0  # a trend of 2 um/h
    pose[:, 1] = np.sin(times / 500.0)  # smooth in time: autocorrelated
    pose[:, 2] = temps.mean(axis=1) ** 3  # monotone in the mean temperature
    legs = 0.01 * rng.standard_normal((n, 6))
    legs[:, 4] = np.exp(temps[:, 4])  # monotone in its own leg's temperature
    s = summarize(
        _residuals(pose, legs, np.ones(n)),
        [f"S{i}" for i in range(n)],
        ["target"] * n,
        times,
        temps,
    )
    tx, ty, tz = s.tests[0], s.tests[1], s.tests[2]
    assert tx.trend.slope_per_h == pytest.approx(2.0)
    assert tx.vs_time.rho == pytest.approx(1.0)
    assert not ty.whiteness.white()
    order = np.argsort(times)
    assert ty.whiteness.q == pytest.approx(ljung_box(pose[order, 1]).q)
    assert tz.vs_temperature.rho == pytest.approx(1.0)
    assert s.tests[6 + 4].vs_temperature.rho == pytest.approx(1.0)
    assert s.tests[6 + 3].vs_temperature.rho < 0.9
    # 1-D temperatures: legs are compared with the mean
    s1 = summarize(
        _residuals(pose, legs, np.ones(n)),
        [f"S{i}" for i in range(n)],
        ["target"] * n,
        times,
        temps.mean(axis=1),
    )
    assert s1.tests[2].vs_temperature.rho == pytest.approx(1.0)


def test_summary_rejects_bad_shapes() -> None:
    res = _residuals(np.zeros((5, 6)), np.zeros((5, 6)), np.zeros(5))
    with pytest.raises(ValueError, match="one label"):
        summarize(res, ["a"] * 4, ["target"] * 5, np.arange(5.0), np.zeros(5))
    with pytest.raises(ValueError, match="temperatures"):
        summarize(res, ["a"] * 5, ["target"] * 5, np.arange(5.0), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="shape"):
        summarize(
            _residuals(np.zeros((5, 3)), np.zeros((5, 6)), np.zeros(5)),
            ["a"] * 5,
            ["target"] * 5,
            np.arange(5.0),
            np.zeros(5),
        )
