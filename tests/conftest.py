"""Shared fixtures: a realistic hexapod, balls and plans built in code (independent of files)."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.thermal import LegThermalModel

REFERENCE_POSE = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]

#: the operating system's fsync, for the tests that want the disk flush itself
REAL_FSYNC = os.fsync


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C reaches the suite and the processes it starts, however it was launched.

    A job started in the background by a shell without job control inherits SIGINT
    ignored, and so would every ``hexatherm`` process the tests start (``serve-twin``,
    ``run``): the tests that stop them with SIGINT would then wait for their safety net.
    A Python handler is not inherited across exec (the child gets SIGINT's default, on
    which Python installs its own KeyboardInterrupt), an ignored signal is.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


#: the test files that take longest, longest first (a file runs whole on one worker:
#: ``--dist loadfile``, each file's set-ups made once). pytest-xdist hands the files out
#: in collection order (``--no-loadscope-reorder``); by default it orders them by their
#: number of tests, which sent a few long files of one or two tests last, one worker
#: idle while the other ran them. Ranked by their CPU seconds (the worker's and its
#: children's, whole suite with ``-n 2``, 28 Nov 2026, 87d6cfd at load 8-31): the 63
#: files of 4 s and more, 612 of the tests' 756 s (seven joined since f556510, among
#: them test_name_bytes, 10 s, which ran in the last third), then three lighter ones
#: listed before. A file missing from here, or out of order, only runs later.
LONGEST_FIRST = (
    "workflows/test_audit_report.py",
    "workflows/test_uncertainty_replicas.py",
    "workflows/test_run_faults.py",
    "io/test_dmis_stream.py",
    "io/test_time_bytes.py",
    "workflows/test_diagnosis.py",
    "workflows/test_calibration_claim.py",
    "workflows/test_audit_calibrate.py",
    "workflows/test_calibrate_controller_frames.py",
    "workflows/test_audit_uncertainty.py",
    "workflows/test_report_browser.py",
    "workflows/test_run_dialects.py",
    "io/test_speed_paths.py",
    "test_wheel.py",
    "workflows/test_run_temperatures.py",
    "io/test_name_bytes.py",
    "workflows/test_lazy_imports.py",
    "cli/test_calibrate_twin.py",
    "core/test_curvature.py",
    "workflows/test_acquire_resume.py",
    "workflows/test_report_17025.py",
    "workflows/test_audit_process.py",
    "cli/test_calibrate.py",
    "workflows/test_report_templates.py",
    "workflows/test_calibration_recommendation.py",
    "workflows/test_run_resume.py",
    "io/test_hostile_truncation.py",
    "workflows/test_run_logger_lines.py",
    "workflows/test_diagnosis_standin.py",
    "workflows/test_adequacy.py",
    "workflows/test_figure_ticks.py",
    "cli/test_report_results.py",
    "workflows/test_plausibility.py",
    "io/test_texttable.py",
    "io/test_yamlfile_speed.py",
    "workflows/test_uncertainty_smooth.py",
    "workflows/test_report_identity.py",
    "workflows/test_run_resume_orders.py",
    "cli/test_exit_codes.py",
    "workflows/test_smooth_shared.py",
    "workflows/test_run_lines.py",
    "test_layers.py",
    "cli/test_run_signals.py",
    "workflows/test_diagnosisreport.py",
    "workflows/test_repeats.py",
    "workflows/test_run_events.py",
    "cli/test_audit_round3.py",
    "workflows/test_report_verdict.py",
    "workflows/test_run_reconnect.py",
    "core/test_calibration_stats.py",
    "cli/test_diagnose.py",
    "cli/test_report.py",
    "cli/test_acquire.py",
    "cli/test_serve_twin.py",
    "cli/test_run_failed_balls.py",
    "workflows/test_repeats_heating.py",
    "core/test_fgm_assembly.py",
    "workflows/test_diagnosis_priors.py",
    "workflows/test_run_hostile.py",
    "workflows/test_report.py",
    "workflows/test_diagnosis_guard.py",
    "workflows/test_replay_calibration.py",
    "workflows/test_run.py",
    "cli/test_replay.py",
    "cli/test_calibrate_outputs.py",
    "io/test_csvfile.py",
)
TESTS = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The files of :data:`LONGEST_FIRST` first, in its order; the rest as collected."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}

    def place(item: pytest.Item) -> int:
        path = item.path
        if not path.is_relative_to(TESTS):
            return len(rank)
        return rank.get(path.relative_to(TESTS).as_posix(), len(rank))

    items.sort(key=place)  # stable: each file's tests keep their order


def _fsync_without_the_flush(fd: object) -> None:
    """``os.fsync`` in this test process: the descriptor is checked as fsync checks it (a
    closed or bad one raises OSError, EBADF), the flush to the platter is not made.

    What a flush adds shows only after a power loss, which no test makes; what the
    product flushes, and in which order, is asserted by spying on the calls
    (tests/io/test_output_safety.py::test_files_and_folders_are_fsynced_before_the_swap_and_the_parent_after,
    which calls :data:`REAL_FSYNC`), and the commands run as subprocesses flush for real.
    Flushing every simulated session the statistical tests write cost the suite about
    a third of its wall time on this machine's shared disk (0.1 s per session).
    """
    os.fstat(fd if isinstance(fd, int) else fd.fileno())  # type: ignore[attr-defined]


@pytest.fixture(scope="session", autouse=True)
def _no_disk_flush():
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(os, "fsync", _fsync_without_the_flush)
        yield


@pytest.fixture(autouse=True)
def _forget_pipython_callbacks():
    """pipython keeps every GCSCommands' connection callback in a list on its gateway
    class until that GCSCommands is closed; one left open by a test makes the next
    connection, in any later test, call it on its closed socket (OSError, EBADF). Each
    test starts with the list as pipython ships it: empty."""
    yield
    gateway = sys.modules.get("pipython.pidevice.interfaces.pigateway")
    if gateway is not None:
        gateway.PIGateway._connection_status_changed_callbacks.clear()


def make_hexapod(convention: str = "symetrie") -> Hexapod:
    legs = LegThermalModel.uniform(
        [("body", "aluminium", 23.1e-6, 148.0), ("screw", "steel", 11.5e-6, None)]
    )
    return Hexapod.symmetric(
        base_radius_mm=150.0,
        platform_radius_mm=100.0,
        base_half_angle_deg=10.0,
        platform_half_angle_deg=10.0,
        height_mm=220.0,
        rotation_deg=-120.0,
        legs=legs,
        convention=convention,  # type: ignore[arg-type]
    )


def make_plan(target_poses: np.ndarray, reference_every: str = "both") -> Plan:
    """O, R0, then targets each followed (and so preceded) by a reference."""
    steps = [("O", "origin", [0.0] * 6), ("R0", "reference", REFERENCE_POSE)]
    for i, pose in enumerate(target_poses, start=1):
        steps.append((f"S{i}", "target", list(pose)))
        if reference_every == "both" or i == len(target_poses):
            steps.append((f"R{i}", "reference", REFERENCE_POSE))
    return Plan.from_steps(steps)


BALLS = np.array([[80.0, 0.0, 20.0], [-40.0, 69.28, 20.0], [-40.0, -69.28, 25.0]])


def random_poses(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    """Poses within a realistic workspace: +-20 mm, +-20 mm, +-10 mm, +-5 deg, +-5 deg, +-10 deg."""
    bounds = np.array([20.0, 20.0, 10.0, 5.0, 5.0, 10.0]) * scale
    return rng.uniform(-bounds, bounds, size=(n, 6))


@pytest.fixture
def hexapod() -> Hexapod:
    return make_hexapod()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261121)
