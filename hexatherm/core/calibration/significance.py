"""Whether a calibration changes anything: the two tests behind ``calibrate``'s
recommendation (apply the calibrated geometry, or keep the controller as it is).

1. **The parameters' change against their uncertainty.** The change ``d = theta -
   theta0`` of the fitted parameters from the nominal ones, with their covariance ``C``
   (rank ``r``: the gauge's freedoms have none), gives ``chi2 = d' C^+ d`` (``C^+`` the
   pseudo-inverse), chi-square with ``r`` degrees of freedom when the true geometry is
   the nominal one: the change is significant when ``P(chi2_r >= chi2) < alpha``. One
   joint test, not one per parameter: of 42 parameters two lie beyond ``2 u`` by chance
   alone.
2. **The held-out improvement against its uncertainty.** Per target ``i`` the reduction
   of the squared residual, ``e_i = |r_before_i|^2 - |r_after_i|^2`` (the residual of
   the nominal geometry and that of the calibrated one, held out: predicted by a fit
   the target was not in); their mean ``m`` with its standard uncertainty ``s / sqrt(n)``
   (a paired comparison over the targets): the calibrated geometry predicts better when
   ``m > k u(m)``, worse when ``m < -k u(m)``. The targets of one session share their O
   and R0 and are not quite independent: the test is approximate, and needs no model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.special import chdtrc  # not scipy.stats: about 0.4-1 s of calibrate's start

#: the level of the parameters' test
ALPHA = 0.01


@dataclass(frozen=True)
class ChangeTest:
    """The joint test of the parameters' change (see the module text)."""

    chi_square: float
    dof: int
    p: float

    @property
    def significant(self) -> bool:
        return self.dof > 0 and self.p < ALPHA


def parameter_change_test(change: npt.ArrayLike, covariance: npt.ArrayLike) -> ChangeTest:
    """``chi2 = d' C^+ d`` with the rank of ``C`` as degrees of freedom, and its p-value."""
    d = np.asarray(change, dtype=float)
    c = np.asarray(covariance, dtype=float)
    scale = np.sqrt(np.maximum(np.diag(c), 0.0))
    keep = scale > 0
    if not keep.any():
        return ChangeTest(0.0, 0, 1.0)
    s = scale[keep]
    correlation = c[np.ix_(keep, keep)] / np.outer(s, s)  # scaled: mm and mm/mm alike
    z = d[keep] / s
    values = np.linalg.eigvalsh(correlation)
    rank = int(np.sum(values > values.max() * 1e-10))
    stat = float(z @ np.linalg.pinv(correlation, rcond=1e-10, hermitian=True) @ z)
    # scipy.stats.chi2.sf's arithmetic: chdtrc above the support's end, 1 at or below it
    return ChangeTest(stat, rank, 1.0 if stat <= 0 else float(chdtrc(rank, stat)))


@dataclass(frozen=True)
class Improvement:
    """The mean reduction of the squared residual over the targets and its standard
    uncertainty (um^2 or urad^2), and the RMS before and after (um or urad)."""

    mean: float
    u: float
    rms_before: float
    rms_after: float

    def verdict(self, k: float = 2.0) -> int:
        """+1: significantly better; -1: significantly worse; 0: no significant change."""
        if self.mean > k * self.u:
            return 1
        if self.mean < -k * self.u:
            return -1
        return 0


def improvement(before: npt.ArrayLike, after: npt.ArrayLike) -> Improvement:
    """The paired comparison of residuals ``before`` and ``after`` (N, m): each row's
    squared norm (see the module text)."""
    b = np.sum(np.asarray(before, dtype=float) ** 2, axis=1)
    a = np.sum(np.asarray(after, dtype=float) ** 2, axis=1)
    e = b - a
    n = len(e)
    u = float(np.std(e, ddof=1) / np.sqrt(n)) if n > 1 else float("inf")
    return Improvement(float(np.mean(e)), u, float(np.sqrt(np.mean(b))), float(np.sqrt(np.mean(a))))
