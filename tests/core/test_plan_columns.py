"""The plan's checks all at once (issue 37, write10k): a plan file of 20,002 steps is
validated without a Python loop over its steps when they are valid, its adjacent
references found by one array pass, and its poses taken as one array. Each is held to the
former code, kept here as the reference, on random and hostile plans: the same plan, or
the same StepError (message, step, index)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.plan import NAME_PATTERN, SAME_POSE_TOL, STEP_KINDS, Plan
from hexatherm.errors import StepError

REFERENCE = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]


def _former_adjacent(plan: Plan) -> list[tuple[int, int]]:
    out = []
    for i in plan.target_indices:
        before = i - 1 if i > 0 and plan.kinds[i - 1] == "reference" else -1
        after = i + 1 if i + 1 < len(plan.kinds) and plan.kinds[i + 1] == "reference" else -1
        out.append((int(before), int(after)))
    return out


def _former_validate(plan: Plan) -> None:
    """``Plan.validate`` as it was: one loop over the steps, then the order."""
    if not plan.labels:
        raise StepError("the plan has no steps")
    seen: dict[str, int] = {}
    finite = np.all(np.isfinite(plan.poses), axis=1).tolist()
    for i, (label, kind) in enumerate(zip(plan.labels, plan.kinds, strict=True)):
        if not NAME_PATTERN.fullmatch(label):
            raise StepError("label must match [A-Za-z0-9-]+", step=label, index=i)
        if label in seen:
            raise StepError(f"duplicate label (also step {seen[label] + 1})", step=label, index=i)
        seen[label] = i
        if kind not in STEP_KINDS:
            raise StepError(
                f"unknown kind {kind!r}; expected origin, reference or target", step=label, index=i
            )
        if not finite[i]:
            raise StepError("pose has a non-finite value", step=label, index=i)
    if plan.kinds[0] != "origin":
        raise StepError(
            "the first step must be the origin (kind: origin)", step=plan.labels[0], index=0
        )
    extra = [i for i, k in enumerate(plan.kinds) if k == "origin"][1:]
    if extra:
        raise StepError(
            "only one origin step is allowed", step=plan.labels[extra[0]], index=extra[0]
        )
    refs = plan.reference_indices
    if plan.target_indices.size and not refs.size:
        raise StepError("the plan has targets but no reference step")
    if refs.size:
        spread = np.abs(plan.poses[refs] - plan.poses[refs[0]]).max(axis=1)
        differ = refs[spread > SAME_POSE_TOL]
        if differ.size:
            i = int(differ[0])
            raise StepError(
                f"reference pose differs from the first reference {plan.labels[refs[0]]}; "
                "all reference steps must command the same pose",
                step=plan.labels[i],
                index=i,
            )
        targets = plan.target_indices
        early = targets[targets < refs[0]]
        if early.size:
            i = int(early[0])
            raise StepError(
                f"target comes before the first reference {plan.labels[refs[0]]}, which "
                "fixes the thermal state of the corrected poses",
                step=plan.labels[i],
                index=i,
            )
    for i, (before, after) in zip(plan.target_indices, _former_adjacent(plan), strict=True):
        if before < 0 and after < 0:
            raise StepError(
                "target has no reference step adjacent to it (right before or after)",
                step=plan.labels[i],
                index=int(i),
            )


def _steps(rng: np.random.Generator, n: int) -> tuple[list[str], list[str], np.ndarray]:
    """A valid plan's columns: O, R0, then targets with references, some back to back."""
    labels, kinds, poses = ["O", "R0"], ["origin", "reference"], [[0.0] * 6, REFERENCE]
    for k in range(n):
        labels.append(f"S{k + 1}")
        kinds.append("target")
        poses.append(list(rng.normal(0, 5, 6)))
        if rng.random() < 0.7 or k == n - 1:
            labels.append(f"R{k + 1}")
            kinds.append("reference")
            poses.append(REFERENCE)
    return labels, kinds, np.array(poses)


