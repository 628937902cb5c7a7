"""The conformity statement of a processed session: each target's corrected deviation
from its commanded pose against the tolerances (``--tolerance``, ``tolerances:``), under
the decision rule of :mod:`hexatherm.core.conformity` (ISO 14253-1)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.conformity import (
    CONFORMS,
    DOES_NOT_CONFORM,
    ISO14253,
    NOT_DECIDABLE,
    WORDS,
    DecisionRule,
    combine,
    conformance_probability,
    decide,
    false_acceptance_at_limit,
)
from hexatherm.core.geometry import to_um_urad
from hexatherm.session import TOLERANCE_UNITS, Tolerance
from hexatherm.typing import FloatArray

if TYPE_CHECKING:
    from hexatherm.workflows.process.views import Processed, Uncertain


__all__ = [
    "Conformity",
    "decision_rule",
    "interval",
    "conformity",
    "conformity_line",
    "parse_tolerances",
]

#: the pose components in order, and the key of each one's tolerance
_KEYS = tuple(TOLERANCE_UNITS)
#: units a --tolerance value may carry -> (unit of the key, factor to it)
_UNIT_FACTORS = {
    "um": ("um", 1.0),
    "mm": ("um", 1000.0),
    "nm": ("um", 1e-3),
    "urad": ("urad", 1.0),
    "mrad": ("urad", 1000.0),
    "deg": ("urad", np.pi / 180 * 1e6),
}


_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"


def parse_tolerances(text: str) -> dict[str, Tolerance]:
    """``"Tx=2um,Rx=10urad,Tz=-1..3um"`` -> ``{"Tx_um": 2.0, "Rx_urad": 10.0, "Tz_um": (-1.0,
    3.0)}``: a half-width ``T`` (the zone ``[-T, T]``) or ``LOWER..UPPER`` limits (an
    asymmetric zone); ValueError naming the bad item. Units: um, mm, nm for Tx..Tz; urad,
    mrad, deg for Rx..Rz."""
    import re

    found: dict[str, Tolerance] = {}
    for item in text.split(","):
        match = re.fullmatch(
            rf"\s*([TR][xyz])\s*=\s*(?:({_NUMBER})\s*\.\.\s*)?([^a-z]+?)\s*([a-z]+)\s*", item
        )
        if match is None:
            raise ValueError(
                f"{item.strip()!r}: expected NAME=VALUEUNIT or NAME=LOWER..UPPERUNIT, e.g. "
                "Tx=2um, Rx=10urad or Tz=-1..3um (Tx..Rz; um, mm, nm or urad, mrad, deg)"
            )
        name, low, number, unit = match.groups()
        want = "um" if name[0] == "T" else "urad"
        if unit not in _UNIT_FACTORS or _UNIT_FACTORS[unit][0] != want:
            units = ", ".join(u for u, (k, _) in _UNIT_FACTORS.items() if k == want)
            raise ValueError(f"{item.strip()!r}: the unit of {name} is one of {units}")
        factor = _UNIT_FACTORS[unit][1]
        try:
            value = float(number) * factor
            lower = None if low is None else float(low) * factor
        except ValueError:
            raise ValueError(f"{item.strip()!r}: {number!r} is not a number") from None
        if lower is None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{item.strip()!r}: a tolerance is a number > 0")
        if lower is not None and not (np.isfinite(value) and np.isfinite(lower) and lower < value):
            raise ValueError(f"{item.strip()!r}: LOWER..UPPER, finite, LOWER below UPPER")
        key = f"{name}_{want}"
        if key in found:
            raise ValueError(f"{item.strip()!r}: {name} is given twice")
        found[key] = value if lower is None else (lower, value)
    return found


def parse_recorded(recorded: Mapping[str, object]) -> dict[str, Tolerance]:
    """The tolerances as ``provenance.json`` records them (``{"Tx_um": 2.0, "Tz_um": [-1.0,
    3.0]}``) as :func:`parse_tolerances` gives them; ResultsError on anything else."""
    from hexatherm.errors import ResultsError

    found: dict[str, Tolerance] = {}
    for key, value in recorded.items():
        if key not in _KEYS:
            raise ResultsError(f"provenance.json: tolerance {key!r} is not one of {_KEYS}")
        if isinstance(value, int | float):
            found[key] = float(value)
        elif isinstance(value, list | tuple) and len(value) == 2:
            found[key] = (float(value[0]), float(value[1]))
        else:
            raise ResultsError(f"provenance.json: tolerance {key}: {value!r} is no tolerance")
    return found


def decision_rule(
    fields: Mapping[str, object], rule: str | None = None, guard_factor: float | None = None
) -> DecisionRule:
    """The decision rule: ``rule`` and ``guard_factor`` (the command line's) over a lab
    file's ``decision_rule`` and ``guard_factor`` (``fields``), else ISO 14253-1, r = 1."""
    lab_rule = fields.get("decision_rule")
    lab_r = fields.get("guard_factor")
    return DecisionRule(
        rule or (lab_rule if isinstance(lab_rule, str) else ISO14253),
        guard_factor
        if guard_factor is not None
        else float(lab_r)
        if isinstance(lab_r, int | float)
        else 1.0,
    )


def interval(tolerance: Tolerance) -> tuple[float, float]:
    """A tolerance as its ``(lower, upper)`` limits (``T``: ``(-T, T)``)."""
    if isinstance(tolerance, tuple):
        return float(tolerance[0]), float(tolerance[1])
    return -float(tolerance), float(tolerance)


@dataclass(frozen=True)
class Conformity:
    """Every target's decision on every toleranced component.

    Attributes
    ----------
    keys : tuple of str
        The toleranced components (``Tx_um`` .. ``Rz_urad``), in pose order.
    lower, upper : ndarray, shape (n,)
        The limits of each tolerance zone (um, urad).
    coverage_factor : float
    rule : DecisionRule
    labels : list of str
        The targets.
    deviation, expanded_u : ndarray, shape (M, n)
        Corrected deviation from the commanded pose and its ``U = k u`` (NaN: no u).
    decisions : ndarray of str, shape (M, n)
    p_conform : ndarray, shape (M, n)
        Probability that the true deviation lies in the tolerance zone (normal pdf of
        ``u = U/k``; NaN without u).
    per_target : ndarray of str, shape (M,)
    overall : str
    """

    keys: tuple[str, ...]
    lower: FloatArray
    upper: FloatArray
    coverage_factor: float
    rule: DecisionRule
    labels: list[str]
    deviation: FloatArray
    expanded_u: FloatArray
    decisions: np.ndarray
    p_conform: FloatArray
    per_target: np.ndarray
    overall: str

    @property
    def symmetric(self) -> bool:
        """Whether every tolerance zone is ``[-T, T]``."""
        return bool(np.all(self.lower == -self.upper))

    def risk_if_accepted(self) -> FloatArray:
        """Per target, the probability that some component lies outside its tolerance
        zone, at most: the sum over components of ``1 - p_conform`` (Bonferroni, capped
        at 1), shape (M,)."""
        return np.asarray(np.minimum(np.sum(1.0 - self.p_conform, axis=1), 1.0), float)

    def pfa_at_limit(self) -> FloatArray:
        """Per target and component, the probability of false acceptance of a deviation
        exactly at an acceptance limit (JCGM 106, :func:`false_acceptance_at_limit`)."""
        return false_acceptance_at_limit(
            self.expanded_u, self.coverage_factor, self.upper, self.lower, self.rule
        )

    def columns(self) -> dict[str, object]:
        """The ``poses.csv`` columns: per component ``tol_lower_d<C>_<unit>``,
        ``tol_upper_d<C>_<unit>``, ``U_d<C>_corr_<unit>``, ``p_conform_d<C>``,
        ``conformity_d<C>``; then ``coverage_factor``, ``decision_rule``, ``guard_factor``
        and the target's ``conformity``."""
        data: dict[str, object] = {}
        n = len(self.labels)
        for j, key in enumerate(self.keys):
            name, unit = key.split("_")
            data[f"tol_lower_d{name}_{unit}"] = np.full(n, self.lower[j])
            data[f"tol_upper_d{name}_{unit}"] = np.full(n, self.upper[j])
            data[f"U_d{name}_corr_{unit}"] = self.expanded_u[:, j]
            data[f"p_conform_d{name}"] = self.p_conform[:, j]
            data[f"conformity_d{name}"] = self.decisions[:, j]
        data["coverage_factor"] = np.full(n, self.coverage_factor)
        data["decision_rule"] = np.full(n, self.rule.rule)
        data["guard_factor"] = np.full(n, self.rule.guard_factor)
        data["conformity"] = self.per_target
        return data


def conformity(
    result: Processed,
    uncertainty: Uncertain | None,
    tolerances: dict[str, Tolerance],
    coverage_factor: float = 2.0,
    rule: DecisionRule | None = None,
) -> Conformity:
    """The decisions for ``tolerances`` (``Tx_um`` .. ``Rz_urad`` -> T or (lower, upper),
    not empty) under ``rule`` (default: ISO 14253-1, ``w = U``)."""
    corr = result.correction
    idx = corr.target_index
    deviation = to_um_urad(corr.corrected - result.session.plan.poses[idx])
    if uncertainty is None:
        expanded = np.full(deviation.shape, np.nan)
    else:
        expanded = coverage_factor * to_um_urad(uncertainty.corrected_u)
    labels = [result.session.plan.labels[i] for i in idx]
    return judge(labels, deviation, expanded, tolerances, coverage_factor, rule)


def judge(
    labels: list[str],
    deviation: FloatArray,
    expanded_u: FloatArray,
    tolerances: dict[str, Tolerance],
    coverage_factor: float = 2.0,
    rule: DecisionRule | None = None,
) -> Conformity:
    """The decisions on deviations ``(M, 6)`` (um, urad, pose order) with their expanded
    uncertainties ``U = k u`` for ``tolerances`` (not empty) under ``rule``."""
    rule = DecisionRule() if rule is None else rule
    keys = tuple(k for k in _KEYS if k in tolerances)
    cols = [_KEYS.index(k) for k in keys]
    deviation = np.asarray(deviation, dtype=float)[:, cols]
    expanded = np.asarray(expanded_u, dtype=float)[:, cols]
    limits = np.array([interval(tolerances[k]) for k in keys], dtype=float).reshape(-1, 2)
    lower, upper = limits[:, 0], limits[:, 1]
    decisions = decide(deviation, expanded, upper, lower, rule)
    p_conform = conformance_probability(deviation, expanded / coverage_factor, upper, lower)
    per_target = combine(decisions, axis=1)
    return Conformity(
        keys,
        lower,
        upper,
        coverage_factor,
        rule,
        labels,
        deviation,
        expanded,
        decisions,
        p_conform,
        per_target,
        str(combine(per_target)),
    )


def tolerance_text(keys: tuple[str, ...], lower: FloatArray, upper: FloatArray) -> str:
    """``Tx ±2 um, Tz -1..3 um``."""
    parts = []
    for k, lo, hi in zip(keys, lower, upper, strict=True):
        name, unit = k.split("_")
        zone = f"\u00b1{hi:g}" if lo == -hi else f"{lo:g}..{hi:g}"
        parts.append(f"{name} {zone} {unit}")
    return ", ".join(parts)


def conformity_line(judged: Conformity) -> str:
    """The statement in one line: overall, and how many targets each way, the rule."""
    counts = {d: int(np.sum(judged.per_target == d)) for d in WORDS}
    return (
        f"conformity of corrected - commanded to "
        f"{tolerance_text(judged.keys, judged.lower, judged.upper)} "
        f"(decision rule {judged.rule.rule}, {judged.rule.guard_text()}, U = k u, "
        f"k = {judged.coverage_factor:g}): {WORDS[judged.overall].upper()}; "
        f"{counts[CONFORMS]} target(s) conform, {counts[DOES_NOT_CONFORM]} do not, "
        f"{counts[NOT_DECIDABLE]} not decidable"
    )
