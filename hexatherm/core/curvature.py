"""The interpolation's own error between references: the shape of the growth.

Linear interpolation of the growth at R between the references before (``t0``) and after
(``t1``) a target is exact for a growth that is a straight line in time; for one that
bends, it errs at the target's time ``t`` by ``e(t) = (t - t0)(t1 - t) / 2 * g''`` (the
interpolation error of a straight line through two points of a function whose second
derivative is ``g''`` there; exact for a quadratic). A target that takes one reference
only (``before``/``after``/``nearest``, or two targets between two references: the
first takes the reference before it, the second the one after) errs at first order,
by the growth between that reference and its own time. The propagation carries the
references' noise, not these errors: under a heating that bends between references the
corrected poses then claimed down to 0.22x of their error against the twin's truth
(issue 35, two targets per pair of references).

The references' growth shows both without a log. With ``W`` the interpolation's weights
of the target over the references (what the correction used) and ``L`` the straight
line's through the two references around the target in time, the error is ``(W - L) g``
(first order; zero for linear between those two) plus the straight line's
``f g''``, ``f = (t - t0)(t1 - t) / 2``. The references' second divided differences, leg
by leg, ``2 g[t_(i-1), t_i, t_(i+1)]``, estimate ``g''`` around each inner reference; the
target takes the mean of the stencils centred on the two around it (the one there is at
the ends). So the error is ``c G`` for one vector ``c = W - L + f s`` over the
references (``s`` the stencil). Its noise, from the references' own (``S_j`` the 6x6
covariance of reference j's leg lengths), is ``N = sum_j c_j^2 S_j``; O's and R0's noise
is common to every reference's growth and cancels (``c`` sums to zero).
``E[(cG)(cG)^T] = e e^T + N``: the noise's share is taken off as one scalar over the legs
(``share = max(0, 1 - tr N / |cG|^2)``, the legs share one heating history), so what the
propagation already holds of the references' noise is not counted twice, and the
covariance added to the growth at R at the target is ``share (cG)(cG)^T``: a Type A
evaluation of the growth's shape, a Type B one of the quadratic model across the
interval. ``f`` grows with the square of the interval: a gap between references is
covered by the same term, as far as the references around it show its curvature.

A target past the last reference (extrapolated: it takes the last reference alone) errs
by the growth since that reference: ``L`` is then the line through the last two
references carried on to its time, and ``f`` (negative there) the straight line's
extrapolation error, with the stencil of the last inner reference; the same ``c``. With
two references only, the first-order part alone (no curvature to read).

Two targets in one interval between the same two references (or both past the last one)
err by the same growth curve's error there: ``e_a = c_a G`` and ``e_b = c_b G`` read the
same references, and their errors are as correlated as those vectors say (of opposite
signs for the two targets of T T R, one taking the reference before, the other the one
after). So each target's error is the vector ``v = sqrt(share) c G`` (its covariance
``v v^T``) and its interval (:attr:`CurvatureError.interval`): the covariance between two
targets of one interval is ``v_a v_b^T``; targets of different intervals are taken as
independent (each interval's curvature read from its own references).

The interval's own curvature (issue 35, an independent generator's kinks): each
stencil is the growth's curvature averaged under a hat over the two intervals around
its reference, so the two stencils around a target's interval hold half of a kink
inside it, and their mean half of it again; a heating switched on inside the interval
(or settling in a gap) read so claimed 0.34 of the corrected Tx error (two time
constants, a 30 min pause). With a stencil on either side of those two, the interval's
own curvature is ``s_p + s_(p+1) - (s_(p-1) + s_(p+2)) / 2`` (the outer stencils read
off the halves of the neighbouring intervals' curvature; a quadratic: the same as the
mean, a kink inside: twice it). Both are evaluated (each with its noise's share off)
and the larger error taken: the references do not tell whether the curvature is spread
over the intervals or inside this one.

Where it holds: a growth whose curvature changes little over three references, or one
bend inside the interval; a step (a rise and a settling both inside one interval) has
no curvature the stencils read in sum, and one that starts or settles past the last
reference is extrapolated (a limit: docs/uncertainty.md). A target before the first
reference is not evaluated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.typing import FloatArray

__all__ = [
    "LEGS_DIFFER",
    "CurvatureError",
    "curvature_error",
    "second_shape",
    "scatter_off_heating",
    "second_difference_stencils",
]


@dataclass(frozen=True)
class CurvatureError:
    """The straight line's own error of the growth at R at each target.

    Attributes
    ----------
    cov_mm2 : ndarray, shape (M, 6, 6)
        Covariance of the growth at R at each target (zero where nothing was evaluated):
        ``v v^T`` of :attr:`vector_mm`.
    error_um : ndarray, shape (M,)
        RMS over the legs of that error (``sqrt(tr / 6)``), um.
    evaluated : ndarray of bool, shape (M,)
        Targets with an error evaluated.
    source : {"curvature", "log"}
        The references' curvature (:func:`curvature_error`), or the straight line's error
        on a growth shaped as a thermocouple log (set by the caller).
    widest_gap : float
        The longest interval between consecutive references over their median one.
    vector_mm : ndarray, shape (M, 6)
        Each target's error ``v`` of the growth at R (``cov_mm2 = v v^T``), mm.
    interval : ndarray of int, shape (M,)
        The interval of each target: the index of the reference before it (the last
        one for a target past it); -1 where nothing was evaluated. Two targets of one
        interval share their error: covariance ``v_a v_b^T``.
    past : ndarray of bool, shape (M,), optional
        The targets past the last reference.
    second_shape : float
        The references' growth's second shape's energy over its noise's
        (:func:`second_shape`; 0: not read). Beyond :data:`LEGS_DIFFER` the legs'
        histories differ, which O's carry does not hold (a limit), and this term
        takes :attr:`vector_mm` along the growth's first shape and the rest leg by leg.
    spread_mm : ndarray, shape (M, 6), optional
        Where the legs' histories differ: each leg's part of the error beyond the
        growth's first shape, taken as independent between the legs (covariance
        ``diag(d^2)``; between two targets of one interval ``diag(d_a d_b)``), mm.
    """

    cov_mm2: FloatArray
    error_um: FloatArray
    evaluated: npt.NDArray[np.bool_]
    source: str = "curvature"
    widest_gap: float = 1.0
    vector_mm: FloatArray | None = None
    interval: npt.NDArray[np.intp] | None = None
    past: npt.NDArray[np.bool_] | None = None
    second_shape: float = 0.0
    spread_mm: FloatArray | None = None

    @classmethod
    def from_vectors(
        cls,
        vector_mm: FloatArray,
        interval: npt.NDArray[np.intp],
        source: str = "curvature",
        widest_gap: float = 1.0,
        past: npt.NDArray[np.bool_] | None = None,
        second_shape: float = 0.0,
        spread_mm: FloatArray | None = None,
    ) -> CurvatureError:
        """From each target's error vector ``v`` (M, 6) and its interval (M,; -1: none);
        ``past``: the targets past the last reference; ``second_shape``: see
        :func:`second_shape`; ``spread_mm`` (M, 6): each leg's own part, independent
        between the legs (:attr:`spread_mm`)."""
        v = np.where((interval >= 0)[:, None], vector_mm, 0.0)
        d = None if spread_mm is None else np.where((interval >= 0)[:, None], spread_mm, 0.0)
        cov = v[:, :, None] * v[:, None, :]
        if d is not None:
            cov = cov + d[:, :, None] ** 2 * np.eye(6)
        return cls(
            cov,
            np.sqrt(np.mean(v**2 + (0.0 if d is None else d**2), axis=1)) * 1e3,
            np.asarray(interval >= 0, dtype=bool),
            source,
            widest_gap,
            v,
            np.asarray(interval, dtype=np.intp),
            None if past is None else np.asarray(past & (interval >= 0), dtype=bool),
            second_shape,
            d,
        )


#: the references' growth's second shape beyond this many times its noise's energy: the
#: legs' histories differ (:func:`second_shape`)
LEGS_DIFFER = 4.0


def second_shape(growth_mm: npt.ArrayLike, leg_cov_mm2: npt.ArrayLike) -> float:
    """How far the references' growth (n, 6: since the first, ``q_R - q_R0``) follows a
    second shape over the legs beyond its noise: the energy of its second singular vector
    ``s`` (its squared singular value) over the noise's along it, ``sum_(j>0) s^T (S_j +
    S_0) s`` (``S_j`` reference j's leg covariance, (n, 6, 6); each growth holds the
    first reference's noise too); 0 with fewer than three references.

    Legs that share one heating history (every leg a gain times one history in time)
    grow along one shape, and the curvature of the references' growth and O's carry read
    them so; legs lagging one another or heated unevenly follow two or more. Over 30
    noise replicas each (1 um point noise, 3 balls, 7 references 400 s apart), the
    second shape held 0.1-2.7x its noise where the legs share one history (the twin's
    heatings from the start, mid-session, after a 30 min pause, none; two time
    constants, a ramp, a step; once 5.4x of 120 with five references), 2.8-28x (22 of 30
    beyond :data:`LEGS_DIFFER`) under the air drifting periodically with the legs lagging
    0-400 s, 11-25x with the legs heated unevenly (``tests/heatgen.py``).

    >>> t = np.arange(7.0)[:, None]
    >>> cov = np.broadcast_to(np.eye(6) * 1e-6, (7, 6, 6))
    >>> one = t * np.array([3.0, 7, 2, 3, 9, 3.5]) * 1e-3       # one history
    >>> lag = np.sin(t - np.arange(6) * 0.5) * 5e-3              # lagging legs
    >>> bool(second_shape(one, cov) < 1e-20), bool(second_shape(lag, cov) > LEGS_DIFFER)
    (True, True)
    """
    g = np.asarray(growth_mm, dtype=float)
    cov = np.asarray(leg_cov_mm2, dtype=float)
    if g.shape[0] < 3:
        return 0.0
    _, sv, vt = np.linalg.svd(g, full_matrices=False)
    noise = float(vt[1] @ (cov[1:] + cov[:1]).sum(axis=0) @ vt[1])
    return float(sv[1] ** 2 / noise) if noise > 0 else 0.0


def second_difference_stencils(times_s: npt.ArrayLike) -> FloatArray:
    """Stencils of the second derivative at each inner reference from its neighbours,
    ``2 g[t_(i-1), t_i, t_(i+1)]``, as three diagonals (n, 3): row i holds the
    coefficients of references i-1, i and i+1 (rows 0, n-1 and any whose neighbours
    share a time are zero).

    >>> t = np.array([0.0, 1.0, 3.0])
    >>> s = second_difference_stencils(t)
    >>> float(s[1] @ t[0:3] ** 2)   # exact for a quadratic: g'' = 2
    2.0
    """
    t = np.asarray(times_s, dtype=float)
    n = len(t)
    out = np.zeros((n, 3))
    if n < 3:
        return out
    h1, h2 = np.diff(t)[:-1], np.diff(t)[1:]
    ok = (h1 > 0) & (h2 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inner = np.stack([2 / (h1 * (h1 + h2)), -2 / (h1 * h2), 2 / (h2 * (h1 + h2))], axis=1)
    out[1:-1] = np.where(ok[:, None], inner, 0.0)
    return out


def _sparse_rows(
    used_weights: npt.ArrayLike, used_columns: npt.ArrayLike | None, m: int, n: int
) -> tuple[npt.NDArray[np.intp], FloatArray]:
    """The weights as columns and values (M, K): from dense (M, n) rows, their nonzero
    entries (zero-padded, column 0), or as given."""
    if used_columns is not None:
        columns = np.asarray(used_columns, dtype=np.intp).reshape(m, -1)
        return columns, np.asarray(used_weights, dtype=float).reshape(m, -1)
    dense = np.asarray(used_weights, dtype=float).reshape(m, n)
    nonzero = dense != 0.0
    k = max(int(nonzero.sum(axis=1).max(initial=0)), 1)
    # each row's nonzero columns first, in order (a stable sort of "is zero")
    order = np.argsort(~nonzero, axis=1, kind="stable")[:, :k]
    keep = np.take_along_axis(nonzero, order, axis=1)
    values = np.where(keep, np.take_along_axis(dense, order, axis=1), 0.0)
    return np.where(keep, order, 0).astype(np.intp), values


def curvature_error(
    ref_times_s: npt.ArrayLike,
    ref_growth_mm: npt.ArrayLike,
    ref_leg_cov_mm2: npt.ArrayLike,
    target_times_s: npt.ArrayLike,
    used_weights: npt.ArrayLike,
    spacing_seen_s: float = 0.0,
    used_columns: npt.ArrayLike | None = None,
    by_leg: bool = True,
) -> CurvatureError:
    """The interpolation's own error of the growth at R at each target (module
    docstring).

    Parameters
    ----------
    ref_times_s : array_like, shape (n,)
        Times of the references, increasing.
    ref_growth_mm : array_like, shape (n, 6)
        Growth of every leg at the references (``q_R - q_R0``; any common offset cancels).
    ref_leg_cov_mm2 : array_like, shape (n, 6, 6)
        Covariance of each reference's leg lengths from its own centres.
    target_times_s : array_like, shape (M,)
    used_weights : array_like, shape (M, n), or (M, K) with ``used_columns``
        The interpolation's weights of each target over the references (rows summing to
        1: the two neighbours', or 1 on the one reference used); a row of zeros: none.
    spacing_seen_s : float
        An interval whose error is already evaluated elsewhere (the smooth fit's residuals
        see its error at the references' spacing): ``f`` is taken beyond that of a target
        halfway across it, ``max(0, f - spacing^2 / 8)``. 0: the whole of ``f``.
    used_columns : array_like of int, shape (M, K), optional
        The references ``used_weights`` (then (M, K)) are on, K a target
        (:func:`~hexatherm.workflows.process.smootherror.neighbour_weights`' form: two, a
        side not used weighing 0); a column given twice adds its weights.
    by_leg : bool
        Where the legs' histories differ (:func:`second_shape` beyond
        :data:`LEGS_DIFFER`), the error beyond the growth's first shape leg by leg
        (:attr:`CurvatureError.spread_mm`); False: one vector always.

    Returns
    -------
    CurvatureError

    Examples
    --------
    A quadratic growth, noise-free: the error of the straight line exactly.

    >>> t = np.array([0.0, 100.0, 200.0, 300.0])
    >>> g = np.outer(1e-6 * t**2, np.ones(6))
    >>> err = curvature_error(t, g, np.zeros((4, 6, 6)), [150.0], [[0, 0.5, 0.5, 0]])
    >>> lin = (g[1] + g[2]) / 2 - 1e-6 * 150.0**2   # the straight line's error at 150 s
    >>> bool(np.allclose(np.sqrt(np.diagonal(err.cov_mm2[0])), lin))
    True

    The same with the two references' columns and weights:

    >>> two = curvature_error(t, g, np.zeros((4, 6, 6)), [150.0], [[0.5, 0.5]], 0.0, [[1, 2]])
    >>> bool(np.allclose(two.vector_mm, err.vector_mm, rtol=1e-12, atol=0))
    True
    """
    t = np.asarray(ref_times_s, dtype=float)
    g = np.asarray(ref_growth_mm, dtype=float)
    s = np.asarray(ref_leg_cov_mm2, dtype=float)
    ts = np.asarray(target_times_s, dtype=float)
    m, n = len(ts), len(t)
    # over the spacings between distinct times: references that share a time (a CMM
    # output stamped once) would make the median 0 and the ratio inf or nan
    spacing = np.diff(t)
    spacing = spacing[spacing > 0]
    widest = float(spacing.max() / np.median(spacing)) if spacing.size else 1.0
    interval = np.full(m, -1, dtype=np.intp)
    if n < 2 or m == 0:
        return CurvatureError.from_vectors(np.zeros((m, 6)), interval, widest_gap=widest)
    columns, values = _sparse_rows(used_weights, used_columns, m, n)
    stencils = second_difference_stencils(t)  # (n, 3): on i-1, i, i+1
    has = np.abs(stencils).sum(axis=1) > 0
    # the reference before each target in time (-1: before the first; n - 1: past the
    # last), and the straight line through the two around it, or through the last two
    # for a target past the last (extrapolated)
    around = np.searchsorted(t, ts, side="right") - 1
    p = np.minimum(around, n - 2)
    pc = np.clip(p, 0, n - 2)
    t0, t1 = t[pc], t[pc + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        w = (ts - t0) / (t1 - t0)
    f = (ts - t0) * (t1 - ts) / 2  # negative past the last reference
    if spacing_seen_s > 0:
        f = np.maximum(0.0, f - spacing_seen_s**2 / 8)
    # every target's c over its own references: the ones it used, then p-2 .. p+3 (the
    # line's two and the stencils of p-1 .. p+2); zero past either end
    k = columns.shape[1]
    window = pc[:, None] + np.arange(-2, 4)
    inside = (window >= 0) & (window < n)
    cols = np.concatenate([columns, np.clip(window, 0, n - 1)], axis=1)  # (M, K + 6)
    zeros = np.zeros((m, 6))
    used = np.concatenate([values, zeros], axis=1)
    line = np.concatenate([np.zeros((m, k)), zeros], axis=1)
    line[:, k + 2], line[:, k + 3] = 1.0 - w, w
    # the stencils of p - 1, p, p + 1, p + 2 on the window (offsets 0-2, 1-3, 2-4, 3-5)
    rows = [has[np.clip(pc + j, 0, n - 1)] & (pc + j >= 0) & (pc + j < n) for j in (-1, 0, 1, 2)]
    parts = []
    for j, row in zip((-1, 0, 1, 2), rows, strict=True):
        part = np.zeros((m, 6))
        part[:, j + 1 : j + 4] = np.where(row[:, None], stencils[np.clip(pc + j, 0, n - 1)], 0.0)
        parts.append(part)
    rows_p, rows_q = rows[1], rows[2]
    count = rows_p.astype(float) + rows_q
    spread_mean = (parts[1] + parts[2]) / np.where(count > 0, count, 1.0)[:, None]
    # the interval's own curvature: the two stencils around it hold half of its curvature
    # each and half of their outer intervals'; those halves read off the outer stencils
    # (a quadratic: the same; a kink inside the interval: twice the mean's)
    all_four = rows[0] & rows_p & rows_q & rows[3]
    own_part = np.where(
        all_four[:, None], parts[1] + parts[2] - (parts[0] + parts[3]) / 2, spread_mean
    )
    trace = np.trace(s, axis1=1, axis2=2)
    candidates = []
    for stencil in (spread_mean, own_part):
        mean = np.concatenate([np.zeros((m, k)), np.where(inside, stencil, 0.0)], axis=1)
        candidates.append(_error_vector(cols, used, line, mean, f, count, g, trace))
    (vec_a, ok_a), (vec_b, _) = candidates
    larger = np.einsum("ml,ml->m", vec_b, vec_b) > np.einsum("ml,ml->m", vec_a, vec_a)
    vector = np.where(larger[:, None], vec_b, vec_a)
    ok = ok_a & (p >= 0) & (t1 > t0)
    vector = np.where(ok[:, None], vector, 0.0)
    interval = np.where(ok, around, -1).astype(np.intp)
    # legs whose histories differ (lagging one another, heated unevenly): the stencils
    # read each leg's curvature, but not where inside the intervals around it each leg's
    # bends; the part along the growth's first shape stays one error of every leg, the
    # rest is taken leg by leg (independent between the legs)
    differ = second_shape(g, s)
    spread = None
    if by_leg and differ > LEGS_DIFFER:
        shape = np.linalg.svd(g, full_matrices=False)[2][0]
        along = (vector @ shape)[:, None] * shape
        spread = np.abs(vector - along)
        vector = along
    return CurvatureError.from_vectors(
        vector,
        interval,
        widest_gap=widest,
        past=around >= n - 1,
        second_shape=differ,
        spread_mm=spread,
    )


def _error_vector(
    cols: npt.NDArray[np.intp],
    used: FloatArray,
    line: FloatArray,
    mean: FloatArray,
    f: FloatArray,
    count: FloatArray,
    g: FloatArray,
    trace: FloatArray,
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Each target's error vector ``sqrt(share) c G`` (M, 6) for ``c = W - L + f s`` over
    its columns ``cols`` (``used``: W, ``line``: L, ``mean``: the stencil s), each
    reference once; and whether it has one (a target on its line with no stencil: none)."""
    same = cols[:, :, None] == cols[:, None, :]  # (M, J, J)
    first = ~np.any(np.tril(same, -1), axis=2)
    u = np.where(first, np.einsum("mij,mj->mi", same, used), 0.0)
    ln = np.where(first, np.einsum("mij,mj->mi", same, line), 0.0)
    st = np.where(first, np.einsum("mij,mj->mi", same, mean), 0.0)
    on_line = np.all(np.abs(u - ln) <= 1e-8 + 1e-5 * np.abs(ln), axis=1)  # np.allclose
    c = (u - ln) + f[:, None] * st
    c = np.where((count > 0)[:, None], c, u - ln)
    ok = np.any(u != 0.0, axis=1) & ~((count == 0) & on_line)
    error = np.einsum("mj,mjl->ml", c, g[cols])  # (M, 6)
    noise = np.einsum("mj,mj->m", c**2, trace[cols])
    total = np.einsum("ml,ml->m", error, error)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(total > 0, np.maximum(0.0, 1.0 - noise / total), 0.0)
    return np.sqrt(share)[:, None] * error, ok


