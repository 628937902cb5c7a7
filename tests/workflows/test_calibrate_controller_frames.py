"""``calibrate`` with controller frames that were not zero during the campaign.

The truth is the twin's: a hexapod whose joints are the nominal ones moved rigidly (base
by ``A``, platform by ``C``; ``TwinWorld(true_parameters=...)``), driven by a controller
twin that computes its legs with the nominal IGM of ``M = U0 X O0^-1`` (Symétrie's
convention, as CGSE's simulator links the frames). The same plan is measured by ``hexatherm
run`` (noise-free CMM, legs at their reference temperature) with the frames zero (API
v2) and with the frames ``U0``, ``O0`` set through each dialect's own command (API v2
``CFG#CS``, gpascii ``C_CFG_CS``). ``calibrate`` must find the same geometry from all
three, and the frames it writes, set on a controller twin through its command, must put
the true platform where the campaign's frame O and the commanded pose say: the object
frame at ``X`` from where it stood at the origin step, ``O0 X O0^-1`` relative to frame
O, within 1 nm and 1 nrad.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.calibration.model import nominal_parameters
from hexatherm.core.geometry import (
    apply_transform,
    invert_transform,
    pose_from_transform,
    to_um_urad,
    transform_from_pose,
)
from hexatherm.core.heating import Mat, MatHeating
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.planning import build_plan
from hexatherm.devices.controller import InPositionCriteria
from hexatherm.devices.sim.symetrie import ManualClock, SimulatedHexapod, SymetrieSimulator
from hexatherm.devices.sim.symetriepmac import SymetriePmacSimulator
from hexatherm.devices.symetrie import format_wire, pose_to_wire
from hexatherm.devices.symetriepmac import format_command
from hexatherm.devices.urls import controller_from_url
from hexatherm.errors import InputError
from hexatherm.io.config import plan_to_yaml, read_hexapod
from hexatherm.io.runrecord import read_recorded_frames
from hexatherm.workflows.acquire.files import load_files
from hexatherm.workflows.calibrate.frames import frames_record
from hexatherm.workflows.calibrate.run import Calibration, calibrate, machine_hexapod, read_campaign
from hexatherm.workflows.run.campaign import run_campaign
from hexatherm.workflows.run.options import RunOptions
from hexatherm.workflows.serve import TwinWorld
from tests.sessions import ROOT
from tests.workflows.test_run import twin_machines

#: the user frame in the machine frame, the object frame in the platform frame (mm, deg)
FRAMES = np.array([0.8, -1.5, 2.0, 0.4, -0.3, 1.2, 0.5, -0.3, 2.0, 0.1, -0.2, 0.3])
A = transform_from_pose([0.21, -0.13, 0.08, 0.03, -0.02, 0.05])
C = transform_from_pose([-0.05, 0.11, -0.04, -0.04, 0.025, -0.03])
TARGETS = np.random.default_rng(5).uniform(-1, 1, (12, 6)) * [6, 6, 4, 1.5, 1.5, 2]
NOMINAL_ORIGIN = (450.0, 320.0, 210.0, 0.0, 0.0, 15.0)
TRUE_ORIGIN = (450.4, 320.3, 210.2, 0.1, -0.1, 15.2)
CRITERIA = InPositionCriteria(settle_s=2.0, poll_s=1.0, timeout_s=900.0)
HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"


def frames_of(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return transform_from_pose(values[:6]), transform_from_pose(values[6:])


def true_hexapod(nominal: Hexapod) -> Hexapod:
    return replace(
        nominal,
        base_joints_mm=apply_transform(A, nominal.base_joints_mm),
        platform_joints_mm=apply_transform(C, nominal.platform_joints_mm),
    )


def set_frames(driver, values: np.ndarray) -> None:
    """The frames through the dialect's own command (API v2 ``CFG#CS``, m and rad;
    gpascii ``C_CFG_CS`` as CGSE sends it), read back as the driver reads them."""
    if driver.scheme == "symetrie":
        driver._transact("CFG#CS", format_wire(pose_to_wire(values.reshape(2, 6))))
    else:
        driver._query(format_command("CFG_CS", [float(v) for v in values], 1))
        while driver._values("c_cmd", 1)[0] > 0:
            pass
        assert driver._values("c_cmd", 1)[0] == 0


def measure(
    tmp: Path,
    dialect: str,
    frames: np.ndarray | None,
    noise_um: float = 0.0,
    seed: int = 3,
    targets: np.ndarray = TARGETS,
) -> Path:
    """``hexatherm run`` of the plan against the twins, with the controller's frames set
    (``--origin-on-cmm``: the nominal placement of the platform at the origin step)."""
    plan = build_plan(targets, np.zeros(6), points_per_ball=5, reference_every="alternate")
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / "plan.yaml").write_text(plan_to_yaml(plan))
    files = load_files(tmp / "plan.yaml", HEXAPOD, ROOT / "configs" / "balls-3.yaml")
    nominal = read_hexapod(HEXAPOD)
    theta = nominal_parameters(nominal)
    theta[:36] = np.concatenate(
        [apply_transform(A, nominal.base_joints_mm), apply_transform(C, nominal.platform_joints_mm)]
    ).ravel()
    clock = ManualClock(1.7e9)
    still = MatHeating(tuple(Mat(0.0, 2400.0, ((0.0, float("inf")),)) for _ in range(6)))
    world = TwinWorld(
        nominal,
        files.balls,
        heating=still,
        origin_on_cmm=TRUE_ORIGIN,
        clock=clock,
        sleep=clock.sleep,
        start_s=1.7e9 - 1200.0,
        true_parameters=theta,
    )
    origin = transform_from_pose(NOMINAL_ORIGIN)
    with twin_machines(world, dialect=dialect, seed=seed, point_noise_um=noise_um) as machines:
        if frames is not None:
            driver = controller_from_url(machines.controller_url, clock=clock, sleep=clock.sleep)
            driver.connect()
            set_frames(driver, frames)
            driver.close()
            user, obj = frames_of(frames)
            origin = origin @ user @ invert_transform(obj)
        options = RunOptions(
            session=tmp / "session",
            cmm_url=machines.cmm_url,
            controller_url=machines.controller_url,
            origin_on_cmm=tuple(float(v) for v in pose_from_transform(origin)),
            criteria=CRITERIA,
            durable=False,
            reconnect_wait_s=0.0,
        )
        run_campaign(files, nominal, options, lambda *_: None, clock=clock, sleep=clock.sleep)
    return tmp / "session"


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Noise-free, with the frames zero (API v2) and set (gpascii); with 0.02 um probing
    noise (the same draws), zero and set (API v2)."""
    root = tmp_path_factory.mktemp("frames")
    return {
        "zero": measure(root / "zero", "symetrie", None),
        "frames": measure(root / "frames", "symetrie-pmac", FRAMES),
        "noisy-zero": measure(root / "noisy-zero", "symetrie", None, 0.02, 4),
        "noisy-frames": measure(root / "noisy-frames", "symetrie", FRAMES, 0.02, 4),
    }


