"""Readers and writers of the YAML contracts: hexapod, balls, plan and session files.

Every reader checks the ``format:`` key, rejects unknown keys and bad values with
an :class:`~hexatherm.errors.InputError` that names the file, the line and the
field, and returns the core's typed objects.
"""

from __future__ import annotations

import dataclasses
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hexatherm.core.effects import EFFECTS, make_effect
from hexatherm.core.geometry import CONVENTIONS
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import NAME_PATTERN, STEP_KINDS, Plan
from hexatherm.core.registration import check_ball_layout
from hexatherm.core.thermal import LegThermalModel, SegmentSpec
from hexatherm.errors import InputError, RegistrationError, StepError
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.yamlfile import PLAIN_NUMBER, YamlDoc, plain_numbers, plain_tag, read_text
from hexatherm.session import Balls, CmmNoise, Datums, QualityLimits, Session

HEXAPOD_FORMAT = "hexatherm-hexapod/1"
BALLS_FORMAT = "hexatherm-balls/1"
PLAN_FORMAT = "hexatherm-plan/1"
SESSION_FORMAT = "hexatherm-session/1"

#: effect names and parameters (spec: "The hexapod twin and its effects"), from the one
#: registry of effects that the twin and the diagnosis use
EFFECT_PARAMETERS: dict[str, tuple[str, ...]] = {
    name: tuple(cls.parameters) for name, cls in EFFECTS.items()
}

#: coefficients of thermal expansion accepted in a leg model, 1/K (invar to plastics; a
#: value in ppm/K, 23 for 23e-6, is refused)
CTE_RANGE_PER_K = (-1e-4, 1e-3)
#: temperatures accepted, degC (a value in kelvin, 293.15 for 20 degC, is refused)
TEMPERATURE_RANGE_C = (-60.0, 150.0)


def _checked_cte(doc: YamlDoc, value: float, *keys: Any) -> float:
    """``value`` (a CTE, 1/K) if within :data:`CTE_RANGE_PER_K`, else an InputError."""
    low, high = CTE_RANGE_PER_K
    if not low <= value <= high:
        hint = f" (ppm/K? write {value:g}e-6)" if 0.1 <= abs(value) <= 1000 else ""
        raise doc.error(
            f"a coefficient of thermal expansion must be within [{low:g}, {high:g}] 1/K, "
            f"got {value:g}{hint}",
            *keys,
        )
    return value


def _checked_temperature(doc: YamlDoc, value: float, *keys: Any) -> float:
    """``value`` (degC) if within :data:`TEMPERATURE_RANGE_C`, else an InputError."""
    low, high = TEMPERATURE_RANGE_C
    if not low <= value <= high:
        hint = " (looks like kelvin: the file is in degC)" if 200 <= value <= 450 else ""
        raise doc.error(
            f"a temperature must be within [{low:g}, {high:g}] degC, got {value:g}{hint}", *keys
        )
    return value


# --------------------------------------------------------------------- hexapod
def read_hexapod(path: str | os.PathLike[str]) -> Hexapod:
    """Read and validate a hexapod file (``format: hexatherm-hexapod/1``)."""
    return _hexapod_from_doc(YamlDoc.load(path))


def read_hexapod_text(text: str, path: str) -> Hexapod:
    """Read a hexapod file's text (``path`` names it in messages)."""
    return _hexapod_from_doc(YamlDoc.from_text(text, path))


