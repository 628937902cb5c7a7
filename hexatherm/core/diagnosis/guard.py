"""Whether the diagnosed model corrects the targets better than the session's own, held out.

``diagnose`` writes its model for ``process --method twin``: every measured target
corrected by the thermal deflection the twin predicts from the thermocouples alone,
relative to the measured origin O. An effect added because it lowers the held-out RMS
of the ball centres (frame O fitted to the steps) may still make that correction worse:
a stand-in (a linear CMM drift for a periodic one) bends the prediction where O was
measured, and that error is common to every corrected pose. So the check follows the
correction: the model is fitted on one fold of blocks of time (the folds of the held-out
check, even and odd blocks), and the held-out targets' pose residuals (measured minus
the twin's prediction) are taken relative to O's (what the twin correction leaves,
to first order); the RMS of their translation, over both folds, is compared with what
the session's own model (its ``thermal_model``, frame O fitted on the same fold)
leaves. A diagnosed model whose figure is larger is not written.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.diagnosis.adequacy import pose_residuals
from hexatherm.core.diagnosis.fitting import _Problem
from hexatherm.core.diagnosis.model import Fit, Folds, Observations
from hexatherm.core.diagnosis.twins import TwinRuns
from hexatherm.core.effects import Effect
from hexatherm.core.hexapod import Hexapod


@dataclass(frozen=True)
class TwinCheck:
    """The held-out twin correction of the targets: the session's model against the
    diagnosed one.

    Attributes
    ----------
    own_um, diagnosed_um : float
        RMS translation (um) the twin correction leaves on the held-out targets (their
        pose residual relative to O's), with the session's own model and with the
        diagnosed one, each fitted on the other fold.
    n_targets : int
        Held-out target steps in the figures (both folds).
    """

    own_um: float
    diagnosed_um: float
    n_targets: int

    @property
    def worse(self) -> bool:
        """Whether the diagnosed model corrects the held-out targets worse."""
        return bool(self.diagnosed_um > self.own_um)

    def sentence(self, names: Sequence[str]) -> str:
        """Why the diagnosed model was not written, in words."""
        return (
            f"the model with {', '.join(names)} is not written: on held-out targets "
            f"({self.n_targets}, each fold corrected by the model fitted on the other) the "
            f"twin correction would leave {self.diagnosed_um:.3f} um RMS, the session's own "
            f"model {self.own_um:.3f} um; hexapod.yaml holds the session's own model"
        )


def twin_check(
    hexapod: Hexapod,
    obs: Observations,
    current: Sequence[Effect],
    final: Fit,
    folds: Sequence[Folds],
    blocks: npt.NDArray[np.intp],
    runs: TwinRuns,
) -> TwinCheck | None:
    """The held-out twin correction with the session's model (``current``) and the
    diagnosed one (``final``'s effects with their parameters on each fold, ``folds``);
    None when nothing was added or no target is held out."""
    if not final.effects or len(folds) != len(final.effects):
        return None
    free = [type(e) for e in final.effects]
    problems = (
        _Problem(hexapod, obs, current, (), runs),
        _Problem(hexapod, obs, current, free, runs),
    )
    targets = np.array([i for i, k in enumerate(obs.plan.kinds) if k == "target"], dtype=np.intp)
    origin = obs.plan.origin_index
    left: tuple[list[np.ndarray], list[np.ndarray]] = ([], [])
    for parity in (0, 1):
        train = blocks % 2 == parity
        held = targets[~train[targets]]
        theta = np.concatenate(
            [
                np.array([fold.values[parity][p] for p in cls.parameters])
                for cls, fold in zip(free, folds, strict=True)
            ]
        )
        for k, (problem, parameters) in enumerate(zip(problems, (np.zeros(0), theta), strict=True)):
            # the residuals alone (no standard errors: no Jacobian)
            origin2cmm, predicted, residual = problem.evaluate(parameters, train)
            fit = Fit((), (), origin2cmm, residual, predicted, 0.0, 0, 0)
            pose = pose_residuals(hexapod, obs, fit).pose_um
            left[k].append(pose[held, :3] - pose[origin, :3])
    own, diagnosed = (np.concatenate(parts) for parts in left)
    if not own.size:
        return None
    return TwinCheck(
        float(np.sqrt(np.mean(own**2))), float(np.sqrt(np.mean(diagnosed**2))), int(own.shape[0])
    )
