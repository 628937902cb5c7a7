"""The few test statistics the diagnosis needs, without importing ``scipy.stats``.

``scipy.stats`` takes about 0.35 s of CPU to import (its distributions are built at
import), more than the residual tests of a whole diagnosis. The tests here are the
arithmetic of ``scipy.stats`` (1.17) written with numpy and ``scipy.special``, in the
same order, so they give the same numbers to the bit (``tests/core/test_ranktests.py``
compares them with ``scipy.stats``):

* :func:`chi2_sf`, :func:`t_sf` -- survival functions (``scipy.stats.chi2.sf``,
  ``scipy.stats.t.sf``);
* :func:`average_ranks` -- ranks with ties given their mean rank (``rankdata``);
* :func:`spearman` -- Spearman's rank correlation and its two-sided p-value
  (``spearmanr``);
* :func:`kruskal_wallis` -- the Kruskal-Wallis H test (``kruskal``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from scipy import special

from hexatherm.typing import FloatArray


def chi2_sf(x: float, dof: float) -> float:
    """P(X > x) for X chi-square with ``dof`` degrees of freedom.

    >>> round(chi2_sf(3.841458820694124, 1), 12)
    0.05
    """
    return float(special.chdtrc(dof, x))


def t_sf(x: float, dof: float) -> float:
    """P(T > x) for T Student's t with ``dof`` degrees of freedom.

    >>> t_sf(0.0, 5)
    0.5
    """
    return float(special.stdtr(dof, -x))


def average_ranks(values: npt.ArrayLike) -> tuple[FloatArray, npt.NDArray[np.intp]]:
    """Ranks (1 to n) of 1-D ``values``, tied values given their mean rank, and the
    size of each group of equal values (in increasing order of the values).

    >>> ranks, counts = average_ranks([3.0, 1.0, 3.0, 2.0])
    >>> ranks.tolist(), counts.tolist()
    ([3.5, 1.0, 3.5, 2.0], [1, 1, 2])
    """
    x = np.asarray(values, dtype=float).reshape(-1)
    order = np.argsort(x, kind="stable")
    ordered = x[order]
    first = np.concatenate([[True], ordered[1:] != ordered[:-1]])
    starts = np.flatnonzero(first)
    counts = np.diff(starts, append=x.size)
    # the first ordinal rank of each group plus half the group's extent: exact
    mean_rank = (starts + 1).astype(float) + (counts.astype(float) - 1) / 2
    ranks = np.empty(x.size)
    ranks[order] = np.repeat(mean_rank, counts)
    return ranks, counts


def spearman(x: npt.ArrayLike, y: npt.ArrayLike) -> tuple[float, float]:
    """Spearman's rank correlation of ``x`` and ``y`` (1-D, same length) and the
    two-sided p-value of no correlation (Student's t with n - 2 degrees of freedom).

    NaN and NaN when either holds a NaN or is constant, or for fewer than 2 values.

    >>> round(spearman([1.0, 2.0, 3.0, 4.0], [1.0, 3.0, 2.0, 4.0])[0], 12)
    0.8
    """
    both = np.column_stack((np.asarray(x, dtype=float), np.asarray(y, dtype=float)))
    n = both.shape[0]
    constant = n > 0 and bool(np.any(np.all(both == both[0], axis=0)))
    if n <= 1 or constant or np.isnan(both).any():
        return float("nan"), float("nan")
    ranked = np.apply_along_axis(lambda column: average_ranks(column)[0], 0, both)
    rs = np.corrcoef(ranked, rowvar=False)
    dof = n - 2
    with np.errstate(divide="ignore"):
        t = rs * np.sqrt((dof / ((rs + 1.0) * (1.0 - rs))).clip(0))
    p = 2 * special.stdtr(dof, -np.abs(t))
    return float(rs[1, 0]), float(p[1, 0])


def kruskal_wallis(groups: Sequence[npt.ArrayLike]) -> tuple[float, float]:
    """The Kruskal-Wallis H statistic of two or more groups (ties corrected) and its
    p-value (chi-square with one degree of freedom fewer than groups).

    NaN and NaN when a value is NaN.

    >>> h, p = kruskal_wallis([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [2.0, 2.0]])
    >>> float(h), round(p, 12)
    (7.0, 0.030197383422)
    """
    samples = [np.asarray(g, dtype=float).reshape(-1) for g in groups]
    if len(samples) < 2:
        raise ValueError("the Kruskal-Wallis test needs at least two groups")
    n = [s.size for s in samples]
    if min(n) < 1:
        raise ValueError("the Kruskal-Wallis test needs values in every group")
    alldata = np.concatenate(samples)
    if np.isnan(alldata).any():
        return float("nan"), float("nan")
    total = sum(n)
    ranked, counts = average_ranks(alldata)
    t = counts.astype(float)
    ties = 1 - np.sum(t**3 - t) / (total**3 - total)
    j = list(itertools.accumulate(n, initial=0))
    ssbn = sum(np.sum(ranked[j[i] : j[i + 1]]) ** 2 / n[i] for i in range(len(samples)))
    h = 12.0 / (total * (total + 1)) * ssbn - 3 * (total + 1)
    h = h / ties
    return float(h), float(special.chdtrc(float(len(samples) - 1), h))
