"""The calibration's frames applied to the gpascii twin (issue 33 item 7): the twin takes
``C_CFG_CS`` as CGSE's ``configure_coordinates_systems`` sends it and composes the frames
as CGSE's simulator links them (``platform in machine = U X O^-1``, hand-computed
here); then, with a true geometry whose joints' error is a known rigid motion, the
frames ``controller.yaml`` gives make the twin drive its actuators to the lengths that
put the true platform on the commanded poses (the truth's FGM of the legs the twin
reports)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from hexatherm.core.calibration.frames import frame_correction
from hexatherm.core.geometry import (
    invert_transform,
    pose_from_transform,
    to_um_urad,
    transform_from_pose,
)
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.symetriepmac import format_command
from tests.core.test_calibration_frames import rigidly_wrong
from tests.devices.test_symetrie_pmac import Rig

POSES = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [1.2, -2.5, 3.0, 0.4, -0.3, 1.5],
        [-4.0, 3.0, -2.0, -0.5, 0.6, -2.0],
        [5.0, 5.0, 4.0, 1.0, 1.0, 1.0],
    ]
)
CRITERIA = InPositionCriteria(settle_s=1.0, poll_s=0.5)


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig()
    r.driver.connect()
    yield r
    r.close()


def set_frames(r: Rig, values: np.ndarray) -> None:
    r.driver._query(format_command("CFG_CS", [float(v) for v in values], 1))
    assert r.driver._values("c_cmd", 1)[0] == 1  # running, then done
    assert r.driver._values("c_cmd", 1)[0] == 0


def test_the_twin_takes_cfg_cs_and_composes_the_frames_as_cgse_links_them(rig: Rig) -> None:
    values = np.array([0.5, -1.0, 2.0, 0.1, -0.2, 0.3, -0.4, 0.3, 1.5, 0.05, 0.0, -0.1])
    set_frames(rig, values)
    np.testing.assert_allclose(rig.driver._get("CFG_CS", 12, cfg=0), values, atol=1e-12)
    pose = POSES[1]
    rig.driver.move_absolute(pose)
    record = rig.driver.wait_in_position(CRITERIA)
    np.testing.assert_allclose(record.pose_mm_deg, pose, atol=1e-9)  # s_uto: object in user
    u, o = transform_from_pose(np.stack([values[:6], values[6:]]))
    want = pose_from_transform(u @ transform_from_pose(pose) @ invert_transform(o))
    np.testing.assert_allclose(rig.model.true_pose(), want, atol=1e-12)  # platform in machine
    np.testing.assert_allclose(rig.driver._values("s_mtp_tx,6,1", 6), want, atol=1e-9)
    # the legs are the controller's IGM of the platform's pose in the machine frame
    np.testing.assert_allclose(record.actuators_mm, rig.model.hexapod.igm(want)[0], atol=1e-8)


def test_the_calibrations_frames_make_the_twin_drive_the_true_poses(rig: Rig) -> None:
    nominal = rig.model.hexapod
    true = rigidly_wrong(nominal)
    values = frame_correction(
        nominal.base_joints_mm,
        nominal.platform_joints_mm,
        true.base_joints_mm,
        true.platform_joints_mm,
    ).values("symetrie")

    def reached(legs: np.ndarray, pose: np.ndarray) -> np.ndarray:
        return true.fgm(legs[None], initial_poses=pose[None])[0]

    rig.driver.move_absolute(POSES[1])
    before = rig.driver.wait_in_position(CRITERIA)
    # without the frames the true platform misses the pose (the test can fail)
    assert np.abs(to_um_urad(reached(before.actuators_mm, POSES[1]) - POSES[1])).max() > 5.0
    set_frames(rig, values)
    for pose in POSES:
        rig.driver.move_absolute(pose)
        record = rig.driver.wait_in_position(CRITERIA)
        error = to_um_urad(reached(record.actuators_mm, pose) - pose)
        assert np.abs(error).max() < 1e-3, (pose, error)  # 1 nm, 1 nrad