@pytest.fixture(scope="module")
def calibrated(sessions: dict[str, Path]) -> dict[str, Calibration]:
    return {name: calibrate(read_campaign([path]), "joints") for name, path in sessions.items()}


def test_the_api_v2_twin_takes_cfg_cs_and_moves_as_cgse_links_the_frames() -> None:
    clock = ManualClock(0.0)
    model = SimulatedHexapod(read_hexapod(HEXAPOD), clock=clock)
    with SymetrieSimulator(model) as sim:
        driver = controller_from_url(sim.url, clock=clock, sleep=clock.sleep)
        driver.connect()
        set_frames(driver, FRAMES)
        driver.close()
        driver.connect()  # CFG#CS?3 read at the connection, recorded in full
        recorded = np.array([float(v) for v in driver.info["frames_mm_deg"].split()])
        np.testing.assert_allclose(recorded, FRAMES, atol=1e-12)
        pose = TARGETS[0]
        driver.move_absolute(pose)
        record = driver.wait_in_position(InPositionCriteria(settle_s=1.0, poll_s=0.5))
        np.testing.assert_allclose(record.pose_mm_deg, pose, atol=1e-9)  # the object in user
        user, obj = frames_of(FRAMES)
        want = pose_from_transform(user @ transform_from_pose(pose) @ invert_transform(obj))
        np.testing.assert_allclose(model.true_pose(), want, atol=1e-12)  # platform in machine
        np.testing.assert_allclose(record.actuators_mm, model.hexapod.igm(want)[0], atol=1e-8)
        driver.close()