def _hexapod_from_doc(doc: YamlDoc) -> Hexapod:
    doc.check_format(HEXAPOD_FORMAT)
    doc.check_keys(
        [
            "format",
            "name",
            "convention",
            "base_joints",
            "platform_joints",
            "stroke",
            "legs",
            "thermal_model",
        ]
    )
    name = doc.string("name", default=Path(doc.path).stem)
    convention = doc.string("convention", default="symetrie", choices=CONVENTIONS)
    joints = {}
    for key in ("base_joints", "platform_joints"):
        items = doc.get(key)
        if not isinstance(items, list) or len(items) != 6:
            raise doc.error(f"expected six [x, y, z] joints (legs 1..6), got {items!r}", key)
        joints[key] = np.array([doc.vector(key, i, size=3) for i in range(6)])
    stroke = None
    if doc.get("stroke", default=None) is not None:
        stroke = np.array(doc.vector("stroke", size=2))
        if not stroke[0] < stroke[1]:
            raise doc.error(f"expected [min, max] with min < max, got {stroke.tolist()}", "stroke")
    legs = _read_legs(doc)
    effects = _read_effects(doc)
    hexapod = Hexapod(
        name=name,
        convention=convention,  # type: ignore[arg-type]
        base_joints_mm=joints["base_joints"],
        platform_joints_mm=joints["platform_joints"],
        stroke_mm=stroke,
        legs=legs,
        effects=effects,
    )
    q0 = hexapod.zero_pose_leg_length_mm()
    variable = q0 - legs.total_fixed_length_mm
    if np.any(variable <= 0):
        leg = int(np.argmax(variable <= 0))
        raise doc.error(
            f"leg {leg + 1}: the fixed segments ({legs.total_fixed_length_mm[leg]:.3f} mm) are "
            f"longer than the leg in the zero pose ({q0[leg]:.3f} mm)",
            "legs",
        )
    if stroke is not None and np.any(hexapod.check_stroke(q0)):
        raise doc.error(
            f"the zero pose leg lengths {q0.round(3).tolist()} are outside the stroke", "stroke"
        )
    return hexapod


def _read_segments(doc: YamlDoc, *keys: Any) -> list[SegmentSpec]:
    items = doc.get(*keys)
    if not isinstance(items, list) or not items:
        raise doc.error("expected a list of segments", *keys)
    segments: list[SegmentSpec] = []
    for j in range(len(items)):
        doc.check_keys(["name", "material", "cte", "length"], *keys, j)
        name = doc.string(*keys, j, "name")
        material = doc.string(*keys, j, "material", default="")
        cte = _checked_cte(doc, doc.number(*keys, j, "cte"), *keys, j, "cte")
        length_value = doc.get(*keys, j, "length")
        length = (
            None if length_value == "variable" else doc.number(*keys, j, "length", positive=True)
        )
        segments.append((name, material, cte, length))
    n_var = sum(1 for s in segments if s[3] is None)
    if n_var != 1:
        raise doc.error(f"exactly one segment must have 'length: variable', found {n_var}", *keys)
    return segments


def _read_legs(doc: YamlDoc) -> LegThermalModel:
    doc.check_keys(["reference_temperature", "segments", "per_leg"], "legs")
    t_ref = _checked_temperature(
        doc,
        doc.number("legs", "reference_temperature", default=20.0),
        "legs",
        "reference_temperature",
    )
    has_segments = doc.get("legs", "segments", default=None) is not None
    has_per_leg = doc.get("legs", "per_leg", default=None) is not None
    if has_segments == has_per_leg:
        raise doc.error("give either 'segments' (all legs alike) or 'per_leg' (six lists)", "legs")
    if has_segments:
        return LegThermalModel.uniform(_read_segments(doc, "legs", "segments"), t_ref)
    per_leg = doc.get("legs", "per_leg")
    if not isinstance(per_leg, list) or len(per_leg) != 6:
        raise doc.error("expected six segment lists (legs 1..6)", "legs", "per_leg")
    return LegThermalModel.from_segments(
        [_read_segments(doc, "legs", "per_leg", i) for i in range(6)], t_ref
    )


def _read_effects(doc: YamlDoc) -> tuple[dict[str, Any], ...]:
    if doc.get("thermal_model", default=None) is None:
        return ()
    doc.check_keys(["effects"], "thermal_model")
    items = doc.get("thermal_model", "effects", default=[])
    if not isinstance(items, list):
        raise doc.error("expected a list of effects", "thermal_model", "effects")
    effects: list[dict[str, Any]] = []
    for i in range(len(items)):
        keys = ("thermal_model", "effects", i)
        doc.check_keys(["name", "parameters"], *keys)
        name = doc.string(*keys, "name", choices=tuple(EFFECTS))
        parameters = tuple(EFFECTS[name].parameters)
        doc.check_keys(parameters, *keys, "parameters")
        params = {p: doc.number(*keys, "parameters", p) for p in parameters}
        if any(e["name"] == name for e in effects):
            raise doc.error(f"effect {name} is given twice", *keys, "name")
        try:
            effect = make_effect(name, params)
        except ValueError as exc:
            raise doc.error(str(exc), *keys, "parameters") from None
        for parameter, problem in effect.out_of_range().items():
            raise doc.error(problem, *keys, "parameters", parameter)
        effects.append({"name": name, "parameters": params})
    return tuple(effects)


