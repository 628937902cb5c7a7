"""The twin's effects: how a real hexapod departs from the plain thermal leg model.

The spec ("The hexapod twin and its effects") names six effects, and four more
physically common ones follow them (ball-plate expansion, quadratic leg growth,
CMM scale, backlash); each one is a small class here, registered under its
contract name, with its parameters, their units, a physically sensible range and
what it changes in the twin's prediction.
The simulator applies them to the truth (``hexatherm simulate``, hidden effects)
and the diagnosis fits them to measurements: one implementation for both.

An effect acts at one or more *stages* of the twin, always in this order, which
is the spec's composition order (lag, then overheat, then CTE error, then
offsets); effects of the same stage apply in the order they are given:

1. ``leg_temperature_C``: each leg's effective temperature from the thermocouple
   log (``leg_thermal_lag``);
2. ``segment_temperature_C``: the temperature of each segment of each leg
   (``steel_overheat``);
3. ``leg_growth_mm``: each leg's thermal growth, knowing the leg temperatures
   (``leg_cte_error``, ``leg_growth_quadratic``);
4. ``commanded_leg_length_mm``: the true leg lengths, knowing the commanded ones
   in the order the steps were moved through (``leg_offset``, ``leg_backlash``);
5. ``base_joints_mm``: the base joints at each step (``base_expansion``);
5b. ``ball_positions_mm``: the balls' centres in the platform frame when each
   was measured (``ball_plate_expansion``);
6. ``cmm_coordinates_mm``: what the CMM reports for a true coordinate measured at
   a time (``cmm_drift``, ``cmm_scale``).

Every stage's method is the identity in :class:`Effect` (stages 3 and 4 call the
simpler ``growth_mm`` and ``leg_length_mm``, which effects that need nothing else
override); an effect overrides the ones it changes. Adding an effect is one new
subclass with a ``name``: it registers itself in :data:`EFFECTS`.

``t_0`` is the time of the first temperature sample, where the hexapod is taken
to be in equilibrium.

>>> effect = make_effect("leg_offset", {f"leg{i}": 0.001 * i for i in range(1, 7)})
>>> effect.leg_length_mm(np.zeros((1, 6))).round(3).tolist()
[[0.001, 0.002, 0.003, 0.004, 0.005, 0.006]]
>>> sorted(EFFECTS)[:4]
['ball_plate_expansion', 'base_expansion', 'cmm_drift', 'cmm_scale']
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from hexatherm.errors import InputError
from hexatherm.typing import FloatArray

#: seconds per hour
_HOUR_S = 3600.0


# ----------------------------------------------------------------- temperatures
@dataclass(frozen=True)
class ThermocoupleLog:
    """Thermocouple samples: leg temperatures and, optionally, the air temperature.

    Between samples a temperature is the straight line joining them; before the
    first sample and after the last one it holds.

    Attributes
    ----------
    times_s : ndarray, shape (m,)
        Sample times, non-decreasing, seconds.
    legs_C : ndarray, shape (m, 6)
        Temperature of each leg's thermocouple.
    air_C : ndarray, shape (m,), optional
        Ambient air temperature (the ``air`` column of ``temperatures.csv``).

    Examples
    --------
    >>> log = ThermocoupleLog([0.0, 100.0], [[20.0] * 6, [30.0] * 6], [20.0, 21.0])
    >>> float(log.legs_at([50.0])[0, 0]), float(log.air_at([200.0])[0]), log.t0_s
    (25.0, 21.0, 0.0)
    """

    times_s: FloatArray
    legs_C: FloatArray
    air_C: FloatArray | None = None
    _lag_grids: dict[bytes, LagGrid] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    def lag_grid(self, times_s: npt.ArrayLike) -> LagGrid:
        """The legs' :class:`LagGrid` at ``times_s`` (kept for the last times asked)."""
        t = np.asarray(times_s, dtype=float).reshape(-1)
        key = t.tobytes()
        if key not in self._lag_grids:
            self._lag_grids.clear()
            self._lag_grids[key] = LagGrid.of(self.times_s, self.legs_C, t)
        return self._lag_grids[key]

    def __post_init__(self) -> None:
        times = np.asarray(self.times_s, dtype=float).reshape(-1)
        legs = np.asarray(self.legs_C, dtype=float)
        if times.size == 0:
            raise ValueError("the thermocouple log has no sample")
        if legs.shape != (times.size, 6):
            raise ValueError(
                f"leg temperatures must have shape ({times.size}, 6), got {legs.shape}"
            )
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(legs))):
            raise ValueError("the thermocouple log has a non-finite value")
        if np.any(np.diff(times) < 0):
            raise ValueError("thermocouple sample times go backwards")
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "legs_C", legs)
        if self.air_C is not None:
            air = np.asarray(self.air_C, dtype=float).reshape(-1)
            if air.shape != times.shape or not np.all(np.isfinite(air)):
                raise ValueError(f"air temperatures must be {times.size} finite values")
            object.__setattr__(self, "air_C", air)

    @property
    def t0_s(self) -> float:
        """Time of the first sample: the hexapod is in equilibrium there."""
        return float(self.times_s[0])

    def legs_at(self, times_s: npt.ArrayLike) -> FloatArray:
        """Leg temperatures (n, 6) at ``times_s``, samples joined by straight lines."""
        t = np.asarray(times_s, dtype=float).reshape(-1)
        return np.column_stack([np.interp(t, self.times_s, self.legs_C[:, j]) for j in range(6)])

    def air_at(self, times_s: npt.ArrayLike) -> FloatArray:
        """Air temperature (n,) at ``times_s``; InputError when the log has none."""
        if self.air_C is None:
            raise InputError("the temperatures have no 'air' column", field="air")
        return np.interp(np.asarray(times_s, dtype=float).reshape(-1), self.times_s, self.air_C)