def test_calibrate_finds_the_same_geometry_with_the_frames_as_without(
    sessions: dict[str, Path], calibrated: dict[str, Calibration], tmp_path: Path
) -> None:
    zero, frames = calibrated["zero"], calibrated["frames"]
    assert zero.campaign.frames is not None and not zero.campaign.frames.values.any()
    assert frames.campaign.frames is not None
    np.testing.assert_allclose(frames.campaign.frames.values, FRAMES, atol=1e-12)
    # noise-free: the truth's platform joints, and one geometry with and without frames
    nominal = read_hexapod(HEXAPOD)
    expected = machine_hexapod(zero)
    truth_platform = apply_transform(C, nominal.platform_joints_mm)
    assert np.abs(expected.platform_joints_mm - truth_platform).max() < 2e-6
    got = machine_hexapod(frames)
    assert np.abs(got.base_joints_mm - expected.base_joints_mm).max() < 3e-6
    assert np.abs(got.platform_joints_mm - expected.platform_joints_mm).max() < 3e-6
    assert np.abs(frames.fit.leg_offsets_mm - zero.fit.leg_offsets_mm).max() < 2e-6
    # with probing noise (the same draws): within half the calibration's U, joint by joint
    # (platform joints and offsets in one frame in both; base joints in hexapod.yaml's)
    noisy, noisy_zero = calibrated["noisy-frames"], calibrated["noisy-zero"]
    u = 2.0 * noisy.fit.std_errors  # k = 2, as parameters.csv
    change = noisy.fit.parameters - noisy_zero.fit.parameters
    assert (np.abs(change[18:42]) <= 0.5 * u[18:42]).all()
    base = machine_hexapod(noisy).base_joints_mm - machine_hexapod(noisy_zero).base_joints_mm
    u_base = np.linalg.norm(u[:18].reshape(6, 3), axis=1)
    assert (np.linalg.norm(base, axis=1) <= 0.5 * u_base).all()
    assert np.abs(change[18:42]).max() > 0.0  # two campaigns, not one twice
    # the same session with the frames taken as zero (as calibrate did before it read
    # them: a session without run.yaml): millimetres off, far beyond U
    blind = tmp_path / "blind"
    shutil.copytree(sessions["frames"], blind)
    (blind / "run.yaml").unlink()
    run = calibrate(read_campaign([blind]), "joints")
    assert run.campaign.frames is not None and run.campaign.frames.values_mm_deg is None
    wrong = machine_hexapod(run)
    assert np.abs(wrong.platform_joints_mm - expected.platform_joints_mm).max() > 0.1


def test_the_written_frames_put_the_true_platform_on_every_commanded_pose(
    calibrated: dict[str, Calibration],
) -> None:
    nominal = read_hexapod(HEXAPOD)
    true = true_hexapod(nominal)
    user, obj = frames_of(FRAMES)

    def stands(machine: np.ndarray) -> np.ndarray:  # the true platform for the legs driven
        return true.fgm(nominal.igm(machine), initial_poses=machine)

    origin = transform_from_pose(stands(pose_from_transform(user @ invert_transform(obj)))[0])
    want = pose_from_transform(obj @ transform_from_pose(TARGETS) @ invert_transform(obj))
    # the frames of the campaign as they were miss by micrometres (the test can fail)
    campaign = user @ transform_from_pose(TARGETS) @ invert_transform(obj)
    placed = transform_from_pose(stands(pose_from_transform(campaign)))
    missed = to_um_urad(pose_from_transform(invert_transform(origin) @ placed) - want)
    assert np.abs(missed).max() > 5.0
    record = frames_record(calibrated["frames"])["symetrie"]
    for dialect, twin in (
        ("symetrie", SymetrieSimulator),
        ("symetrie-pmac", SymetriePmacSimulator),
    ):
        written = np.array(
            [*record["user_frame_in_machine"]["pose"].values()]
            + [*record["object_frame_in_platform"]["pose"].values()]
        )
        clock = ManualClock(0.0)
        model = SimulatedHexapod(nominal, clock=clock)
        with twin(model) as sim:  # type: ignore[abstract]
            driver = controller_from_url(sim.url, clock=clock, sleep=clock.sleep)
            driver.connect()
            if dialect == "symetrie":  # the 12 values as written, m and rad
                driver._transact("CFG#CS", format_wire(record["api_v2_values_m_rad"]))
            else:  # the line as written
                driver._query(record["gpascii_line"])
                while driver._values("c_cmd", 1)[0] > 0:
                    pass
            np.testing.assert_allclose(sim.frames, written, atol=1e-9)
            reached = []
            for pose in TARGETS:
                driver.move_absolute(pose)
                driver.wait_in_position(InPositionCriteria(settle_s=1.0, poll_s=0.5))
                here = transform_from_pose(stands(model.true_pose()[None])[0])
                reached.append(pose_from_transform(invert_transform(origin) @ here))
            driver.close()
        error = to_um_urad(np.array(reached) - want)
        assert np.abs(error).max() < 1e-3, (dialect, np.abs(error).max())