def hexapod_to_yaml(hexapod: Hexapod) -> str:
    """The hexapod file text of ``hexapod`` (reads back to the same model)."""
    legs = hexapod.legs
    doc: dict[str, Any] = {
        "format": HEXAPOD_FORMAT,
        "name": hexapod.name,
        "convention": hexapod.convention,
        "base_joints": hexapod.base_joints_mm.tolist(),
        "platform_joints": hexapod.platform_joints_mm.tolist(),
    }
    if hexapod.stroke_mm is not None:
        doc["stroke"] = hexapod.stroke_mm.tolist()
    if legs is not None:
        per_leg = []
        for i in range(6):
            segs = []
            for j, name in enumerate(legs.names[i]):
                length: Any = (
                    "variable" if legs.variable[i, j] else float(legs.fixed_length_mm[i, j])
                )
                segs.append(
                    {
                        "name": name,
                        "material": legs.materials[i][j],
                        "cte": float(legs.cte_per_K[i, j]),
                        "length": length,
                    }
                )
            per_leg.append(segs)
        leg_doc: dict[str, Any] = {"reference_temperature": legs.reference_temperature_C}
        if all(p == per_leg[0] for p in per_leg):
            leg_doc["segments"] = per_leg[0]
        else:
            leg_doc["per_leg"] = per_leg
        doc["legs"] = leg_doc
    if hexapod.effects:
        doc["thermal_model"] = {"effects": [dict(e) for e in hexapod.effects]}
    return _dump(doc)


# ----------------------------------------------------------------------- balls


def read_balls(path: str | os.PathLike[str]) -> Balls:
    """Read and validate a balls file (``format: hexatherm-balls/1``)."""
    doc = YamlDoc.load(path)
    doc.check_format(BALLS_FORMAT)
    doc.check_keys(["format", "balls", "probe"])
    balls = doc.get("balls")
    if not isinstance(balls, dict):
        raise doc.error("expected a mapping of ball names", "balls")
    names, centres, diameters = [], [], []
    for name in balls:
        if not NAME_PATTERN.fullmatch(name):
            raise doc.error("ball name must match [A-Za-z0-9-]+", "balls", name)
        doc.check_keys(["centre", "diameter"], "balls", name)
        names.append(name)
        centres.append(doc.vector("balls", name, "centre", size=3))
        diameters.append(doc.number("balls", name, "diameter", positive=True))
    if len(names) < 3:
        raise doc.error(f"at least three balls are needed, got {len(names)}", "balls")
    try:
        check_ball_layout(centres)
    except RegistrationError as exc:
        raise doc.error(str(exc), "balls") from None
    compensated, tip = True, 0.0
    if doc.get("probe", default=None) is not None:
        doc.check_keys(["compensated", "tip_diameter"], "probe")
        compensated = doc.get("probe", "compensated", default=True)
        if not isinstance(compensated, bool):
            raise doc.error(f"expected true or false, got {compensated!r}", "probe", "compensated")
        tip = doc.number("probe", "tip_diameter", default=0.0)
        if tip < 0:
            raise doc.error("must not be negative", "probe", "tip_diameter")
    return Balls(tuple(names), np.array(centres), np.array(diameters), compensated, tip)


def balls_to_yaml(balls: Balls) -> str:
    """The balls file text of ``balls``."""
    doc = {
        "format": BALLS_FORMAT,
        "balls": {
            n: {"centre": c.tolist(), "diameter": float(d)}
            for n, c, d in zip(balls.names, balls.centres_mm, balls.diameters_mm, strict=True)
        },
        "probe": {
            "compensated": balls.probe_compensated,
            "tip_diameter": float(balls.tip_diameter_mm),
        },
    }
    return _dump(doc)


