"""The report's verdict: what a reader needs first, in numbers.

:func:`verdict` reduces a processed session, its pose uncertainty and its quality
checks to a :class:`Verdict`: how many targets, which failed a check, the largest
corrected deviation from the commanded pose (translation and rotation) with its
expanded uncertainty ``U = k u``, the size of the thermal correction (the largest
``|corrected - conventional|``) and the uncertainty's basis.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.geometry import to_um_urad
from hexatherm.typing import FloatArray
from hexatherm.workflows.report.figures import POSE_NAMES, pose_deviations, target_labels

if TYPE_CHECKING:
    from hexatherm.core.conformity import DecisionRule
    from hexatherm.session import Tolerance
    from hexatherm.workflows.process.conformity import Conformity
    from hexatherm.workflows.process.quality import QualityReport
    from hexatherm.workflows.process.views import Processed, Uncertain


@dataclass(frozen=True)
class Extreme:
    """The largest magnitude of a set of pose parameters over the targets.

    Attributes
    ----------
    value : float
        The signed value of largest magnitude (um for translations, urad for rotations).
    target : str
        The target's label.
    parameter : str
        ``Tx`` .. ``Rz``.
    expanded_u : float
        Its expanded uncertainty ``U = k u`` in the same unit (NaN without an uncertainty).
    """

    value: float
    target: str
    parameter: str
    expanded_u: float


@dataclass(frozen=True)
class Verdict:
    """The report's summary of a session.

    Attributes
    ----------
    targets : int
        Number of target steps.
    failing_targets : list of (str, str)
        ``(label, failed checks)`` of the targets that failed a check.
    failing_other : list of (str, str)
        The same for the origin and the references.
    quality_ran : bool
        Whether quality checks were given.
    deviation_um, deviation_urad : Extreme
        Largest corrected deviation from the commanded pose: translation, rotation.
    correction_um, correction_urad : Extreme
        Largest ``|corrected - conventional|`` (the thermal correction); its
        ``expanded_u`` is NaN.
    coverage_factor : float
        ``k`` of every expanded uncertainty.
    basis : str
        How the uncertainty was obtained ("not available" without one).
    conformity : Conformity, optional
        The conformity statement, with tolerances.
    common_u : ndarray, shape (6,), optional
        The largest expanded common part ``k u_common`` of the corrected deviations over
        the targets (um, urad): from O and R0, shared by every target.
    insignificant : tuple of (str, float, float)
        The components whose thermal correction is smaller than its U: ``(name, largest
        correction, median U)`` (``process.outputs.insignificant_corrections``).
    """

    targets: int
    failing_targets: list[tuple[str, str]]
    failing_other: list[tuple[str, str]]
    quality_ran: bool
    deviation_um: Extreme
    deviation_urad: Extreme
    correction_um: Extreme
    correction_urad: Extreme
    coverage_factor: float
    basis: str
    conformity: Conformity | None = None
    common_u: FloatArray | None = None
    insignificant: tuple[tuple[str, float, float], ...] = ()


def uncertainty_basis(uncertainty: Uncertain | None) -> str:
    """One line: linear propagation or Monte Carlo (draws, seed), or "not available"."""
    if uncertainty is None:
        return "not available"
    if uncertainty.method == "linear":
        return "linear propagation (GUM)"
    return f"Monte Carlo (GUM Supplement 1), {uncertainty.draws} draws, seed {uncertainty.seed}"


def _extreme(
    values: FloatArray, u: FloatArray | None, labels: list[str], columns: slice
) -> Extreme:
    block = np.abs(values[:, columns])
    if not block.size or not np.any(np.isfinite(block)):
        return Extreme(float("nan"), "", "", float("nan"))
    i, j = np.unravel_index(int(np.nanargmax(block)), block.shape)
    j_all = j + (columns.start or 0)
    return Extreme(
        float(values[i, j_all]),
        labels[i],
        POSE_NAMES[j_all],
        float("nan") if u is None else float(u[i, j_all]),
    )


def failing_steps(quality: QualityReport | None) -> dict[str, str]:
    """``{label: failed checks}`` of the steps that failed a check (empty without checks)."""
    if quality is None:
        return {}
    frame = quality.frame
    failed = frame["failed"].fillna("").astype(str)
    return {
        str(label): text.replace(";", ", ")
        for label, text in zip(frame["label"], failed, strict=True)
        if text
    }


def verdict(
    result: Processed,
    uncertainty: Uncertain | None,
    quality: QualityReport | None,
    coverage_factor: float = 2.0,
    tolerances: dict[str, Tolerance] | None = None,
    rule: DecisionRule | None = None,
) -> Verdict:
    """The verdict of a processed session (see :class:`Verdict`).

    Parameters
    ----------
    result : ProcessResult
    uncertainty : PoseUncertainty, optional
        Standard uncertainties; the expanded ones are ``coverage_factor`` times them.
    quality : QualityReport, optional
    coverage_factor : float
        ``k`` of the expanded uncertainties, > 0.
    tolerances : dict, optional
        ``Tx_um`` .. ``Rz_urad`` -> T or (lower, upper): the conformity statement is made
        for them.
    rule : DecisionRule, optional
        The decision rule of the conformity statement (default: ISO 14253-1, w = U).
    """
    # process's output tables, with its pipeline: not loaded by diagnose, whose page takes
    # this package's figures and text only
    from hexatherm.workflows.process.outputs import insignificant_corrections

    if not coverage_factor > 0:
        raise ValueError(f"coverage factor {coverage_factor}: must be > 0")
    conventional, corrected = pose_deviations(result)
    labels = target_labels(result)
    u = None
    if uncertainty is not None:
        u = coverage_factor * to_um_urad(uncertainty.corrected_u)
    failing = failing_steps(quality)
    targets = set(labels)
    translation, rotation = slice(0, 3), slice(3, 6)
    return Verdict(
        targets=len(labels),
        failing_targets=[(k, v) for k, v in failing.items() if k in targets],
        failing_other=[(k, v) for k, v in failing.items() if k not in targets],
        quality_ran=quality is not None,
        deviation_um=_extreme(corrected, u, labels, translation),
        deviation_urad=_extreme(corrected, u, labels, rotation),
        correction_um=_extreme(corrected - conventional, None, labels, translation),
        correction_urad=_extreme(corrected - conventional, None, labels, rotation),
        coverage_factor=float(coverage_factor),
        basis=uncertainty_basis(uncertainty),
        common_u=None
        if uncertainty is None or uncertainty.common_u is None
        else coverage_factor * to_um_urad(uncertainty.common_u[:, 6:12]).max(axis=0),
        conformity=None
        if not tolerances
        else _conformity(result, uncertainty, tolerances, coverage_factor, rule),
        insignificant=()
        if uncertainty is None
        else tuple(insignificant_corrections(result, uncertainty, coverage_factor)),
    )


def _conformity(
    result: Processed,
    uncertainty: Uncertain | None,
    tolerances: dict[str, Tolerance],
    coverage_factor: float,
    rule: DecisionRule | None,
) -> Conformity:
    from hexatherm.workflows.process.conformity import conformity

    return conformity(result, uncertainty, tolerances, coverage_factor, rule)
