"""The held-out folds of :func:`~hexatherm.core.calibration.select_level`, refitted by
Gauss-Newton from the fit to all poses.

Each fold's poses are predicted by the level refitted to the other poses. A fold's
refit starts at the fit to all poses, micrometres from its own solution, where the
least-squares problem is linear to far below the poses' noise. So a fold is refitted
from what the fit to all poses has (its predictions and Jacobian at its solution: one
evaluation of the model for all poses, shared by the folds): the Gauss-Newton step,
one evaluation of the model at the fold's parameters (predictions and Jacobian, all
poses: the held-out ones are predicted by the same evaluation), and the next step from
there; the refit is taken when that step moves no prediction by more than
:data:`STEP_TOL` (mm or deg, a tenth of the files' resolution), else stepped again.

The solution is the one Levenberg-Marquardt converges to from the same start (the same
minimum; on the scanning session of ``bench/floor_commands.py`` the held-out residuals
of the two differ by at most 4e-9 mm, the size of the step either would take next).
The work is one evaluation of the model and one decomposition a fold, against three
or four evaluations, two decompositions and the optimizer's own. A fold that this
refit does not vouch for (rank deficient or identified only in name at the start, a
trial geometry the model cannot stand, not converged within :data:`MAX_STEPS`
evaluations) is refitted by :func:`~hexatherm.core.calibration.fit.fit_calibration`
as before, whose refusal is the one said. ``leg`` residuals (their weights move with
the parameters) are refitted by it too.
"""

from __future__ import annotations

import numpy as np

from hexatherm.core.calibration.fit import (
    CalibrationFit,
    _inverse_normal,
    _singular,
    fit_calibration,
    observability,
    refuse_rank_deficient,
)
from hexatherm.core.calibration.identified import diverged, refuse_unidentified
from hexatherm.core.calibration.weights import PoseWeights
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError, ConvergenceError
from hexatherm.typing import FloatArray, IntArray

#: a fold's refit is taken when its next Gauss-Newton step moves no prediction by more
#: than this (mm, or deg): a tenth of the files' resolution (1e-7 mm), the size of the
#: step Levenberg-Marquardt's tolerances left
STEP_TOL = 1e-8
#: most evaluations of the model a fold's refit takes before it is refitted by
#: Levenberg-Marquardt
MAX_STEPS = 4


def heldout_residuals(
    nominal: Hexapod,
    fit: CalibrationFit,
    x_cmd: FloatArray,
    x_meas: FloatArray,
    weights: PoseWeights,
    folds: IntArray,
    residuals: str,
) -> tuple[FloatArray, float, list[str]]:
    """Each fold's measured minus predicted poses (N, 6), the predictions by the level
    refitted to the other folds; the sum of their whitened squares (NaN when a fold could
    not be refitted) and the notes of the folds that could not (``fold k: why``)."""
    held = np.full(x_cmd.shape, np.nan)
    squares, notes = 0.0, []
    at_fit = None
    for f in np.unique(folds):
        train, test = np.flatnonzero(folds != f), np.flatnonzero(folds == f)
        try:
            predicted = None
            if residuals == "pose":
                try:
                    if at_fit is None:  # once for every fold
                        at_fit = _evaluation(fit, fit.parameters, x_cmd)
                    predicted = _refit(fit, x_cmd, x_meas, weights, train, at_fit)
                except CalibrationError:
                    pass  # refused: Levenberg-Marquardt's refusal is the one said
            if predicted is None:
                predicted = _by_levenberg_marquardt(
                    nominal, fit, x_cmd, x_meas, weights, train, residuals
                ).predict(x_cmd)
            predicted = predicted[test]
        except CalibrationError as error:
            notes.append(f"fold {f + 1}: {error}")
            squares = float("nan")
            continue
        held[test] = x_meas[test] - predicted
        white = weights.subset(test).whiten(held[test])
        squares += float(white @ white)
    return held, squares, notes


def _evaluation(
    fit: CalibrationFit, theta: FloatArray, x_cmd: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The model's predictions (N, 6) at ``theta`` and their Jacobian (N, 6, n_free) in the
    free coordinates (CalibrationError when the model cannot stand the hexapod there)."""
    try:
        predicted, jac = fit.model.predict(theta, x_cmd)
    except ConvergenceError as error:
        raise diverged(fit.model, error, x_cmd) from None
    return predicted, jac @ fit.model.basis


def _by_levenberg_marquardt(
    nominal: Hexapod,
    fit: CalibrationFit,
    x_cmd: FloatArray,
    x_meas: FloatArray,
    weights: PoseWeights,
    train: IntArray,
    residuals: str,
) -> CalibrationFit:
    """The fold refitted as the fit to all poses is, from its solution."""
    return fit_calibration(
        nominal,
        x_cmd[train],
        x_meas[train],
        weights.subset(train),
        level=fit.model.level,
        residuals=residuals,
        start=fit.parameters,
    )


def _refit(
    fit: CalibrationFit,
    x_cmd: FloatArray,
    x_meas: FloatArray,
    weights: PoseWeights,
    train: IntArray,
    at_fit: tuple[FloatArray, FloatArray],
) -> FloatArray | None:
    """The predictions (N, 6) of the level refitted to the poses ``train`` (see the
    module text), from the fit to all poses and its evaluation there ``at_fit``; None
    when not within :data:`MAX_STEPS` (CalibrationError: refused)."""
    model, w = fit.model, weights.subset(train)
    predicted, jac = at_fit
    # the fold's whitened residual Jacobian at the start, as fit_calibration checks it
    j_w = -w.whiten(jac[train])
    s, vt = _singular(j_w, model.n_free)
    refuse_rank_deficient(observability(model, j_w, x_cmd[train], (s, vt)), model.level)
    cov_z = _inverse_normal(s, vt)
    refuse_unidentified(model, model.basis @ cov_z @ model.basis.T, x_cmd[train])
    z = model.coordinates(fit.parameters)
    for _ in range(MAX_STEPS):
        r_w = w.whiten(x_meas[train] - predicted[train])
        step = -cov_z @ (j_w.T @ r_w)  # Gauss-Newton: (J^T J)^-1 J^T r, J's at the start
        if np.abs(jac @ step).max() <= STEP_TOL:
            return predicted
        z = z + step
        predicted, jac = _evaluation(fit, model.parameters(z), x_cmd)
        j_w = -w.whiten(jac[train])
    return None
