"""``hexatherm calibrate``: processed sessions in, a calibrated geometry out.

Every session is processed as ``process`` does (its poses relative to its own
measured frame O, with their linear uncertainty); the targets of all sessions are
pooled and the geometry is fitted by :func:`~hexatherm.core.calibration.fit_calibration`
at a level chosen by :func:`~hexatherm.core.calibration.select_level` (BIC and
held-out folds) or forced. The sessions must share one hexapod file (the geometry
their controller commanded with).

``poses`` chooses what is fitted: ``corrected`` (the thermal state of each session's
first reference R0, the default: the point of the method), ``conventional`` (as
measured, thermal drift included: for comparison), or ``twin`` (each measured pose
corrected to R0's thermal state by the deflection a twin model predicts from the
thermocouple log alone, as ``process --method twin``; no reference measurement used).

The twin-corrected poses are weighted with the covariance of the measured
(conventional) poses they correct: the twin adds no measurement noise (its
correction depends on the thermocouples and the model, not on the CMM's centres,
but for the registered origin frame, a second-order term that is left out). Its
model error (a missing or mis-fitted effect, thermocouple noise, the twin's nominal
geometry) is not in that covariance: it shows as a chi-square per degree of
freedom above 1, and as parameters off by more than their uncertainty.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from scipy.linalg import block_diag

from hexatherm.core.calibration import (
    PARAMETER_UNITS,
    BandedCovariance,
    CalibrationFit,
    LevelChoice,
    fit_calibration,
    select_level,
)
from hexatherm.core.calibration.frames import in_frame
from hexatherm.core.correction import Interpolation
from hexatherm.core.frames import campaign_transforms, hexapod_in_origin, machine_in_origin
from hexatherm.core.geometry import pose_from_transform, to_um_urad
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError, InputError
from hexatherm.io.config import hexapod_to_yaml, read_hexapod, read_hexapod_text, read_session
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.manifest import sha256_file
from hexatherm.io.runrecord import RecordedFrames, read_recorded_frames
from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import Session
from hexatherm.typing import FloatArray
from hexatherm.workflows.calibrate.checks import (
    check_distinct_measurements,
    check_distinct_sessions,
    check_one_balls,
    check_one_frames,
    check_one_hexapod,
    check_reference_states,
)
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.twin import twin_poses
from hexatherm.workflows.process.uncertainty import (
    joint_pose_covariance,
    joint_pose_covariance_for_fit,
)

PoseKind = Literal["corrected", "conventional", "twin"]
POSE_KINDS: tuple[PoseKind, ...] = ("corrected", "conventional", "twin")
#: the fewest target poses calibrate takes (the offsets level alone has 6 parameters)
MIN_POSES = 4


@dataclass(frozen=True)
class TwinModel:
    """The twin's model for ``poses="twin"``: a hexapod file whose ``thermal_model``
    effects (and leg model) predict the thermal deflection from the thermocouples.

    Attributes
    ----------
    hexapod : Hexapod
        Geometry, legs and effects of the model.
    path : str
        Where it came from (the file, or what it was built from), for messages and the
        calibration record.
    sha256 : str or None
        SHA-256 of the file (None when it was not read from one file).
    """

    hexapod: Hexapod
    path: str
    sha256: str | None = None

    @classmethod
    def read(cls, path: str | Path) -> TwinModel:
        """The model of the hexapod file ``path`` (InputError naming it when invalid)."""
        return cls(read_hexapod(path), str(path), sha256_file(Path(path)))

    def with_geometry(self, geometry: Hexapod | None) -> Hexapod:
        """The model's hexapod with the joints of ``geometry`` (a calibrated one; legs and
        effects stay the model's), or as it is."""
        if geometry is None:
            return self.hexapod
        return dataclasses.replace(
            self.hexapod,
            base_joints_mm=geometry.base_joints_mm,
            platform_joints_mm=geometry.platform_joints_mm,
        )


def truth_twin_model(session: str | Path) -> TwinModel:
    """The twin model equal to a simulated session's true thermal model: the session's
    hexapod file (the nominal geometry and legs) with the effects of its
    ``truth/effects.yaml`` (what ``simulate`` applied) as ``thermal_model``.

    Parameters
    ----------
    session : str or Path
        A folder written by ``hexatherm simulate`` (or its ``session.yaml``).

    Returns
    -------
    TwinModel
        Named by the ``truth/effects.yaml`` it was built from, no SHA-256.
    """
    spec = read_session(session)
    path = spec.path.parent / "truth" / "effects.yaml"
    doc = YamlDoc.load(path)
    effects = doc.get("effects")
    if not isinstance(effects, list):
        raise doc.error("expected a list of effects", "effects")
    text = hexapod_to_yaml(dataclasses.replace(spec.hexapod, effects=tuple(effects)))
    return TwinModel(read_hexapod_text(text, str(path)), str(path))