def first_order_lag(
    times_s: npt.ArrayLike, values: npt.ArrayLike, tau_s: float, query_s: npt.ArrayLike
) -> FloatArray:
    """The first-order lag of a piecewise-linear signal, exactly, at ``query_s``.

    ``y`` solves ``dy/dt = (x(t) - y) / tau`` with ``y(t_0) = x(t_0)``, where ``x``
    joins the samples ``(times_s, values)`` by straight lines and holds after the
    last one (before ``t_0`` the system is at rest: ``y = x(t_0)``). On a segment
    where ``x(t) = x_j + b (t - t_j)`` the solution is, with ``d = t - t_j``,

        y(t) = x_j + b d - b tau (1 - exp(-d/tau)) + (y_j - x_j) exp(-d/tau)

    which gives ``y`` at every sample by recursion and between samples directly.

    Parameters
    ----------
    times_s : array_like, shape (m,)
        Sample times, non-decreasing.
    values : array_like, shape (m,) or (m, L)
        The signal at the samples (one column per channel).
    tau_s : float
        Time constant, positive.
    query_s : array_like, shape (n,)

    Returns
    -------
    ndarray, shape (n,) or (n, L)

    Examples
    --------
    A ramp ``x = t`` from rest: ``y = t - tau (1 - exp(-t/tau))``.

    >>> y = first_order_lag([0.0, 100.0], [0.0, 100.0], 10.0, [0.0, 10.0, 100.0])
    >>> bool(np.allclose(y, [0.0, 10 - 10 * (1 - np.exp(-1)), 100 - 10 * (1 - np.exp(-10))]))
    True
    """
    _check_tau(tau_s)
    return LagGrid.of(times_s, values, query_s).at(tau_s)


def _check_tau(tau_s: float) -> None:
    if not (np.isfinite(tau_s) and tau_s > 0):
        raise ValueError(f"the time constant must be positive, got {tau_s}")