#: chance level of the heights' scatter along the heating's direction beyond the rest's,
#: above which the heating's motion is taken off (:func:`scatter_off_heating`)
HEATING_P = 0.05


def scatter_off_heating(
    times_s: npt.ArrayLike, values: npt.ArrayLike, weights: npt.ArrayLike | None = None
) -> tuple[float, int, int]:
    """Type A variance of repeated measurements of k columns that a heating moves along
    one direction: ``(s^2, dof, projected)``.

    As :func:`~hexatherm.core.propagation.reference_scatter` (each inner measurement
    against the straight line through its two neighbours, ``e_i``, pooled), unless the
    ``e_i`` show a common motion: the direction the columns move together along over the
    session (the references' ball heights under a heating: the platform's thermal
    motion, one direction when the legs share one heating history), taken for each
    ``e_i`` as the first principal axis of the measurements outside its stencil (at least
    two), so that it does not follow ``e_i``'s own noise. Noise of equal variance in
    every column puts ``1 / k`` of it along that axis, ``chi^2`` of m degrees of freedom
    over the m stencils against the rest's ``(k - 1) m``; when their ratio exceeds chance
    (:data:`HEATING_P`, Fisher's F), a curvature of the heating between neighbours is
    there (it inflated the plain second differences 3.9x in variance under mats switched
    on mid-session), and the variance is read off that axis, ``E |P e_i|^2 = (k - 1) s^2
    factor_i``, on ``(k - 1)`` degrees of freedom a stencil. Otherwise the plain
    estimate stands (all its degrees of freedom). Stencils with fewer than two
    measurements outside are kept whole. ``projected`` counts the stencils read off the
    axis (0: the plain estimate).

    >>> rng = np.random.default_rng(2)
    >>> t = np.arange(41) * 400.0
    >>> heat = 40e-3 * (1 - np.exp(-np.clip(t - 1000.0, 0, None) / 600.0))  # 40 um, a kink
    >>> v = np.outer(heat, [1.0, 0.5, -0.8]) + rng.normal(scale=1e-3, size=(41, 3))
    >>> s2, dof, projected = scatter_off_heating(t, v)
    >>> bool(abs(np.sqrt(s2) * 1e3 - 1.0) < 0.15), dof, projected
    (True, 78, 39)
    """
    t = np.asarray(times_s, dtype=float)
    v = np.asarray(values, dtype=float).reshape(len(t), -1)
    w = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=float)
    n, k = v.shape
    plain, along, off = 0.0, 0.0, 0.0  # sums of e^2 / factor: all, along the axis, off it
    dof_plain, dof_off, projected = 0, 0, 0
    for i in range(1, n - 1):
        span = t[i + 1] - t[i - 1]
        if span <= 0:
            continue
        f = (t[i] - t[i - 1]) / span
        e = v[i] - ((1 - f) * v[i - 1] + f * v[i + 1])
        factor = 1 / w[i] + (1 - f) ** 2 / w[i - 1] + f**2 / w[i + 1]
        plain += float(e @ e) / factor
        dof_plain += k
        rest = np.r_[0 : i - 1, i + 2 : n]
        if rest.size >= 2 and k > 1:
            spread = v[rest] - v[rest].mean(axis=0)
            axis = np.linalg.svd(spread, full_matrices=False)[2][0]
            a = float(axis @ e)
            along += a**2 / factor
            off += (float(e @ e) - a**2) / factor
            dof_off += k - 1
            projected += 1
        else:
            off += float(e @ e) / factor
            dof_off += k
    if dof_plain == 0:
        return float("nan"), 0, 0
    if projected and off > 0:
        from scipy.special import fdtri  # not scipy.stats: its import is slow

        ratio = (along / projected) / (off / dof_off)
        if ratio > float(fdtri(projected, dof_off, 1.0 - HEATING_P)):
            return off / dof_off, dof_off, projected
    return plain / dof_plain, dof_plain, 0
