"""``run`` and ``process`` with a Symétrie controller's user and object frames set.

A lab that rotates about its payload sets the user and object frames some 120 mm above
the platform: the controller then puts the platform at ``M = U0 X O0^-1`` for the
commanded ``X`` (the twin's controller, as CGSE's simulator links the frames), at
``O0 X O0^-1`` relative to frame O. The truth is the twin's: the platform poses its
controller's own mapping gives (``_model_pose``) through ``TwinWorld.truth``. ``run``
must plan its touch points where the balls are (every ball probed once, its fit within
micrometres of the prediction; before, millimetres off: 3 deg about a point 120 mm up
move the balls by 6 mm) and check the stroke of the legs the controller drives;
``process`` must pass its pose check and report the deviations from the commanded pose
as the frames make it (before: refused, the measured poses millimetres from ``X``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.core.geometry import invert_transform, pose_from_transform, transform_from_pose
from hexatherm.devices.symetrie import format_wire, pose_to_wire
from hexatherm.devices.urls import controller_from_url
from hexatherm.errors import PoseError, StepError
from hexatherm.io.config import read_session
from hexatherm.io.files import STRICT
from hexatherm.io.provenance import run_context
from hexatherm.workflows.process.pipeline import Checks, process_session
from hexatherm.workflows.process.run import ProcessRequest, process
from hexatherm.workflows.process.written import read_written
from hexatherm.workflows.report.figures import pose_deviations as report_deviations
from hexatherm.workflows.report.run import read_results
from tests.workflows.test_run import URAD, Bench, make_bench, step_times

#: the user frame in the machine frame, the object frame in the platform frame (mm, deg):
#: both about 120 mm above the platform, a little apart
FRAMES = np.array([0.8, -1.5, 122.0, 0.4, -0.3, 21.2, 0.5, -0.3, 120.0, 0.1, -0.2, 20.3])
TARGETS = [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0], [-8.0, 6.0, -5.0, -2.5, 1.5, -4.0]]


def set_frames(b: Bench, values: np.ndarray) -> None:
    """The frames through API v2's own command (``CFG#CS``, m and rad), as a lab sets them."""
    driver = controller_from_url(b.machines.controller_url, clock=b.clock, sleep=b.clock.sleep)
    driver.connect()
    try:
        driver._transact("CFG#CS", format_wire(pose_to_wire(values.reshape(2, 6))))
    finally:
        driver.close()


def platform_poses(b: Bench, poses: np.ndarray) -> np.ndarray:
    """Where the twin's controller puts the platform (machine frame) for ``poses``: its
    own mapping of the frames it was given."""
    return np.array([b.machines.controller._model_pose(p) for p in poses])


