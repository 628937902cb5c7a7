"""``hexatherm calibrate``: processed sessions in, a calibrated geometry out.

Every session is processed as ``process`` does (its poses relative to its own
measured frame O, with their linear uncertainty); the targets of all sessions are
pooled and the geometry is fitted by :func:`~hexatherm.core.calibration.fit_calibration`
at a level chosen by :func:`~hexatherm.core.calibration.select_level` (BIC and
held-out folds) or forced. The sessions must share one hexapod file (the geometry
their controller commanded with).

``poses`` chooses what is fitted: ``corrected`` (the thermal state of each session's
first reference R0, the default: the point of the method), or ``conventional`` (as
measured, thermal drift included: for comparison).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.linalg import block_diag

from hexatherm.core.calibration import (
    PARAMETER_UNITS,
    CalibrationFit,
    LevelChoice,
    fit_calibration,
    select_level,
)
from hexatherm.core.correction import Interpolation
from hexatherm.core.geometry import to_um_urad
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError, InputError
from hexatherm.io.config import read_session
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.uncertainty import joint_pose_covariance

PoseKind = Literal["corrected", "conventional"]
POSE_KINDS: tuple[PoseKind, ...] = ("corrected", "conventional")
#: the fewest target poses calibrate takes (the offsets level alone has 6 parameters)
MIN_POSES = 4


@dataclass(frozen=True)
class Campaign:
    """The pooled targets of the sessions a calibration rests on.

    Attributes
    ----------
    results : list of ProcessResult
        One per session, in the order given.
    nominal : Hexapod
        The hexapod file the sessions share.
    labels : list of str
        ``session:step`` of every target.
    commanded, measured : ndarray, shape (N, 6)
        Commanded and measured (``poses``) poses relative to O, mm and deg.
    covariance : ndarray, shape (6N, 6N)
        Of the measured poses together (linear propagation), mm and deg: the terms
        between targets of one session (its one frame O and reference R0 move every
        pose) included, sessions independent.
    poses : {"corrected", "conventional"}
    """

    results: list[ProcessResult]
    nominal: Hexapod
    labels: list[str]
    commanded: FloatArray
    measured: FloatArray
    covariance: FloatArray
    poses: PoseKind


def read_campaign(
    paths: Sequence[str | Path],
    poses: PoseKind = "corrected",
    reading: ReadOptions = STRICT,
    interpolation: Interpolation = "linear",
    geometry: Hexapod | None = None,
) -> Campaign:
    """Process every session of ``paths`` (``interpolation`` of the growth at the
    references as in ``process``; ``geometry``, a calibrated hexapod, for the
    correction's IGM and FGM instead of the sessions' file) and pool their targets (see
    the module text). The nominal geometry, the one the controller commanded with,
    stays the sessions' hexapod file."""
    if poses not in POSE_KINDS:
        raise ValueError(f"poses must be one of {', '.join(POSE_KINDS)}, got {poses!r}")
    if not paths:
        raise ValueError("calibrate needs at least one session")
    results = [
        process_session(path, interpolation, reading=reading, hexapod=geometry) for path in paths
    ]
    nominal = read_session(paths[0]).hexapod
    for path, result in zip(paths[1:], results[1:], strict=True):
        other = read_session(path).hexapod
        same = other.convention == nominal.convention and all(
            np.array_equal(getattr(other, name), getattr(nominal, name))
            for name in ("base_joints_mm", "platform_joints_mm")
        )
        if not same:
            raise InputError(
                f"its hexapod file's geometry differs from {results[0].session.path}'s: the "
                "sessions of one calibration must be commanded with one geometry",
                path=str(result.session.path),
                field="hexapod",
            )
    check_reference_states(results)
    labels: list[str] = []
    commanded, measured, covariance = [], [], []
    for result in results:
        corr = result.correction
        targets = corr.target_index
        labels += [f"{result.session.name}:{result.session.plan.labels[i]}" for i in targets]
        commanded.append(result.session.plan.poses[targets])
        measured.append(corr.corrected if poses == "corrected" else corr.conventional)
        covariance.append(joint_pose_covariance(result, corrected=poses == "corrected"))
    n = len(labels)
    if n < MIN_POSES:
        raise InputError(
            f"{n} target pose(s) in all: a calibration needs at least {MIN_POSES} (and 30 or "
            "more spread over the stroke for the joints)",
            path=str(results[0].session.path),
        )
    return Campaign(
        results,
        nominal,
        labels,
        np.concatenate(commanded),
        np.concatenate(measured),
        block_diag(*covariance),
        poses,
    )


#: the largest difference of the legs' mean temperature at R0 between the sessions of
#: one calibration, K (each session's corrected poses refer to its own R0)
MAX_REFERENCE_STATE_K = 0.5