def simulated_twin_campaign(
    session: str | Path, interpolation: Interpolation = "linear"
) -> Campaign:
    """The twin-corrected campaign of one simulated session, the twin's model being its
    true thermal model (:func:`truth_twin_model`): ``read_campaign([session], "twin",
    twin=truth_twin_model(session))``."""
    return read_campaign(
        [session], "twin", interpolation=interpolation, twin=truth_twin_model(session)
    )


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
        ``session:step`` of every target (``session#k:step`` for sessions that share a
        name, ``k`` their place in the order given).
    commanded, measured : ndarray, shape (N, 6)
        Commanded and measured (``poses``) poses relative to O, mm and deg.
    poses : {"corrected", "conventional", "twin"}
    twin : TwinModel or None
        The twin's model (``twin`` poses only).
    frames : RecordedFrames or None
        The controller's frames during the sessions (``run.yaml``'s record; its
        ``values_mm_deg`` None: not recorded, assumed zero). When they are not zero,
        :attr:`nominal` is the hexapod file's geometry with its base joints moved into
        frame O (the platform at the origin step, :func:`~hexatherm.core.frames.
        hexapod_in_origin`) and :attr:`commanded` the nominal poses relative to
        it (``O0 X O0^-1``): the same leg lengths as the controller drove.
    structure : BandedCovariance or None
        :attr:`covariance` with its structure (O and R0 low-rank, the rest banded), what
        the fit whitens with (None: not banded, the dense one is used).
    dense_covariance : ndarray, shape (6N, 6N), or None
        :attr:`covariance` as computed when it has no structure (None: it has one, and
        the dense matrix, 288 MB at 1000 targets, is built only on request).
    """

    results: list[ProcessResult]
    nominal: Hexapod
    labels: list[str]
    commanded: FloatArray
    measured: FloatArray
    poses: PoseKind
    twin: TwinModel | None = None
    structure: BandedCovariance | None = None
    dense_covariance: FloatArray | None = None
    frames: RecordedFrames | None = None

    @property
    def machine_zero(self) -> FloatArray | None:
        """The pose (6,) of the controller's machine frame (its zero pose with no frames)
        relative to frame O; None when the frames were zero."""
        if self.frames is None or not self.frames.values.any():
            return None
        user, obj = campaign_transforms(self.frames.values)
        return np.asarray(
            pose_from_transform(machine_in_origin(user, obj), self.nominal.convention), float
        )

    def __post_init__(self) -> None:
        if (self.structure is None) == (self.dense_covariance is None):
            raise ValueError("a campaign's covariance is either structured or dense")

    @functools.cached_property
    def covariance(self) -> FloatArray:
        """Covariance (6N, 6N) of the measured poses together (linear propagation), mm
        and deg: the terms between targets of one session (its one frame O and reference
        R0 move every pose) included, sessions independent; for ``twin`` poses, the
        measured (conventional) poses' covariance (see the module text). Dense, built
        from :attr:`structure` on first use where there is one."""
        if self.dense_covariance is not None:
            return self.dense_covariance
        assert self.structure is not None
        return self.structure.dense()

    @property
    def weights_covariance(self) -> FloatArray | BandedCovariance:
        """The covariance the fit whitens with: its structure where it has one."""
        return self.covariance if self.structure is None else self.structure


def read_campaign(
    paths: Sequence[str | Path],
    poses: PoseKind = "corrected",
    reading: ReadOptions = STRICT,
    interpolation: Interpolation = "linear",
    geometry: Hexapod | None = None,
    twin: TwinModel | None = None,
    specs: Sequence[Session] | None = None,
) -> Campaign:
    """Process every session of ``paths`` (``interpolation`` of the growth at the
    references as in ``process``; ``geometry``, a calibrated hexapod, for the
    correction's IGM and FGM instead of the sessions' file, and for the twin's joints)
    and pool their targets (see the module text). The nominal geometry, the one the
    controller commanded with, stays the sessions' hexapod file. ``twin`` is the twin's
    model, required with ``poses="twin"`` and refused otherwise (ValueError). ``specs``:
    the session files of ``paths`` already read (``calibrate`` reads them first, to check
    the output folder against its inputs), so that their YAML files are read once (a
    plan of 20,002 steps takes a quarter of a second)."""
    if poses not in POSE_KINDS:
        raise ValueError(f"poses must be one of {', '.join(POSE_KINDS)}, got {poses!r}")
    if (poses == "twin") != (twin is not None):
        raise ValueError("a twin model is required with poses='twin' and only with it")
    if not paths:
        raise ValueError("calibrate needs at least one session")
    if specs is None:
        specs = [read_session(path) for path in paths]
    check_distinct_sessions(specs)
    check_one_hexapod(specs)
    check_one_balls(specs)
    frames = check_one_frames([read_recorded_frames(spec.path.parent) for spec in specs])
    results = [
        process_session(path, interpolation, reading=reading, hexapod=geometry, session=spec)
        for path, spec in zip(paths, specs, strict=True)
    ]
    check_distinct_measurements(results)
    # the campaign relative to frame O, as with no frames (process_session's sessions too:
    # their plans' poses are O0 X O0^-1)
    nominal = hexapod_in_origin(specs[0].hexapod, frames.values, np.zeros(6))[0]
    check_reference_states(results, warn=geometry is None)  # --iterate's rounds: said once
    labels: list[str] = []
    commanded, measured = [], []
    weights: list[BandedCovariance | FloatArray] = []
    names = [result.session.name for result in results]
    for k, result in enumerate(results, 1):
        corr = result.correction
        targets = corr.target_index
        name = names[k - 1]
        tag = f"{name}#{k}" if names.count(name) > 1 else name  # sessions of one name apart
        labels += [f"{tag}:{result.session.plan.labels[i]}" for i in targets]
        commanded.append(result.session.plan.poses[targets])
        if twin is not None:
            measured.append(twin_poses(result, twin.with_geometry(geometry), twin.path))
        else:
            measured.append(corr.corrected if poses == "corrected" else corr.conventional)
        weights.append(joint_pose_covariance_for_fit(result, corrected=poses == "corrected"))
    n = len(labels)
    if n < MIN_POSES:
        raise InputError(
            f"{n} target pose(s) in all: a calibration needs at least {MIN_POSES} (and 30 or "
            "more spread over the stroke for the joints)",
            path=str(results[0].session.path),
        )
    banded = [w for w in weights if isinstance(w, BandedCovariance)]
    structure = BandedCovariance.stacked(banded) if len(banded) == len(weights) else None
    dense = None
    if structure is None:  # the dense matrix only when the fit whitens with it
        dense = block_diag(
            *[
                joint_pose_covariance(r, corrected=poses == "corrected")
                if isinstance(w, BandedCovariance)
                else w
                for w, r in zip(weights, results, strict=True)
            ]
        )
    return Campaign(
        results,
        nominal,
        labels,
        np.concatenate(commanded),
        np.concatenate(measured),
        poses,
        twin,
        structure,
        dense,
        frames,
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


def machine_hexapod(run: Calibration) -> Hexapod:
    """The calibrated geometry as ``hexapod.yaml`` gives it: base joints in frame O of
    the controller's zero pose with no frames (the platform where the calibrated
    geometry stands for the legs of the nominal zero pose). With zero frames during the
    campaign that is its origin step's frame O, :meth:`CalibrationFit.hexapod`; else
    the calibrated platform at the machine's zero, predicted relative to frame O."""
    hexapod = run.fit.hexapod()
    zero = run.campaign.machine_zero
    if zero is None:
        return hexapod
    at = run.fit.predict(zero[None])[0]
    base = in_frame(hexapod.base_joints_mm, at, hexapod.convention)
    return dataclasses.replace(hexapod, base_joints_mm=base)


