"""The probed cap that a sphere fit's lateral scatter shows.

A free-radius fit over a shallower cap is more uncertain across the cap's axis and far
more along it: for 25 points, 1.6x the lateral and 3.4x the axial variance of a 70 deg cap
at 50 deg, 4.0x and 24x at 30 deg
(:func:`~hexatherm.core.propagation.cap_centre_covariance`). Registration residuals of
three coplanar balls see the centres' lateral error only, and they are blind to the
platform's thermal motion (a rigid motion): the lateral variance they show, over an
assumed cap's, names the cap, and with it the axial part no residual sees.
"""

from __future__ import annotations

import numpy as np

from hexatherm.core.propagation import cap_centre_covariance

__all__ = ["cap_for_lateral"]

#: shallowest cap considered, deg (a 5 deg cap's lateral variance is ~135x a 70 deg one's)
SHALLOWEST_DEG = 5.0


def cap_for_lateral(n_points: int, assumed_deg: float, lateral_ratio: float) -> float:
    """Half-angle (deg) of the cap whose fit has ``lateral_ratio`` times the lateral
    variance (x plus y) of a fit over ``assumed_deg``, same points and noise; the assumed
    cap for a ratio of 1 or less, the shallowest considered beyond its ratio.

    >>> round(cap_for_lateral(25, 70.0, 1.0), 6)
    70.0
    >>> from hexatherm.core.propagation import cap_centre_covariance
    >>> c45, c70 = cap_centre_covariance(25, 45.0, 1.0), cap_centre_covariance(25, 70.0, 1.0)
    >>> ratio = (c45[0, 0] + c45[1, 1]) / (c70[0, 0] + c70[1, 1])
    >>> round(cap_for_lateral(25, 70.0, ratio), 2)
    45.0
    """
    if not lateral_ratio > 1.0:
        return float(assumed_deg)

    def lateral(cap_deg: float) -> float:
        cov = cap_centre_covariance(n_points, cap_deg, 1.0)
        return float(cov[0, 0] + cov[1, 1])

    target = lateral_ratio * lateral(assumed_deg)
    lo, hi = SHALLOWEST_DEG, float(assumed_deg)  # lateral variance falls as the cap deepens
    if lateral(lo) <= target:
        return lo
    for _ in range(50):  # bisection to 1e-13 of the range
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lateral(mid) > target else (lo, mid)
    return float(np.clip(0.5 * (lo + hi), SHALLOWEST_DEG, assumed_deg))