def check_reference_states(results: Sequence[ProcessResult]) -> None:
    """Refuse sessions whose reference states (the legs' temperature at each R0, where
    logged) differ by more than :data:`MAX_REFERENCE_STATE_K`."""
    states = []
    for result in results:
        temps = result.temperatures
        if temps is None:
            continue
        r0 = int(result.session.plan.reference_indices[0])
        t = float(result.centres.times_s[r0])
        legs = np.array([np.interp(t, temps.time_s, temps.legs_C[:, k]) for k in range(6)])
        states.append((result, float(legs.mean())))
    if len(states) < 2:
        return
    first, base = states[0]
    for result, mean in states[1:]:
        if abs(mean - base) > MAX_REFERENCE_STATE_K:
            raise InputError(
                f"the legs were at {mean:.2f} degC at its R0 and at {base:.2f} degC at "
                f"{first.session.path}'s: its corrected poses refer to another thermal state "
                f"(more than {MAX_REFERENCE_STATE_K} K apart); calibrate them apart",
                path=str(result.session.path),
                field="temperatures",
            )


@dataclass(frozen=True)
class Calibration:
    """A campaign's calibration.

    Attributes
    ----------
    campaign : Campaign
    fit : CalibrationFit
        At the chosen (or forced) level.
    choice : LevelChoice or None
        Every level's figures when the level was chosen (None when forced).
    residuals_before_um_urad : ndarray, shape (N, 6)
        Measured minus commanded poses: what the nominal geometry leaves (um, urad).
    residuals_after_um_urad : ndarray, shape (N, 6)
        Measured minus the calibrated model's predictions (um, urad), held out (each
        pose predicted by the fit to the folds it is not in) when the level was chosen.
    heldout : bool
        Whether ``residuals_after_um_urad`` are held out.
    """

    campaign: Campaign
    fit: CalibrationFit
    choice: LevelChoice | None
    residuals_before_um_urad: FloatArray
    residuals_after_um_urad: FloatArray
    heldout: bool


def calibrate(campaign: Campaign, level: str = "auto", residuals: str = "pose") -> Calibration:
    """Fit the campaign's geometry at ``level`` (``auto``: chosen by BIC and held-out folds)."""
    before = to_um_urad(campaign.measured - campaign.commanded)
    if level == "auto":
        choice = select_level(
            campaign.nominal,
            campaign.commanded,
            campaign.measured,
            campaign.covariance,
            residuals=residuals,
        )
        fit = choice.fit
        score = next(s for s in choice.scores if s.level == choice.level)
        after = to_um_urad(score.heldout_residuals)
        return Calibration(campaign, fit, choice, before, after, True)
    try:
        fit = fit_calibration(
            campaign.nominal,
            campaign.commanded,
            campaign.measured,
            campaign.covariance,
            level=level,
            residuals=residuals,
        )
    except CalibrationError as exc:
        raise CalibrationError(f"level {level}: {exc}") from None
    after = to_um_urad(campaign.measured - fit.predict(campaign.commanded))
    return Calibration(campaign, fit, None, before, after, False)


#: ``--iterate`` stops when no parameter moved more than this between rounds (mm; a gain
#: counts per 1000 mm of travel)
ITERATE_TOL_MM = 1e-5
#: and gives up after this many rounds
MAX_ROUNDS = 6


def calibrate_iterated(
    paths: Sequence[str | Path],
    poses: PoseKind = "corrected",
    reading: ReadOptions = STRICT,
    interpolation: Interpolation = "linear",
    level: str = "auto",
    residuals: str = "pose",
) -> tuple[Calibration, list[float]]:
    """Calibrate, reprocess the sessions with the calibrated geometry (the correction's
    IGM and FGM), calibrate again, until no parameter moves more than
    :data:`ITERATE_TOL_MM`; returns the last calibration and each round's largest move
    (mm). CalibrationError after :data:`MAX_ROUNDS` rounds without convergence."""
    run = calibrate(read_campaign(paths, poses, reading, interpolation), level, residuals)
    moves: list[float] = []
    while len(moves) < MAX_ROUNDS:
        campaign = read_campaign(paths, poses, reading, interpolation, run.fit.hexapod())
        again = calibrate(campaign, level, residuals)
        scale = np.where(np.array(PARAMETER_UNITS) == "mm", 1.0, 1000.0)
        moves.append(float(np.max(np.abs(again.fit.parameters - run.fit.parameters) * scale)))
        run = again
        if moves[-1] <= ITERATE_TOL_MM:
            return run, moves
    raise CalibrationError(
        f"--iterate: the parameters still moved {moves[-1] * 1e3:.3g} um after {MAX_ROUNDS} "
        "rounds (expected: a fraction of a micrometre after the first)"
    )
