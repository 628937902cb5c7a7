"""Conformity with a tolerance: the decision rules of ILAC-G8:09/2019 and JCGM 106:2012.

A measured deviation ``y`` from the nominal (here: the corrected pose minus the
commanded one, per component) with its expanded uncertainty ``U = k u`` is judged
against a tolerance interval ``[TL, TU]`` (lower and upper limit, ``TL < TU``; a
symmetric tolerance ``|y| <= T`` is ``[-T, T]``). A guard band ``w`` moves the
acceptance limits ``AL`` off the tolerance limits:

* :data:`ISO14253` (ISO 14253-1, the default; ``w = r U``): **conforms** when ``y`` lies
  in the acceptance zone ``[TL + w, TU - w]`` (conformity proven), **does not conform**
  when it lies outside ``[TL - w, TU + w]`` (non-conformity proven), **not decidable**
  in between (and always when ``U`` is unknown);
* :data:`SIMPLE` (simple acceptance, ILAC-G8 4.2.1, ``w = 0``): conforms inside
  ``[TL, TU]``, does not conform outside: a binary decision;
* :data:`GUARDED_ACCEPTANCE` (ILAC-G8 4.2.2, ``w = r U``): conforms inside
  ``[TL + w, TU - w]``, does not conform outside it (binary);
* :data:`GUARDED_REJECTION` (ILAC-G8 4.2.3, ``w = r U``): conforms inside the widened
  ``[TL - w, TU + w]``, does not conform outside it (binary): rejection only where
  non-conformity is shown.

A limit is inclusive on the accepting side: ``y`` exactly at an acceptance limit conforms.

**The risk** (JCGM 106:2012, 9.3, the *specific* risk of one decision). With the
knowledge of the measurand after measurement a normal pdf of mean ``y`` and standard
deviation ``u = U / k``, the probability that the true value lies inside the tolerance
interval (the conformance probability) is

    p_c(y) = Phi((TU - y) / u) - Phi((TL - y) / u),

and a decision "conforms" made at ``y`` is a false acceptance with probability
``1 - p_c(y)``. It is largest at the acceptance limits; at the upper one,
``y = AU = TU - w``:

    PFA(AU) = 1 - Phi(w / u) + Phi((TL - AU) / u)
            = 1 - Phi(r k) + Phi(-(TU - TL) / u + r k),

the second term (the far limit) negligible unless the tolerance interval is only a few
``u`` wide. Simple acceptance (``w = 0``) accepts a value at a limit with a risk of
false acceptance of 50 %; guarded acceptance with ``w = U``, ``k = 2``: 2.3 %; guarded
rejection with ``w = U``, ``k = 2``: 97.7 % (a value just outside its acceptance zone
is rejected with a probability of false rejection of 2.3 %). :func:`false_acceptance_at_limit`
computes it per component, both limits, :func:`conformance_probability` per value.

A set of decisions (a target's components, a session's targets) is *conforms* when every
one conforms, *does not conform* when any does not, else *not decidable*; the probability
that a target conforming on every component is in fact outside some tolerance is at most
the sum of its components' ``1 - p_c`` (Bonferroni: whatever their correlation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.typing import FloatArray

CONFORMS = "conforms"
DOES_NOT_CONFORM = "does_not_conform"
NOT_DECIDABLE = "not_decidable"
#: the decisions in words, for people
WORDS = {
    CONFORMS: "conforms",
    DOES_NOT_CONFORM: "does not conform",
    NOT_DECIDABLE: "not decidable",
}

ISO14253 = "iso14253"
SIMPLE = "simple"
GUARDED_ACCEPTANCE = "guarded-acceptance"
GUARDED_REJECTION = "guarded-rejection"
#: the rules, as the command line and the lab file name them
RULES = (ISO14253, SIMPLE, GUARDED_ACCEPTANCE, GUARDED_REJECTION)
#: each rule's sign of the guard band on the acceptance limits (+1: inside the tolerance)
_GUARD_SIGN = {ISO14253: 1.0, SIMPLE: 0.0, GUARDED_ACCEPTANCE: 1.0, GUARDED_REJECTION: -1.0}


@dataclass(frozen=True)
class DecisionRule:
    """A decision rule agreed with the customer (ILAC-G8:09/2019).

    Attributes
    ----------
    rule : str
        One of :data:`RULES`.
    guard_factor : float
        ``r`` of the guard band ``w = r U`` (>= 0; ignored by :data:`SIMPLE`).
    """

    rule: str = ISO14253
    guard_factor: float = 1.0

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"decision rule {self.rule!r}: one of {', '.join(RULES)}")
        if not (np.isfinite(self.guard_factor) and self.guard_factor >= 0):
            raise ValueError(f"guard factor {self.guard_factor!r}: a number >= 0")

    @property
    def binary(self) -> bool:
        """Whether every decision is conforms or does not conform (no third zone)."""
        return self.rule != ISO14253

    @property
    def guard_sign(self) -> float:
        """+1: the acceptance zone is the tolerance shrunk by ``w``; -1: widened; 0: none."""
        return _GUARD_SIGN[self.rule]

    def guard_text(self) -> str:
        """``w = U``, ``w = 1.5·U`` or ``w = 0``."""
        if self.rule == SIMPLE or self.guard_factor == 0:
            return "w = 0"
        r = self.guard_factor
        return "w = U" if r == 1 else f"w = {r:g}\u00b7U"

    def describe(self) -> str:
        """The rule in one sentence, with its reference."""
        g = self.guard_text()
        if self.rule == ISO14253:
            return (
                f"ISO 14253-1 (guard band {g}): conforms when the deviation lies in the "
                "tolerance interval shrunk by w at each limit, does not conform when it "
                "lies outside the interval widened by w, else not decidable"
            )
        if self.rule == SIMPLE:
            return (
                "simple acceptance, ILAC-G8:09/2019 4.2.1 (w = 0): conforms when the "
                "deviation lies in the tolerance interval, else does not conform"
            )
        if self.rule == GUARDED_ACCEPTANCE:
            return (
                f"guarded acceptance, ILAC-G8:09/2019 4.2.2 ({g}): conforms when the "
                "deviation lies in the tolerance interval shrunk by w at each limit, else "
                "does not conform"
            )
        return (
            f"guarded rejection, ILAC-G8:09/2019 4.2.3 ({g}): conforms when the deviation "
            "lies in the tolerance interval widened by w at each limit, else does not conform"
        )

    def risk_text(self, coverage_factor: float) -> str:
        """The risk the rule carries at its acceptance limit (JCGM 106:2012 9.3, a normal
        pdf, the far limit neglected), in one sentence."""
        from scipy.special import ndtr  # here: a process without tolerances loads no scipy

        pfa = float(1.0 - ndtr(self.guard_sign * self.guard_factor * coverage_factor))
        text = (
            f"probability of false acceptance of a deviation exactly at an acceptance "
            f"limit {100 * pfa:.3g} % (JCGM 106:2012 specific risk, normal pdf of "
            f"u = U/k, k = {coverage_factor:g}: 1 \u2212 \u03a6(w/u))"
        )
        if self.rule == GUARDED_REJECTION:
            text += (
                f"; a deviation just beyond it is rejected with a probability of false "
                f"rejection of {100 * (1 - pfa):.3g} %"
            )
        return text


def _limits(
    lower: npt.ArrayLike, upper: npt.ArrayLike
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    if np.any(lo >= hi):
        raise ValueError("a tolerance's lower limit must lie below its upper limit")
    return lo, hi


def acceptance_limits(
    lower: npt.ArrayLike,
    upper: npt.ArrayLike,
    expanded_u: npt.ArrayLike,
    rule: DecisionRule = DecisionRule(),
) -> tuple[FloatArray, FloatArray]:
    """The acceptance limits ``(AL, AU)`` (broadcast): ``TL + s w`` and ``TU - s w`` with
    ``w = r U`` and ``s`` the rule's :attr:`~DecisionRule.guard_sign`. An acceptance zone
    that the guard band closes (``AL > AU``) is empty: nothing conforms."""
    lo, hi = _limits(lower, upper)
    w = rule.guard_sign * rule.guard_factor * np.asarray(expanded_u, dtype=float)
    if rule.rule == SIMPLE:
        w = np.zeros_like(w)
    return lo + w, hi - w


def decide(
    deviation: npt.ArrayLike,
    expanded_u: npt.ArrayLike,
    upper: npt.ArrayLike,
    lower: npt.ArrayLike | None = None,
    rule: DecisionRule = DecisionRule(),
) -> npt.NDArray[np.str_]:
    """The decision for each deviation (broadcast) against ``[lower, upper]`` (``lower``
    None: ``-upper``, a symmetric tolerance) under ``rule``: :data:`CONFORMS`,
    :data:`DOES_NOT_CONFORM` or :data:`NOT_DECIDABLE`. A NaN ``U`` leaves every rule but
    simple acceptance not decidable: without an uncertainty the guard band is unknown."""
    y = np.asarray(deviation, dtype=float)
    u = np.asarray(expanded_u, dtype=float)
    hi = np.asarray(upper, dtype=float)
    lo = -hi if lower is None else np.asarray(lower, dtype=float)
    shape = np.broadcast(y, u, lo, hi).shape
    known = np.isfinite(y) & (np.isfinite(u) | (rule.rule == SIMPLE))
    al, au = acceptance_limits(lo, hi, np.nan_to_num(u, nan=0.0), rule)
    inside = known & (al <= y) & (y <= au) & (al <= au)
    out = np.full(shape, NOT_DECIDABLE, dtype=object)
    if rule.binary:
        fails = known & ~inside
    else:
        w = rule.guard_factor * u
        fails = known & ((y < lo - w) | (y > hi + w))
    out[np.broadcast_to(inside, shape)] = CONFORMS
    out[np.broadcast_to(fails, shape)] = DOES_NOT_CONFORM
    return out.astype(str)


def conformance_probability(
    deviation: npt.ArrayLike,
    standard_u: npt.ArrayLike,
    upper: npt.ArrayLike,
    lower: npt.ArrayLike | None = None,
) -> FloatArray:
    """``p_c = Phi((TU - y)/u) - Phi((TL - y)/u)`` (broadcast): the probability that the
    true value lies in the tolerance interval, for a normal pdf of mean ``y`` and standard
    deviation ``u`` (JCGM 106:2012, 7.3); NaN where ``u`` is unknown; for ``u = 0`` 1 inside
    (limits included) and 0 outside."""
    y = np.asarray(deviation, dtype=float)
    u = np.asarray(standard_u, dtype=float)
    hi = np.asarray(upper, dtype=float)
    lo = -hi if lower is None else np.asarray(lower, dtype=float)
    from scipy.special import ndtr  # here: a process without tolerances loads no scipy

    with np.errstate(divide="ignore", invalid="ignore"):
        p = ndtr((hi - y) / u) - ndtr((lo - y) / u)
    exact = (u == 0) & np.isfinite(y)
    p = np.where(exact, ((lo <= y) & (y <= hi)).astype(float), p)
    return np.asarray(np.where(np.isfinite(u) & np.isfinite(y), p, np.nan), dtype=float)


def false_acceptance_at_limit(
    expanded_u: npt.ArrayLike,
    coverage_factor: float,
    upper: npt.ArrayLike,
    lower: npt.ArrayLike | None = None,
    rule: DecisionRule = DecisionRule(),
) -> FloatArray:
    """The probability of false acceptance of a deviation exactly at an acceptance limit
    (the larger of the two limits'), ``1 - p_c(AL)`` with ``u = U / k`` (see the module
    text); NaN where the acceptance zone is empty or ``U`` unknown."""
    u = np.asarray(expanded_u, dtype=float) / float(coverage_factor)
    hi = np.asarray(upper, dtype=float)
    lo = -hi if lower is None else np.asarray(lower, dtype=float)
    al, au = acceptance_limits(lo, hi, np.asarray(expanded_u, dtype=float), rule)
    at_upper = 1.0 - conformance_probability(au, u, hi, lo)
    at_lower = 1.0 - conformance_probability(al, u, hi, lo)
    risk = np.maximum(at_upper, at_lower)
    return np.asarray(np.where(al <= au, risk, np.nan), dtype=float)


def combine(decisions: npt.ArrayLike, axis: int | None = None) -> npt.NDArray[np.str_]:
    """Several decisions as one (along ``axis``; all of them for None)."""
    d = np.asarray(decisions, dtype=str)
    any_fail = np.any(d == DOES_NOT_CONFORM, axis=axis)
    all_ok = np.all(d == CONFORMS, axis=axis)
    out = np.where(any_fail, DOES_NOT_CONFORM, np.where(all_ok, CONFORMS, NOT_DECIDABLE))
    return np.asarray(out, dtype=str)
