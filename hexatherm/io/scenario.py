"""Reader of simulation scenarios (``format: hexatherm-scenario/1``, an extension).

A scenario says what ``hexatherm simulate`` should simulate: which hexapod,
balls and plan, where frame O sits on the CMM, how long things take, how the
legs are heated, how noisy the thermocouples, the CMM and the hexapod are, what
the CMM writes, and which effects the truth has that the session's files do
not tell. Paths are relative to the scenario file. Every field but ``format``,
``hexapod``, ``balls`` and ``plan`` has a default (the value shown, or the
one in parentheses)::

    format: hexatherm-scenario/1
    name: my-campaign                  # default: the file's name
    hexapod: ../symetrie-like.yaml
    balls: ../balls-3.yaml
    plan: plan.yaml                    # a plan file, or inline:
    # plan: {targets: [[Tx, Ty, Tz, Rx, Ry, Rz], ...], reference_pose: [0, 0, -40, 0, 0, 0],
    #        cycles: 2, references: both, points_per_ball: 25}
    origin_on_cmm: [450, 320, 210, 0, 0, 15]   # frame O on the CMM (hexapod's convention)
    start: "2024-03-05T08:00:00"       # t_0, the first thermocouple sample (2024-01-01T08:00:00)
    seed: 0                            # --seed overrides it
    timing: {seconds_per_point: 2.4, seconds_per_move: 20}
    heating:
      air_C: 20.0                      # or a history [[t_s, degC], ...] (straight lines)
      mats:                            # legs 1..6 (none: the legs follow the air)
        - {gain_C: 3.0, tau_s: 2400, power: [[300, null]]}   # on/off times, s; null: stays on
    thermocouples: {period_s: 30, noise_C: 0.02}   # noise default 0
    cmm:
      point_noise_um: 0.5              # sigma along the normal (0); or mpe_um (sigma = MPE/2)
      points_per_ball: 25              # default: the plan's
      cap_angle_deg: 70                # half-angle of the probed cap
      probe: {compensated: true, tip_diameter: 2.0}   # default: the balls file's
    hexapod_repeatability_um: 0.0      # sigma of each leg's positioning error, per step
    output: centres                    # centres | points | dmis
    hidden_effects:                    # applied to the truth only (none)
      - {name: leg_thermal_lag, parameters: {tau_s: 1800}}
    geometry_errors:                   # the true geometry differs from the hexapod file (none)
      seed: 0                          # a seeded draw with these sigmas (0):
      joint_sigma_um: 50               #   every base and platform joint coordinate
      offset_sigma_um: 30              #   every leg length at the home pose
      gain_sigma_ppm: 0                #   every leg's scale
      base_joints_um: [[dx, dy, dz], ...]   # and/or given errors, added to the draw:
      platform_joints_um: [[dx, dy, dz], ...]   # six each (0)
      leg_offsets_um: [d1, .., d6]
      leg_gains_ppm: [g1, .., g6]
    readme: |                          # written as README.md in the session folder
      # my-campaign ...

Inline plans are O, R0, then the targets (repeated ``cycles`` times) with a
reference between every two targets (``references: both``: each target has a
reference on both sides) or between every pair of targets (``one-side``: R0 S1
S2 R1 S3 S4 R2 ..., each target has a reference on one side only).
"""

from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.core.calibration.model import (
    BASE,
    GAINS,
    N_PARAMETERS,
    OFFSETS,
    PLATFORM,
    nominal_parameters,
)
from hexatherm.core.effects import EFFECTS, Effect, effects_from_dicts
from hexatherm.core.heating import Mat, MatHeating
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.planning import (
    DEFAULT_CAP_ANGLE_DEG,
    DEFAULT_SECONDS_PER_MOVE,
    DEFAULT_SECONDS_PER_POINT,
    MAX_TOUCH_POINTS,
    ReferenceEvery,
    sequence_steps,
)
from hexatherm.errors import InputError, PlanError
from hexatherm.io.config import read_balls, read_hexapod_text, read_plan
from hexatherm.io.config.hexapod import checked_temperature
from hexatherm.io.measurements import COORDINATE_MAX_MM
from hexatherm.io.records import iso_to_seconds
from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import Balls
from hexatherm.typing import FloatArray

