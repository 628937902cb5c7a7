"""A controller's frames (``hexatherm.core.frames``) against 4 x 4 matrices composed by
hand with SciPy's rotations: Symétrie's ``R = Rz Ry Rx`` about fixed axes is SciPy's
extrinsic ``"xyz"``, PI's ``U -> V -> W`` about moving axes its intrinsic ``"XYZ"``; the
platform in the machine frame is ``U0 X O0^-1`` (CGSE's simulator's links), frame O the
platform at the origin step."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hexatherm.core.frames import hexapod_in_origin, platform_in_machine, poses_from_origin
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plausibility import commanded_relative
from tests.sessions import ROOT

FRAMES = np.array([0.8, -1.5, 122.0, 0.4, -0.3, 21.2, 0.5, -0.3, 120.0, 0.1, -0.2, 20.3])
POSES = np.array(
    [
        [0.0] * 6,
        [0, 0, -40.0, 0, 0, 0],
        [5.0, -3.0, 4.0, 1.0, -2.0, 3.0],
        [-8, 6, -5, -2.5, 1.5, -4],
    ]
)
EULER = {"symetrie": "xyz", "pi": "XYZ"}


def matrix(pose: np.ndarray, convention: str = "symetrie") -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler(EULER[convention], pose[3:], degrees=True).as_matrix()
    out[:3, 3] = pose[:3]
    return out


def pose(m: np.ndarray, convention: str = "symetrie") -> np.ndarray:
    angles = Rotation.from_matrix(m[:3, :3]).as_euler(EULER[convention], degrees=True)
    return np.concatenate([m[:3, 3], angles])


def by_hand(frames: np.ndarray, x: np.ndarray, convention: str = "symetrie") -> np.ndarray:
    """``U0 X O0^-1``, 4 x 4."""
    return matrix(frames[:6]) @ matrix(x, convention) @ np.linalg.inv(matrix(frames[6:]))


def hexapod() -> Hexapod:
    from hexatherm.io.config import read_hexapod

    return read_hexapod(ROOT / "configs" / "symetrie-like.yaml")


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_platform_in_machine_and_relative_to_frame_o_are_the_compositions(convention) -> None:
    machine = platform_in_machine(FRAMES, POSES, convention)
    origin = np.linalg.inv(by_hand(FRAMES, POSES[0], convention))
    for x, got, y in zip(
        POSES,
        machine,
        poses_from_origin(POSES, matrix(FRAMES[6:]), convention),  # type: ignore[arg-type]
        strict=True,
    ):
        np.testing.assert_allclose(got, pose(by_hand(FRAMES, x, convention), convention), atol=1e-9)
        want = pose(origin @ by_hand(FRAMES, x, convention), convention)
        np.testing.assert_allclose(y, want, atol=1e-9)


def test_the_session_from_frame_o_drives_the_controllers_legs_and_compares_to_its_poses():
    """The legs the controller drives (its nominal joints, ``M = U0 X O0^-1``) are those of
    the hexapod moved into frame O at ``O0 X O0^-1``; what process compares a measured
    step with (:func:`commanded_relative`, step relative to the origin step) is
    ``M(X_O)^-1 M(X_S)``, here with the origin step off zero too."""
    nominal = hexapod()
    moved, y = hexapod_in_origin(nominal, FRAMES, POSES)
    legs = []
    for x in POSES:
        m = by_hand(FRAMES, x)
        placed = nominal.platform_joints_mm @ m[:3, :3].T + m[:3, 3]
        legs.append(np.linalg.norm(placed - nominal.base_joints_mm, axis=1))
    np.testing.assert_allclose(moved.igm(y), legs, atol=1e-9)
    shifted = POSES + [1.0, -2.0, 3.0, 0.5, -0.4, 0.3]  # an origin step off zero
    relative = commanded_relative(hexapod_in_origin(nominal, FRAMES, shifted)[1], 0)
    for x, got in zip(shifted, relative, strict=True):
        want = pose(np.linalg.inv(by_hand(FRAMES, shifted[0])) @ by_hand(FRAMES, x))
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_zero_frames_give_back_what_they_are_given() -> None:
    nominal = hexapod()
    moved, y = hexapod_in_origin(nominal, np.zeros(12), POSES)
    assert moved is nominal and np.array_equal(y, POSES)
    assert np.array_equal(platform_in_machine(np.zeros(12), POSES, "symetrie"), POSES)