def test_run_probes_every_ball_where_the_frames_put_it_and_process_finds_the_truth(
    tmp_path: Path,
) -> None:
    b = make_bench(tmp_path, targets=TARGETS, points_per_ball=5)
    try:
        set_frames(b, FRAMES)
        plan = b.files.plan
        machine = platform_poses(b, plan.poses)
        # --origin-on-cmm: the nominal placement of frame O, the platform at the origin step
        origin = transform_from_pose(b.options().origin_on_cmm) @ transform_from_pose(machine[0])
        result = b.run(origin_on_cmm=tuple(float(v) for v in pose_from_transform(origin)))
    finally:
        b.machines.close()
    assert result.n_points == len(plan.labels) * 3 * plan.points_per_ball
    assert not result.remeasured
    # after frame O (its prediction rests on the nominal placement, 0.5 mm and 0.2 deg off),
    # each ball probed once, around a prediction micrometres from its fit
    later = [r for r in result.balls if r.label != plan.labels[plan.origin_index]]
    assert all(r.attempts == 1 and not r.problems for r in later)
    miss = max(float(np.linalg.norm(r.centre_mm - r.predicted_mm)) for r in later)
    assert miss < 0.02, miss
    assert any("controller frames" in m for _, m in b.messages)

    with run_context("process", [str(b.session)], {}):  # as the command line: provenance
        outcome = process(ProcessRequest(session=b.session))  # writes SESSION/results
    processed = outcome.result
    np.testing.assert_allclose(processed.frames, FRAMES, atol=1e-12)
    truth = b.world.truth(
        dataclasses.replace(plan, poses=machine, reference_pose=machine[plan.reference_indices[0]]),
        step_times(b.session, plan.labels),
    )
    idx = processed.correction.target_index
    err = processed.correction.corrected - truth.corrected_pose[idx]
    assert np.abs(err[:, :3]).max() * 1e3 < 0.3
    assert np.abs(err[:, 3:]).max() * URAD < 10.0
    # the deviations from the commanded pose as the frames make it (the twin's mapping,
    # relative to frame O): the thermal error conventionally, none once corrected
    at_origin = invert_transform(transform_from_pose(machine[plan.origin_index]))
    commanded = pose_from_transform(at_origin @ transform_from_pose(machine[idx]))
    table = pd.read_csv(b.session / "results" / "poses.csv")
    # the report reads the folder back and takes the deviations from the same commanded pose
    results = read_results(b.session / "results")
    written, _, _ = read_written(
        results.folder, read_session(results.session_file), results.options, results.notes, STRICT
    )
    conv, corr = report_deviations(written)
    assert "O0 X O0^-1" in results.notes["controller_frames"]
    cols = [
        f"d{a}_{{}}_{u}"
        for a, u in zip(
            ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz"), ["um"] * 3 + ["urad"] * 3, strict=True
        )
    ]
    scale = np.array([1e3] * 3 + [URAD] * 3)
    for tag, truth_pose in (("conv", truth.pose[idx]), ("corr", truth.corrected_pose[idx])):
        got = table[[c.format(tag) for c in cols]].to_numpy()
        want = (truth_pose - commanded) * scale
        np.testing.assert_allclose(conv if tag == "conv" else corr, got, atol=2e-3)
        assert np.abs(got[:, :3] - want[:, :3]).max() < 0.3
        assert np.abs(got[:, 3:] - want[:, 3:]).max() < 10.0
    # a refusal shows the commanded pose the frames make (a tolerance below the heating)
    with pytest.raises(StepError, match=r"commanded \[.*\] \(the plan's through the controller's"):
        process_session(b.session, checks=Checks(pose_tolerance=(1e-4, 1.0)))
    thermal = (truth.pose[idx] - truth.corrected_pose[idx])[:, :3] * 1e3
    assert np.abs(thermal).max() > 3.0  # the correction took off micrometres
    np.testing.assert_allclose(
        table[[f"{a}_cmd_mm" for a in ("Tx", "Ty", "Tz")]], commanded[:, :3], atol=1e-6
    )


def test_the_stroke_is_checked_where_the_frames_put_the_platform(tmp_path: Path) -> None:
    """A user frame 20 mm up: ``Tz = -65`` commanded is ``-45`` for the legs (within the
    stroke, which the twin's controller agrees with), ``+35`` is ``+55`` (beyond it)."""
    up = np.zeros(12)
    up[2] = 20.0
    b = make_bench(tmp_path / "low", targets=[[0, 0, -65.0, 0, 0, 0]], points_per_ball=4)
    try:
        set_frames(b, up)
        assert b.dry_run() == 4  # before: refused, IGM(X) is 211.5 mm (stroke 220..310)
    finally:
        b.machines.close()
    b = make_bench(tmp_path / "high", targets=[[0, 0, 35.0, 0, 0, 0]], points_per_ball=4)
    try:
        set_frames(b, up)
        with pytest.raises(PoseError, match=r"step S1: .*through the controller's user and object"):
            b.dry_run()
        assert b.world.model.moves == 0
    finally:
        b.machines.close()
