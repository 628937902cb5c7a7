"""The measuring plan: which pose is measured at which step, in which order.

The method needs the steps in the paper's order: the origin O first, then the
first reference R0 (it fixes the thermal state that corrected poses refer to),
then targets, each with a reference step right before and/or right after it.

>>> plan = Plan.from_steps([("O", "origin", [0] * 6), ("R0", "reference", [0, 0, -40, 0, 0, 0]),
...                         ("S1", "target", [1, 0, 0, 0, 0, 0]),
...                         ("R1", "reference", [0, 0, -40, 0, 0, 0])])
>>> plan.adjacent_references()
[(1, 3)]
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Literal, cast

import numpy as np
import numpy.typing as npt

from hexatherm.errors import StepError

StepKind = Literal["origin", "reference", "target"]
STEP_KINDS: tuple[StepKind, ...] = ("origin", "reference", "target")
NAME_PATTERN = re.compile(r"[A-Za-z0-9-]+")
#: names of :data:`NAME_PATTERN`, one a line: every label of a plan checked in one match
NAME_LINES = re.compile(r"[A-Za-z0-9-]+(?:\n[A-Za-z0-9-]+)*")
#: commanded reference poses equal to this tolerance are the same pose (mm, deg)
SAME_POSE_TOL = 1e-9


@dataclass(frozen=True)
class Plan:
    """Steps of a measuring session, in measuring order.

    Attributes
    ----------
    labels : tuple of str
    kinds : tuple of {"origin", "reference", "target"}
    poses : ndarray, shape (N, 6)
        Commanded pose of each step relative to frame O (mm, deg).
    reference_pose : ndarray, shape (6,)
    points_per_ball : int
    """

    labels: tuple[str, ...]
    kinds: tuple[StepKind, ...]
    poses: npt.NDArray[np.float64]
    reference_pose: npt.NDArray[np.float64]
    points_per_ball: int = 25

    @classmethod
    def from_steps(
        cls,
        steps: Iterable[tuple[str, str, Sequence[float]]],
        reference_pose: Sequence[float] | None = None,
        points_per_ball: int = 25,
    ) -> Plan:
        """Build and validate a plan from ``(label, kind, pose)`` triples."""
        steps = list(steps)
        labels = tuple(str(s[0]) for s in steps)
        kinds = tuple(cast(StepKind, s[1]) for s in steps)
        poses = np.array([np.asarray(s[2], dtype=float) for s in steps]).reshape(-1, 6)
        return cls.from_columns(labels, kinds, poses, reference_pose, points_per_ball)

    @classmethod
    def from_columns(
        cls,
        labels: Sequence[str],
        kinds: Sequence[str],
        poses: npt.ArrayLike,
        reference_pose: Sequence[float] | npt.NDArray[np.float64] | None = None,
        points_per_ball: int = 25,
    ) -> Plan:
        """:meth:`from_steps` of the steps given as columns: their labels, kinds and poses
        (N, 6) already one array (a plan file's 20,002 steps are not made 20,002 arrays
        and stacked again)."""
        names = tuple(str(label) for label in labels)
        step_kinds = tuple(cast(StepKind, kind) for kind in kinds)
        rows = np.array(poses, dtype=float).reshape(-1, 6)
        if reference_pose is None:
            refs = [p for p, k in zip(rows, step_kinds, strict=True) if k == "reference"]
            reference = refs[0] if refs else np.zeros(6)
        else:
            reference = np.asarray(reference_pose, dtype=float)
        plan = cls(
            names,
            step_kinds,
            rows,
            np.asarray(reference, float),
            int(points_per_ball),
        )
        plan.validate()
        return plan

    def validate(self) -> None:
        """Raise :class:`StepError` naming the step when the plan cannot be processed."""
        if not self.labels:
            raise StepError("the plan has no steps")
        if not self._steps_valid():
            self._name_invalid_step()
        self._validate_order()

    def _steps_valid(self) -> bool:
        """Whether every step passes :meth:`_name_invalid_step`'s checks, all at once: the
        labels as one text (a label holds no line break), a set of them, the kinds' set,
        the poses' finiteness (a plan of 20,002 steps is not looped over when it is valid)."""
        labels = self.labels
        joined = "\n".join(labels)
        return (
            joined.count("\n") == len(labels) - 1  # no label holds a line break itself
            and NAME_LINES.fullmatch(joined) is not None
            and len(set(labels)) == len(labels)
            and set(self.kinds) <= set(STEP_KINDS)
            and bool(np.isfinite(self.poses).all())
        )

    def _name_invalid_step(self) -> None:
        """Raise :class:`StepError` naming the first step with a bad label, a label seen
        before, an unknown kind or a non-finite pose."""
        seen: dict[str, int] = {}
        finite = np.all(np.isfinite(self.poses), axis=1).tolist()  # one pass, not one a step
        for i, (label, kind) in enumerate(zip(self.labels, self.kinds, strict=True)):
            if not NAME_PATTERN.fullmatch(label):
                raise StepError("label must match [A-Za-z0-9-]+", step=label, index=i)
            if label in seen:
                raise StepError(
                    f"duplicate label (also step {seen[label] + 1})", step=label, index=i
                )
            seen[label] = i
            if kind not in STEP_KINDS:
                raise StepError(
                    f"unknown kind {kind!r}; expected origin, reference or target",
                    step=label,
                    index=i,
                )
            if not finite[i]:
                raise StepError("pose has a non-finite value", step=label, index=i)

    def _validate_order(self) -> None:
        """Raise :class:`StepError` naming the step when the steps' order cannot be
        processed: the origin not first or twice, references differing, a target before
        R0 or without a reference next to it."""
        if self.kinds[0] != "origin":
            raise StepError(
                "the first step must be the origin (kind: origin)", step=self.labels[0], index=0
            )
        extra = [i for i, k in enumerate(self.kinds) if k == "origin"][1:]
        if extra:
            raise StepError(
                "only one origin step is allowed", step=self.labels[extra[0]], index=extra[0]
            )
        refs = self.reference_indices
        if self.target_indices.size and not refs.size:
            raise StepError("the plan has targets but no reference step")
        if refs.size:
            # each row at once (one array pass, not one per step); the first one named
            spread = np.abs(self.poses[refs] - self.poses[refs[0]]).max(axis=1)
            differ = refs[spread > SAME_POSE_TOL]
            if differ.size:
                i = int(differ[0])
                raise StepError(
                    f"reference pose differs from the first reference {self.labels[refs[0]]}; "
                    "all reference steps must command the same pose",
                    step=self.labels[i],
                    index=i,
                )
            targets = self.target_indices
            early = targets[targets < refs[0]]
            if early.size:
                i = int(early[0])
                raise StepError(
                    f"target comes before the first reference {self.labels[refs[0]]}, which "
                    "fixes the thermal state of the corrected poses",
                    step=self.labels[i],
                    index=i,
                )
        alone = [
            i
            for i, (before, after) in zip(
                self.target_indices.tolist(), self.adjacent_references(), strict=True
            )
            if before < 0 and after < 0
        ]
        if alone:
            raise StepError(
                "target has no reference step adjacent to it (right before or after)",
                step=self.labels[alone[0]],
                index=alone[0],
            )

    @property
    def reference_indices(self) -> npt.NDArray[np.intp]:
        """Indices of the reference steps, in order."""
        return self._kind_indices["reference"].copy()

    @property
    def target_indices(self) -> npt.NDArray[np.intp]:
        """Indices of the target steps, in order."""
        return self._kind_indices["target"].copy()

    @functools.cached_property
    def _kind_indices(self) -> dict[str, npt.NDArray[np.intp]]:
        """The steps of each kind, found once (``process`` asks for them dozens of times,
        20,002 steps each at 10,000 targets); the properties hand out copies. The kinds are a
        tuple: they cannot change under the cache."""
        kinds = np.array(self.kinds, dtype=object)
        return {
            kind: np.flatnonzero(kinds == kind).astype(np.intp)
            for kind in ("origin", "reference", "target")
        }

    @property
    def origin_index(self) -> int:
        """Index of the origin step (always 0 in a valid plan)."""
        return self.kinds.index("origin")

    def adjacent_references(self) -> list[tuple[int, int]]:
        """For each target, the indices of the reference right before and after it (-1: none)."""
        targets = self._kind_indices["target"]
        reference = np.zeros(len(self.kinds) + 2, dtype=bool)  # a step of no kind at each end
        reference[self._kind_indices["reference"] + 1] = True
        before = np.where(reference[targets], targets - 1, -1)
        after = np.where(reference[targets + 2], targets + 1, -1)
        return list(zip(before.tolist(), after.tolist(), strict=True))


