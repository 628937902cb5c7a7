"""``hexatherm simulate``: a scenario file -> a session folder and its truth.

Glue between the scenario reader (:mod:`hexatherm.io.scenario`) and the twin
session writer (:mod:`hexatherm.workflows.simulate.twinsession`): the scenario's timing, heating,
noise and effects become a :class:`~hexatherm.workflows.simulate.twinsession.TwinSessionSpec`.

Choices the scenario does not spell out:

- The CMM probes ``points_per_ball`` points spread evenly over the upper cap of
  each ball, one after the other, ``seconds_per_point`` apart; each point gets
  normal noise of ``point_noise_um`` along the surface normal (with an ISO 10360
  MPE instead, sigma = MPE / 2: the MPE as roughly a 2-sigma bound).
- A centres file holds what the CMM reports: the sphere (free radius) fitted to
  each ball's noisy points, at the mean time of the points.
- The truth's effects are the hexapod file's thermal model followed by the
  scenario's hidden effects; the session's hexapod file is the scenario's, as
  is, so ``process`` knows only what the hexapod file says.
- The hexapod's repeatability is a normal error of each leg's length at each
  step (the same error in the reference thermal state: it is not thermal).
- ``truth/scenario.yaml`` is the scenario file as it was read; its ``readme``
  becomes the session's ``README.md``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexatherm.io.outputs import check_output_settled
from hexatherm.io.scenario import Scenario, plan_scenario, read_scenario
from hexatherm.workflows.simulate.twinsession import (
    SimulatedSession,
    TwinSessionSpec,
    simulate_session,
    write_files,
)


def scenario_spec(scenario: Scenario, seed: int | None = None) -> TwinSessionSpec:
    """The twin session of ``scenario`` (``seed`` overrides the scenario's)."""
    ppb = scenario.plan.points_per_ball
    return TwinSessionSpec(
        name=scenario.name,
        hexapod_text=scenario.hexapod_text,
        balls=scenario.balls,
        plan=scenario.plan,
        heating=scenario.heating,
        origin_on_cmm=scenario.origin_on_cmm,
        start=scenario.start,
        seconds_per_ball=ppb * scenario.seconds_per_point,
        seconds_per_move=scenario.seconds_per_move,
        sample_period_s=scenario.sample_period_s,
        thermocouple_noise_C=scenario.thermocouple_noise_C,
        seed=scenario.seed if seed is None else seed,
        extra={"truth/scenario.yaml": scenario.text},
        readme=scenario.readme,
        output=scenario.output,
        points_per_ball=ppb,
        cap_half_angle_deg=scenario.cap_half_angle_deg,
        point_noise_mm=scenario.point_noise_mm,
        effects=scenario.effects,
        repeatability_mm=scenario.repeatability_mm,
        fit_centres=True,
        true_parameters=scenario.true_parameters,
    )


def simulate(
    scenario: Scenario, seed: int | None = None, truth_files: bool = True
) -> SimulatedSession:
    """Simulate ``scenario``: the session's files and the truth, nothing written (without
    ``truth_files``, no ``truth/``: :func:`~.twinsession.simulate_session`)."""
    return simulate_session(scenario_spec(scenario, seed), truth_files)


def simulate_file(
    path: str | os.PathLike[str] | Scenario,
    out: str | os.PathLike[str],
    seed: int | None = None,
    overwrite: bool = False,
) -> tuple[Scenario, SimulatedSession, list[Path]]:
    """Read the scenario ``path`` (or take it), simulate it and write the session folder
    ``out``.

    Nothing is written when the scenario is invalid or the simulation fails;
    ``out`` is replaced only with ``overwrite``.
    """
    scenario = path if isinstance(path, Scenario) else read_scenario(path)
    simulated = simulate(scenario, seed)
    written = write_files(simulated.files, out, overwrite, scenario.input_files)
    return scenario, simulated, written


@dataclass(frozen=True)
class SimulateRequest:
    """What ``hexatherm simulate`` was asked: a scenario file, or a plan with its hexapod
    and balls files (measured as a typical session, :func:`~hexatherm.io.scenario.
    plan_scenario`), and the session folder to write."""

    out: Path
    scenario: Path | None = None
    plan: Path | None = None
    hexapod: Path | None = None
    balls: Path | None = None
    seed: int | None = None
    overwrite: bool = False


@dataclass(frozen=True)
class TargetError:
    """The true thermal error of a target's conventional pose (vs. R0's thermal state)."""

    label: str
    translation_um: float
    rotation_urad: float


@dataclass(frozen=True)
class SimulateOutcome:
    """What ``hexatherm simulate`` wrote, and the truth it prints."""

    scenario: Scenario
    n_steps: int
    n_targets: int
    duration_h: float
    targets: tuple[TargetError, ...]
    written: tuple[Path, ...]


def simulate_folder(request: SimulateRequest) -> SimulateOutcome:
    """Check the output folder, simulate the scenario (or the plan) and write the session
    folder ``request.out``; the outcome holds each target's true thermal error."""
    source: Path | Scenario
    if request.plan is None:
        assert request.scenario is not None
        inputs, source = [request.scenario], request.scenario
    else:
        assert request.hexapod is not None and request.balls is not None
        inputs = [request.plan, request.hexapod, request.balls]
        source = plan_scenario(
            request.plan, request.hexapod, request.balls, request.out.name, request.seed or 0
        )
    out = request.out
    check_output_settled(
        out, kind="folder", inputs=inputs, overwrite=request.overwrite, sessions=True
    )
    read, simulated, written = simulate_file(source, out, request.seed, request.overwrite)
    plan, truth = read.plan, simulated.truth
    targets = plan.target_indices
    error = truth.pose[targets] - truth.corrected_pose[targets]
    d_t = np.linalg.norm(error[:, :3], axis=1) * 1e3
    d_r = np.linalg.norm(error[:, 3:], axis=1) * np.pi / 180 * 1e6
    return SimulateOutcome(
        scenario=read,
        n_steps=len(plan.labels),
        n_targets=int(targets.size),
        duration_h=float(simulated.step_times_s[-1]) / 3600.0,
        targets=tuple(
            TargetError(plan.labels[step], float(d_t[i]), float(d_r[i]))
            for i, step in enumerate(targets)
        ),
        written=tuple(written),
    )
