"""The plan file (``hexatherm-plan/1``): the steps of a session, in order."""

from __future__ import annotations

import os
import re

import numpy as np

from hexatherm.core.plan import STEP_KINDS, Plan
from hexatherm.errors import StepError
from hexatherm.io.config.yamlout import _flow
from hexatherm.io.yamlfile import PLAIN_NUMBER, YamlDoc, plain_numbers, plain_tag, read_text

PLAN_FORMAT = "hexatherm-plan/1"

#: points per ball of a plan file without ``points_per_ball``
DEFAULT_POINTS_PER_BALL = 25


def read_plan(path: str | os.PathLike[str]) -> Plan:
    """Read and validate a plan file (``format: hexatherm-plan/1``).

    A plan laid out as :func:`plan_to_yaml` writes it is read line by line
    (:func:`_read_plan_fast`); any other layout, and any plan with an error, is
    read as YAML (:func:`_plan_from_doc`), which gives the same plan and names
    the file, line and field of the error.
    """
    text = read_text(path)
    plan = _read_plan_fast(text)
    if plan is not None and not _off_zero(plan.poses[plan.origin_index]):
        return plan
    return _plan_from_doc(YamlDoc.from_text(text, os.fspath(path)))


def _off_zero(pose: object) -> bool:
    """Whether an origin step's pose is not the zero pose (to 1e-9 mm, deg)."""
    return bool(np.abs(np.asarray(pose, float)).max() > 1e-9)


def _plan_from_doc(doc: YamlDoc) -> Plan:
    """The plan of a parsed plan file (the general reader, with the errors)."""
    doc.check_format(PLAN_FORMAT)
    doc.check_keys(["format", "reference_pose", "points_per_ball", "steps"])
    reference = doc.vector("reference_pose", size=6)
    ppb = doc.number("points_per_ball", default=DEFAULT_POINTS_PER_BALL, positive=True)
    if ppb != int(ppb):
        raise doc.error(f"expected a whole number, got {ppb}", "points_per_ball")
    items = doc.get("steps")
    if not isinstance(items, list) or not items:
        raise doc.error("expected a list of steps", "steps")
    steps = []
    for i in range(len(items)):
        doc.check_keys(["label", "kind", "pose"], "steps", i)
        label = doc.get("steps", i, "label")
        if not isinstance(label, str | int) or isinstance(label, bool):
            raise doc.error(f"expected a label, got {doc.shown(label)}", "steps", i, "label")
        kind = doc.string("steps", i, "kind", choices=STEP_KINDS)
        pose = doc.vector("steps", i, "pose", size=6)
        if kind == "origin" and i == 0 and _off_zero(pose):
            # the spec's frame O is the platform in the zero pose, and every step's pose
            # is relative to it (process's IGM takes O at zero; calibrate's model too)
            raise doc.error(
                "the origin step is frame O, the platform in the zero pose, to which every "
                "other step's pose is relative: its pose must be [0, 0, 0, 0, 0, 0], got "
                f"[{', '.join(f'{v:g}' for v in pose)}]",
                "steps",
                i,
                "pose",
            )
        if kind == "reference" and np.abs(np.subtract(pose, reference)).max() > 1e-9:
            raise doc.error(
                f"reference step pose {pose} differs from reference_pose {reference}",
                "steps",
                i,
                "pose",
            )
        steps.append((str(label), kind, pose))
    try:
        return Plan.from_steps(steps, reference_pose=reference, points_per_ball=int(ppb))
    except StepError as exc:
        index = exc.index
        raise doc.error(
            str(exc), *(("steps", index) if index is not None else ("steps",))
        ) from None