def calibrate(campaign: Campaign, level: str = "auto", residuals: str = "pose") -> Calibration:
    """Fit the campaign's geometry at ``level`` (``auto``: chosen by BIC and held-out folds)."""
    before = to_um_urad(campaign.measured - campaign.commanded)
    if level == "auto":
        choice = select_level(
            campaign.nominal,
            campaign.commanded,
            campaign.measured,
            campaign.weights_covariance,
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
            campaign.weights_covariance,
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
    twin: TwinModel | None = None,
    specs: Sequence[Session] | None = None,
) -> tuple[Calibration, list[float]]:
    """Calibrate, reprocess the sessions with the calibrated geometry (the correction's
    IGM and FGM), calibrate again, until no parameter moves more than
    :data:`ITERATE_TOL_MM`; returns the last calibration and each round's largest move
    (mm). CalibrationError after :data:`MAX_ROUNDS` rounds without convergence. With
    ``twin``, the twin's joints are the calibrated ones too from the second round."""
    specs = [read_session(path) for path in paths] if specs is None else specs
    campaign = read_campaign(paths, poses, reading, interpolation, twin=twin, specs=specs)
    run = calibrate(campaign, level, residuals)
    moves: list[float] = []
    while len(moves) < MAX_ROUNDS:
        campaign = read_campaign(
            paths, poses, reading, interpolation, run.fit.hexapod(), twin, specs
        )
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