# ------------------------------------------------------------------------ plan
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
    if plan is not None:
        return plan
    return _plan_from_doc(YamlDoc.from_text(text, os.fspath(path)))


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
            raise doc.error(f"expected a label, got {label!r}", "steps", i, "label")
        kind = doc.string("steps", i, "kind", choices=STEP_KINDS)
        pose = doc.vector("steps", i, "pose", size=6)
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
    ppb = (
        int(found["points_per_ball"][1]) if "points_per_ball" in found else DEFAULT_POINTS_PER_BALL
    )
    try:
        return Plan.from_steps(
            zip(labels, kinds, poses, strict=True), reference_pose=reference, points_per_ball=ppb
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


# --------------------------------------------------------------------- session


def read_session(path: str | os.PathLike[str]) -> Session:
    """Read a session file, or the ``session.yaml`` of a session folder, and its configs."""
    path = Path(path)
    if path.is_dir():
        path = path / "session.yaml"
    doc = YamlDoc.load(path)
    doc.check_format(SESSION_FORMAT)
    doc.check_keys(
        [
            "format",
            "name",
            "hexapod",
            "balls",
            "plan",
            "measurements",
            "temperatures",
            "cmm",
            "quality",
            "pose_check",
        ]
    )
    name = doc.string("name", default=path.parent.name)
    _read_pose_check(doc)  # checked here, used by process (read_pose_check)

    def existing(*keys: Any) -> Path:
        rel = doc.string(*keys)
        target = doc.resolve(rel)
        if not target.is_file():
            raise doc.error(f"file not found: {target}", *keys)
        return target

    hexapod = read_hexapod(existing("hexapod"))
    balls = read_balls(existing("balls"))
    plan = read_plan(existing("plan"))
    files = doc.get("measurements")
    if isinstance(files, str):
        raise doc.error("expected a list of files, e.g. [centres.csv]", "measurements")
    if not isinstance(files, list) or not files:
        raise doc.error("expected a non-empty list of measurement files", "measurements")
    measurements = tuple(existing("measurements", i) for i in range(len(files)))
    temperatures = None
    if doc.get("temperatures", default=None) is not None:
        temperatures = existing("temperatures")
    return Session(
        path,
        name,
        hexapod,
        balls,
        plan,
        measurements,
        temperatures,
        _read_cmm(doc),
        _read_quality(doc),
    )


def read_pose_check(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The optional ``pose_check:`` mapping of a session file (an extension), checked.

    ``path`` is the session file or its folder. The mapping's keys, all optional:
    ``tolerance_mm`` and ``tolerance_deg`` (> 0, ``.inf`` turns the check off): the
    largest deviation of a step's measured pose relative to O from its commanded pose
    relative to O; ``offset`` (``[Tx, Ty, Tz, Rx, Ry, Rz]``, mm and deg): a known,
    constant deviation of every step but O. Returns None without the mapping, else a
    dict of the keys given (``offset`` as a list of six floats).
    """
    path = Path(path)
    if path.is_dir():
        path = path / "session.yaml"
    return _read_pose_check(YamlDoc.load(path))


def _read_pose_check(doc: YamlDoc) -> dict[str, Any] | None:
    if doc.get("pose_check", default=None) is None:
        return None
    doc.check_keys(["tolerance_mm", "tolerance_deg", "offset"], "pose_check")
    found: dict[str, Any] = {}
    for key in ("tolerance_mm", "tolerance_deg"):
        value = doc.get("pose_check", key, default=None)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            raise doc.error(
                f"expected a number > 0 (.inf turns the check off), got {value!r}",
                "pose_check",
                key,
            )
        found[key] = float(value)
    if doc.get("pose_check", "offset", default=None) is not None:
        found["offset"] = doc.vector("pose_check", "offset", size=6)
    return found


def _read_quality(doc: YamlDoc) -> dict[str, float]:
    """The optional ``quality:`` mapping of a session file: check name -> limit (>= 0;
    ``.inf`` turns a check off, as does 0 for ``min_rcond``)."""
    if doc.get("quality", default=None) is None:
        return {}
    doc.check_keys([f.name for f in dataclasses.fields(QualityLimits)], "quality")
    limits = {}
    for name in doc.get("quality"):
        value = doc.get("quality", name)
        if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
            raise doc.error(
                f"expected a number >= 0 (.inf turns the check off), got {value!r}", "quality", name
            )
        limits[name] = float(value)
    return limits


def _read_cmm(doc: YamlDoc) -> CmmNoise | None:
    """The optional ``cmm:`` mapping of a session file."""
    if doc.get("cmm", default=None) is None:
        return None
    doc.check_keys(["point_noise_um", "mpe_um", "points_per_ball", "cap_angle_deg"], "cmm")
    given = [k for k in ("point_noise_um", "mpe_um") if doc.get("cmm", k, default=None) is not None]
    if len(given) != 1:
        raise doc.error(
            "give point_noise_um or mpe_um (sigma = MPE/2), exactly one", "cmm", *given[1:]
        )
    sigma = doc.number("cmm", given[0], positive=True)
    if given[0] == "mpe_um":
        sigma /= 2.0
    points = doc.get("cmm", "points_per_ball", default=None)
    if points is not None and (
        isinstance(points, bool) or not isinstance(points, int) or points < 4
    ):
        raise doc.error(f"expected a whole number >= 4, got {points!r}", "cmm", "points_per_ball")
    cap = doc.number("cmm", "cap_angle_deg", default=70.0, positive=True)
    if cap > 180.0:
        raise doc.error(f"must be at most 180, got {cap!r}", "cmm", "cap_angle_deg")
    return CmmNoise(sigma, points, cap)


def session_to_yaml(
    name: str,
    hexapod: str,
    balls: str,
    plan: str,
    measurements: list[str],
    temperatures: str | None = None,
    cmm: dict[str, float] | None = None,
) -> str:
    """The session file text (paths relative to the session file).

    ``cmm`` is the optional ``cmm:`` mapping, e.g. ``{"mpe_um": 1.0}``.
    """
    doc: dict[str, Any] = {
        "format": SESSION_FORMAT,
        "name": name,
        "hexapod": hexapod,
        "balls": balls,
        "plan": plan,
        "measurements": list(measurements),
    }
    if temperatures is not None:
        doc["temperatures"] = temperatures
    if cmm:
        doc["cmm"] = dict(cmm)
    return _dump(doc)


# --------------------------------------------------------------------- helpers
def _number(value: float) -> str:
    """Shortest round-tripping text of a number that every YAML reader takes as one."""
    value = float(value)
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    text = repr(value)
    if "e" in text and "." not in text:
        text = text.replace("e", ".0e")
    return text


def _flow(values: Any) -> str:
    return "[" + ", ".join(_number(v) for v in np.asarray(values, float)) + "]"


def _dump(doc: dict[str, Any]) -> str:
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write a config file atomically."""
    atomic_write_text(path, text)


__all__ = [
    "Balls",
    "CmmNoise",
    "Session",
    "read_hexapod",
    "read_balls",
    "read_plan",
    "read_session",
    "hexapod_to_yaml",
    "balls_to_yaml",
    "plan_to_yaml",
    "session_to_yaml",
    "InputError",
]


# ---------------------------------------------------------------------- datums
DATUMS_FORMAT = "hexatherm-datums/1"


def read_datums(path: str | os.PathLike[str]) -> Datums:
    """Read a datums file (``format: hexatherm-datums/1``)."""
    doc = YamlDoc.load(path)
    doc.check_format(DATUMS_FORMAT)
    doc.check_keys(["format", "step", "plane", "bores", "origin_offset", "balls", "probe"])
    step = doc.get("step", default=None)
    if step is not None:
        step = doc.string("step")
    names = {"plane": doc.string("plane")}
    bores = doc.get("bores")
    if not isinstance(bores, list) or len(bores) != 2:
        raise doc.error("expected two bore names [origin, x-direction]", "bores")
    names["bore 1"], names["bore 2"] = doc.string("bores", 0), doc.string("bores", 1)
    offset = np.array(doc.vector("origin_offset", size=3, default=[0.0, 0.0, 0.0]))
    balls = doc.get("balls")
    if not isinstance(balls, dict) or len(balls) < 3:
        raise doc.error("expected at least three balls, name: diameter", "balls")
    diameters = {name: doc.number("balls", name, positive=True) for name in balls}
    for key, name in [*names.items(), *((f"ball {b}", b) for b in diameters)]:
        if not NAME_PATTERN.fullmatch(name):
            raise doc.error(f"{key} name {name!r} must match [A-Za-z0-9-]+")
    if len(set(names.values()) | set(diameters)) != len(names) + len(diameters):
        raise doc.error("plane, bores and balls must have different names")
    compensated, tip = True, 0.0
    if doc.get("probe", default=None) is not None:
        doc.check_keys(["compensated", "tip_diameter"], "probe")
        compensated = doc.get("probe", "compensated", default=True)
        if not isinstance(compensated, bool):
            raise doc.error("expected true or false", "probe", "compensated")
        tip = doc.number("probe", "tip_diameter", default=0.0)
        if tip < 0:
            raise doc.error(f"must not be negative, got {tip:g}", "probe", "tip_diameter")
    return Datums(
        step,
        names["plane"],
        (names["bore 1"], names["bore 2"]),
        offset,
        diameters,
        compensated,
        tip,
    )
