"""Summaries of where the twin and the measurements disagree: tables' numbers and tests.

The diagnosis (:mod:`hexatherm.core.diagnosis`) gives, for every step, the
residual between the measured pose and the twin's prediction (six pose
components, and the six legs through the IGM) and the RMS of the step's centre
residuals (a :class:`~hexatherm.core.diagnosis.PoseResiduals`). This module
sums them up, with no I/O:

* RMS and mean of each pose component, RMS and mean of each leg;
* RMS of the centre residuals by step kind and by quarter of the session;
* the worst steps (largest centre RMS);
* for every series (six pose components, six legs), in time order: a
  whiteness test (Ljung-Box), a linear trend against time (slope, standard
  error, t), and Spearman's rank correlation with time and with temperature.

A model that explains the measurements leaves residuals that are white noise:
no autocorrelation, no trend, no dependence on temperature. The p-values are
those of each test alone (not corrected for the twelve series), and the
trend's and correlations' p-values assume independent residuals: read them as
"this series has structure", not as exact probabilities when it is not white.

>>> rng = np.random.default_rng(0)
>>> r = ljung_box(rng.standard_normal(200))
>>> r.lags, bool(r.p_value > 0.05)
(10, True)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.ranktests import chi2_sf, t_sf
from hexatherm.core.ranktests import spearman as rank_correlation
from hexatherm.typing import FloatArray

#: names and units of the six pose components (residuals in um and urad)
POSE_COMPONENTS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
POSE_UNITS = ("um", "um", "um", "urad", "urad", "urad")
LEG_NAMES = ("leg1", "leg2", "leg3", "leg4", "leg5", "leg6")
STEP_KINDS = ("origin", "reference", "target")
#: significance level of the flags ("white", "trend") in tables
ALPHA = 0.05
#: most lags of the Ljung-Box test
MAX_LAGS = 10
#: parts of the session in time order for the RMS over time
TIME_PARTS = 4
_HOUR_S = 3600.0


# ------------------------------------------------------------ the residuals
@dataclass(frozen=True)
class PoseResiduals:
    """Measured minus predicted, per step, in pose and leg space.

    Attributes
    ----------
    pose_um : ndarray, shape (N, 6)
        ``Tx, Ty, Tz`` in um and ``Rx, Ry, Rz`` in urad: the measured pose minus the
        predicted one, both relative to the fitted frame O.
    legs_um : ndarray, shape (N, 6)
        IGM leg lengths of the measured pose minus those of the predicted one.
    centre_rms_um : ndarray, shape (N,)
        RMS of each step's centre residuals.
    """

    pose_um: FloatArray
    legs_um: FloatArray
    centre_rms_um: FloatArray


def time_blocks(times_s: npt.ArrayLike, n_blocks: int = 6) -> npt.NDArray[np.intp]:
    """Block number (0 .. n_blocks-1) of every step: contiguous runs in time order.

    >>> time_blocks([5.0, 1.0, 2.0, 3.0, 4.0, 0.0], 3).tolist()
    [2, 0, 1, 1, 2, 0]
    """
    t = np.asarray(times_s, dtype=float)
    order = np.argsort(t, kind="stable")
    blocks = np.empty(t.size, dtype=np.intp)
    blocks[order] = np.arange(t.size) * n_blocks // max(t.size, 1)
    return blocks


# ------------------------------------------------------------------ the tests
@dataclass(frozen=True)
class LjungBox:
    """Ljung-Box portmanteau test of a series' autocorrelation.

    Attributes
    ----------
    q : float
        ``Q = n (n + 2) sum_{k=1..h} r_k^2 / (n - k)``, ``r_k`` the lag-k sample
        autocorrelation (about the mean).
    lags : int
        ``h``, the number of lags summed.
    p_value : float
        ``P(chi2_h > Q)``: small when the series is autocorrelated (not white).
    """

    q: float
    lags: int
    p_value: float

    def white(self, alpha: float = ALPHA) -> bool:
        """Whether whiteness is *not* rejected at level ``alpha``."""
        return bool(self.p_value >= alpha)


@dataclass(frozen=True)
class Trend:
    """Least-squares straight line of a series against time.

    Attributes
    ----------
    slope_per_h : float
        Slope, in the series' unit per hour.
    std_error_per_h : float
        Its standard error (residual variance with ``n - 2`` degrees of freedom).
    t : float
        ``slope / std_error``.
    p_value : float
        Two-sided, Student's t with ``n - 2`` degrees of freedom.
    """

    slope_per_h: float
    std_error_per_h: float
    t: float
    p_value: float

    def significant(self, alpha: float = ALPHA) -> bool:
        """Whether the slope differs from zero at level ``alpha``."""
        return bool(self.p_value < alpha)


@dataclass(frozen=True)
class Correlation:
    """Spearman's rank correlation ``rho`` and its two-sided p-value (nan when undefined)."""

    rho: float
    p_value: float