@dataclass(frozen=True)
class LagGrid:
    """What :func:`first_order_lag` computes of a signal and query times whatever the
    time constant: kept, the lags at many time constants (a fit's) cost only the
    rest, with the same numbers.

    Attributes
    ----------
    h : ndarray, shape (m - 1,)
        Sample intervals.
    x : ndarray, shape (m, L)
        The samples.
    slope : ndarray, shape (m, L)
        Each segment's slope (0 after the last sample and on empty intervals).
    seg : ndarray of int, shape (n,)
        The segment of each query time.
    d : ndarray, shape (n, 1)
        Time of each query since its segment's start.
    x_seg, slope_seg : ndarray, shape (n, L)
        The samples and slopes of the query times' segments.
    flat : bool
        Whether the signal was one channel (m,).
    """

    h: FloatArray
    x: FloatArray
    slope: FloatArray
    seg: npt.NDArray[np.intp]
    d: FloatArray
    x_seg: FloatArray
    slope_seg: FloatArray
    flat: bool

    @classmethod
    def of(cls, times_s: npt.ArrayLike, values: npt.ArrayLike, query_s: npt.ArrayLike) -> LagGrid:
        t = np.asarray(times_s, dtype=float).reshape(-1)
        x = np.asarray(values, dtype=float)
        flat = x.ndim == 1
        x = x.reshape(t.size, -1)
        h = np.diff(t)
        slope = np.zeros((t.size, x.shape[1]))  # the last "segment" holds: slope 0
        moving = h > 0
        slope[:-1][moving] = np.diff(x, axis=0)[moving] / h[moving, None]
        q = np.asarray(query_s, dtype=float).reshape(-1)
        seg = np.clip(np.searchsorted(t, q, side="right") - 1, 0, t.size - 1)
        d = np.clip(q - t[seg], 0.0, None)[:, None]
        return cls(h, x, slope, seg, d, x[seg], slope[seg], flat)

    def at(self, tau_s: float) -> FloatArray:
        """The lag with time constant ``tau_s`` at the query times, (n,) or (n, L)."""
        _check_tau(tau_s)
        h, x, slope, seg, d = self.h, self.x, self.slope, self.seg, self.d
        # The recursion over the samples is linear, y_{j+1} = a_j y_j + c_j with
        # a_j = exp(-h_j / tau) and c_j = x_j (1 - a_j) + b_j (h_j - tau (1 - a_j)), so
        # its prefix compositions (a, c) o (a', c') = (a a', a c' + c) give every y_j
        # at once: log2(m) passes of doubling span (a parallel prefix scan), no loop
        # over the samples. The gains are the same for every channel: one column.
        y_nodes = np.empty_like(x)
        y_nodes[0] = x[0]
        if h.size:
            gain = np.exp(-h / tau_s)[:, None]
            rise = -np.expm1(-h / tau_s)[:, None]
            offset = x[:-1] * rise + slope[:-1] * (h[:, None] - tau_s * rise)
            span = 1
            while span < gain.shape[0]:
                offset[span:] = gain[span:] * offset[:-span] + offset[span:]
                gain[span:] = gain[span:] * gain[:-span]
                span *= 2
            y_nodes[1:] = gain * x[0] + offset
        decay = np.exp(-d / tau_s)
        rise_d = -np.expm1(-d / tau_s)  # 1 - exp(-d/tau), accurate for d << tau
        y_j, x_j, b = y_nodes[seg], self.x_seg, self.slope_seg
        out = x_j + b * (d - tau_s * rise_d) + (y_j - x_j) * decay
        return out[:, 0] if self.flat else out


# ---------------------------------------------------------------------- effects
#: the registry: contract name -> effect class
EFFECTS: dict[str, type[Effect]] = {}


#: a fitted parameter within this share of its range's span of a bound is at the bound
#: (a bounded least-squares fit stops a little inside it)
AT_BOUND = 1e-3


