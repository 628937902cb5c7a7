"""The conformity statement of a processed session: each target's corrected deviation
from its commanded pose against the tolerances (``--tolerance``, ``tolerances:``), under
the decision rule of :mod:`hexatherm.core.conformity` (ISO 14253-1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.conformity import (
    CONFORMS,
    DECISION_RULE,
    DOES_NOT_CONFORM,
    NOT_DECIDABLE,
    WORDS,
    combine,
    decide,
)
from hexatherm.core.geometry import to_um_urad
from hexatherm.session import TOLERANCE_UNITS
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.pipeline import ProcessResult

if TYPE_CHECKING:
    from hexatherm.workflows.process.uncertainty import PoseUncertainty

__all__ = ["DECISION_RULE", "Conformity", "conformity", "conformity_line", "parse_tolerances"]

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


def parse_tolerances(text: str) -> dict[str, float]:
    """``"Tx=2um,Rx=10urad"`` -> ``{"Tx_um": 2.0, "Rx_urad": 10.0}``; ValueError naming
    the bad item. Units: um, mm, nm for Tx..Tz; urad, mrad, deg for Rx..Rz."""
    import re

    found: dict[str, float] = {}
    for item in text.split(","):
        match = re.fullmatch(r"\s*([TR][xyz])\s*=\s*([0-9.eE+-]+)\s*([a-z]+)\s*", item)
        if match is None:
            raise ValueError(
                f"{item.strip()!r}: expected NAME=VALUEUNIT, e.g. Tx=2um or Rx=10urad "
                "(Tx..Rz; um, mm, nm or urad, mrad, deg)"
            )
        name, number, unit = match.groups()
        want = "um" if name[0] == "T" else "urad"
        if unit not in _UNIT_FACTORS or _UNIT_FACTORS[unit][0] != want:
            units = ", ".join(u for u, (k, _) in _UNIT_FACTORS.items() if k == want)
            raise ValueError(f"{item.strip()!r}: the unit of {name} is one of {units}")
        try:
            value = float(number) * _UNIT_FACTORS[unit][1]
        except ValueError:
            raise ValueError(f"{item.strip()!r}: {number!r} is not a number") from None
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{item.strip()!r}: a tolerance is a number > 0")
        key = f"{name}_{want}"
        if key in found:
            raise ValueError(f"{item.strip()!r}: {name} is given twice")
        found[key] = value
    return found


@dataclass(frozen=True)
class Conformity:
    """Every target's decision on every toleranced component.

    Attributes
    ----------
    keys : tuple of str
        The toleranced components (``Tx_um`` .. ``Rz_urad``), in pose order.
    tolerances : ndarray, shape (n,)
        Half-width ``T`` of each tolerance zone (um, urad).
    coverage_factor : float
    labels : list of str
        The targets.
    deviation, expanded_u : ndarray, shape (M, n)
        Corrected deviation from the commanded pose and its ``U = k u`` (NaN: no u).
    decisions : ndarray of str, shape (M, n)
    per_target : ndarray of str, shape (M,)
    overall : str
    """

    keys: tuple[str, ...]
    tolerances: FloatArray
    coverage_factor: float
    labels: list[str]
    deviation: FloatArray
    expanded_u: FloatArray
    decisions: np.ndarray
    per_target: np.ndarray
    overall: str

    def columns(self) -> dict[str, object]:
        """The ``poses.csv`` columns: per component ``tol_d<C>_<unit>``,
        ``U_d<C>_corr_<unit>``, ``conformity_d<C>``; then ``coverage_factor`` and the
        target's ``conformity``."""
        data: dict[str, object] = {}
        for j, key in enumerate(self.keys):
            name, unit = key.split("_")
            data[f"tol_d{name}_{unit}"] = np.full(len(self.labels), self.tolerances[j])
            data[f"U_d{name}_corr_{unit}"] = self.expanded_u[:, j]
            data[f"conformity_d{name}"] = self.decisions[:, j]
        data["coverage_factor"] = np.full(len(self.labels), self.coverage_factor)
        data["conformity"] = self.per_target
        return data


def conformity(
    result: ProcessResult,
    uncertainty: PoseUncertainty | None,
    tolerances: dict[str, float],
    coverage_factor: float = 2.0,
) -> Conformity:
    """The decisions for ``tolerances`` (``Tx_um`` .. ``Rz_urad`` -> T, not empty)."""
    keys = tuple(k for k in _KEYS if k in tolerances)
    cols = [_KEYS.index(k) for k in keys]
    corr = result.correction
    idx = corr.target_index
    deviation = to_um_urad(corr.corrected - result.session.plan.poses[idx])[:, cols]
    if uncertainty is None:
        expanded = np.full(deviation.shape, np.nan)
    else:
        expanded = coverage_factor * to_um_urad(uncertainty.corrected_u)[:, cols]
    limits = np.array([tolerances[k] for k in keys], dtype=float)
    decisions = decide(deviation, expanded, limits)
    per_target = combine(decisions, axis=1)
    labels = [result.session.plan.labels[i] for i in idx]
    return Conformity(
        keys,
        limits,
        coverage_factor,
        labels,
        deviation,
        expanded,
        decisions,
        per_target,
        str(combine(per_target)),
    )


def tolerance_text(keys: tuple[str, ...], limits: FloatArray) -> str:
    """``Tx 2 um, Rx 10 urad``."""
    return ", ".join(
        f"{k.split('_')[0]} {v:g} {k.split('_')[1]}" for k, v in zip(keys, limits, strict=True)
    )


def conformity_line(judged: Conformity) -> str:
    """The statement in one line: overall, and how many targets each way."""
    counts = {d: int(np.sum(judged.per_target == d)) for d in WORDS}
    return (
        f"conformity to |corrected - commanded| <= {tolerance_text(judged.keys, judged.tolerances)}"
        f" (ISO 14253-1, guard band U = k u, k = {judged.coverage_factor:g}): "
        f"{WORDS[judged.overall].upper()}; {counts[CONFORMS]} target(s) conform, "
        f"{counts[DOES_NOT_CONFORM]} do not, {counts[NOT_DECIDABLE]} not decidable"
    )