def default_lags(n: int) -> int:
    """Lags of the Ljung-Box test for ``n`` values: ``min(10, n // 5)``, at least 1.

    >>> default_lags(26), default_lags(200), default_lags(3)
    (5, 10, 1)
    """
    return max(1, min(MAX_LAGS, n // 5))


def autocorrelation(x: npt.ArrayLike, lags: int) -> FloatArray:
    """Sample autocorrelation ``r_1 .. r_lags`` of a series (about its mean).

    ``r_k = sum_{t>=k} (x_t - m)(x_{t-k} - m) / sum_t (x_t - m)^2``; all nan for a
    constant series.
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    d = x - x.mean()
    denominator = float(d @ d)
    if denominator == 0.0:
        return np.full(lags, np.nan)
    return np.array([float(d[k:] @ d[:-k]) / denominator for k in range(1, lags + 1)])


def ljung_box(x: npt.ArrayLike, lags: int | None = None) -> LjungBox:
    """Ljung-Box test of whiteness of a series taken in time order.

    Parameters
    ----------
    x : array_like, shape (n,)
        The series, in time order.
    lags : int, optional
        Lags summed (default :func:`default_lags`); fewer than ``n``.

    Returns
    -------
    LjungBox
        nan ``q`` and p-value for a constant series or fewer than 3 values.

    Examples
    --------
    >>> r = ljung_box([1.0, 2.0, 0.0, 1.0], lags=1)   # r_1 = -1/2
    >>> round(r.q, 6), r.lags
    (2.0, 1)
    """
    x = np.asarray(x, dtype=float).reshape(-1)
    n = x.size
    h = default_lags(n) if lags is None else int(lags)
    if n < 3 or not 1 <= h < n:
        return LjungBox(float("nan"), h, float("nan"))
    r = autocorrelation(x, h)
    if np.any(np.isnan(r)):
        return LjungBox(float("nan"), h, float("nan"))
    k = np.arange(1, h + 1)
    q = float(n * (n + 2) * np.sum(r**2 / (n - k)))
    return LjungBox(q, h, chi2_sf(q, h))


def linear_trend(times_s: npt.ArrayLike, y: npt.ArrayLike) -> Trend:
    """Least-squares slope of ``y`` against time, with its standard error and t.

    Examples
    --------
    >>> tr = linear_trend([0.0, 3600.0, 7200.0, 10800.0], [1.0, 3.0, 5.0, 7.0])
    >>> tr.slope_per_h, tr.std_error_per_h
    (2.0, 0.0)
    """
    t = np.asarray(times_s, dtype=float).reshape(-1) / _HOUR_S
    y = np.asarray(y, dtype=float).reshape(-1)
    n = t.size
    sxx = float(np.sum((t - t.mean()) ** 2)) if n else 0.0
    if n < 2 or sxx == 0.0:
        return Trend(float("nan"), float("nan"), float("nan"), float("nan"))
    slope = float(np.sum((t - t.mean()) * (y - y.mean())) / sxx)
    if n < 3:
        return Trend(slope, float("nan"), float("nan"), float("nan"))
    fitted = y.mean() + slope * (t - t.mean())
    s2 = float(np.sum((y - fitted) ** 2)) / (n - 2)
    se = float(np.sqrt(s2 / sxx))
    if se == 0.0:
        return Trend(
            slope, 0.0, float("inf") if slope else float("nan"), 0.0 if slope else float("nan")
        )
    t_value = slope / se
    return Trend(slope, se, t_value, 2 * t_sf(abs(t_value), n - 2))


def spearman(x: npt.ArrayLike, y: npt.ArrayLike) -> Correlation:
    """Spearman's rank correlation of ``x`` and ``y`` (nan when either is constant)."""
    x = np.asarray(x, dtype=float).reshape(-1)
    y = np.asarray(y, dtype=float).reshape(-1)
    if x.size < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return Correlation(float("nan"), float("nan"))
    return Correlation(*rank_correlation(x, y))


# ---------------------------------------------------------------- the summary
@dataclass(frozen=True)
class SeriesTests:
    """The tests of one residual series (a pose component or a leg).

    Attributes
    ----------
    name, unit : str
        e.g. ``"Tx"``, ``"um"``; ``"leg3"``, ``"um"``.
    whiteness : LjungBox
    trend : Trend
    vs_time : Correlation
    vs_temperature : Correlation
        With the mean leg temperature (pose components) or the leg's own
        temperature (legs) at each step.
    """

    name: str
    unit: str
    whiteness: LjungBox
    trend: Trend
    vs_time: Correlation
    vs_temperature: Correlation


@dataclass(frozen=True)
class WorstStep:
    """A step with a large centre residual."""

    index: int
    label: str
    kind: str
    time_s: float
    centre_rms_um: float


@dataclass(frozen=True)
class ResidualSummary:
    """Summary of the residuals of one model (e.g. before or after the diagnosis).

    Attributes
    ----------
    n_steps : int
    centre_rms_um : float
        RMS of every centre residual (all steps).
    component_rms, component_mean : ndarray, shape (6,)
        Of ``Tx, Ty, Tz`` (um) and ``Rx, Ry, Rz`` (urad).
    leg_rms_um, leg_mean_um : ndarray, shape (6,)
    kind_rms_um : dict of str to float
        RMS of the centre residuals of the steps of each kind present.
    kind_count : dict of str to int
    part_rms_um : ndarray, shape (TIME_PARTS,)
        RMS of the centre residuals in each quarter of the steps, in time order.
    part_span_s : ndarray, shape (TIME_PARTS, 2)
        First and last step time of each part (nan when empty).
    worst : tuple of WorstStep
        Largest centre RMS first.
    tests : tuple of SeriesTests
        Six pose components, then six legs.
    """

    n_steps: int
    centre_rms_um: float
    component_rms: FloatArray
    component_mean: FloatArray
    leg_rms_um: FloatArray
    leg_mean_um: FloatArray
    kind_rms_um: dict[str, float]
    kind_count: dict[str, int]
    part_rms_um: FloatArray
    part_span_s: FloatArray
    worst: tuple[WorstStep, ...]
    tests: tuple[SeriesTests, ...]

    @property
    def pose_tests(self) -> tuple[SeriesTests, ...]:
        return self.tests[:6]

    @property
    def leg_tests(self) -> tuple[SeriesTests, ...]:
        return self.tests[6:]


def rms(x: npt.ArrayLike, axis: int | None = None) -> FloatArray:
    """Root mean square of ``x`` (over ``axis``; all of it by default).

    >>> rms([[3.0, 1.0], [4.0, 1.0]], axis=0).tolist()
    [3.5355339059327378, 1.0]
    """
    return np.asarray(np.sqrt(np.mean(np.square(np.asarray(x, dtype=float)), axis=axis)))


def summarize(
    residuals: PoseResiduals,
    labels: Sequence[str],
    kinds: Sequence[str],
    times_s: npt.ArrayLike,
    temperature_C: npt.ArrayLike,
    *,
    n_worst: int = 5,
) -> ResidualSummary:
    """Summarize one model's residuals.

    Parameters
    ----------
    residuals : PoseResiduals
        ``pose_um`` (N, 6), ``legs_um`` (N, 6), ``centre_rms_um`` (N,).
    labels, kinds : sequence of str, length N
        The plan's step labels and kinds.
    times_s : array_like, shape (N,)
        Step times, seconds (any origin).
    temperature_C : array_like, shape (N,) or (N, 6)
        Leg temperatures at each step (``log.legs_at(times_s)``) or their mean.
        Pose components are compared with the mean over the legs, each leg's
        residual with its own column (with the mean when 1-D).
    n_worst : int
        How many worst steps to keep.

    Returns
    -------
    ResidualSummary

    Examples
    --------
    >>> n = 20
    >>> res = PoseResiduals(np.ones((n, 6)), np.zeros((n, 6)), np.full(n, 2.0))
    >>> s = summarize(res, [f"S{i}" for i in range(n)], ["target"] * n,
    ...               np.arange(n) * 60.0, np.full(n, 20.0))
    >>> s.component_rms.tolist(), s.kind_rms_um, s.worst[0].label
    ([1.0, 1.0, 1.0, 1.0, 1.0, 1.0], {'target': 2.0}, 'S0')
    """
    pose = np.asarray(residuals.pose_um, dtype=float)
    legs = np.asarray(residuals.legs_um, dtype=float)
    step_rms = np.asarray(residuals.centre_rms_um, dtype=float).reshape(-1)
    n = step_rms.size
    times = np.asarray(times_s, dtype=float).reshape(-1)
    temp = np.asarray(temperature_C, dtype=float)
    if pose.shape != (n, 6) or legs.shape != (n, 6):
        raise ValueError(f"pose and leg residuals must have shape ({n}, 6)")
    if len(labels) != n or len(kinds) != n or times.shape != (n,):
        raise ValueError(f"need one label, kind and time per step ({n})")
    if temp.shape not in ((n,), (n, 6)):
        raise ValueError(f"temperatures must have shape ({n},) or ({n}, 6), got {temp.shape}")
    mean_temp = temp if temp.ndim == 1 else temp.mean(axis=1)
    leg_temp = np.column_stack([mean_temp] * 6) if temp.ndim == 1 else temp

    kind_rms, kind_count = {}, {}
    for kind in [*STEP_KINDS, *sorted(set(kinds) - set(STEP_KINDS))]:
        sel = np.array([k == kind for k in kinds], dtype=bool)
        if sel.any():
            kind_rms[kind] = float(rms(step_rms[sel]))
            kind_count[kind] = int(sel.sum())

    blocks = time_blocks(times, TIME_PARTS)
    part_rms = np.full(TIME_PARTS, np.nan)
    part_span = np.full((TIME_PARTS, 2), np.nan)
    for b in range(TIME_PARTS):
        sel = blocks == b
        if sel.any():
            part_rms[b] = rms(step_rms[sel])
            part_span[b] = times[sel].min(), times[sel].max()

    order_worst = np.argsort(-step_rms, kind="stable")[: max(0, n_worst)]
    worst = tuple(
        WorstStep(int(i), str(labels[i]), str(kinds[i]), float(times[i]), float(step_rms[i]))
        for i in order_worst
    )

    order = np.argsort(times, kind="stable")
    tests = []
    series = [(POSE_COMPONENTS[j], POSE_UNITS[j], pose[:, j], mean_temp) for j in range(6)]
    series += [(LEG_NAMES[j], "um", legs[:, j], leg_temp[:, j]) for j in range(6)]
    for name, unit, y, temperature in series:
        tests.append(
            SeriesTests(
                name,
                unit,
                ljung_box(y[order]),
                linear_trend(times, y),
                spearman(times, y),
                spearman(temperature, y),
            )
        )

    return ResidualSummary(
        n_steps=n,
        centre_rms_um=float(rms(step_rms)) if n else float("nan"),
        component_rms=rms(pose, axis=0),
        component_mean=pose.mean(axis=0),
        leg_rms_um=rms(legs, axis=0),
        leg_mean_um=legs.mean(axis=0),
        kind_rms_um=kind_rms,
        kind_count=kind_count,
        part_rms_um=part_rms,
        part_span_s=part_span,
        worst=worst,
        tests=tuple(tests),
    )
