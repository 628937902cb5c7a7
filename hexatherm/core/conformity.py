"""Conformity with a tolerance under the decision rule of ISO 14253-1.

A measured deviation ``d`` from the nominal (here: the corrected pose minus the
commanded one, per component) with its expanded uncertainty ``U = k u`` is judged
against a symmetric tolerance zone ``|d| <= T``:

* **conforms** when ``|d| + U <= T``: the measured value lies in the acceptance zone,
  the tolerance zone shrunk by the guard band ``U`` on each side;
* **does not conform** when ``|d| - U > T``: the value lies beyond the tolerance zone
  widened by ``U``;
* **not decidable** otherwise: the interval ``d +- U`` straddles a limit (and always when
  ``U`` is unknown, or ``U >= T`` leaves no acceptance zone and ``d`` is not beyond it).

A set of decisions (a target's components, a session's targets) is *conforms* when every
one conforms, *does not conform* when any does not, else *not decidable*.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

CONFORMS = "conforms"
DOES_NOT_CONFORM = "does_not_conform"
NOT_DECIDABLE = "not_decidable"
#: the decisions in words, for people
WORDS = {
    CONFORMS: "conforms",
    DOES_NOT_CONFORM: "does not conform",
    NOT_DECIDABLE: "not decidable",
}
DECISION_RULE = (
    "ISO 14253-1: conforms when |deviation| + U \u2264 tolerance (the guard band U inside "
    "the tolerance zone), does not conform when |deviation| \u2212 U > tolerance, else not "
    "decidable"
)


def decide(
    deviation: npt.ArrayLike, expanded_u: npt.ArrayLike, tolerance: npt.ArrayLike
) -> npt.NDArray[np.str_]:
    """The decision for each deviation (broadcast): :data:`CONFORMS`,
    :data:`DOES_NOT_CONFORM` or :data:`NOT_DECIDABLE` (always for a NaN ``U``: without an
    uncertainty the rule cannot be applied)."""
    d = np.abs(np.asarray(deviation, dtype=float))
    u = np.asarray(expanded_u, dtype=float)
    t = np.asarray(tolerance, dtype=float)
    known = np.isfinite(u) & np.isfinite(d)
    conforms = known & (d + u <= t)
    fails = known & (d - u > t)
    out = np.full(np.broadcast(d, u, t).shape, NOT_DECIDABLE, dtype=object)
    out[np.broadcast_to(conforms, out.shape)] = CONFORMS
    out[np.broadcast_to(fails, out.shape)] = DOES_NOT_CONFORM
    return out.astype(str)


def combine(decisions: npt.ArrayLike, axis: int | None = None) -> npt.NDArray[np.str_]:
    """Several decisions as one (along ``axis``; all of them for None)."""
    d = np.asarray(decisions, dtype=str)
    any_fail = np.any(d == DOES_NOT_CONFORM, axis=axis)
    all_ok = np.all(d == CONFORMS, axis=axis)
    out = np.where(any_fail, DOES_NOT_CONFORM, np.where(all_ok, CONFORMS, NOT_DECIDABLE))
    return np.asarray(out, dtype=str)
