"""The centres' error along the cap's axis, evaluated from the references (Type A).

Three coplanar balls leave registration residuals in their plane only: a centre's error
along the CMM's z, where a cap fit's error is largest and where it reaches Tz, Rx and
Ry, is not seen by them. The references, measured again and again over a session, see
it in their ball heights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexatherm.core.curvature import scatter_off_heating
from hexatherm.workflows.process.pipeline import ProcessResult

#: fewest degrees of freedom of the references' heights for a Type A evaluation of the
#: centres' error along the cap's axis (3 balls: 3 references, the shortest session with
#: two targets; issue 35: with 6, such a session kept the assumed cap, which claimed
#: 1.23-1.42x the observed Tz, Rx, Ry of another touch pattern)
MIN_HEIGHT_DOF = 3
#: below this many degrees of freedom the screen gives Student's k for 95 %
FEW_HEIGHT_DOF = 6


@dataclass(frozen=True)
class HeightScale:
    """The centres' error along the cap's axis (z), evaluated from the references.

    ``ratio``: the variance the references' heights show over the assumed cap's
    (:func:`~hexatherm.core.curvature.scatter_off_heating`, second differences in time
    off the heights' common thermal motion);
    ``used`` when they have at least :data:`MIN_HEIGHT_DOF` degrees of freedom; ``text``
    (to go after the shape's description) and ``why`` (when not used) say so."""

    used: bool
    ratio: float
    dof: int
    text: str
    why: str


def reference_height_scale(result: ProcessResult, assumed_mm2: float) -> HeightScale:
    """How much larger (or smaller) the scatter of the references' ball heights is than
    ``assumed_mm2``, one measurement's z variance by the assumed cap shape."""
    plan, centres = result.session.plan, result.centres
    ref = np.array([k == "reference" for k in plan.kinds], dtype=bool)
    # second differences in time, off the direction the heating moves the heights along
    # (a heating that bends between references inflated the plain ones 3.9x in variance)
    variance, dof, projected = scatter_off_heating(
        centres.times_s[ref], centres.centres_mm[ref][:, :, 2], centres.measurements[ref]
    )
    count = int(ref.sum())
    if dof < MIN_HEIGHT_DOF or not assumed_mm2 > 0 or not np.isfinite(variance):
        why = (
            f"{count} references, {dof} degrees of freedom in their heights: too few to "
            f"evaluate the centres' error along the cap's axis (at least {MIN_HEIGHT_DOF})"
        )
        return HeightScale(False, 1.0, dof, "", why)
    ratio = variance / assumed_mm2
    text = (
        f", its z part scaled by {ratio:.3g} (in variance) to the scatter of the "
        f"{count} references' ball heights (Type A: second differences in time"
        + (f", {projected} of them off the heights' common thermal motion" if projected else "")
        + f", {dof} degrees of freedom)"
    )
    return HeightScale(True, float(ratio), dof, text, "")
