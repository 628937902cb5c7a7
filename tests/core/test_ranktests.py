"""The diagnosis's tests without scipy.stats give scipy.stats's numbers, to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from hexatherm.core.ranktests import (
    average_ranks,
    chi2_sf,
    kruskal_wallis,
    spearman,
    t_sf,
)


def _samples(seed: int, n: int) -> np.ndarray:
    """Values with and without ties: continuous, rounded to a few levels."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    return np.round(x, 1) if seed % 2 else x


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("n", [3, 7, 40, 257])
def test_ranks_and_spearman_equal_scipy(seed: int, n: int) -> None:
    x = _samples(seed, n)
    y = 0.3 * x + _samples(seed + 10, n)
    assert np.array_equal(average_ranks(x)[0], stats.rankdata(x))
    rho, p = spearman(x, y)
    expected = stats.spearmanr(x, y)
    assert rho == float(expected.statistic)
    assert p == float(expected.pvalue)


def test_spearman_of_a_constant_or_nan_is_nan() -> None:
    assert np.isnan(spearman([1.0, 1.0, 1.0], [1.0, 2.0, 3.0])).all()
    assert np.isnan(spearman([1.0, np.nan, 3.0], [1.0, 2.0, 3.0])).all()
    assert spearman([1.0, 2.0, 3.0], [3.0, 2.0, 1.0])[0] == -1.0


@pytest.mark.parametrize("seed", range(8))
def test_kruskal_equals_scipy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    sizes = rng.integers(2, 60, size=int(rng.integers(2, 5)))
    groups = [_samples(seed + 100 * k, int(m)) + 0.2 * k for k, m in enumerate(sizes)]
    h, p = kruskal_wallis(groups)
    expected = stats.kruskal(*groups)
    assert h == float(expected.statistic)
    assert p == float(expected.pvalue)


@pytest.mark.parametrize("dof", [1, 3, 10, 1024])
def test_survival_functions_equal_scipy(dof: int) -> None:
    for x in (0.0, 0.3, 2.5, 17.0, 400.0):
        assert chi2_sf(x, dof) == float(stats.chi2.sf(x, dof))
        assert t_sf(x, dof) == float(stats.t.sf(x, dof))
        assert t_sf(-x, dof) == float(stats.t.sf(-x, dof))
