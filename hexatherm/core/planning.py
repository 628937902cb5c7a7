"""Measuring plans generated from target poses: order, checks, timing, touch points.

A plan follows the paper's order: the origin O (zero pose) first, then the first
reference R0, then the targets S_i, each with a reference step R right before
and/or right after it. This module builds such a plan from a list of target
poses (read from a file, on a grid or drawn at random in a workspace box),
checks every commanded pose against the legs' stroke and for near-singular
Jacobians, estimates when each step is measured, and computes where a CMM
should touch every ball at every step. No I/O: numbers in, typed results out.

>>> import numpy as np
>>> steps = sequence_steps(np.array([[1.0, 0, 0, 0, 0, 0], [2.0, 0, 0, 0, 0, 0]]),
...                        [0, 0, -40, 0, 0, 0])
>>> [label for label, _, _ in steps]
['O', 'R0', 'S1', 'R1', 'S2', 'R2']
>>> [label for label, _, _ in sequence_steps(np.zeros((2, 6)), [0, 0, -40, 0, 0, 0],
...                                          reference_every="before")]
['O', 'R0', 'S1', 'R1', 'S2']
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan, repeat_label
from hexatherm.errors import InputError, PlanError, PoseError

#: reciprocal condition number of the Jacobian dq/dX (mm per mm, mm per degree) below
#: which a commanded pose is called near-singular: the table of limits'
from hexatherm.limits import DEFAULT_MIN_RCOND
from hexatherm.text import format_number
from hexatherm.typing import FloatArray

ReferenceEvery = Literal["both", "before", "after", "alternate"]
REFERENCE_EVERY: tuple[ReferenceEvery, ...] = ("both", "before", "after", "alternate")

#: names of the six pose components, in pose-vector order
AXES: tuple[str, ...] = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
#: the paper's reference pose (mm, deg)
DEFAULT_REFERENCE = (0.0, 0.0, -40.0, 0.0, 0.0, 0.0)
#: one set of defaults for every command that plans or simulates a campaign (issue 25):
#: probing time per point and time to command a pose and settle (s), as ``simulate``'s
#: scenario has them, and the half-angle of the probed cap (deg), as the session's ``cmm:``
DEFAULT_SECONDS_PER_POINT = 2.4
DEFAULT_SECONDS_PER_MOVE = 20.0
DEFAULT_CAP_ANGLE_DEG = 70.0


# ----------------------------------------------------------------------- targets
_COMMENT = re.compile(r"^\s*#")


def parse_targets(text: str, path: str) -> tuple[FloatArray, list[int]]:
    """Target poses from the text of a targets CSV file.

    The file has one pose per line, ``Tx,Ty,Tz,Rx,Ry,Rz`` (mm, deg), after an
    optional header line naming exactly these six columns. Blank lines and lines
    starting with ``#`` are skipped.

    Parameters
    ----------
    text : str
        The file's content.
    path : str
        The file's name, for messages.

    Returns
    -------
    poses : ndarray, shape (n, 6)
    lines : list of int
        1-based line of each pose.

    Raises
    ------
    InputError
        Naming the file, the line and the field of the first bad value.

    Examples
    --------
    >>> text = "Tx,Ty,Tz,Rx,Ry,Rz\\n1,2,3,0,0,0.5\\n\\n-1,0,0,0,0,0\\n"
    >>> poses, lines = parse_targets(text, "t.csv")
    >>> poses.tolist(), lines
    ([[1.0, 2.0, 3.0, 0.0, 0.0, 0.5], [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0]], [2, 4])
    >>> parse_targets("1,2,3,0,0\\n", "t.csv")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hexatherm.errors.InputError: t.csv:1: expected 6 comma-separated values ..., found 5
    """
    poses: list[list[float]] = []
    lines: list[int] = []
    header_seen = False
    for number, raw in enumerate(text.lstrip("\ufeff").splitlines(), start=1):
        if not raw.strip() or _COMMENT.match(raw):
            continue
        cells = [c.strip() for c in raw.split(",")]
        if not header_seen and not poses and not _is_number(cells[0]):
            names = [c.strip("\"'") for c in cells]
            if [n.lower() for n in names] != [a.lower() for a in AXES]:
                raise InputError(
                    f"header must be {','.join(AXES)}, got {raw.strip()!r}", path=path, line=number
                )
            header_seen = True
            continue
        if len(cells) != 6:
            raise InputError(
                f"expected 6 comma-separated values {','.join(AXES)}, found {len(cells)}",
                path=path,
                line=number,
            )
        row = []
        for axis, cell in zip(AXES, cells, strict=True):
            if not _is_number(cell) or not math.isfinite(float(cell)):
                raise InputError(
                    f"not a finite number: {cell!r}", path=path, line=number, field=axis
                )
            row.append(float(cell))
        poses.append(row)
        lines.append(number)
    if not poses:
        raise InputError("no target poses in the file", path=path)
    return np.array(poses, dtype=float), lines


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return text.strip().lower() not in ("nan", "inf", "-inf", "+inf", "infinity")


def grid_targets(
    lower: Sequence[float], upper: Sequence[float], levels: int | Sequence[int]
) -> FloatArray:
    """Poses on a regular grid over the box ``lower <= pose <= upper``.

    Parameters
    ----------
    lower, upper : sequence of 6 floats
        The workspace box (mm, deg). Axes with ``lower == upper`` are fixed.
    levels : int or sequence of 6 ints
        Number of grid values along each axis (ignored for fixed axes; 1 means
        the box's middle).

    Returns
    -------
    ndarray, shape (n, 6)
        The grid, the last axis (Rz) varying fastest.

    Examples
    --------
    >>> grid_targets([-1, 0, 0, 0, 0, -2], [1, 0, 0, 0, 0, 2], 3)[:, [0, 5]].tolist()
    [[-1.0, -2.0], [-1.0, 0.0], [-1.0, 2.0], [0.0, -2.0], [0.0, 0.0], [0.0, 2.0], [1.0, -2.0], [1.0, 0.0], [1.0, 2.0]]
    """  # noqa: E501
    lo, hi = _box(lower, upper)
    counts = np.broadcast_to(np.asarray(levels, dtype=int), (6,))
    if np.any(counts < 1):
        raise PlanError(f"grid levels must be at least 1, got {counts.tolist()}")
    axes = []
    for a in range(6):
        if lo[a] == hi[a]:
            axes.append(np.array([lo[a]]))
        elif counts[a] == 1:
            axes.append(np.array([(lo[a] + hi[a]) / 2.0]))
        else:
            axes.append(np.linspace(lo[a], hi[a], int(counts[a])))
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.column_stack([m.ravel() for m in mesh])


def random_targets(
    lower: Sequence[float],
    upper: Sequence[float],
    n: int,
    seed: int | None,
    feasible: Callable[[FloatArray], npt.NDArray[np.bool_]] | None = None,
    max_draws: int = 1000,
    decimals: int | None = 3,
) -> tuple[FloatArray, int]:
    """``n`` poses drawn uniformly in a box, keeping only feasible ones.

    Parameters
    ----------
    lower, upper : sequence of 6 floats
        The workspace box (mm, deg).
    n : int
        Number of poses.
    seed : int or None
        Seed of the random generator (None: a fresh one).
    feasible : callable, optional
        ``feasible(poses (m, 6)) -> mask (m,)``; poses it rejects are drawn again.
    max_draws : int
        Give up after ``max_draws * n`` draws.
    decimals : int or None
        Round the poses to this many decimals (um and mdeg by default: poses an
        operator types into the hexapod's controller); None keeps every digit.

    Returns
    -------
    poses : ndarray, shape (n, 6)
    rejected : int
        How many draws were rejected.

    Raises
    ------
    PlanError
        When too few feasible poses are found (the box is mostly out of reach).

    Examples
    --------
    >>> poses, rejected = random_targets([-1] * 6, [1] * 6, 4, seed=3)
    >>> poses.shape, rejected, bool(np.all(np.abs(poses) <= 1))
    ((4, 6), 0, True)
    """
    lo, hi = _box(lower, upper)
    if n < 1:
        raise PlanError(f"the number of random poses must be at least 1, got {n}")
    rng = np.random.default_rng(seed)
    kept: list[FloatArray] = []
    have, drawn, rejected = 0, 0, 0
    while have < n:
        if drawn >= max_draws * n:
            raise PlanError(
                f"only {have} of {n} random poses drawn in the box are reachable "
                f"({drawn} draws): shrink the box"
            )
        batch = rng.uniform(lo, hi, size=(max(n - have, 16), 6))
        if decimals is not None:
            batch = np.clip(np.round(batch, decimals), lo, hi)
        drawn += len(batch)
        ok = np.ones(len(batch), dtype=bool) if feasible is None else np.asarray(feasible(batch))
        rejected += int((~ok).sum())
        kept.append(batch[ok])
        have += int(ok.sum())
    poses = np.concatenate(kept)[:n]
    return poses, rejected


def _box(lower: Sequence[float], upper: Sequence[float]) -> tuple[FloatArray, FloatArray]:
    lo = np.asarray(lower, dtype=float).reshape(-1)
    hi = np.asarray(upper, dtype=float).reshape(-1)
    if lo.shape != (6,) or hi.shape != (6,):
        raise PlanError("a workspace box needs six lower and six upper bounds")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise PlanError("the workspace box has a non-finite bound")
    bad = lo > hi
    if np.any(bad):
        a = int(np.argmax(bad))
        raise PlanError(
            f"workspace box: {AXES[a]} lower bound {lo[a]} is above the upper bound {hi[a]}"
        )
    return lo, hi


# ---------------------------------------------------------------------- sequence
#: the most target steps (targets x cycles) of a plan: a campaign of a thousand targets is
#: a week of measuring; beyond this the plan only fills the memory
MAX_TARGET_STEPS = 100_000

#: the most touch points of a plan's DMIS program (``plan --dmis``) or a simulated
#: session: a scanning probe's campaign of 2000 targets at 400 points a ball (issue 37);
#: the twin needs about 1.3 kB a point (3.2 GB for 2.4 million), so beyond it they only
#: fill the memory
MAX_TOUCH_POINTS = 5_000_000


def sequence_steps(
    targets: npt.ArrayLike,
    reference_pose: Sequence[float],
    *,
    cycles: int = 1,
    reference_every: ReferenceEvery = "both",
    origin_repeats: int = 1,
    reference0_repeats: int = 1,
) -> list[tuple[str, str, list[float]]]:
    """The steps ``(label, kind, pose)`` of a plan in measuring order.

    The origin ``O`` (zero pose) comes first, then the first reference ``R0``,
    then the targets ``S1 .. Sn`` (the given targets repeated ``cycles`` times)
    with one reference between consecutive targets. ``reference_every`` decides
    the end: ``both`` and ``after`` end with a reference after the last target,
    so every target has a reference right before and right after it; ``before``
    ends with the last target (every target has one right before it). Because
    the first reference must precede every target (it fixes the thermal state
    the corrected poses refer to), ``after`` gives the same order as ``both``.
    ``alternate`` puts a reference after every second target (and after the last
    one): every target has one reference right next to it, on one side only (the
    scenarios' ``references: one-side``). References are numbered in the order they
    are measured; with ``both``, ``before`` and ``after``, ``R_i`` follows ``S_i``.

    With ``origin_repeats`` or ``reference0_repeats`` above 1, O and R0 are measured
    again right after R0, alternately: ``O, R0, O-2, R0-2, O-3, R0-3, S1 ...``
    (:class:`~hexatherm.core.plan.Repeats`: a repeat of O is a target at the zero pose,
    which needs a reference beside it, so R0 is measured at least as often as O).
    ``process`` averages them.

    Parameters
    ----------
    targets : array_like, shape (n, 6)
    reference_pose : sequence of 6 floats
    cycles : int
        How many times the targets are measured.
    reference_every : {"both", "before", "after", "alternate"}
    origin_repeats, reference0_repeats : int
        How many times O and R0 are measured (1: once).

    Returns
    -------
    list of (str, str, list of float)

    >>> [s[0] for s in sequence_steps(np.zeros((3, 6)), [0, 0, -40, 0, 0, 0],
    ...                               reference_every="alternate")]
    ['O', 'R0', 'S1', 'S2', 'R1', 'S3', 'R2']
    """
    poses = np.asarray(targets, dtype=float).reshape(-1, 6)
    if cycles < 1:
        raise PlanError(f"cycles must be at least 1, got {cycles}")
    if reference_every not in REFERENCE_EVERY:
        raise PlanError(
            f"reference_every must be one of {', '.join(REFERENCE_EVERY)}, got {reference_every!r}"
        )
    if not len(poses):
        raise PlanError("no target poses")
    if len(poses) * cycles > MAX_TARGET_STEPS:
        raise PlanError(
            f"{len(poses):,} targets x {cycles:,} cycles: {len(poses) * cycles:,} target steps, "
            f"at most {MAX_TARGET_STEPS:,} (a thousand are a week of measuring)"
        )
    if origin_repeats < 1 or reference0_repeats < 1:
        raise PlanError(
            f"O and R0 are measured at least once, got {origin_repeats} and {reference0_repeats}"
        )
    reference = [float(v) for v in reference_pose]
    steps: list[tuple[str, str, list[float]]] = [
        ("O", "origin", [0.0] * 6),
        ("R0", "reference", reference),
    ]
    for n in range(2, max(origin_repeats, reference0_repeats) + 1):
        if n <= origin_repeats:
            steps.append((repeat_label("O", n), "target", [0.0] * 6))
        steps.append((repeat_label("R0", n), "reference", list(reference)))
    all_targets = np.tile(poses, (cycles, 1))
    n = len(all_targets)
    n_refs = 0
    for i, pose in enumerate(all_targets, start=1):
        steps.append((f"S{i}", "target", pose.tolist()))
        if reference_every == "alternate":
            follows = i % 2 == 0 or i == n
        else:
            follows = reference_every != "before" or i < n
        if follows:
            n_refs += 1
            steps.append((f"R{n_refs}", "reference", list(reference)))
    return steps


def build_plan(
    targets: npt.ArrayLike,
    reference_pose: Sequence[float] = DEFAULT_REFERENCE,
    *,
    cycles: int = 1,
    reference_every: ReferenceEvery = "both",
    points_per_ball: int = 25,
    origin_repeats: int = 1,
    reference0_repeats: int = 1,
) -> Plan:
    """A validated :class:`~hexatherm.core.plan.Plan` from target poses.

    See :func:`sequence_steps` for the order of the steps.

    Examples
    --------
    >>> plan = build_plan([[1, 0, 0, 0, 0, 0]], cycles=2, points_per_ball=9)
    >>> plan.labels, plan.points_per_ball
    (('O', 'R0', 'S1', 'R1', 'S2', 'R2'), 9)
    """
    if points_per_ball < 1:
        raise PlanError(f"points per ball must be at least 1, got {points_per_ball}")
    steps = sequence_steps(
        targets,
        reference_pose,
        cycles=cycles,
        reference_every=reference_every,
        origin_repeats=origin_repeats,
        reference0_repeats=reference0_repeats,
    )
    return Plan.from_steps(steps, reference_pose=reference_pose, points_per_ball=points_per_ball)


# ------------------------------------------------------------------------ checks
def pose_problems(
    hexapod: Hexapod, poses: npt.ArrayLike, min_rcond: float = DEFAULT_MIN_RCOND
) -> list[str | None]:
    """What is wrong with each commanded pose (None where nothing is).

    A pose is refused when a leg length ``IGM(pose)`` is outside the hexapod's
    stroke (when the hexapod file gives one), or when the reciprocal condition
    number of the Jacobian ``dq/dX`` (mm per mm, mm per degree) is below
    ``min_rcond``: near a singularity small leg errors make large pose errors.

    Parameters
    ----------
    hexapod : Hexapod
    poses : array_like, shape (n, 6)
    min_rcond : float

    Returns
    -------
    list of (str or None), length n
    """
    x = np.atleast_2d(np.asarray(poses, dtype=float))
    q = hexapod.igm(x)
    outside = hexapod.check_stroke(q)
    sv = np.linalg.svd(hexapod.jacobian(x), compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        rcond = sv[:, -1] / sv[:, 0]
    out: list[str | None] = []
    for n in range(len(x)):
        if np.any(outside[n]):
            assert hexapod.stroke_mm is not None
            legs = np.flatnonzero(outside[n])
            lo, hi = hexapod.stroke_mm
            what = ", ".join(f"leg {leg + 1} at {q[n, leg]:.3f} mm" for leg in legs)
            stroke = f"[{format_number(lo, 3)}, {format_number(hi, 3)}]"
            out.append(f"outside the stroke {stroke} mm: {what}")
        elif not rcond[n] >= min_rcond:
            out.append(
                f"near-singular Jacobian (reciprocal condition number {rcond[n]:.2e} "
                f"< {min_rcond:.2e}): the legs do not hold the platform well there"
            )
        else:
            out.append(None)
    return out


def check_plan_poses(
    hexapod: Hexapod,
    plan: Plan,
    min_rcond: float = DEFAULT_MIN_RCOND,
    sources: Sequence[str | None] | None = None,
) -> None:
    """Raise :class:`PoseError` for the first step whose pose is not reachable.

    Parameters
    ----------
    hexapod : Hexapod
    plan : Plan
    min_rcond : float
        See :func:`pose_problems`.
    sources : sequence of (str or None), optional
        Where each step's pose came from, for the message (one per step).
    """
    problems = pose_problems(hexapod, plan.poses, min_rcond)
    for i, problem in enumerate(problems):
        if problem is not None:
            raise PoseError(
                problem,
                step=plan.labels[i],
                pose=plan.poses[i],
                source=None if sources is None else sources[i],
            )


# ------------------------------------------------------------------------ timing
@dataclass(frozen=True)
class StepTiming:
    """Estimated times of the steps of a plan, seconds from the start of the session.

    Attributes
    ----------
    start_s : ndarray, shape (N,)
        When the hexapod is commanded to the step's pose.
    duration_s : ndarray, shape (N,)
        Move plus probing time of the step.
    time_s : ndarray, shape (N,)
        The step's time as the method sees it: the mean time of its points.
    """

    start_s: FloatArray
    duration_s: FloatArray
    time_s: FloatArray

    @property
    def total_s(self) -> float:
        """Duration of the whole session."""
        return float(self.start_s[-1] + self.duration_s[-1]) if len(self.start_s) else 0.0


def estimate_timing(
    plan: Plan,
    n_balls: int,
    seconds_per_point: float,
    seconds_per_move: float = DEFAULT_SECONDS_PER_MOVE,
) -> StepTiming:
    """Estimate when each step is measured.

    Each step takes ``seconds_per_move`` (commanding the pose and letting the
    hexapod settle), then ``n_balls * points_per_ball`` points at
    ``seconds_per_point`` each.

    Examples
    --------
    >>> plan = build_plan([[1, 0, 0, 0, 0, 0]], points_per_ball=10)
    >>> t = estimate_timing(plan, 3, 2.0, 30.0)
    >>> t.duration_s.tolist(), t.time_s.tolist()[:2], t.total_s
    ([90.0, 90.0, 90.0, 90.0], [60.0, 150.0], 360.0)
    """
    if not (seconds_per_point >= 0 and seconds_per_move >= 0):
        raise PlanError("durations must not be negative")
    n = len(plan.labels)
    probing = n_balls * plan.points_per_ball * float(seconds_per_point)
    duration = np.full(n, probing + float(seconds_per_move))
    start = np.concatenate([[0.0], np.cumsum(duration)[:-1]])
    return StepTiming(start, duration, start + seconds_per_move + probing / 2.0)


@dataclass(frozen=True)
class ReferenceGap:
    """Time between a target and an adjacent reference step.

    Attributes
    ----------
    target : str
    reference : str
    gap_s : float
        Absolute time between the two steps.
    """

    target: str
    reference: str
    gap_s: float


def reference_gaps(plan: Plan, times_s: npt.ArrayLike) -> list[ReferenceGap]:
    """Time between every target and each reference right before or after it.

    Steps whose time is NaN (not measured yet) are left out.

    Examples
    --------
    >>> plan = build_plan([[1, 0, 0, 0, 0, 0]])
    >>> [(g.target, g.reference, g.gap_s) for g in reference_gaps(plan, [0, 10, 25, 70])]
    [('S1', 'R0', 15.0), ('S1', 'R1', 45.0)]
    """
    t = np.asarray(times_s, dtype=float)
    gaps = []
    for i, (before, after) in zip(plan.target_indices, plan.adjacent_references(), strict=True):
        for r in (before, after):
            if r >= 0 and np.isfinite(t[i]) and np.isfinite(t[r]):
                gaps.append(ReferenceGap(plan.labels[i], plan.labels[r], float(abs(t[i] - t[r]))))
    return gaps