def _hostile(rng: np.random.Generator, labels, kinds, poses):
    """One edit of a valid plan that the checks must name (or, rarely, still accept)."""
    labels, kinds, poses = list(labels), list(kinds), poses.copy()
    i = int(rng.integers(len(labels)))
    edit = int(rng.integers(13))
    if edit == 0:
        labels[i] = str(rng.choice(["a b", "", "S\n1", "Ü1", "S_1", "S1\n", "\n", "x.y"]))
    elif edit == 1:
        labels[i] = labels[int(rng.integers(len(labels)))]  # a duplicate (or itself)
    elif edit == 2:
        kinds[i] = str(rng.choice(["Target", "", "reference ", "origin\n"]))
    elif edit == 3:
        poses[i, int(rng.integers(6))] = rng.choice([np.nan, np.inf, -np.inf])
    elif edit == 4:
        kinds[0] = "target"  # the origin not first
    elif edit == 5:
        kinds[i] = "origin"  # a second origin
    elif edit == 6:
        poses[kinds.index("reference", i) if "reference" in kinds[i:] else 1, 0] += 1e-6
    elif edit == 7:  # a target before R0
        labels.insert(1, "E1"), kinds.insert(1, "target")
        poses = np.insert(poses, 1, 1.0, axis=0)
    elif edit == 8:  # references taken out: targets alone
        keep = [j for j, k in enumerate(kinds) if k != "reference" or rng.random() < 0.3]
        labels, kinds, poses = [labels[j] for j in keep], [kinds[j] for j in keep], poses[keep]
    elif edit == 9:  # no steps but the origin, or none at all
        labels, kinds, poses = labels[: i % 2], kinds[: i % 2], poses[: i % 2]
    elif edit == 10:
        poses[i] = -0.0 if rng.random() < 0.5 else 1e-8
    elif edit == 11:
        poses[i] = rng.choice([1e300, -1e300, 1e-320])
    else:
        labels[i] = labels[i].replace("S", "s") + "-x"  # still a name
    return labels, kinds, poses


def _outcome(build):
    try:
        return build()
    except StepError as exc:
        return ("StepError", str(exc), exc.step, exc.index)


def _former_plan(labels, kinds, poses, reference):
    plan = Plan(tuple(labels), tuple(kinds), np.array(poses, float).reshape(-1, 6),
                np.asarray(reference, float), 25)  # fmt: skip
    _former_validate(plan)
    return plan


@pytest.mark.parametrize("seed", range(8))
def test_plans_from_columns_are_the_former_plans_and_refusals(seed):
    rng = np.random.default_rng(seed)
    labels, kinds, poses = _steps(rng, int(rng.integers(1, 60)))
    cases = [(labels, kinds, poses)] + [_hostile(rng, labels, kinds, poses) for _ in range(60)]
    refused = 0
    for case in cases:
        for reference in (REFERENCE, None):
            new = _outcome(lambda c=case, r=reference: Plan.from_columns(*c, reference_pose=r))
            steps = list(zip(*case, strict=True))
            via_steps = _outcome(lambda s=steps, r=reference: Plan.from_steps(s, r))
            ref = REFERENCE if reference is not None else None
            if ref is None:  # the former from_steps' choice: the first reference's pose
                refs = [p for p, k in zip(case[2], case[1], strict=True) if k == "reference"]
                ref = refs[0] if refs else np.zeros(6)
            old = _outcome(lambda c=case, r=ref: _former_plan(*c, r))
            if isinstance(old, tuple):
                assert new == old and via_steps == old
                refused += 1
                continue
            for plan in (new, via_steps):
                assert isinstance(plan, Plan)
                assert plan.labels == old.labels and plan.kinds == old.kinds
                np.testing.assert_array_equal(plan.poses, old.poses)
                np.testing.assert_array_equal(plan.reference_pose, old.reference_pose)
                assert plan.adjacent_references() == _former_adjacent(old)
    assert refused > len(cases)  # most hostile edits were refused, as before


def test_adjacent_references_at_the_ends_and_back_to_back():
    plan = Plan.from_steps(
        [("O", "origin", [0] * 6), ("R0", "reference", REFERENCE), ("S1", "target", [1] * 6),
         ("S2", "target", [2] * 6), ("R1", "reference", REFERENCE), ("S3", "target", [3] * 6)]
    )  # fmt: skip
    assert plan.adjacent_references() == [(1, -1), (-1, 4), (4, -1)]
    assert plan.adjacent_references() == _former_adjacent(plan)
