"""The smooth growth's own error carried to the corrected poses (``--interpolation smooth``).

The glue between :class:`~hexatherm.workflows.process.pipeline.ProcessResult` and
:mod:`hexatherm.core.smoothbias`; :func:`~hexatherm.workflows.process.uncertainty.pose_uncertainty`
adds the result to the corrected poses' own part.
"""

from __future__ import annotations

from hexatherm.core.propagation import PoseChain
from hexatherm.core.smoothbias import (
    GrowthExcess,
    corrected_excess,
    growth_excess,
    own_leg_covariance,
)
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.pipeline import ProcessResult

__all__ = ["smooth_excess"]


def smooth_excess(
    result: ProcessResult, chain: PoseChain, centre_cov_mm2: FloatArray
) -> tuple[FloatArray, GrowthExcess] | None:
    """The smooth growth's own error carried to the corrected poses, (M, 6, 6), and its
    evaluation at the references; None unless the smooth fit was used.

    The inner references' standardized residuals beyond what their noise predicts
    (:func:`~hexatherm.core.smoothbias.growth_excess`) give the covariance of the growth
    at R that the fixed-smoothing propagation leaves out (the spline's bias, the smoothing's
    choice); it is carried to every target's legs by the growth scaling and through the
    FGM, as the target's own part (not shared with the other targets).
    """
    corr = result.correction
    smooth = corr.smooth
    if smooth is None or not smooth.used:
        return None
    refs = result.session.plan.reference_indices
    q = result.steps.q_mm
    legs_cov = own_leg_covariance(chain, result.centres.centres_mm, centre_cov_mm2, refs)
    excess = growth_excess(
        result.centres.times_s[refs],
        q[refs] - q[refs[0]],
        result.centres.measurements[refs].astype(float),
        float(smooth.lam[0]),
        legs_cov,
    )
    added = corrected_excess(
        chain,
        corr.reference_growth_mm,
        q[refs[0]],
        q[corr.target_index],
        corr.corrected,
        excess.cov_mm2,
    )
    return added, excess
