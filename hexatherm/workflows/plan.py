"""``hexatherm plan``: a measuring plan in the paper's order, its DMIS program and checklist.

The workflow takes the parsed options (:class:`PlanRequest`), reads the hexapod and balls
files and the targets, builds the plan (O, R0, then every S_i with a reference around it),
checks every commanded pose against the legs' stroke and for a near-singular Jacobian
(nothing is returned when one fails), estimates the timing and returns the texts to write
(:class:`PlanTexts`). No click and no printing: the command line writes and tells.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from hexatherm.core.calibration import PoseSelection, select_poses
from hexatherm.core.plan import Plan, find_repeats
from hexatherm.core.planning import (
    DEFAULT_CAP_ANGLE_DEG,
    DEFAULT_MIN_RCOND,
    DEFAULT_SECONDS_PER_MOVE,
    DEFAULT_SECONDS_PER_POINT,
    MAX_TOUCH_POINTS,
    ReferenceGap,
    StepTiming,
    build_plan,
    check_plan_poses,
    estimate_timing,
    grid_targets,
    parse_targets,
    pose_problems,
    random_targets,
    reference_gaps,
)
from hexatherm.core.touch import nominal_centres, touch_points
from hexatherm.errors import PlanError
from hexatherm.io.checklist import checklist_markdown
from hexatherm.io.config import plan_to_yaml, read_balls, read_hexapod
from hexatherm.io.csvtext import read_text
from hexatherm.io.dmisprog import dmis_program
from hexatherm.io.measurements import COORDINATE_MAX_MM as COORDINATE_MAX_MM
from hexatherm.io.outputs import check_output_settled, write_output_file
from hexatherm.io.qifout import NominalSphere, qif_plan

#: random choices of as many candidates that ``plan --calibration`` compares its design with
RANDOM_DESIGN_DRAWS = 20


@dataclass(frozen=True)
class PlanRequest:
    """What ``hexatherm plan`` was asked for (the command line's options, parsed).

    Exactly one target source: ``targets_path`` (a CSV file), ``grid_levels`` or
    ``n_random`` (both over the box ``box_lower``..``box_upper``, mm and deg).
    ``origin_on_cmm`` (where frame O nominally is on the CMM) is needed for a DMIS program
    and for a QIF plan (``qif``).
    """

    hexapod_path: Path
    balls_path: Path
    reference_pose: Sequence[float]
    targets_path: Path | None = None
    grid_levels: Sequence[int] | None = None
    n_random: int | None = None
    seed: int | None = None
    box_lower: Sequence[float] | None = None
    box_upper: Sequence[float] | None = None
    cycles: int = 1
    reference_every: str = "both"
    origin_repeats: int = 1
    reference0_repeats: int = 1
    points_per_ball: int = 25
    seconds_per_point: float = DEFAULT_SECONDS_PER_POINT
    seconds_per_move: float = DEFAULT_SECONDS_PER_MOVE
    max_gap_s: float = 600.0
    min_rcond: float | None = None
    origin_on_cmm: Sequence[float] | None = None
    cap_angle_deg: float = DEFAULT_CAP_ANGLE_DEG
    clearance_mm: float = 10.0
    dmis_name: str | None = None
    qif: bool = False
    checklist: bool = False
    calibration_poses: int | None = None
    calibration_level: str = "joints"
    calibration_criterion: str = "d-optimal"


@dataclass(frozen=True)
class PlanTexts:
    """The plan and what goes with it.

    Attributes
    ----------
    plan : Plan
    ball_names : tuple of str
    timing : StepTiming
        The estimated time of every step.
    gaps : list of ReferenceGap
        The target-reference gaps expected above ``max_gap_s``.
    redrawn : int
        Random poses drawn again (out of the stroke or near-singular).
    plan_yaml : str
    dmis : str or None
    checklist : str or None
    qif : bytes or None
        The QIF 3 plan document (``plan --qif``): every ball of every step as a sphere
        feature named ``<step>_<ball>`` at its nominal centre in CMM coordinates.
    selection : PoseSelection or None
        With ``calibration_poses``: the targets chosen from the candidates (the
        targets, grid or random poses asked for) for a calibration.
    """

    plan: Plan
    ball_names: tuple[str, ...]
    timing: StepTiming
    gaps: list[ReferenceGap]
    redrawn: int
    plan_yaml: str
    dmis: str | None
    checklist: str | None
    selection: PoseSelection | None = None
    qif: bytes | None = None


def make_plan(request: PlanRequest) -> PlanTexts:
    """Build, check and write out (as texts) the plan of ``request``."""
    sources = [request.targets_path, request.grid_levels, request.n_random]
    if sum(s is not None for s in sources) != 1:
        raise ValueError("give exactly one of targets_path, grid_levels and n_random")
    if (request.dmis_name is not None or request.qif) and request.origin_on_cmm is None:
        raise ValueError("a DMIS program or a QIF plan needs origin_on_cmm")
    rcond = DEFAULT_MIN_RCOND if request.min_rcond is None else request.min_rcond
    hexapod = read_hexapod(request.hexapod_path)
    balls = read_balls(request.balls_path)
    redrawn = 0
    if request.targets_path is not None:
        path = request.targets_path
        targets, lines = parse_targets(read_text(path), os.fspath(path))
        target_sources = [f"{path}:{line}" for line in lines]
    else:
        if request.box_lower is None or request.box_upper is None:
            raise ValueError("a grid or random targets need the box")
        lower, upper = list(request.box_lower), list(request.box_upper)
        if request.grid_levels is not None:
            targets = grid_targets(lower, upper, list(request.grid_levels))
            n = len(targets)
            target_sources = [f"grid point {k + 1} of {n}" for k in range(n)]
        else:
            assert request.n_random is not None

            def feasible(poses: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
                return np.array([p is None for p in pose_problems(hexapod, poses, rcond)])

            targets, redrawn = random_targets(
                lower, upper, request.n_random, request.seed, feasible
            )
            target_sources = [f"random pose {k + 1}" for k in range(len(targets))]

    selection = None
    if request.calibration_poses is not None:
        # the targets are candidates: keep the n that best identify the geometry
        selection = select_poses(
            hexapod,
            targets,
            request.calibration_poses,
            level=request.calibration_level,
            criterion=request.calibration_criterion,
            box_lower=request.box_lower,
            box_upper=request.box_upper,
            min_rcond=rcond,
            random_draws=RANDOM_DESIGN_DRAWS,
        )
        targets = selection.poses
        target_sources = [target_sources[int(k)] for k in selection.indices]
    plan = build_plan(
        targets,
        request.reference_pose,
        cycles=request.cycles,
        reference_every=request.reference_every,  # type: ignore[arg-type]
        points_per_ball=request.points_per_ball,
        origin_repeats=request.origin_repeats,
        reference0_repeats=request.reference0_repeats,
    )
    step_sources: list[str | None] = []
    n_targets = 0
    origin_again = set(find_repeats(plan).origin[1:])
    for i, kind in enumerate(plan.kinds):
        if i in origin_again:
            step_sources.append("origin (repeat)")
        elif kind == "target":
            step_sources.append(target_sources[n_targets % len(target_sources)])
            n_targets += 1
        else:
            step_sources.append("origin" if kind == "origin" else "--reference")
    check_plan_poses(hexapod, plan, rcond, step_sources)

    timing = estimate_timing(
        plan, len(balls.names), request.seconds_per_point, request.seconds_per_move
    )
    gaps = [g for g in reference_gaps(plan, timing.time_s) if g.gap_s > request.max_gap_s]
    dmis = None
    if request.dmis_name is not None:
        assert request.origin_on_cmm is not None
        n_points = len(plan.labels) * len(balls.names) * request.points_per_ball
        if n_points > MAX_TOUCH_POINTS:
            raise PlanError(
                f"the DMIS program would hold {len(plan.labels):,} steps x "
                f"{len(balls.names)} balls x {request.points_per_ball:,} points = "
                f"{n_points:,} touch points, {timing.total_s / 86400:.0f} days of probing: "
                f"at most {MAX_TOUCH_POINTS:,}; fewer points per ball, targets or cycles"
            )
        touch = touch_points(
            plan,
            balls.centres_mm,
            balls.diameters_mm,
            request.origin_on_cmm,
            hexapod.convention,
            cap_half_angle_deg=request.cap_angle_deg,
        )
        dmis = dmis_program(
            plan,
            balls,
            touch,
            origin_on_cmm=request.origin_on_cmm,
            name=request.dmis_name,
            clearance_mm=request.clearance_mm,
            timing=timing,
        )
    qif = None
    if request.qif:
        assert request.origin_on_cmm is not None
        centres = nominal_centres(plan, balls.centres_mm, request.origin_on_cmm, hexapod.convention)
        spheres = [
            NominalSphere(f"{label}_{ball}", tuple(centres[i, j]), float(balls.diameters_mm[j]))
            for i, label in enumerate(plan.labels)
            for j, ball in enumerate(balls.names)
        ]
        qif = qif_plan(spheres, application=f"hexatherm plan ({len(plan.labels)} steps)")
    checklist = None
    if request.checklist:
        checklist = checklist_markdown(
            plan,
            balls.names,
            timing,
            gaps=gaps,
            max_gap_s=request.max_gap_s,
            hexapod_name=hexapod.name,
        )
    return PlanTexts(
        plan,
        balls.names,
        timing,
        gaps,
        redrawn,
        plan_to_yaml(plan),
        dmis,
        checklist,
        selection,
        qif,
    )


# ------------------------------------------------------------------- the command
@dataclass(frozen=True)
class PlanFiles:
    """Where ``hexatherm plan`` writes: the plan (``out``; None: standard output), the
    DMIS program, the checklist and the QIF plan (None: not asked for)."""

    out: Path | None = None
    dmis: Path | None = None
    checklist: Path | None = None
    qif: Path | None = None
    overwrite: bool = False


@dataclass(frozen=True)
class PlanOutcome:
    """What ``hexatherm plan`` made and wrote.

    Attributes
    ----------
    made : PlanTexts
    stdout : str or None
        The plan's text for standard output (no ``out`` given).
    written : tuple of Path
        The files written, in the order -o, --dmis, --checklist, --qif.
    n_targets : int
        Targets of the plan (a repeat of O is not one).
    n_origin, n_reference0 : int
        How often O and R0 are measured.
    repeat_labels : tuple of str
        The labels of O, R0 and their repeats, in plan order, when there are repeats.
    """

    made: PlanTexts
    stdout: str | None
    written: tuple[Path, ...]
    n_targets: int
    n_origin: int
    n_reference0: int
    repeat_labels: tuple[str, ...]


def write_plan(request: PlanRequest, files: PlanFiles) -> PlanOutcome:
    """``hexatherm plan`` from its request to its outcome: check the outputs (never an
    input, never a foreign file), make the plan (:func:`make_plan`) and write its texts."""
    named = [
        (files.out, "-o"),
        (files.dmis, "--dmis"),
        (files.checklist, "--checklist"),
        (files.qif, "--qif"),
    ]
    inputs = [
        p for p in (request.hexapod_path, request.balls_path, request.targets_path) if p is not None
    ]
    for path, option in named:
        if path is not None:
            check_output_settled(
                path, kind="file", inputs=inputs, overwrite=files.overwrite, option=option
            )
    made = make_plan(request)
    texts = [made.plan_yaml, made.dmis, made.checklist, made.qif]
    stdout, written = None, []
    for (target, option), text in zip(named, texts, strict=True):
        if text is None:
            continue
        if target is None:
            assert isinstance(text, str)
            stdout = text
        else:
            write_output_file(target, text, inputs=inputs, overwrite=files.overwrite, option=option)
            written.append(target)
    plan = made.plan
    repeats = find_repeats(plan)
    return PlanOutcome(
        made,
        stdout,
        tuple(written),
        n_targets=len(plan.target_indices) - (len(repeats.origin) - 1),
        n_origin=len(repeats.origin),
        n_reference0=len(repeats.reference0),
        repeat_labels=tuple(plan.labels[i] for i in sorted(repeats.origin + repeats.reference0))
        if repeats.any
        else (),
    )
