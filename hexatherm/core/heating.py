"""Leg and air temperatures of a simulated session: heating mats with a first-order response.

A heating mat on leg i, switched on at ``on`` and off at ``off``, warms the leg
with a first-order response of time constant ``tau`` towards ``gain`` kelvin
above the air: while it is on the rise approaches ``gain`` as
``1 - exp(-(t - on)/tau)``, after it is off the rise decays as
``exp(-(t - off)/tau)``. The response is linear, so several on/off periods add
up. The air follows its own history (samples joined by straight lines).

Both models here give ``legs(t)`` (n, 6) and ``air(t)`` (n,) at times ``t`` in
seconds from the start of the session.

>>> mat = Mat(gain_C=4.0, tau_s=100.0, periods=((0.0, 100.0),))
>>> rise = mat.rise_C(np.array([100.0, 200.0]))
>>> bool(np.allclose(rise, [4 * (1 - np.exp(-1)), 4 * (1 - np.exp(-1)) * np.exp(-1)]))
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.typing import FloatArray


class HeatingModel(Protocol):
    """Anything that gives leg and air temperatures at times (seconds from the start)."""

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        """Leg temperatures (n, 6), degC."""
        ...

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        """Air temperature (n,), degC."""
        ...


@dataclass(frozen=True)
class Heating:
    """Six heating mats switched on together and an air temperature drifting linearly.

    ``T_i(t) = T_air(t) + gain_i * (1 - exp(-(t - on_s) / tau_s))`` while the mat
    is on (after ``on_s``), ``T_air(t) = air_C + air_drift_C_per_h * t / 3600``.
    """

    air_C: float = 20.0
    air_drift_C_per_h: float = 0.0
    on_s: float = 0.0
    tau_s: float = 2400.0
    gain_C: tuple[float, ...] = (0.0,) * 6

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        """Air temperature at times ``t_s`` (seconds from the session start)."""
        return self.air_C + self.air_drift_C_per_h * np.asarray(t_s, dtype=float) / 3600.0

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        """Leg temperatures (n, 6) at times ``t_s`` (seconds from the session start)."""
        t = np.asarray(t_s, dtype=float)
        rise = 1.0 - np.exp(-np.clip(t - self.on_s, 0.0, None) / self.tau_s)
        return self.air(t)[:, None] + rise[:, None] * np.asarray(self.gain_C)


@dataclass(frozen=True)
class Mat:
    """One leg's heating mat.

    Attributes
    ----------
    gain_C : float
        Steady rise above the air with the mat on, kelvin.
    tau_s : float
        Time constant of the leg's response, seconds (positive).
    periods : tuple of (on_s, off_s)
        When the mat is powered; ``off_s`` may be ``inf`` (stays on).
    """

    gain_C: float = 0.0
    tau_s: float = 2400.0
    periods: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if not (np.isfinite(self.tau_s) and self.tau_s > 0):
            raise ValueError(f"the time constant must be positive, got {self.tau_s}")
        for on, off in self.periods:
            if not (np.isfinite(on) and off > on):
                raise ValueError(f"a power period must have on < off, got [{on}, {off}]")

    def rise_C(self, t_s: npt.ArrayLike) -> FloatArray:
        """Rise of the leg above the air at times ``t_s`` (n,)."""
        t = np.asarray(t_s, dtype=float)
        rise = np.zeros_like(t)
        for on, off in self.periods:
            for start, sign in ((on, 1.0), (off, -1.0)):
                if np.isfinite(start):
                    since = np.clip(t - start, 0.0, None)
                    rise += sign * -np.expm1(-since / self.tau_s)
        return self.gain_C * rise


@dataclass(frozen=True)
class MatHeating:
    """Six mats (legs 1..6) on top of an air temperature history.

    Attributes
    ----------
    mats : tuple of Mat
        One per leg.
    air_times_s, air_values_C : tuple of float
        The air temperature history, joined by straight lines, held outside.
    """

    mats: tuple[Mat, ...]
    air_times_s: tuple[float, ...] = (0.0,)
    air_values_C: tuple[float, ...] = (20.0,)

    def __post_init__(self) -> None:
        if len(self.mats) != 6:
            raise ValueError(f"need one mat per leg (6), got {len(self.mats)}")
        if len(self.air_times_s) != len(self.air_values_C) or not self.air_times_s:
            raise ValueError("the air history needs one temperature per time")
        if np.any(np.diff(self.air_times_s) <= 0):
            raise ValueError("the air history's times must increase")

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        """Air temperature at times ``t_s`` (n,)."""
        return np.interp(np.asarray(t_s, dtype=float), self.air_times_s, self.air_values_C)

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        """Leg temperatures (n, 6): the air plus each mat's rise."""
        t = np.asarray(t_s, dtype=float)
        return self.air(t)[:, None] + np.column_stack([m.rise_C(t) for m in self.mats])