class Effect:
    """One effect of the twin with its parameter values.

    Subclasses set the class attributes and override the stage methods they
    change; defining a subclass with a ``name`` registers it in :data:`EFFECTS`.

    Attributes
    ----------
    name : str
        Contract name (the ``name`` of a ``thermal_model.effects`` entry).
    parameters : tuple of str
        Parameter names, in the order of :meth:`vector`.
    units : tuple of str
        Unit of each parameter.
    ranges : tuple of (float, float)
        A physically sensible range of each parameter (bounds for a fit; a
        simulation refuses values outside it).
    plausible : tuple of (float, float), optional
        Where a parameter of a real, physical instance of the effect lies, when
        that is much narrower than ``ranges`` (None: ``ranges``). A fitted value
        outside it is far from physical: ``diagnose`` then says the effect may be
        a stand-in for a cause outside its registry (:meth:`implausible`).
    needs_air : bool
        Whether the effect needs the air temperature of the log.
    summary : str
        What it changes, one line.
    values : dict of str to float
        The parameter values of this instance.

    Parameters
    ----------
    **values : float
        One finite value per parameter (exactly the class's ``parameters``).
    """

    name: ClassVar[str] = ""
    parameters: ClassVar[tuple[str, ...]] = ()
    units: ClassVar[tuple[str, ...]] = ()
    ranges: ClassVar[tuple[tuple[float, float], ...]] = ()
    plausible: ClassVar[tuple[tuple[float, float], ...] | None] = None
    needs_air: ClassVar[bool] = False
    summary: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if not cls.name:
            return
        if cls.name in EFFECTS:
            raise ValueError(f"effect {cls.name!r} is defined twice")
        if not (len(cls.parameters) == len(cls.units) == len(cls.ranges)):
            raise ValueError(f"effect {cls.name!r}: one unit and one range per parameter")
        EFFECTS[cls.name] = cls

    def __init__(self, **values: float) -> None:
        missing = [p for p in self.parameters if p not in values]
        unknown = [p for p in values if p not in self.parameters]
        if missing or unknown:
            raise ValueError(
                f"effect {self.name}: parameters are {', '.join(self.parameters)}"
                + (f"; missing {', '.join(missing)}" if missing else "")
                + (f"; unknown {', '.join(unknown)}" if unknown else "")
            )
        checked = {}
        for p in self.parameters:
            value = values[p]
            if isinstance(value, bool) or not np.isfinite(value):
                raise ValueError(f"effect {self.name}: {p} must be a finite number, got {value!r}")
            checked[p] = float(value)
        self.values: dict[str, float] = checked

    # ------------------------------------------------------------- parameters
    def __repr__(self) -> str:
        args = ", ".join(f"{p}={v!r}" for p, v in self.values.items())
        return f"{type(self).__name__}({args})"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Effect) and type(other) is type(self) and other.values == self.values
        )

    def __hash__(self) -> int:
        return hash((self.name, tuple(self.values.items())))

    def vector(self) -> FloatArray:
        """Parameter values in the order of ``parameters``."""
        return np.array([self.values[p] for p in self.parameters])

    @classmethod
    def from_vector(cls, values: Sequence[float]) -> Effect:
        """The effect with parameter values in the order of ``parameters``."""
        if len(values) != len(cls.parameters):
            raise ValueError(f"effect {cls.name}: expected {len(cls.parameters)} values")
        return cls(**dict(zip(cls.parameters, (float(v) for v in values), strict=True)))

    @classmethod
    def neutral(cls) -> FloatArray:
        """Parameter values that make the effect vanish (or nearly: a fit starts here).

        By default zero, brought into each parameter's range.
        """
        return np.array([min(max(0.0, lo), hi) for lo, hi in cls.ranges])

    @classmethod
    def scales(cls) -> FloatArray:
        """A typical magnitude of each parameter: a fit's unit step (default: range / 10)."""
        return np.array([(hi - lo) / 10.0 for lo, hi in cls.ranges])

    @classmethod
    def start_values(cls) -> list[FloatArray]:
        """Where a fit of the parameters may start (the best of them is kept).

        By default only :meth:`neutral`; an effect that is far from linear in its
        parameters gives several.
        """
        return [cls.neutral()]

    def out_of_range(self) -> dict[str, str]:
        """The parameters outside their sensible range: name -> what is wrong."""
        problems = {}
        for p, unit, (lo, hi) in zip(self.parameters, self.units, self.ranges, strict=True):
            if not lo <= self.values[p] <= hi:
                problems[p] = (
                    f"{self.values[p]:g} is outside the sensible range [{lo:g}, {hi:g}] {unit}"
                )
        return problems

    def at_bound(self, parameter: str) -> bool:
        """Whether a parameter's value is at a bound of its range (within
        :data:`AT_BOUND` of its span: a bounded fit stops there, not on it)."""
        lo, hi = self.ranges[self.parameters.index(parameter)]
        value, span = self.values[parameter], hi - lo
        return bool(value <= lo + AT_BOUND * span or value >= hi - AT_BOUND * span)

    def implausible(self) -> dict[str, str]:
        """The parameters far from physical: outside ``plausible`` (default ``ranges``),
        or at a bound of ``ranges`` (a fit stopped there): name -> why, in words."""
        plausible = self.plausible if self.plausible is not None else self.ranges
        problems = {}
        for p, unit, (lo, hi), (plo, phi) in zip(
            self.parameters, self.units, self.ranges, plausible, strict=True
        ):
            value = self.values[p]
            if self.at_bound(p):
                problems[p] = (
                    f"{p} = {value:.4g} {unit} is at a bound of its range [{lo:g}, {hi:g}]"
                )
            elif not plo <= value <= phi:
                problems[p] = (
                    f"{p} = {value:.4g} {unit} is outside what physics gives [{plo:g}, {phi:g}]"
                )
        return problems

    def as_dict(self) -> dict[str, Any]:
        """``{"name": ..., "parameters": {...}}``, as in a hexapod file's thermal model."""
        return {"name": self.name, "parameters": dict(self.values)}

    def per_leg(self) -> FloatArray:
        """Values of ``leg1`` .. ``leg6`` (for per-leg effects), shape (6,)."""
        return np.array([self.values[f"leg{i}"] for i in range(1, 7)])

    # ----------------------------------------------------------------- stages
    def leg_temperature_C(
        self, leg_C: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        """Stage 1: effective leg temperatures (n, 6) at ``times_s`` (n,)."""
        return leg_C

    def segment_temperature_C(
        self,
        segment_C: FloatArray,
        leg_C: FloatArray,
        leg0_C: FloatArray,
        variable: npt.NDArray[np.bool_],
    ) -> FloatArray:
        """Stage 2: segment temperatures (n, 6, S).

        ``leg_C`` (n, 6) are the effective leg temperatures, ``leg0_C`` (6,) the
        ones at ``t_0``, ``variable`` (6, S) marks the variable segment of each leg.
        """
        return segment_C

    def growth_mm(self, growth_mm: FloatArray) -> FloatArray:
        """Stage 3: thermal growth (n, 6) of each leg (see :meth:`leg_growth_mm`)."""
        return growth_mm

    def leg_growth_mm(
        self, growth_mm: FloatArray, leg_C: FloatArray, reference_C: float
    ) -> FloatArray:
        """Stage 3: thermal growth (n, 6), given each leg's effective temperature (n, 6).

        ``reference_C`` is the leg model's reference temperature (no growth there).
        By default :meth:`growth_mm`.
        """
        return self.growth_mm(growth_mm)

    def leg_length_mm(self, q_mm: FloatArray) -> FloatArray:
        """Stage 4: true leg lengths (n, 6) (see :meth:`commanded_leg_length_mm`)."""
        return q_mm

    def commanded_leg_length_mm(
        self, q_mm: FloatArray, q_cmd_mm: FloatArray, order: npt.NDArray[np.intp]
    ) -> FloatArray:
        """Stage 4: true leg lengths (n, 6), given the commanded ones (n, 6).

        ``order`` (n,) lists the steps in the order the hexapod moved through them.
        By default :meth:`leg_length_mm`.
        """
        return self.leg_length_mm(q_mm)

    def ball_positions_mm(
        self, balls_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        """Stage 5b: ball centres in the platform frame, (k, 3) or (n, k, 3), when each
        ball of each step was measured (``times_s``, (n, k))."""
        return balls_mm

    def base_joints_mm(
        self, base_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        """Stage 5: base joints, (6, 3) or (n, 6, 3), at ``times_s`` (n,)."""
        return base_mm

    def cmm_coordinates_mm(
        self, xyz_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        """Stage 6: the CMM's reading (..., 3) of true coordinates measured at ``times_s`` (...)."""
        return xyz_mm


_LEGS = tuple(f"leg{i}" for i in range(1, 7))


class LegThermalLag(Effect):
    """Each leg's temperature lags its thermocouple (first order, exact per segment).

    ``dT_eff/dt = (T_i - T_eff) / tau``, ``T_eff(t_0) = T_i(t_0)``, the samples
    joined by straight lines (:func:`first_order_lag`).
    """

    name = "leg_thermal_lag"
    parameters = ("tau_s",)
    units = ("s",)
    ranges = ((1.0, 86400.0),)
    summary = "each leg's temperature is the first-order lag of its thermocouple"

    @classmethod
    def scales(cls) -> FloatArray:
        return np.array([600.0])

    @classmethod
    def start_values(cls) -> list[FloatArray]:
        # far from linear in tau: start from a few time constants, minutes to hours
        return [np.array([tau]) for tau in (120.0, 600.0, 1800.0, 5400.0, 14400.0)]

    def leg_temperature_C(
        self, leg_C: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        # the first stage: leg_C is the thermocouple log itself, which is what lags
        return log.lag_grid(times_s).at(self.values["tau_s"])


class SteelOverheat(Effect):
    """The variable segment runs hotter: ``T_var = T_i + ratio (T_i - T_i(t_0))``."""

    name = "steel_overheat"
    parameters = ("ratio",)
    units = ("1",)
    ranges = ((-0.9, 5.0),)
    summary = "the variable segment (screw) warms ratio times more than the leg's thermocouple"

    def segment_temperature_C(
        self,
        segment_C: FloatArray,
        leg_C: FloatArray,
        leg0_C: FloatArray,
        variable: npt.NDArray[np.bool_],
    ) -> FloatArray:
        extra = self.values["ratio"] * (leg_C - leg0_C)  # (n, 6)
        return segment_C + variable * extra[..., None]


class LegCteError(Effect):
    """Leg i's thermal growth is multiplied by ``(1 + leg_i)``."""

    name = "leg_cte_error"
    parameters = _LEGS
    units = ("1",) * 6
    ranges = ((-0.5, 0.5),) * 6
    # a leg's expansion coefficient is known to about 10 % (one standard deviation: the
    # steel's grade, the screw's share of the length); 3 of them: beyond, a fitted error
    # stands in for another cause (a base joint that moves with the heat: issue 35)
    plausible = ((-0.3, 0.3),) * 6
    summary = "each leg's thermal growth is off by a relative error"

    def growth_mm(self, growth_mm: FloatArray) -> FloatArray:
        return growth_mm * (1.0 + self.per_leg())


class LegOffset(Effect):
    """Leg i is longer than commanded by a constant ``leg_i`` (mm)."""

    name = "leg_offset"
    parameters = _LEGS
    units = ("mm",) * 6
    ranges = ((-0.5, 0.5),) * 6
    # a homed leg's zero is known to about 50 um (one standard deviation); 3 of them:
    # beyond, the offsets stand in for the geometry (a base joint shifted: issue 35)
    plausible = ((-0.15, 0.15),) * 6
    summary = "each leg is longer than commanded by a constant"

    def leg_length_mm(self, q_mm: FloatArray) -> FloatArray:
        return q_mm + self.per_leg()


class BaseExpansion(Effect):
    """Base joints scale about their centroid with the air temperature.

    ``b(t) = c + (1 + alpha (T_air(t) - T_air(t_0))) (b - c)``.
    """

    name = "base_expansion"
    parameters = ("alpha_per_K",)
    units = ("1/K",)
    ranges = ((0.0, 30e-6),)
    needs_air = True
    summary = "the base expands with the air temperature (about its joints' centroid)"

    def base_joints_mm(
        self, base_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        t = np.asarray(times_s, dtype=float).reshape(-1)
        d_air = log.air_at(t) - log.air_at([log.t0_s])[0]
        scale = 1.0 + self.values["alpha_per_K"] * d_air  # (n,)
        base = np.broadcast_to(base_mm, (t.size, 6, 3))
        centre = base.mean(axis=1, keepdims=True)
        return centre + scale[:, None, None] * (base - centre)


class CmmDrift(Effect):
    """Every measured coordinate moves by ``v (t - t_0)``, in the CMM frame."""

    name = "cmm_drift"
    parameters = ("vx_um_per_h", "vy_um_per_h", "vz_um_per_h")
    units = ("um/h",) * 3
    ranges = ((-50.0, 50.0),) * 3
    summary = "the CMM's readings drift linearly in time"

    def cmm_coordinates_mm(
        self, xyz_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        v_mm_per_s = self.vector() * 1e-3 / _HOUR_S
        dt = np.asarray(times_s, dtype=float) - log.t0_s
        return np.asarray(xyz_mm, dtype=float) + dt[..., None] * v_mm_per_s


class BallPlateExpansion(Effect):
    """The balls' plate expands with the air temperature, about the platform origin.

    A ball measured at time ``t`` sits at ``(1 + alpha (T_air(t) - T_air(t_0))) p``
    in the platform frame, ``p`` its nominal position (the balls file); the
    platform joints do not move (a ball plate mounted on the platform, or the
    platform's top expanding above its joints).
    """

    name = "ball_plate_expansion"
    parameters = ("alpha_per_K",)
    units = ("1/K",)
    ranges = ((0.0, 30e-6),)
    needs_air = True
    summary = "the balls move apart with the air temperature (the plate's expansion)"

    def ball_positions_mm(
        self, balls_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        t = np.asarray(times_s, dtype=float)
        d_air = log.air_at(t.reshape(-1)).reshape(t.shape) - log.air_at([log.t0_s])[0]
        scale = 1.0 + self.values["alpha_per_K"] * d_air  # (n, k)
        return scale[..., None] * np.asarray(balls_mm, dtype=float)


class LegGrowthQuadratic(Effect):
    """Leg i grows by ``leg_i (T_i - T_ref)^2`` (um) on top of its linear growth.

    The expansion coefficient changing with temperature: a quadratic term of the
    growth in the leg's effective temperature ``T_i`` (after a lag) about the leg
    model's reference temperature, where the nominal lengths hold.
    """

    name = "leg_growth_quadratic"
    parameters = _LEGS
    units = ("um/K^2",) * 6
    ranges = ((-0.5, 0.5),) * 6
    # aluminium's expansion coefficient changes by about 0.02e-6/K per K near room
    # temperature: 0.5 L dalpha/dT is 0.003 um/K^2 for a 300 mm leg; 0.02 allows 7 times it
    plausible = ((-0.02, 0.02),) * 6
    summary = "each leg's growth has a term quadratic in its temperature"

    @classmethod
    def scales(cls) -> FloatArray:
        return np.full(6, 0.01)

    def leg_growth_mm(
        self, growth_mm: FloatArray, leg_C: FloatArray, reference_C: float
    ) -> FloatArray:
        return growth_mm + 1e-3 * self.per_leg() * (np.asarray(leg_C) - reference_C) ** 2


class CmmScale(Effect):
    """The CMM reads every coordinate scaled by ``1 + s`` per axis (ppm), about its origin."""

    name = "cmm_scale"
    parameters = ("sx_ppm", "sy_ppm", "sz_ppm")
    units = ("ppm",) * 3
    ranges = ((-200.0, 200.0),) * 3
    summary = "the CMM's scales are off by a few ppm per axis"

    @classmethod
    def scales(cls) -> FloatArray:
        return np.full(3, 10.0)

    def cmm_coordinates_mm(
        self, xyz_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        return np.asarray(xyz_mm, dtype=float) * (1.0 + 1e-6 * self.vector())


class LegBacklash(Effect):
    """Leg i is off by ``+leg_i`` (mm) after it last extended and ``-leg_i`` after it
    last retracted (approach-direction backlash); a leg not yet moved is not off.

    The direction of a leg's last move is the sign of the change of its commanded
    length from the previous step, in the order the steps were moved through
    (steps that leave a leg where it was, to 1e-9 mm, keep its direction). A
    negative ``leg_i`` is a leg that stops short of its target. The same in the
    reference thermal state: it is not thermal.
    """

    name = "leg_backlash"
    parameters = _LEGS
    units = ("mm",) * 6
    ranges = ((-0.05, 0.05),) * 6
    summary = "each leg is off by a constant whose sign follows the direction of its last move"

    @classmethod
    def scales(cls) -> FloatArray:
        return np.full(6, 0.002)

    @staticmethod
    def directions(q_cmd_mm: FloatArray, order: npt.NDArray[np.intp]) -> FloatArray:
        """The direction (n, 6) of each leg's last move before each step: +1, -1 or 0.

        >>> q = np.array([[0.0] * 6, [1.0] * 6, [1.0] * 6, [0.5] * 6])
        >>> LegBacklash.directions(q, np.arange(4))[:, 0].tolist()
        [0.0, 1.0, 1.0, -1.0]
        """
        q = np.asarray(q_cmd_mm, dtype=float)[order]
        move = np.zeros_like(q)
        change = np.diff(q, axis=0)
        move[1:] = np.where(np.abs(change) > 1e-9, np.sign(change), 0.0)
        # carry the last nonzero move forward: index of the last step that moved
        step = np.arange(q.shape[0])[:, None]
        last = np.maximum.accumulate(np.where(move != 0, step, 0), axis=0)
        sign = np.take_along_axis(move, last, axis=0)
        out = np.empty_like(sign)
        out[order] = sign
        return out

    def commanded_leg_length_mm(
        self, q_mm: FloatArray, q_cmd_mm: FloatArray, order: npt.NDArray[np.intp]
    ) -> FloatArray:
        return q_mm + self.directions(q_cmd_mm, order) * self.per_leg()


# ---------------------------------------------------------------------- helpers
def make_effect(name: str, parameters: Mapping[str, float]) -> Effect:
    """The effect called ``name`` with ``parameters``; ValueError for unknown names."""
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; expected one of {', '.join(EFFECTS)}")
    return EFFECTS[name](**dict(parameters))


def effects_from_dicts(items: Iterable[Mapping[str, Any]]) -> tuple[Effect, ...]:
    """Effects from ``{"name": ..., "parameters": {...}}`` entries (a thermal model)."""
    return tuple(make_effect(item["name"], item["parameters"]) for item in items)


def check_distinct(effects: Sequence[Effect]) -> None:
    """ValueError when an effect is given twice (their parameters would be ambiguous)."""
    seen: set[str] = set()
    for effect in effects:
        if effect.name in seen:
            raise ValueError(f"effect {effect.name} is given twice")
        seen.add(effect.name)