#: the plan layout that :func:`_read_plan_fast` reads: lines of a top-level key each
#: (``points_per_ball`` optional), then step lines ``- {label: L, kind: K, pose: [...]}``
#: under ``steps:``, all at one indentation; blank and comment lines anywhere
_END = r" *(?:(?<= )#.*)?"
_POSE = r"\[ *" + r" *, *".join([f"({PLAIN_NUMBER})"] * 6) + r" *\]"
_PLAN_KEY_LINES = {
    "format": re.compile(rf"format: +{re.escape(PLAN_FORMAT)}{_END}"),
    "reference_pose": re.compile(rf"reference_pose: +{_POSE}{_END}"),
    "points_per_ball": re.compile(rf"points_per_ball: +([1-9][0-9]{{0,8}}){_END}"),
    "steps": re.compile(rf"steps:{_END}"),
}
_PLAN_STEP_LINE = re.compile(
    rf"( *)- +\{{ *label: +([A-Za-z0-9][A-Za-z0-9-]*) *, *kind: +(origin|reference|target) *,"
    rf" *pose: +{_POSE} *\}}{_END}"
)
_BLANK_LINE = re.compile(r" *(?:#.*)?")
#: characters that the fast reader leaves to YAML (tabs, controls, CR of old Macs)
_IRREGULAR = re.compile(r"[^\n\x20-\x7e]")
#: labels that are the same text when YAML reads them as an int
_DECIMAL = re.compile(r"0|[1-9][0-9]*")


def _read_plan_fast(text: str) -> Plan | None:
    """The plan of a plan file's text in the usual layout, or None to read it as YAML.

    Parameters
    ----------
    text : str
        The plan file's text.

    Returns
    -------
    Plan or None
        The plan that :func:`_plan_from_doc` gives, bit for bit, when the text has
        the layout of :func:`plan_to_yaml` (see ``_PLAN_KEY_LINES``) with plain
        decimal numbers and labels, and passes every check; None otherwise, and
        then :func:`_plan_from_doc` reads it (and names the line of an error).
    """
    text = text.replace("\r\n", "\n")
    if _IRREGULAR.search(text):
        return None
    found: dict[str, re.Match[str]] = {}
    labels: list[str] = []
    kinds: list[str] = []
    numbers: list[str] = []
    indent = None  # of the step lines
    in_steps = False
    step_line = _PLAN_STEP_LINE.fullmatch
    for line in text.split("\n"):
        match = step_line(line)
        if match is not None:
            if not in_steps or (indent is not None and match[1] != indent):
                return None
            indent = match[1]
            labels.append(match[2])
            kinds.append(match[3])
            numbers += match.group(4, 5, 6, 7, 8, 9)
            continue
        if _BLANK_LINE.fullmatch(line):
            continue
        key = line.partition(":")[0]
        pattern = _PLAN_KEY_LINES.get(key)
        match = None if pattern is None or key in found else pattern.fullmatch(line)
        if match is None:
            return None
        found[key] = match
        in_steps = key == "steps"
    if "format" not in found or "reference_pose" not in found or not labels:
        return None
    for label in labels:
        tag = plain_tag(label)
        if tag != "str" and not (tag == "int" and _DECIMAL.fullmatch(label)):
            return None
    reference = plain_numbers(found["reference_pose"].groups())
    values = plain_numbers(numbers)
    if reference is None or values is None:
        return None
    poses = np.array(values).reshape(-1, 6)
    is_reference = np.array(kinds) == "reference"
    if np.any(np.abs(poses[is_reference] - reference).max(axis=1) > 1e-9):
        return None
    if kinds[0] == "origin" and _off_zero(poses[0]):
        return None  # the general reader refuses it, naming steps[0].pose
    ppb = (
        int(found["points_per_ball"][1]) if "points_per_ball" in found else DEFAULT_POINTS_PER_BALL
    )
    try:
        return Plan.from_columns(
            labels, kinds, poses, reference_pose=reference, points_per_ball=ppb
        )
    except StepError:
        return None


def plan_to_yaml(plan: Plan) -> str:
    """The plan file text of ``plan``, one step per line."""
    lines = [
        f"format: {PLAN_FORMAT}",
        f"reference_pose: {_flow(plan.reference_pose)}",
        f"points_per_ball: {plan.points_per_ball}",
        "steps:",
    ]
    for label, kind, pose in zip(plan.labels, plan.kinds, plan.poses, strict=True):
        lines.append(f"  - {{label: {label}, kind: {kind}, pose: {_flow(pose)}}}")
    return "\n".join(lines) + "\n"
