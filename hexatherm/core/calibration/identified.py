"""Whether a fit of full rank identifies its level in practice (session 10's audit).

The rank test of :func:`~hexatherm.core.calibration.fit.observability` is relative (the
singular values against the largest): poses that span almost nothing pass it, and the
fit then either returns parameters known only to metres or steps, linearised, to a
geometry where the model cannot stand the hexapod at all. Both are refused here, as a
:class:`~hexatherm.errors.CalibrationError` naming the level, the span of the poses and
what to add (``--level auto`` counts the level as not fitted).
"""

from __future__ import annotations

import numpy as np

from hexatherm.core.calibration.model import PARAMETER_NAMES, PARAMETER_UNITS, CalibrationModel
from hexatherm.core.residuals import POSE_COMPONENTS
from hexatherm.errors import CalibrationError, ConvergenceError
from hexatherm.typing import FloatArray

#: the largest standard uncertainty of a fitted parameter, as a fraction of the legs' mean
#: home length (a gain's times that length): beyond it the poses identify the level only
#: in name, and the fit, linearised about the nominal geometry, means nothing
MAX_U_FRACTION = 0.01
#: the units of a commanded pose's components
_UNITS = ("mm",) * 3 + ("deg",) * 3


def pose_spans(commanded_poses: FloatArray) -> str:
    """How far the poses spread in each component, in words (mm, deg)."""
    span = np.ptp(np.atleast_2d(commanded_poses), axis=0)
    return ", ".join(
        f"{c} {v:.3g} {u}" for c, v, u in zip(POSE_COMPONENTS, span, _UNITS, strict=True)
    )


def refuse_unidentified(
    model: CalibrationModel, covariance: FloatArray, commanded_poses: FloatArray
) -> None:
    """CalibrationError when a fitted parameter's standard uncertainty (from the (48, 48)
    ``covariance``) exceeds :data:`MAX_U_FRACTION` of the legs' mean home length (a
    gain's, times that length)."""
    length = float(np.mean(model.home_leg_mm))
    scale = np.where(np.array(PARAMETER_UNITS) == "mm", 1.0, length)
    u = np.sqrt(np.maximum(np.diag(covariance), 0.0)) * scale
    u[~model.mask] = 0.0
    worst = int(np.argmax(u))
    limit = MAX_U_FRACTION * length
    if u[worst] <= limit:
        return
    value = (
        f"{u[worst]:.3g} mm"
        if PARAMETER_UNITS[worst] == "mm"
        else f"{u[worst] / length * 1e6:.3g} ppm"
    )
    raise CalibrationError(
        f"the poses identify level {model.level!r} only to u = {value} "
        f"({PARAMETER_NAMES[worst]}), more than {MAX_U_FRACTION:.0%} of the legs' home "
        f"length ({limit:.3g} mm): a fit linearised about the nominal geometry means "
        f"nothing there; the poses span {pose_spans(commanded_poses)}: spread them over "
        "the stroke, rotations included"
    )


def diverged(
    model: CalibrationModel, error: ConvergenceError, commanded_poses: FloatArray
) -> CalibrationError:
    """The error for a fit whose steps left the geometries the model can stand (its
    forward model failed at a trial geometry: ``error``)."""
    return CalibrationError(
        f"the fit of level {model.level!r} diverged: at a trial geometry the model could "
        f"not stand the hexapod ({error}); the poses identify the level too weakly: they "
        f"span {pose_spans(commanded_poses)}: spread them over the stroke, rotations "
        "included"
    )