@dataclass(frozen=True)
class Repeats:
    """Steps that measure O and R0 again (``plan --origin-repeats/--reference0-repeats``).

    The plan contract allows one origin step and requires a reference next to every
    target, so a repeat of O is a *target* labelled ``<O>-<n>`` commanded at O's pose,
    and a repeat of R0 a *reference* labelled ``<R0>-<n>``, both before the first other
    target (``O, R0, O-2, R0-2, O-3, R0-3, S1, R1, ...``). A reader that does not know
    repeats sees targets at the zero pose and references measured early: valid.

    Attributes
    ----------
    origin : tuple of int
        Step indices measuring O: O itself first, then its repeats.
    reference0 : tuple of int
        Step indices measuring R0: R0 first, then its repeats.
    """

    origin: tuple[int, ...]
    reference0: tuple[int, ...]

    @property
    def any(self) -> bool:
        """Whether O or R0 is measured more than once."""
        return len(self.origin) > 1 or len(self.reference0) > 1

    def groups(self) -> tuple[tuple[int, ...], ...]:
        """The groups of steps measuring one step again, O's then R0's (when repeated)."""
        return tuple(g for g in (self.origin, self.reference0) if len(g) > 1)


def repeat_label(label: str, n: int) -> str:
    """Label of the ``n``-th measurement (n >= 2) of step ``label``: ``O-2``, ``R0-3``."""
    return f"{label}-{n}"


