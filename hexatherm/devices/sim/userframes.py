"""A simulated Symétrie controller's user and object frames (both dialects' twins).

As CGSE's simulator links them: the user frame ``U`` in the machine frame, the object
frame ``O`` in the platform frame (:attr:`UserObjectFrames.frames`: 12 values, mm and
deg, Symétrie convention, zero at the start: ``C_CFG_CS`` on gpascii, ``CFG#CS`` on API
v2); a pose on the wire is the object's in the user frame, the platform standing at
``M = U X O^-1`` in the machine frame (the model's pose, whose legs the controller's
nominal IGM gives).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from hexatherm.core.geometry import Convention, pose_from_transform, transform_from_pose
from hexatherm.devices.controller import convert_pose
from hexatherm.typing import FloatArray


class _Model(Protocol):
    """What the frames need of the simulated hexapod (its pose and convention)."""

    convention: Convention

    def read_pose(self) -> FloatArray: ...


class UserObjectFrames:
    """The frames and the poses they map, for a simulated controller with a ``model``
    (:class:`~hexatherm.devices.sim.symetrie.SimulatedHexapod`) that sets
    :attr:`frames` (zeros) when built."""

    model: _Model
    native_convention: Convention
    #: the user frame in the machine frame, then the object frame in the platform frame
    frames: FloatArray

    def _frames(self) -> tuple[FloatArray, FloatArray]:
        user = transform_from_pose(self.frames[:6], "symetrie")
        return user, transform_from_pose(self.frames[6:], "symetrie")

    def _object_pose(self, model_pose: FloatArray) -> FloatArray:
        """The object's pose in the user frame (wire) of the platform's ``model_pose``:
        ``U^-1 M O``."""
        native = convert_pose(model_pose, self.model.convention, self.native_convention)
        if not self.frames.any():
            return native
        user, obj = self._frames()
        frame = np.linalg.inv(user) @ transform_from_pose(native, "symetrie") @ obj
        return np.asarray(pose_from_transform(frame, "symetrie"), dtype=float)

    def _wire_pose(self) -> FloatArray:
        return self._object_pose(self.model.read_pose())

    def _platform_pose(self) -> FloatArray:
        """The platform's read-back pose in the machine frame."""
        return convert_pose(self.model.read_pose(), self.model.convention, "symetrie")

    def _model_pose(self, native: FloatArray) -> FloatArray:
        """The platform's pose (model) of the object's pose ``native`` in the user frame:
        ``M = U X O^-1``."""
        if self.frames.any():
            user, obj = self._frames()
            frame = user @ transform_from_pose(native, "symetrie") @ np.linalg.inv(obj)
            native = np.asarray(pose_from_transform(frame, "symetrie"), dtype=float)
        return convert_pose(native, "symetrie", self.model.convention)
