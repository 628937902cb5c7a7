"""The outcome of a diagnosis (:func:`hexatherm.core.diagnosis.search.diagnose`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from hexatherm.core.diagnosis.adequacy import Adequacy
from hexatherm.core.diagnosis.model import Addition, Candidate, Fit, rms_um
from hexatherm.core.diagnosis.standin import cautions


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of :func:`diagnose`.

    Attributes
    ----------
    baseline : Fit
        The current model (the hexapod's own effects), only ``C`` fitted.
    final : Fit
        The model with every added effect, fitted jointly.
    added : tuple of Addition
        In the order they were added.
    rounds : tuple of tuple of Candidate
        Every candidate of every round.
    baseline_heldout_rms_um, final_heldout_rms_um : float
    skipped : dict of str to str
        Candidates not tried at all, and why (e.g. no air temperature).
    adequacy : Adequacy or None
        The verdict on the final model (None when not assessed).
    """

    baseline: Fit
    final: Fit
    added: tuple[Addition, ...]
    rounds: tuple[tuple[Candidate, ...], ...]
    baseline_heldout_rms_um: float
    final_heldout_rms_um: float
    skipped: dict[str, str] = field(default_factory=dict)
    adequacy: Adequacy | None = None

    @property
    def baseline_rms_um(self) -> float:
        return rms_um(self.baseline.residual_mm)

    @property
    def final_rms_um(self) -> float:
        return rms_um(self.final.residual_mm)

    def chosen_fits(self) -> tuple[Fit, ...]:
        """The joint fit of each round that added an effect (every effect added up to it)."""
        out = []
        for round_, addition in zip(self.rounds, self.added, strict=False):
            fit = next(c.fit for c in round_ if c.name == addition.effect.name)
            if fit is not None:
                out.append(fit)
        return tuple(out)

    def cautions(self) -> list[str]:
        """Added effects that may stand in for a cause outside the registry, and pairs
        that trade off, in words (:mod:`hexatherm.core.diagnosis.standin`)."""
        return cautions(self.added, self.final, self.chosen_fits())
