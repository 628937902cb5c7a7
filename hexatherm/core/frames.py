"""A controller's coordinate frames: where a commanded pose puts the platform.

A Symétrie controller takes a user frame ``U0`` (its pose in the machine frame) and an
object frame ``O0`` (its pose in the platform frame), 12 values (mm, deg, Symétrie's
convention: ``R = Rz Ry Rx``, fixed axes) as ``run.yaml`` records them; a commanded pose
``X`` is the object's in the user frame, so the platform stands at ``M = U0 X O0^-1`` in
the machine frame (CGSE's simulator links the frames so, to 2e-12 mm and 1e-12 deg in
``bench/peers.py``; hexatherm's twin too: ``devices/sim/userframes.py``) and its legs
are the nominal IGM of ``M``
(:func:`platform_in_machine`). The origin step (``X = 0``) puts it at ``M0 = U0 O0^-1``:
relative to frame O (the platform there, what every measured pose refers to), the
platform at ``X`` stands at ``M0^-1 M = O0 X O0^-1`` (:func:`poses_from_origin`, the user
frame gone), and the machine frame at ``M0^-1 = O0 U0^-1`` (:func:`machine_in_origin`).
So relative to frame O a session measured with frames is one without frames of the
nominal hexapod whose base joints are moved by ``O0 U0^-1``, commanded ``O0 X O0^-1``:
the same leg lengths, exactly (:func:`hexapod_in_origin`). ``run`` predicts the balls
and checks the stroke with it, ``process`` compares the measured poses with it,
``calibrate`` fits on it. With zero frames every function gives back what it was given.

PI's work and tool frames are not supported: ``run`` moves a PI hexapod only in its
``ZERO`` coordinate system with its pivot at zero (its driver refuses others), so a PI
session's frames are zero.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    Convention,
    apply_transform,
    check_poses,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.typing import FloatArray

__all__ = [
    "campaign_transforms",
    "hexapod_in_origin",
    "machine_in_origin",
    "platform_in_machine",
    "poses_from_origin",
]


def campaign_transforms(
    values_mm_deg: npt.ArrayLike, convention: Convention = "symetrie"
) -> tuple[FloatArray, FloatArray]:
    """``U0`` and ``O0`` (4 x 4 each) of the 12 values a controller reported during a
    campaign: its user (work) frame in the machine frame, then its object (tool) frame in
    the platform frame (mm, deg, in ``convention``: Symétrie's own by default)."""
    v = np.asarray(values_mm_deg, float).reshape(12)
    frames = transform_from_pose(np.stack([v[:6], v[6:]]), convention)
    return frames[0], frames[1]


def platform_in_machine(
    values_mm_deg: npt.ArrayLike, poses: npt.ArrayLike, convention: Convention
) -> FloatArray:
    """The platform's poses in the machine frame (..., 6) for commanded poses ``X``
    (..., 6, ``convention``) with the frames ``values_mm_deg`` (12, Symétrie convention)
    set: ``U0 X O0^-1``, whose nominal IGM the controller drives; in ``convention``.

    >>> frames = [0, 0, 100.0, 0, 0, 0] + [0, 0, 100.0, 0, 0, 0]  # both 100 mm up: Rx about
    >>> # the point 100 mm above the platform
    >>> platform_in_machine(frames, [0, 0, 0, 2.0, 0, 0], "symetrie").round(4) + 0.0
    array([0.    , 3.4899, 0.0609, 2.    , 0.    , 0.    ])
    """
    x = check_poses(poses)
    if not np.any(values_mm_deg):
        return np.array(x, dtype=float)
    user, obj = campaign_transforms(values_mm_deg)
    m = user @ transform_from_pose(x, convention) @ invert_transform(obj)
    return np.asarray(pose_from_transform(m, convention), float)


def poses_from_origin(
    poses: npt.ArrayLike, obj: npt.ArrayLike, convention: Convention
) -> FloatArray:
    """The nominal poses (N, 6) relative to frame O of the platform for commanded poses
    ``X`` (N, 6) given to a controller whose object (tool) frame is ``O0`` (4 x 4): the
    controller puts the platform at ``M = U0 X O0^-1`` in its machine frame and at
    ``M0 = U0 O0^-1`` for the origin step, so the platform relative to frame O (where
    the origin step put it) is ``M0^-1 M = O0 X O0^-1``, the user frame gone.

    >>> o0 = transform_from_pose([1.0, 2.0, 3.0, 0.0, 0.0, 90.0])
    >>> poses_from_origin([[1.0, 0, 0, 0, 0, 0]], o0, "symetrie").round(12) + 0.0
    array([[0., 1., 0., 0., 0., 0.]])
    """
    x = transform_from_pose(np.atleast_2d(check_poses(poses)), convention)
    o0 = np.asarray(obj, float)
    return np.asarray(pose_from_transform(o0 @ x @ invert_transform(o0), convention), float)


def machine_in_origin(user: npt.ArrayLike, obj: npt.ArrayLike) -> FloatArray:
    """The machine frame (ZERO) in frame O of a campaign whose frames were ``U0``, ``O0``
    (4 x 4): ``M0^-1 = O0 U0^-1``. The nominal base joints in frame O are this applied
    to those of the hexapod file (machine frame), and the controller's zero pose with no
    frames is this pose relative to frame O."""
    return np.asarray(np.asarray(obj, float) @ invert_transform(np.asarray(user, float)), float)


def hexapod_in_origin(
    hexapod: Hexapod, values_mm_deg: npt.ArrayLike, poses: npt.ArrayLike
) -> tuple[Hexapod, FloatArray]:
    """A session measured with the frames ``values_mm_deg`` (12, Symétrie convention)
    set, relative to its frame O: the hexapod with its base joints moved by ``O0 U0^-1``
    and the commanded ``poses`` (N, 6) as ``O0 X O0^-1`` (the same legs as the
    controller drove: ``IGM'(O0 X O0^-1) = IGM(U0 X O0^-1)``). Zero frames: both as
    given."""
    x = np.atleast_2d(check_poses(poses))
    if not np.any(values_mm_deg):
        return hexapod, np.array(x, dtype=float)
    user, obj = campaign_transforms(values_mm_deg)
    base = apply_transform(machine_in_origin(user, obj), hexapod.base_joints_mm)
    moved = dataclasses.replace(hexapod, base_joints_mm=base)
    return moved, poses_from_origin(x, obj, hexapod.convention)
