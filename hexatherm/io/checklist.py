"""The operator's checklist of a plan, in Markdown (``hexatherm plan --checklist``).

One row per step: the step, its kind, the pose to command, the balls to probe
and how many points, the estimated start and duration, and a box to tick. Above
the table the rules of the method: measure in this order and never let time pass
between a target S_i and its reference R.

>>> import numpy as np
>>> from hexatherm.core.planning import build_plan, estimate_timing
>>> plan = build_plan([[1, 0, 0, 0, 0, 0.5]], points_per_ball=5)
>>> text = checklist_markdown(plan, ("B1", "B2", "B3"), estimate_timing(plan, 3, 2.0, 30.0))
>>> print(text.splitlines()[-2])
| 3 | S1 | target | 1, 0, 0, 0, 0, 0.5 | B1, B2, B3 | 15 | 0:02:00 | 1 min | [ ] |
"""

from __future__ import annotations

from collections.abc import Sequence

from hexatherm.core.plan import Plan
from hexatherm.core.planning import ReferenceGap, StepTiming
from hexatherm.text import format_number


def _clock(seconds: float) -> str:
    """``H:MM:SS`` of a number of seconds.

    >>> _clock(3725.4)
    '1:02:05'
    """
    total = int(round(seconds))
    return f"{total // 3600}:{total % 3600 // 60:02d}:{total % 60:02d}"


def _minutes(seconds: float) -> str:
    return f"{max(seconds / 60.0, 0.0):.0f} min" if seconds >= 60 else f"{seconds:.0f} s"


def checklist_markdown(
    plan: Plan,
    ball_names: Sequence[str],
    timing: StepTiming,
    *,
    title: str = "hexatherm measuring checklist",
    gaps: Sequence[ReferenceGap] = (),
    max_gap_s: float | None = None,
    hexapod_name: str | None = None,
) -> str:
    """The checklist text.

    Parameters
    ----------
    plan : Plan
    ball_names : sequence of str
        The balls, in the order they are probed.
    timing : StepTiming
        Estimated times of the steps.
    title : str
    gaps : sequence of ReferenceGap
        Target/reference pairs further apart than allowed, listed as warnings.
    max_gap_s : float, optional
        The allowed time between a target and its reference, stated in the rules.
    hexapod_name : str, optional

    Returns
    -------
    str
    """
    balls = ", ".join(ball_names)
    n_points = len(ball_names) * plan.points_per_ball
    lines = [f"# {title}", ""]
    if hexapod_name:
        lines.append(f"- Hexapod: {hexapod_name}")
    lines += [
        f"- Steps: {len(plan.labels)} ({len(plan.target_indices)} targets, "
        f"{len(plan.reference_indices)} references), balls {balls}, "
        f"{plan.points_per_ball} points per ball",
        f"- Estimated duration: {_clock(timing.total_s)}",
        f"- Reference pose R: {', '.join(format_number(v) for v in plan.reference_pose)}",
        "",
        "## Rules",
        "",
        "1. Measure the steps in this order, every ball of a step in the order given.",
        "2. Measure each reference R right before and/or right after its target S "
        "(as listed): no pause, no other work in between.",
        "3. O is the zero pose of the hexapod; the first reference R0 fixes the thermal "
        "state the corrected poses refer to.",
        "4. Command the pose, wait for the hexapod to settle, then probe the balls.",
    ]
    if max_gap_s is not None:
        lines.append(f"5. A target and its reference must be at most {_minutes(max_gap_s)} apart.")
    if gaps:
        lines += ["", "## Warnings", ""]
        for gap in gaps:
            lines.append(
                f"- {gap.target} and {gap.reference} are expected "
                f"{_minutes(gap.gap_s)} apart (allowed: "
                f"{_minutes(max_gap_s or 0.0)})"
            )
    lines += [
        "",
        "## Steps",
        "",
        "| # | step | kind | pose to command (Tx, Ty, Tz mm; Rx, Ry, Rz deg) | balls | "
        "points | start | duration | done |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for i, (label, kind, pose) in enumerate(zip(plan.labels, plan.kinds, plan.poses, strict=True)):
        command = ", ".join(format_number(v) for v in pose)
        lines.append(
            f"| {i + 1} | {label} | {kind} | {command} | "
            f"{balls} | {n_points} | {_clock(timing.start_s[i])} | "
            f"{_minutes(timing.duration_s[i])} | [ ] |"
        )
    lines.append("")
    return "\n".join(lines)
