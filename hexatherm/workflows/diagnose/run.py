"""From a session folder to a diagnosis: read, assemble, then :func:`core.diagnosis.diagnose`.

The glue of ``hexatherm diagnose``: it reads the session like ``process`` does
(fitting spheres to probed points), builds the thermocouple log, takes the
current model from the hexapod file (the session's, or ``--hexapod``) and runs
the diagnosis. Writing is :mod:`hexatherm.workflows.diagnose.outputs`' job.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexatherm.core.diagnosis import (
    HELDOUT_BLOCKS,
    MIN_STEPS,
    Diagnosis,
    Observations,
    diagnose,
    pose_residuals,
)
from hexatherm.core.effects import Effect
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.residuals import PoseResiduals
from hexatherm.errors import InputError
from hexatherm.io.config import read_hexapod, read_session
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.runrecord import RecordedFrames
from hexatherm.io.temperatures import Temperatures
from hexatherm.session import Session
from hexatherm.workflows.process.frames import session_frames, session_in_origin
from hexatherm.workflows.process.measured import constant_legs_warning, read_measured
from hexatherm.workflows.process.twin import model_effects, thermocouple_log


@dataclass(frozen=True)
class SessionData:
    """A session read for the diagnosis.

    Attributes
    ----------
    session : Session
        As frame O sees it: with the controller's frames set during the session
        (``run.yaml``), its plan's poses ``O0 X O0^-1``
        (:func:`~hexatherm.workflows.process.frames.session_in_origin`).
    hexapod : Hexapod
        The model diagnosed (the session's hexapod or the one given) relative to frame O:
        its base joints moved by ``O0 U0^-1`` when the frames were set, so that its IGM of
        the session's poses gives the legs the controller drove.
    hexapod_source : str
        Where the hexapod came from (the session, or the file given).
    current : tuple of Effect
        The model's own effects (its ``thermal_model``).
    observations : Observations
    temperatures : Temperatures
    uncertainty_source : str
        Where the centres' uncertainties come from, in words.
    warnings : tuple of str
        What the diagnosis rests on that the user should know (a constant log).
    file_hexapod : Hexapod or None
        The hexapod as its file gives it (machine frame), what the diagnosed model file is
        written from; None: ``hexapod`` (no frames were set).
    frames : RecordedFrames or None
        The controller's frames the session was measured with (None: not read).
    """

    session: Session
    hexapod: Hexapod
    hexapod_source: str
    current: tuple[Effect, ...]
    observations: Observations
    temperatures: Temperatures
    uncertainty_source: str
    warnings: tuple[str, ...] = ()
    file_hexapod: Hexapod | None = None
    frames: RecordedFrames | None = None

    @property
    def frames_said(self) -> str | None:
        """The controller's frames in one line when they were set (None: zero, or not
        recorded): what the diagnosis's commanded poses went through."""
        if self.frames is None or self.frames.values_mm_deg is None:
            return None
        if not self.frames.values_mm_deg.any():
            return None
        return (
            "user, object frames "
            + " ".join(f"{v:.15g}" for v in self.frames.values_mm_deg)
            + " (mm, deg; run.yaml): the commanded poses relative to frame O are O0 X O0^-1"
        )

    @property
    def written_hexapod(self) -> Hexapod:
        """The hexapod in its file's frame (the machine's): what ``hexapod.yaml`` holds."""
        return self.hexapod if self.file_hexapod is None else self.file_hexapod


@dataclass(frozen=True)
class DiagnosisResult:
    """A diagnosis with the residuals before and after, in pose and leg space."""

    data: SessionData
    diagnosis: Diagnosis
    before: PoseResiduals
    after: PoseResiduals


def read_for_diagnosis(
    path: str | Path,
    hexapod_path: str | Path | None = None,
    reading: ReadOptions = STRICT,
    session: Session | None = None,
) -> SessionData:
    """Read a session (and optionally another hexapod file) for the diagnosis; ``reading``
    as in :func:`~hexatherm.workflows.process.measured.read_measured`; ``session``: its
    session file already read (``diagnose`` reads it first, to check the output folder
    against its inputs: a plan of 20,002 steps takes a quarter of a second)."""
    session = read_session(path) if session is None else session
    if session.temperatures is None:
        raise InputError(
            "the diagnosis compares the measurements with the twin, which needs "
            "the thermocouple log: add 'temperatures: temperatures.csv' "
            "(time,leg1..leg6[,air]) to the session",
            path=str(session.path),
            field="temperatures",
        )
    file_hexapod = session.hexapod if hexapod_path is None else read_hexapod(hexapod_path)
    current = model_effects(file_hexapod, str(hexapod_path or session.path))
    # with the controller's frames set, the session as frame O sees it (as process does):
    # the twin's commanded legs are the IGM of the poses relative to frame O
    frames = session_frames(session)
    session = session_in_origin(dataclasses.replace(session, hexapod=file_hexapod), frames.values)
    hexapod = session.hexapod
    _, _, centres, temperatures = read_measured(session, reading=reading)
    assert temperatures is not None  # the session names them (checked above)
    # after the files are read: what is wrong in them is said first
    n_steps = len(session.plan.labels)
    if n_steps < MIN_STEPS:
        raise InputError(
            f"the session has {n_steps} steps; the diagnosis needs at least {MIN_STEPS} "
            f"(two in each of the {HELDOUT_BLOCKS} blocks of time of its held-out check): "
            "with fewer, an effect it adds or its verdict rests on chance",
            path=str(session.path),
            field="plan",
        )
    log = thermocouple_log(temperatures)
    needing = [e.name for e in current if type(e).needs_air]
    if log.air_C is None and needing:
        raise InputError(
            f"the model's {', '.join(needing)} ({hexapod_path or session.path}) needs the air "
            "temperature: the temperatures have no 'air' column",
            path=temperatures.path,
            line=1,
            field="air",
        )
    u_um = centres.u_um
    if np.all(np.isnan(u_um)):
        u_mm = np.full(u_um.shape, 1e-3)
        source = "none given: all centres weighted alike (the noise level is estimated)"
    else:
        median = float(np.nanmedian(u_um))
        u_mm = np.maximum(np.where(np.isnan(u_um), median, u_um), 1e-3) * 1e-3
        source = f"sphere fits (median {median:.2f} um)"
    obs = Observations(
        session.plan,
        centres.times_s,
        centres.centres_mm,
        session.balls.centres_mm,
        log,
        u_mm,
        u_given=not np.all(np.isnan(u_um)),
    )
    source_hexapod = "the session's" if hexapod_path is None else str(hexapod_path)
    constant = constant_legs_warning(temperatures)
    return SessionData(
        session,
        hexapod,
        source_hexapod,
        current,
        obs,
        temperatures,
        source,
        () if constant is None else (constant,),
        file_hexapod,
        frames,
    )


def run_diagnosis(
    data: SessionData, progress: Callable[[int, int, int], None] | None = None
) -> DiagnosisResult:
    """Diagnose a session read by :func:`read_for_diagnosis` (``progress``: see ``diagnose``)."""
    diagnosis = diagnose(data.hexapod, data.observations, data.current, progress=progress)
    before = pose_residuals(data.hexapod, data.observations, diagnosis.baseline)
    after = pose_residuals(data.hexapod, data.observations, diagnosis.final)
    return DiagnosisResult(data, diagnosis, before, after)
