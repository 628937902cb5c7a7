"""Hexapod controllers: one protocol for every dialect, and what the dialects share.

A driver moves the hexapod and reports what its controller says: the pose, the actuator
(leg) lengths, the controller's temperatures. hexatherm drives two dialects over plain
TCP sockets (no vendor library): Symétrie API v2 (:mod:`hexatherm.devices.symetrie`)
and PI GCS (:mod:`hexatherm.devices.pi`); :func:`controller_from_url` picks one.

Poses at this interface are hexatherm's ``[Tx, Ty, Tz, Rx, Ry, Rz]`` in mm and deg,
in the convention of the hexapod (``symetrie``: fixed axes, ``R = Rz Ry Rx``; ``pi``:
mobile axes, ``R = Rx Ry Rz``; :mod:`hexatherm.core.geometry`). Each driver speaks its
controller's units and convention on the wire (Symétrie: m and rad, ``symetrie``
convention; PI: mm and deg, ``pi`` convention) and converts both ways; a driver given
another interface convention converts the angles through the rotation matrix.

"Not moving" is not "there". :meth:`HexapodController.wait_in_position` waits for the
controller's in-position flag, then a settle time, then requires ``n_readings``
consecutive read-back poses to agree within a tolerance (um, urad, peak to peak per
component), and their mean to lie within a tolerance of the commanded pose. It returns a
:class:`StepRecord` of the step. Clock and sleep are injectable, so the waiting can run
on simulated time.

Errors a user can meet derive from :class:`ControllerError` (a
:class:`~hexatherm.errors.HexathermError`): :class:`ControllerConnectionError` (refused,
dropped, silent connection), :class:`ControllerTimeoutError` (no in-position flag, an
unstable read-back), :class:`PoseRefusedError` (the pose fails validation: nothing was
moved) and :class:`ControllerReplyError` (the controller answered with an error code,
decoded into words).

>>> import numpy as np
>>> pose = [1.0, -2.0, 3.0, 0.5, -0.25, 10.0]
>>> back = convert_pose(convert_pose(pose, "symetrie", "pi"), "pi", "symetrie")
>>> bool(np.allclose(back, pose, atol=1e-12))
True
"""

from __future__ import annotations

from hexatherm.devices.controller.protocol import (
    MAX_LINE,
    UM_PER_MM,
    URAD_PER_DEG,
    ControllerState,
    HexapodController,
    InPositionCriteria,
    LineBuffer,
    StepRecord,
    convert_pose,
    format_pose,
    pose_deviation_um_urad,
    stroke_violations,
    wrap_deg,
)
from hexatherm.devices.controller.sockets import (
    LogCallback,
    SocketController,
    parse_numbers,
)

__all__ = [
    "ControllerState",
    "HexapodController",
    "InPositionCriteria",
    "LineBuffer",
    "LogCallback",
    "MAX_LINE",
    "SocketController",
    "StepRecord",
    "UM_PER_MM",
    "URAD_PER_DEG",
    "convert_pose",
    "format_pose",
    "parse_numbers",
    "pose_deviation_um_urad",
    "stroke_violations",
    "wrap_deg",
]