SCENARIO_FORMAT = "hexatherm-scenario/1"
#: what ``output:`` may say; ``serial`` writes the ``serial.log`` of an ``acquire --auto``
#: capture (and no session.yaml): ``hexatherm acquire PLAN --replay`` makes it a session
OUTPUT_FORMATS = ("centres", "points", "dmis", "serial")
#: the scenario's ``references:`` -> the plan's reference layout (``core.planning``)
REFERENCE_LAYOUTS: dict[str, ReferenceEvery] = {"both": "both", "one-side": "alternate"}
DEFAULT_REFERENCE = (0.0, 0.0, -40.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes
    ----------
    path : str
    text : str
        The scenario file's text (kept with the truth).
    name : str
    hexapod_text : str
        The hexapod file, copied as is into the session.
    hexapod : Hexapod
    balls : Balls
        With the scenario's probe settings.
    plan : Plan
        With the scenario's points per ball.
    origin_on_cmm : tuple of 6 floats
    start : str
        ISO 8601 time of the session start.
    seed : int
    seconds_per_point, seconds_per_move : float
    heating : MatHeating
    sample_period_s, thermocouple_noise_C : float
    point_noise_mm : float
    cap_half_angle_deg : float
    repeatability_mm : float
    output : {"centres", "points", "dmis"}
    model_effects : tuple of Effect
        The hexapod file's ``thermal_model`` (part of the truth too).
    hidden_effects : tuple of Effect
        The scenario's hidden effects.
    readme : str
        Written as the session's ``README.md`` when not empty.
    true_parameters : ndarray, shape (48,), or None
        The true geometry (``geometry_errors:``), in the layout of
        :data:`hexatherm.core.calibration.model.PARAMETER_NAMES`; None: the hexapod
        file's.
    input_files : tuple of Path
        The scenario file and the hexapod, balls and plan files it names (an output
        may never be, contain or sit inside any of them).
    """

    path: str
    text: str
    name: str
    hexapod_text: str
    hexapod: Hexapod
    balls: Balls
    plan: Plan
    origin_on_cmm: tuple[float, ...]
    start: str
    seed: int
    seconds_per_point: float
    seconds_per_move: float
    heating: MatHeating
    sample_period_s: float
    thermocouple_noise_C: float
    point_noise_mm: float
    cap_half_angle_deg: float
    repeatability_mm: float
    output: str
    model_effects: tuple[Effect, ...]
    hidden_effects: tuple[Effect, ...]
    readme: str = ""
    true_parameters: FloatArray | None = None
    input_files: tuple[Path, ...] = ()

    @property
    def effects(self) -> tuple[Effect, ...]:
        """Every effect of the truth: the hexapod file's, then the hidden ones."""
        return self.model_effects + self.hidden_effects


#: what ``simulate --plan`` assumes beside the plan: a typical session (the scenario's
#: defaults for the rest); written to the session's ``truth/scenario.yaml``, whose paths
#: name the session's own copies of the hexapod, balls and plan files
PLAN_SCENARIO = """\
format: hexatherm-scenario/1
name: {name}
hexapod: {hexapod}
balls: {balls}
plan: {plan}
seed: {seed}
heating:
  mats:
{mats}
thermocouples: {{period_s: 30, noise_C: 0.02}}
cmm: {{point_noise_um: 0.5}}
output: centres
"""
PLAN_SCENARIO_MAT = "    - {gain_C: 3.0, tau_s: 2400, power: [[300, null]]}"


def plan_scenario(
    plan: str | os.PathLike[str],
    hexapod: str | os.PathLike[str],
    balls: str | os.PathLike[str],
    name: str,
    seed: int = 0,
) -> Scenario:
    """The scenario of ``simulate --plan``: a plan file measured as a typical session.

    Heating mats warm every leg by 3 K (time constant 2400 s) from 5 minutes after the
    start; 0.5 um CMM point noise, 0.02 K thermocouple noise; the scenario's defaults
    for the rest (:data:`PLAN_SCENARIO`). The files are read and checked as a scenario's
    would be (errors name them). The scenario's ``text`` is the same scenario with the
    paths of the session's own copies (``../hexapod.yaml``, ``../balls.yaml``,
    ``../plan.yaml`` from its ``truth/``): simulating it again gives the same session.
    """
    fields = {"name": _yaml_string(name), "seed": seed, "mats": "\n".join([PLAN_SCENARIO_MAT] * 6)}
    given = {
        "hexapod": _yaml_string(str(Path(hexapod).resolve())),
        "balls": _yaml_string(str(Path(balls).resolve())),
        "plan": _yaml_string(str(Path(plan).resolve())),
    }
    doc = YamlDoc.from_text(PLAN_SCENARIO.format(**fields, **given), os.fspath(plan))
    scenario = _scenario(doc, doc_text=None)
    own = {"hexapod": "../hexapod.yaml", "balls": "../balls.yaml", "plan": "../plan.yaml"}
    return replace(scenario, text=PLAN_SCENARIO.format(**fields, **own))


def _yaml_string(text: str) -> str:
    """``text`` as a YAML double-quoted scalar (any path or name survives)."""
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def read_scenario(path: str | os.PathLike[str]) -> Scenario:
    """Read and validate a scenario file; InputError naming file, line and field."""
    doc = YamlDoc.load(path)
    return _scenario(doc, Path(doc.path).read_bytes().decode("utf-8-sig"))


def _scenario(doc: YamlDoc, doc_text: str | None) -> Scenario:
    """The scenario ``doc`` (its file's text ``doc_text``; None: not from a file)."""
    doc.check_format(SCENARIO_FORMAT)
    doc.check_keys(
        [
            "format",
            "name",
            "hexapod",
            "balls",
            "plan",
            "origin_on_cmm",
            "start",
            "seed",
            "timing",
            "heating",
            "thermocouples",
            "cmm",
            "hexapod_repeatability_um",
            "output",
            "hidden_effects",
            "geometry_errors",
            "readme",
        ]
    )
    text = doc_text or ""
    name = doc.string("name", default=Path(doc.path).stem)

    hexapod_path = _existing(doc, "hexapod")
    hexapod_text = _read_text(hexapod_path)
    hexapod = read_hexapod_text(hexapod_text, str(hexapod_path))
    balls_path = _existing(doc, "balls")
    balls = read_balls(balls_path)
    plan = _plan(doc)
    inputs = ([Path(doc.path)] if doc_text is not None else []) + [hexapod_path, balls_path]
    if isinstance(doc.get("plan"), str):
        inputs.append(_existing(doc, "plan"))
    _check_stroke(doc, hexapod, plan)

    origin = tuple(
        doc.vector("origin_on_cmm", size=6, default=[450.0, 320.0, 210.0, 0.0, 0.0, 15.0])
    )
    if max(abs(v) for v in origin[:3]) > COORDINATE_MAX_MM:
        raise doc.error(
            f"frame O at {max(abs(v) for v in origin[:3]):g} mm: farther than "
            f"{COORDINATE_MAX_MM / 1e3:g} m from the CMM's origin (a value in um?)",
            "origin_on_cmm",
        )
    start = _start(doc)
    seed = _whole(doc, "seed", default=0, minimum=0)

    _mapping(doc, "timing", ["seconds_per_point", "seconds_per_move"])
    per_point = _non_negative(doc, "timing", "seconds_per_point", default=DEFAULT_SECONDS_PER_POINT)
    per_move = _non_negative(doc, "timing", "seconds_per_move", default=DEFAULT_SECONDS_PER_MOVE)

    heating = _heating(doc)
    _mapping(doc, "thermocouples", ["period_s", "noise_C"])
    period = doc.number("thermocouples", "period_s", default=30.0, positive=True)
    tc_noise = _non_negative(doc, "thermocouples", "noise_C", default=0.0)

    _mapping(doc, "cmm", ["point_noise_um", "mpe_um", "points_per_ball", "cap_angle_deg", "probe"])
    if (
        doc.get("cmm", "point_noise_um", default=None) is not None
        and doc.get("cmm", "mpe_um", default=None) is not None
    ):
        raise doc.error("give point_noise_um or mpe_um, not both", "cmm", "mpe_um")
    if doc.get("cmm", "mpe_um", default=None) is not None:
        point_noise_um = _non_negative(doc, "cmm", "mpe_um") / 2.0
    else:
        point_noise_um = _non_negative(doc, "cmm", "point_noise_um", default=0.0)
    if doc.get("cmm", "points_per_ball", default=None) is not None:
        plan = replace(plan, points_per_ball=_whole(doc, "cmm", "points_per_ball", minimum=4))
    elif plan.points_per_ball < 4:
        raise doc.error(
            f"the plan's points_per_ball ({plan.points_per_ball}) is below 4: a "
            "sphere needs at least 4 points",
            "plan",
        )
    n_points = len(plan.labels) * len(balls.names) * plan.points_per_ball
    if n_points > MAX_TOUCH_POINTS:
        given = doc.get("cmm", "points_per_ball", default=None) is not None
        raise doc.error(
            f"{len(plan.labels):,} steps x {len(balls.names)} balls x "
            f"{plan.points_per_ball:,} points = {n_points:,} touch points: at most "
            f"{MAX_TOUCH_POINTS:,}",
            *(("cmm", "points_per_ball") if given else ("plan",)),
        )
    cap = doc.number("cmm", "cap_angle_deg", default=DEFAULT_CAP_ANGLE_DEG, positive=True)
    if cap > 90.0:
        raise doc.error(
            f"a vertical probe reaches at most the upper half: must be at most 90, got {cap:g}",
            "cmm",
            "cap_angle_deg",
        )
    balls = _probe(doc, balls)

    repeatability_um = _non_negative(doc, "hexapod_repeatability_um", default=0.0)
    output = doc.string("output", default="centres")
    if output not in OUTPUT_FORMATS:
        raise doc.error(f"expected one of {', '.join(OUTPUT_FORMATS)}, got {output!r}", "output")

    model_effects = effects_from_dicts(hexapod.effects)
    hidden = _hidden_effects(doc, {e.name for e in model_effects})
    return Scenario(
        path=doc.path,
        text=text,
        name=name,
        hexapod_text=hexapod_text,
        hexapod=hexapod,
        balls=balls,
        plan=plan,
        origin_on_cmm=origin,
        start=start,
        seed=seed,
        seconds_per_point=per_point,
        seconds_per_move=per_move,
        heating=heating,
        sample_period_s=period,
        thermocouple_noise_C=tc_noise,
        point_noise_mm=point_noise_um * 1e-3,
        cap_half_angle_deg=cap,
        repeatability_mm=repeatability_um * 1e-3,
        output=output,
        model_effects=model_effects,
        hidden_effects=hidden,
        readme=doc.string("readme", default=""),
        true_parameters=_geometry_errors(doc, hexapod),
        input_files=tuple(inputs),
    )


# ---------------------------------------------------------------------- pieces
def _read_text(path: Path) -> str:
    try:
        return path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text ({exc.reason} at byte {exc.start})", path=path) from None


def _existing(doc: YamlDoc, *keys: Any) -> Path:
    target = doc.resolve(doc.string(*keys))
    if not target.is_file():
        raise doc.error(f"file not found: {target}", *keys)
    return target


def _mapping(doc: YamlDoc, key: str, allowed: list[str]) -> None:
    if doc.get(key, default=None) is not None:
        doc.check_keys(allowed, key)


def _non_negative(doc: YamlDoc, *keys: Any, default: Any = ...) -> float:
    value = doc.number(*keys, default=default)
    if value < 0:
        raise doc.error(f"must not be negative, got {value:g}", *keys)
    return value


def _whole(doc: YamlDoc, *keys: Any, default: Any = ..., minimum: int = 0) -> int:
    value = doc.number(*keys, default=default)
    if value != int(value) or value < minimum:
        raise doc.error(f"expected a whole number of at least {minimum}, got {value:g}", *keys)
    return int(value)


def _start(doc: YamlDoc) -> str:
    value = doc.get("start", default="2024-01-01T08:00:00")
    if isinstance(value, dt.datetime):  # YAML reads an unquoted timestamp as one
        value = value.isoformat()
    if not isinstance(value, str):
        raise doc.error(f"expected an ISO 8601 time, got {value!r}", "start")
    try:
        iso_to_seconds(value)
    except ValueError:
        raise doc.error(f"expected an ISO 8601 time, got {value!r}", "start") from None
    return value


def _plan(doc: YamlDoc) -> Plan:
    value = doc.get("plan")
    if isinstance(value, str):
        return read_plan(_existing(doc, "plan"))
    if not isinstance(value, dict):
        raise doc.error(
            "expected a plan file or a mapping {targets, reference_pose, cycles}", "plan"
        )
    doc.check_keys(["targets", "reference_pose", "cycles", "references", "points_per_ball"], "plan")
    items = doc.get("plan", "targets")
    if not isinstance(items, list) or not items:
        raise doc.error(
            "expected a list of target poses [Tx, Ty, Tz, Rx, Ry, Rz]", "plan", "targets"
        )
    targets = [doc.vector("plan", "targets", i, size=6) for i in range(len(items))]
    reference = doc.vector("plan", "reference_pose", size=6, default=list(DEFAULT_REFERENCE))
    cycles = _whole(doc, "plan", "cycles", default=1, minimum=1)
    layout = doc.string("plan", "references", default="both", choices=tuple(REFERENCE_LAYOUTS))
    ppb = _whole(doc, "plan", "points_per_ball", default=25, minimum=4)
    try:
        return Plan.from_steps(
            sequence_steps(
                targets, reference, cycles=cycles, reference_every=REFERENCE_LAYOUTS[layout]
            ),
            reference_pose=reference,
            points_per_ball=ppb,
        )
    except PlanError as exc:
        raise doc.error(str(exc), "plan") from None


def _check_stroke(doc: YamlDoc, hexapod: Hexapod, plan: Plan) -> None:
    outside = hexapod.check_stroke(hexapod.igm(plan.poses)).any(axis=1)
    if np.any(outside):
        i = int(np.argmax(outside))
        keys: tuple[Any, ...] = ("plan",)
        inline = doc.get("plan", "targets", default=None)
        if isinstance(inline, list) and plan.kinds[i] == "target":
            keys = ("plan", "targets", (int(plan.labels[i][1:]) - 1) % len(inline))
        raise doc.error(
            f"step {plan.labels[i]}: pose {plan.poses[i].tolist()} is outside the "
            f"hexapod's stroke {hexapod.stroke_mm.tolist()} mm",  # type: ignore[union-attr]
            *keys,
        )


def _air(doc: YamlDoc) -> tuple[tuple[float, ...], tuple[float, ...]]:
    value = doc.get("heating", "air_C", default=20.0)
    if not isinstance(value, list):
        air = doc.number("heating", "air_C", default=20.0)
        return (0.0,), (checked_temperature(doc, air, "heating", "air_C"),)
    if not value:
        raise doc.error("expected a temperature or a list of [t_s, degC]", "heating", "air_C")
    pairs = [doc.vector("heating", "air_C", i, size=2) for i in range(len(value))]
    for i, pair in enumerate(pairs):  # an ambient of 1e308 degC is a typing error
        checked_temperature(doc, pair[1], "heating", "air_C", i, 1)
        if i and pair[0] <= pairs[i - 1][0]:
            raise doc.error("times must increase", "heating", "air_C", i)
    return tuple(p[0] for p in pairs), tuple(p[1] for p in pairs)


def _heating(doc: YamlDoc) -> MatHeating:
    if doc.get("heating", default=None) is None:
        return MatHeating(mats=(Mat(),) * 6)
    doc.check_keys(["air_C", "mats"], "heating")
    air_t, air_c = _air(doc)
    items = doc.get("heating", "mats", default=None)
    if items is None:
        return MatHeating((Mat(),) * 6, air_t, air_c)
    if not isinstance(items, list) or len(items) != 6:
        raise doc.error("expected six mats (legs 1..6)", "heating", "mats")
    mats = []
    for leg in range(6):
        keys = ("heating", "mats", leg)
        doc.check_keys(["gain_C", "tau_s", "power"], *keys)
        gain = doc.number(*keys, "gain_C", default=0.0)
        tau = doc.number(*keys, "tau_s", default=2400.0, positive=True)
        periods = doc.get(*keys, "power", default=[])
        if not isinstance(periods, list):
            raise doc.error("expected a list of [on_s, off_s] (off_s null: on)", *keys, "power")
        parsed: list[tuple[float, float]] = []
        for j, period in enumerate(periods):
            if not isinstance(period, list) or len(period) != 2:
                raise doc.error("expected [on_s, off_s] (off_s null: stays on)", *keys, "power", j)
            on = doc.number(*keys, "power", j, 0)
            off = np.inf if period[1] is None else doc.number(*keys, "power", j, 1)
            if on < 0:
                raise doc.error(
                    "the mats start at t_0 or later: on_s must not be negative",
                    *keys,
                    "power",
                    j,
                    0,
                )
            if not off > on:
                raise doc.error(
                    f"off_s ({off:g}) must come after on_s ({on:g})", *keys, "power", j, 1
                )
            if parsed and on < parsed[-1][1]:
                raise doc.error("power periods must not overlap", *keys, "power", j)
            parsed.append((on, off))
        mats.append(Mat(gain_C=gain, tau_s=tau, periods=tuple(parsed)))
    return MatHeating(tuple(mats), air_t, air_c)


def _probe(doc: YamlDoc, balls: Balls) -> Balls:
    if doc.get("cmm", "probe", default=None) is None:
        return balls
    doc.check_keys(["compensated", "tip_diameter"], "cmm", "probe")
    compensated = doc.get("cmm", "probe", "compensated", default=balls.probe_compensated)
    if not isinstance(compensated, bool):
        raise doc.error(
            f"expected true or false, got {compensated!r}", "cmm", "probe", "compensated"
        )
    tip = _non_negative(doc, "cmm", "probe", "tip_diameter", default=balls.tip_diameter_mm)
    return replace(balls, probe_compensated=compensated, tip_diameter_mm=tip)


#: the keys of ``geometry_errors:`` and the scale of each to mm (or to a unit gain)
_GEOMETRY_KEYS = {
    "base_joints_um": (BASE, 18, 1e-3),
    "platform_joints_um": (PLATFORM, 18, 1e-3),
    "leg_offsets_um": (OFFSETS, 6, 1e-3),
    "leg_gains_ppm": (GAINS, 6, 1e-6),
}
_GEOMETRY_SIGMAS = {
    "joint_sigma_um": ((BASE, OFFSETS), 1e-3),
    "offset_sigma_um": ((OFFSETS, GAINS), 1e-3),
    "gain_sigma_ppm": ((GAINS, N_PARAMETERS), 1e-6),
}
#: the largest geometry error accepted, mm (a millimetre is a wrong file, not an error)
_GEOMETRY_MAX_MM = 1.0


def _geometry_errors(doc: YamlDoc, hexapod: Hexapod) -> FloatArray | None:
    """The true geometry of ``geometry_errors:`` (None without it)."""
    if doc.get("geometry_errors", default=None) is None:
        return None
    key = "geometry_errors"
    doc.check_keys(["seed", *_GEOMETRY_SIGMAS, *_GEOMETRY_KEYS], key)
    delta = np.zeros(N_PARAMETERS)
    rng = np.random.default_rng(_whole(doc, key, "seed", default=0))
    for name, ((start, stop), scale) in _GEOMETRY_SIGMAS.items():
        sigma = _non_negative(doc, key, name, default=0.0)
        delta[start:stop] += rng.normal(0.0, sigma, stop - start) * scale
    for name, (start, size, scale) in _GEOMETRY_KEYS.items():
        value = doc.get(key, name, default=None)
        if value is None:
            continue
        if size == 18:
            rows = value if isinstance(value, list) and len(value) == 6 else None
            if rows is None:
                raise doc.error("expected six [dx, dy, dz] (one per joint)", key, name)
            numbers = [doc.vector(key, name, i, size=3) for i in range(6)]
            delta[start : start + 18] += np.ravel(numbers) * scale
        else:
            delta[start : start + 6] += np.asarray(doc.vector(key, name, size=6)) * scale
    mm = np.abs(delta[:GAINS])
    if mm.size and mm.max() > _GEOMETRY_MAX_MM:
        raise doc.error(
            f"an error of {mm.max():g} mm: at most {_GEOMETRY_MAX_MM:g} mm (um expected)", key
        )
    return nominal_parameters(hexapod) + delta


def _hidden_effects(doc: YamlDoc, model: set[str]) -> tuple[Effect, ...]:
    items = doc.get("hidden_effects", default=[])
    if items is None:
        return ()
    if not isinstance(items, list):
        raise doc.error("expected a list of {name, parameters}", "hidden_effects")
    effects: list[Effect] = []
    for i in range(len(items)):
        keys = ("hidden_effects", i)
        doc.check_keys(["name", "parameters"], *keys)
        name = doc.string(*keys, "name", choices=tuple(EFFECTS))
        if name in model:
            raise doc.error(f"the hexapod file's thermal model already has {name}", *keys, "name")
        if any(e.name == name for e in effects):
            raise doc.error(f"{name} is given twice", *keys, "name")
        cls = EFFECTS[name]
        doc.check_keys(cls.parameters, *keys, "parameters")
        values = {p: doc.number(*keys, "parameters", p) for p in cls.parameters}
        effect = cls(**values)
        for p, problem in effect.out_of_range().items():
            raise doc.error(problem, *keys, "parameters", p)
        effects.append(effect)
    return tuple(effects)
