"""The smooth growth's own error carried to the corrected poses (``--interpolation smooth``).

The glue between :class:`~hexatherm.workflows.process.pipeline.ProcessResult` and
:mod:`hexatherm.core.smoothbias`; :func:`~hexatherm.workflows.process.uncertainty.pose_uncertainty`
adds the result to the corrected poses' own part.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hexatherm.core.propagation import PoseChain
from hexatherm.core.smoothbias import (
    GrowthExcess,
    corrected_excess,
    growth_excess,
    log_growth,
    log_shape_error,
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
    FGM, as the target's own part (not shared with the other targets). With a
    thermocouple log, each target also gets the fit's error on a growth shaped as the log
    (:func:`~hexatherm.core.smoothbias.log_shape_error`): what the residuals at the
    references cannot see at a target far from them (a gap, irregular times) or across a
    heating switched on or off.
    """
    corr = result.correction
    smooth = corr.smooth
    if smooth is None or not smooth.used:
        return None
    refs = result.session.plan.reference_indices
    q = result.steps.q_mm
    times = result.centres.times_s
    legs_cov = own_leg_covariance(chain, result.centres.centres_mm, centre_cov_mm2, refs)
    temperatures, legs = result.temperatures, chain.hexapod.legs
    shape, ref_model = None, None
    if temperatures is not None and legs is not None:
        # the log's shape: at the targets against the fit of it, and at the references
        # (its residuals there are not the fit's unexplained error)
        sensitivity = legs.sensitivity_mm_per_K(q[refs[0]])
        log = (temperatures.time_s, temperatures.legs_C, sensitivity)
        shape = log_shape_error(smooth.weights, times[refs], times[corr.target_index], *log)
        ref_model = log_growth(times[refs], *log)
    excess = growth_excess(
        times[refs],
        q[refs] - q[refs[0]],
        result.centres.measurements[refs].astype(float),
        float(smooth.lam[0]),
        legs_cov,
        ref_model,
    )
    growth_cov = np.broadcast_to(excess.cov_mm2, (corr.target_index.size, 6, 6))
    if shape is not None:
        growth_cov = growth_cov + shape[:, :, None] * shape[:, None, :]
        excess = dataclasses.replace(excess, shape_um=np.sqrt(np.mean(shape**2, axis=1)) * 1e3)
    added = corrected_excess(
        chain,
        corr.reference_growth_mm,
        q[refs[0]],
        q[corr.target_index],
        corr.corrected,
        growth_cov,
    )
    return added, excess
