"""``diagnose`` of a session measured with the controller's frames set.

With a user frame ``U0`` and an object frame ``O0`` set, commanding ``X`` drives the
legs of ``U0 X O0^-1`` and puts the platform at ``O0 X O0^-1`` relative to frame O
(``hexatherm.core.frames``). So a twin session without frames, of a hexapod ``H'``
commanded ``P``, is the same measurement as a session of the hexapod ``H`` whose base
joints are ``H'``'s moved by ``U0 O0^-1``, commanded ``X = O0^-1 P O0`` with those frames
recorded in ``run.yaml``: the same legs, the same platform, the same centres. The truth
here is that equality: the diagnosis of the framed session must be the unframed one's,
and the model it writes must be in the file's (machine) frame, not frame O's.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from hexatherm.core.effects import make_effect
from hexatherm.core.frames import campaign_transforms, machine_in_origin
from hexatherm.core.geometry import (
    apply_transform,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.io.config import hexapod_to_yaml, plan_to_yaml, read_hexapod_text, read_session
from hexatherm.workflows.diagnose.outputs import diagnosed_hexapod_yaml, diagnosis_json, story
from hexatherm.workflows.diagnose.run import read_for_diagnosis, run_diagnosis
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session

#: the user frame in the machine frame, the object frame in the platform frame (mm, deg):
#: both about 120 mm above the platform, as a lab puts them at the workpiece
FRAMES = np.array([0.8, -1.5, 118.0, 0.4, -0.3, 1.2, 0.5, -0.3, 120.0, 0.1, -0.2, 0.3])


def framed_copy(plain: Path, folder: Path) -> Path:
    """The same measurement as ``plain`` recorded as run with :data:`FRAMES` set."""
    shutil.copytree(plain, folder)  # a twin session: hexapod.yaml, plan.yaml beside it
    session = read_session(plain / "session.yaml")
    hexapod, plan = session.hexapod, session.plan
    user, obj = campaign_transforms(FRAMES)
    # H: the base joints that frame O sees at H' (plain's) once moved by O0 U0^-1
    base = apply_transform(invert_transform(machine_in_origin(user, obj)), hexapod.base_joints_mm)
    file_hexapod = dataclasses.replace(hexapod, base_joints_mm=base)
    (folder / "hexapod.yaml").write_text(hexapod_to_yaml(file_hexapod))

    def commanded(poses: np.ndarray) -> np.ndarray:  # X = O0^-1 P O0
        p = transform_from_pose(poses, hexapod.convention)
        return pose_from_transform(invert_transform(obj) @ p @ obj, hexapod.convention)

    framed_plan = dataclasses.replace(
        plan, poses=commanded(plan.poses), reference_pose=commanded(plan.reference_pose)
    )
    (folder / "plan.yaml").write_text(plan_to_yaml(framed_plan))
    record = {"frames_mm_deg": " ".join(repr(float(v)) for v in FRAMES)}
    (folder / "run.yaml").write_text(yaml.safe_dump({"controller": [record]}))
    return folder


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("diagnose-frames")
    hidden = (make_effect("leg_thermal_lag", NOMINAL_HIDDEN["leg_thermal_lag"]),)
    plain = root / "plain"
    write_twin_session(diagnosis_campaign(hidden, 7, n_targets=4), plain)
    return {"plain": plain, "framed": framed_copy(plain, root / "framed")}


def test_the_framed_copy_differs_where_the_frames_act(folders: dict[str, Path]) -> None:
    plain = read_session(folders["plain"] / "session.yaml")
    framed = read_session(folders["framed"] / "session.yaml")
    # the copy is not the plain session by another name: its commanded poses and base
    # joints are millimetres away (what a diagnosis blind to the frames would take)
    assert np.abs(framed.plan.poses[:, :3] - plain.plan.poses[:, :3]).max() > 1.0
    assert np.abs(framed.hexapod.base_joints_mm - plain.hexapod.base_joints_mm).max() > 1.0


def test_the_diagnosis_of_the_framed_session_is_the_unframed_ones(
    folders: dict[str, Path],
) -> None:
    results = {name: run_diagnosis(read_for_diagnosis(path)) for name, path in folders.items()}
    plain, framed = results["plain"], results["framed"]
    # the session seen from frame O: the plain one's poses and joints
    np.testing.assert_allclose(
        framed.data.observations.plan.poses, plain.data.observations.plan.poses, atol=1e-9
    )
    np.testing.assert_allclose(
        framed.data.hexapod.base_joints_mm, plain.data.hexapod.base_joints_mm, atol=1e-9
    )
    d_plain, d_framed = plain.diagnosis, framed.diagnosis
    assert [a.effect.name for a in d_framed.added] == [a.effect.name for a in d_plain.added]
    assert [a.effect.name for a in d_plain.added] == ["leg_thermal_lag"]  # the hidden effect
    for a, b in zip(d_framed.added, d_plain.added, strict=True):
        for name, value in b.effect.values.items():
            assert a.effect.values[name] == pytest.approx(value, rel=1e-6)
    assert d_framed.baseline_rms_um == pytest.approx(d_plain.baseline_rms_um, rel=1e-6)
    assert d_framed.final_rms_um == pytest.approx(d_plain.final_rms_um, rel=1e-6)
    assert d_plain.final_rms_um < 1.0  # the hidden lag explained: a real diagnosis

    # the frames are said; the plain session's outputs say nothing of them
    doc = json.loads(diagnosis_json(framed))
    assert "O0 X O0^-1" in doc["controller_frames"]
    assert "controller_frames" not in json.loads(diagnosis_json(plain))
    assert "controller frames: user, object frames 0.8 -1.5 118" in story(framed)
    assert "controller frames" not in story(plain)

    # the model written is in the hexapod file's frame (machine), the lag added
    written = read_hexapod_text(diagnosed_hexapod_yaml(framed), "hexapod.yaml")
    file_hexapod = read_session(folders["framed"] / "session.yaml").hexapod
    np.testing.assert_array_equal(written.base_joints_mm, file_hexapod.base_joints_mm)
    assert written.effects[-1]["name"] == "leg_thermal_lag"
