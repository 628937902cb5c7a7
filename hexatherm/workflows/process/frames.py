"""A session measured with the controller's frames set, seen from its frame O.

``run`` records the frames a Symétrie controller had at every connection (``run.yaml``,
:mod:`hexatherm.io.runrecord`). With a user frame ``U0`` and an object frame ``O0`` set,
commanding ``X`` puts the platform at ``O0 X O0^-1`` relative to frame O, not at ``X``,
and its legs are the nominal IGM of ``U0 X O0^-1``: relative to frame O the session is
one without frames of the nominal hexapod whose base joints are moved by ``O0 U0^-1``,
commanded ``O0 X O0^-1`` (:func:`hexatherm.core.frames.hexapod_in_origin`, what
``calibrate`` fits on too). ``process`` works on that session (:func:`session_in_origin`): its
pose check, the deviations from the commanded pose, the IGM and FGM of the correction
and the twin. Without ``run.yaml``, or with zero frames, the session is as read.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hexatherm.core.frames import hexapod_in_origin
from hexatherm.core.hexapod import Hexapod
from hexatherm.io.runrecord import RecordedFrames, read_recorded_frames
from hexatherm.session import Session
from hexatherm.typing import FloatArray


def session_frames(session: Session) -> RecordedFrames:
    """The frames ``run.yaml`` beside the session file recorded (zero, assumed, when none
    did); InputError naming the file, record and field when they cannot be read."""
    return read_recorded_frames(session.path.parent)


def session_in_origin(session: Session, values: FloatArray) -> Session:
    """``session`` relative to its frame O when measured with the frames ``values`` (12,
    mm and deg, Symétrie convention; see the module text): its hexapod's base joints moved
    by ``O0 U0^-1``, its plan's poses (and reference pose) ``O0 X O0^-1``; as it is with
    zero frames."""
    if not np.any(values):
        return session
    plan = session.plan
    poses = np.vstack([plan.poses, plan.reference_pose[None]])
    hexapod, mapped = hexapod_in_origin(session.hexapod, values, poses)
    plan = dataclasses.replace(plan, poses=mapped[:-1], reference_pose=mapped[-1])
    return dataclasses.replace(session, hexapod=hexapod, plan=plan)


def model_in_origin(hexapod: Hexapod, frames: FloatArray | None) -> Hexapod:
    """A hexapod model (the twin's) relative to frame O of a session measured with
    ``frames`` (12 values, or None: zero): its base joints moved by ``O0 U0^-1``."""
    if frames is None:
        return hexapod
    return hexapod_in_origin(hexapod, frames, np.zeros(6))[0]