def test_calibration_json_and_the_screen_say_the_frames(sessions, tmp_path) -> None:
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["calibrate", str(sessions["frames"]), "--level", "joints", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "controller frames during the campaign: user, object [0.8, -1.5, 2" in result.output
    doc = json.loads((out / "calibration.json").read_text())["controller_frames_during_campaign"]
    assert not doc["assumed_zero"] and doc["record"].endswith("run.yaml")
    during = [*doc["user_frame_in_machine"].values(), *doc["object_frame_in_platform"].values()]
    np.testing.assert_allclose(during, FRAMES, atol=1e-9)


def test_sessions_measured_with_other_frames_are_refused_in_one_line(sessions) -> None:
    result = CliRunner().invoke(main, ["calibrate", str(sessions["zero"]), str(sessions["frames"])])
    assert result.exit_code != 0
    line = result.output.strip()
    assert "\n" not in line and "Traceback" not in line
    assert "run.yaml" in line and "one frame setting" in line
    assert str(sessions["frames"] / "run.yaml") in line


def record_file(tmp_path: Path, records: list[dict]) -> Path:
    doc = {"format": "hexatherm-run/1", "origin_on_cmm": [0.0] * 6, "controller": records}
    (tmp_path / "run.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    return tmp_path


def test_the_records_run_yaml_keeps_as_calibrate_reads_them(tmp_path: Path) -> None:
    # PI: run moves only in ZERO: frames zero, known
    pi = read_recorded_frames(
        record_file(tmp_path, [{"at": "x", "checks": {"coordinate_system": "ZERO=ZERO"}}])
    )
    assert pi.values_mm_deg is not None and not pi.values.any() and "PI" in pi.source
    # a Symétrie record from before frames_mm_deg: the rounded text, said so
    rounded = {
        "user_frame_in_machine": "[0.8000, -1.5000, 2.0000] mm, [0.40000, -0.30000, 1.2] deg",
        "object_frame_in_platform": "[0.5000, -0.3000, 2.0000] mm, [0.1, -0.20000, 0.3] deg",
    }
    got = read_recorded_frames(record_file(tmp_path, [rounded]))
    np.testing.assert_allclose(got.values, FRAMES, atol=1e-12)
    assert "rounded" in got.source
    # no record, no run.yaml: assumed zero
    assert read_recorded_frames(record_file(tmp_path, [])).values_mm_deg is None
    assert read_recorded_frames(tmp_path / "nowhere").values_mm_deg is None
    # frames that changed between two connections of one session: refused, naming the record
    full = " ".join(str(v) for v in FRAMES)
    other = " ".join(str(v) for v in FRAMES * 0.5)
    path = record_file(tmp_path, [{"frames_mm_deg": full}, {"frames_mm_deg": other}])
    with pytest.raises(InputError, match=r"run.yaml.*controller\[1\].*changed between"):
        read_recorded_frames(path)


def test_a_pi_campaign_is_at_zero_frames_by_its_record(tmp_path: Path) -> None:
    """``run`` moves a PI hexapod only with ``ZERO`` enabled (its driver refuses another
    system, a pivot off zero): its record says so, and calibrate takes the frames as
    known zero, not assumed."""
    session = measure(tmp_path, "pi", None, targets=TARGETS[:1])
    recorded = read_recorded_frames(session)
    assert recorded.values_mm_deg is not None and not recorded.values.any()
    assert "PI" in recorded.source and "ZERO=ZERO" in recorded.source
