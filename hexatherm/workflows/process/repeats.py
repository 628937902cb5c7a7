"""The repeated measurements of O and R0 against their claimed uncertainty (chi-square).

``plan --origin-repeats/--reference0-repeats`` measures O and R0 several times; ``process``
averages them (:func:`~hexatherm.workflows.process.pipeline.average_repeats`) and checks
here that their scatter is what one measurement's claimed covariance allows: more means
the platform moved or drifted between them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexatherm.typing import FloatArray
from hexatherm.workflows.process.pipeline import ProcessResult


@dataclass(frozen=True)
class RepeatCheck:
    """Scatter of a repeated step's measurements against their claimed uncertainty.

    Attributes
    ----------
    label : str
        The step (``O``, ``R0``).
    n : int
        Its measurements.
    ratio : float
        ``sqrt(chi2 / dof)``: the observed scatter over the claimed one (about 1).
    chi2 : float
        ``sum d^T C^-1 d`` over measurements and balls, ``d`` a centre's deviation (from
        the mean, or from a straight line in time for 3 or more), ``C`` one measurement's
        centre covariance.
    dof : int
    p_value : float
        Chance of a chi2 as large from noise alone.
    """

    label: str
    n: int
    ratio: float
    chi2: float
    dof: int
    p_value: float

    #: below this chance the scatter is more than noise: warn
    P_LIMIT = 1e-3

    @property
    def ok(self) -> bool:
        """Whether the scatter is what the claimed uncertainty allows."""
        return not self.p_value < self.P_LIMIT


def repeat_checks(result: ProcessResult, cov_mm2: FloatArray) -> tuple[RepeatCheck, ...]:
    """Chi-square of every repeated step's measurements against one measurement's covariance.

    One measurement's covariance is its sphere fit's where there is one, else the averaged
    step's (``cov_mm2``, (N, k, 3, 3)) times the number of measurements.
    """
    if not result.repeats:
        return ()
    from scipy.stats import chi2 as chi2_dist

    index = {label: i for i, label in enumerate(result.session.plan.labels)}
    checks = []
    for group in result.repeats:
        n = len(group.labels)
        averaged = cov_mm2[index[group.label]] * n  # (k, 3, 3)
        fitted = np.asarray(np.isfinite(group.cov_mm2).all(axis=(-2, -1)))
        single = np.where(
            fitted[..., None, None],
            group.cov_mm2,
            averaged[None],
        )
        d = group.deviations_mm
        chi2 = float(np.einsum("nki,nkij,nkj->", d, np.linalg.pinv(single), d))
        dof = group.dof
        p = float(chi2_dist.sf(chi2, dof)) if dof > 0 else float("nan")
        ratio = float(np.sqrt(chi2 / dof)) if dof > 0 else float("nan")
        checks.append(RepeatCheck(group.label, n, ratio, chi2, dof, p))
    return tuple(checks)