def find_repeats(plan: Plan) -> Repeats:
    """The repeats of O and R0 in ``plan`` (see :class:`Repeats`).

    >>> plan = Plan.from_steps([("O", "origin", [0] * 6), ("R0", "reference", [0, 0, -40, 0, 0, 0]),
    ...     ("O-2", "target", [0] * 6), ("R0-2", "reference", [0, 0, -40, 0, 0, 0]),
    ...     ("S1", "target", [1, 0, 0, 0, 0, 0]), ("R1", "reference", [0, 0, -40, 0, 0, 0])])
    >>> find_repeats(plan)
    Repeats(origin=(0, 2), reference0=(1, 3))
    """
    origin = plan.origin_index
    refs = plan.reference_indices
    if not refs.size:
        return Repeats((origin,), ())
    r0 = int(refs[0])
    o_repeat = re.compile(re.escape(plan.labels[origin]) + r"-[0-9]+")
    r_repeat = re.compile(re.escape(plan.labels[r0]) + r"-[0-9]+")
    o_steps, r_steps = [origin], [r0]
    for i in range(r0 + 1, len(plan.labels)):
        label, kind = plan.labels[i], plan.kinds[i]
        at_origin = np.abs(plan.poses[i] - plan.poses[origin]).max() <= SAME_POSE_TOL
        if kind == "target" and o_repeat.fullmatch(label) and at_origin:
            o_steps.append(i)
        elif kind == "reference" and r_repeat.fullmatch(label):
            r_steps.append(i)
        elif kind == "target":
            break
    return Repeats(tuple(o_steps), tuple(r_steps))


def without_repeats(plan: Plan, repeats: Repeats) -> tuple[Plan, npt.NDArray[np.intp]]:
    """The plan with every repeat removed (O and R0 stand for their averages), and the
    indices of the steps kept. The first target after the repeats then has R0 as its
    reference before (the repeats of R0 being R0)."""
    drop = set(repeats.origin[1:]) | set(repeats.reference0[1:])
    keep = np.array([i for i in range(len(plan.labels)) if i not in drop], dtype=np.intp)
    reduced = Plan(
        tuple(plan.labels[i] for i in keep),
        tuple(plan.kinds[i] for i in keep),
        plan.poses[keep],
        plan.reference_pose,
        plan.points_per_ball,
    )
    reduced.validate()
    return reduced, keep


def name_indices(names: Sequence[str], values: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """The index in ``names`` of each of ``values`` (text), -1 where it is not one of
    them; a name given twice has its last index (as ``{name: i for i, name in
    enumerate(names)}`` keeps it).

    A search in the names sorted, not a Python lookup per value: a scanning campaign's
    records name 60,000 centres by their steps' labels and balls.

    >>> name_indices(["O", "R0", "S1"], ["S1", "O", "X", "S1"]).tolist()
    [2, 0, -1, 2]
    """
    wanted = np.asarray(values)
    if wanted.dtype.kind != "U":
        wanted = wanted.astype(str)
    out = np.full(wanted.shape, -1, dtype=np.intp)
    keys = np.asarray(names, dtype=str)
    if keys.size == 0 or wanted.size == 0:
        return out
    order = np.argsort(keys, kind="stable")  # equal names in their order: the last last
    ordered = keys[order]
    at = np.searchsorted(ordered, wanted, side="right") - 1
    found = at >= 0
    found[found] = ordered[at[found]] == wanted[found]
    out[found] = order[at[found]]
    return out


def known_indices(names: Sequence[str], values: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """:func:`name_indices` of names that must be there: KeyError naming the first value
    that is not (as the lookup of a dict of the names raised)."""
    at = name_indices(names, values)
    if np.any(at < 0):
        raise KeyError(str(np.asarray(values)[np.argmax(at < 0)]))
    return at
