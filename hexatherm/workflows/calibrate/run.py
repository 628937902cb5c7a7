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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.linalg import block_diag

from hexatherm.core.calibration import (
    CalibrationFit,
    LevelChoice,
    fit_calibration,
    select_level,
)
from hexatherm.core.correction import Interpolation
from hexatherm.core.geometry import to_um_urad
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError, InputError
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
) -> Campaign:
    """Process every session of ``paths`` (``interpolation`` of the growth at the
    references as in ``process``) and pool their targets (see the module text)."""
    if poses not in POSE_KINDS:
        raise ValueError(f"poses must be one of {', '.join(POSE_KINDS)}, got {poses!r}")
    if not paths:
        raise ValueError("calibrate needs at least one session")
    results = [process_session(path, interpolation, reading=reading) for path in paths]
    nominal = results[0].session.hexapod
    for result in results[1:]:
        other = result.session.hexapod
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
    notes: list[str] = field(default_factory=list)


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


def rms(values: FloatArray) -> FloatArray:
    """RMS per column."""
    return np.asarray(np.sqrt(np.mean(np.asarray(values, float) ** 2, axis=0)), float)
