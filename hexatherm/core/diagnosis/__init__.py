"""Where the twin and the measurements disagree, and which missing effect explains it.

The twin (:mod:`hexatherm.core.twin`) predicts, from the commanded poses and the
thermocouple log, where every ball of every step of a session should be. The
diagnosis compares that with the measured ball centres and, one effect of the
registry (:mod:`hexatherm.core.effects`) at a time, asks whether adding it to the
model explains the difference.

**The comparison.** Residuals are in ball-centre space, the space the CMM
measures in: for step k and ball b, ``x_kb - cmm(C y_kb(theta), t_kb)`` where
``x`` is the measured centre (CMM frame), ``y(theta)`` the twin's ball centre in
the nominal frame O with the effects' parameters ``theta``, ``cmm`` the CMM-side
effects (a drift) and ``C`` the placement of frame O on the CMM. ``C`` is the
nuisance of every model, the baseline included: six parameters fitted to all
steps (a weighted rigid registration of every predicted centre onto every
measured one, exact for each ``theta``). So the one measurement of O is one step
among the others and its error does not sit in every residual. Residuals are
weighted by each centre's standard uncertainty.

**The scores.** For a model with ``p`` parameters (6 for ``C`` plus the
effects') fitted to ``n`` residual values, ``BIC = n ln(RSS_w / n) + p ln n``
with ``RSS_w`` the weighted sum of squares (the noise level is estimated, so a
misestimated uncertainty scales all models alike). The held-out check splits
the steps, in time order, into blocks; the model (``C`` included) is fitted on
every other block and evaluated on the rest, then the other way round. A
candidate is added when ``BIC`` drops by more than 10 *and* the held-out RMS
goes down; the best (largest drop) is added, all added parameters are refitted
together, and the search repeats until no candidate passes.

**Reported RMS** (``*_rms_um``): root mean square, over all steps, balls and the
three axes, of the measured minus the predicted centre, micrometres.

Candidates that explain the same residual are flagged: when another passing
candidate's fitted change of the residuals is nearly parallel to the chosen
one's (cosine above 0.9), both are named and the choice is the smaller BIC.
"""

from __future__ import annotations

from hexatherm.core.diagnosis.adequacy import (
    CHI2_SIGMAS,
    RMS_RATIO_LIMIT,
    STRUCTURE_ALPHA,
    Adequacy,
    Finding,
    adequacy,
    bound_flags,
    noise_floor,
    pose_residuals,
)
from hexatherm.core.diagnosis.fitting import (
    fit_model,
    heldout_rms_um,
)
from hexatherm.core.diagnosis.model import (
    DELTA_BIC_THRESHOLD,
    FOLD_SIGMAS,
    SIMILARITY_THRESHOLD,
    Addition,
    BoolArray,
    Candidate,
    Fit,
    Folds,
    Observations,
    RunnerUp,
    place,
    rms_um,
    twin_centres,
)
from hexatherm.core.diagnosis.outcome import Diagnosis
from hexatherm.core.diagnosis.search import HELDOUT_BLOCKS, MIN_STEPS, diagnose
from hexatherm.core.diagnosis.standin import (
    TRADE_OFF_SE,
    cautions,
    stand_in_reasons,
    trade_offs,
)

__all__ = [
    "Addition",
    "Adequacy",
    "BoolArray",
    "CHI2_SIGMAS",
    "Candidate",
    "DELTA_BIC_THRESHOLD",
    "Diagnosis",
    "Finding",
    "FOLD_SIGMAS",
    "HELDOUT_BLOCKS",
    "MIN_STEPS",
    "Fit",
    "Folds",
    "Observations",
    "RMS_RATIO_LIMIT",
    "RunnerUp",
    "SIMILARITY_THRESHOLD",
    "STRUCTURE_ALPHA",
    "TRADE_OFF_SE",
    "adequacy",
    "bound_flags",
    "cautions",
    "diagnose",
    "fit_model",
    "heldout_rms_um",
    "noise_floor",
    "place",
    "pose_residuals",
    "rms_um",
    "stand_in_reasons",
    "trade_offs",
    "twin_centres",
]
