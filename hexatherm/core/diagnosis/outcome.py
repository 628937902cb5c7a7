"""The outcome of a diagnosis (:func:`hexatherm.core.diagnosis.search.diagnose`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from hexatherm.core.diagnosis.adequacy import Adequacy
from hexatherm.core.diagnosis.guard import TwinCheck
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
    twin_check : TwinCheck or None
        The held-out twin correction of the targets with the session's model and the
        diagnosed one (None: nothing added, or no target held out).
    """

    baseline: Fit
    final: Fit
    added: tuple[Addition, ...]
    rounds: tuple[tuple[Candidate, ...], ...]
    baseline_heldout_rms_um: float
    final_heldout_rms_um: float
    skipped: dict[str, str] = field(default_factory=dict)
    adequacy: Adequacy | None = None
    twin_check: TwinCheck | None = None

    @property
    def writes_diagnosed(self) -> bool:
        """Whether the diagnosed model is written (else the session's own): not when it
        corrects the held-out targets worse (:mod:`hexatherm.core.diagnosis.guard`)."""
        return self.twin_check is None or not self.twin_check.worse

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
        that trade off, in words (:mod:`hexatherm.core.diagnosis.standin`); and why the
        diagnosed model is not written, when it is not."""
        out = cautions(self.added, self.final, self.chosen_fits())
        if not self.writes_diagnosed:
            assert self.twin_check is not None
            out.append(self.twin_check.sentence([a.effect.name for a in self.added]))
        return out
