"""The derivatives of the poses a geometry stands at by its 48 parameters, kept factored.

By the implicit function theorem on ``IGM_theta(Y) = q_true(theta)``, a pose's
derivatives are ``dY/dtheta = J^-1 (dq/dtheta - dIGM/dtheta)`` (``J = dIGM/dY``). The
right-hand side has one non-zero row per column, the leg the parameter belongs to: a
base joint ``b_i`` enters leg i alone (``-dIGM/db_i = u_i``, the leg's unit vector), a
platform joint too (``-dIGM/dp_i = -R^T u_i``), an offset as 1 and a gain as the leg's
travel from home. So column ``c`` of ``dY/dtheta`` is ``J^-1``'s column of its leg times
its coefficient, and ``A dY/dtheta`` (a pose relative to frame O, say) is the same with
``A J^-1`` (N, 6, 6) in place of ``J^-1``: no 48-column solve, no (N, 6, 6) by (N, 6, 48)
product.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexatherm.typing import FloatArray

#: the parameter vector's blocks (as :mod:`hexatherm.core.calibration.model`'s)
_BASE, _PLATFORM, _OFFSETS, _GAINS, _N = 0, 18, 36, 42, 48


@dataclass(frozen=True)
class StandDerivatives:
    """``dY/dtheta`` of poses (N, 6) factored (see the module text).

    Attributes
    ----------
    inverse : ndarray, shape (N, 6, 6)
        ``J^-1`` at the poses.
    units : ndarray, shape (N, 6, 3)
        The legs' unit vectors ``u_i`` (base frame).
    platform : ndarray, shape (N, 6, 3)
        ``R^T u_i``: the same in the platform frame.
    travel_mm : ndarray, shape (N, 6)
        The commanded legs' travel from home, mm.
    """

    inverse: FloatArray
    units: FloatArray
    platform: FloatArray
    travel_mm: FloatArray

    def __getitem__(self, index: slice) -> StandDerivatives:
        """The derivatives of some of the poses."""
        return StandDerivatives(
            self.inverse[index], self.units[index], self.platform[index], self.travel_mm[index]
        )

    def times(self, left: FloatArray | None = None) -> FloatArray:
        """``A dY/dtheta`` (N, 6, 48) for ``left`` A (N, 6, 6); ``dY/dtheta`` without."""
        m = self.inverse if left is None else left @ self.inverse
        n = m.shape[0]
        by_leg = m[:, :, :, None]  # (N, 6, leg, 1)
        out = np.empty((n, 6, _N))
        out[:, :, _BASE:_PLATFORM] = (by_leg * self.units[:, None]).reshape(n, 6, 18)
        out[:, :, _PLATFORM:_OFFSETS] = (by_leg * -self.platform[:, None]).reshape(n, 6, 18)
        out[:, :, _OFFSETS:_GAINS] = m
        out[:, :, _GAINS:] = m * self.travel_mm[:, None, :]
        return out
