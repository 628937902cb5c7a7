"""The hexapod file (``hexatherm-hexapod/1``): geometry, leg thermal model, effects."""

from __future__ import annotations

import os
import re
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.core.geometry import CONVENTIONS
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.thermal import LegThermalModel, SegmentSpec
from hexatherm.io.config.yamlout import _dump
from hexatherm.io.csvcolumns import ISO_TIME
from hexatherm.io.temperatures import TEMPERATURE_RANGE_C
from hexatherm.io.yamlfile import YamlDoc

HEXAPOD_FORMAT = "hexatherm-hexapod/1"


def __getattr__(name: str) -> Any:
    """``EFFECT_PARAMETERS``: effect names and parameters (spec: "The hexapod twin and
    its effects"), from the one registry of effects that the twin and the diagnosis use;
    made on first use, so that reading a hexapod file without effects does not load
    that registry (30 kB of source compiled at each start of ``process``)."""
    if name == "EFFECT_PARAMETERS":
        from hexatherm.core.effects import EFFECTS

        return {key: tuple(cls.parameters) for key, cls in EFFECTS.items()}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: coefficients of thermal expansion accepted in a leg model, 1/K (invar to plastics; a
#: value in ppm/K, 23 for 23e-6, is refused)
CTE_RANGE_PER_K = (-1e-4, 1e-3)


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


#: the zero pose's Jacobian of a hexapod file is refused below this reciprocal condition
#: number (the shipped hexapods' is 0.25; joints in one plane give 1e-17)
DEGENERATE_RCOND = 1e-9


def checked_temperature(doc: YamlDoc, value: float, *keys: Any) -> float:
    """``value`` (degC) if within :data:`TEMPERATURE_RANGE_C`, else an InputError."""
    low, high = TEMPERATURE_RANGE_C
    if not low <= value <= high:
        hint = " (looks like kelvin: the file is in degC)" if 200 <= value <= 450 else ""
        raise doc.error(
            f"a temperature must be within [{low:g}, {high:g}] degC, got {value:g}{hint}", *keys
        )
    return value


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
            "calibration",
        ]
    )
    _check_calibration(doc)
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
        fixed = float(legs.total_fixed_length_mm[leg])
        # 3 decimals of a mm, but not the 300 digits of a length of 1e300
        fixed_text = f"{fixed:.3f}" if abs(fixed) < 1e9 else f"{fixed:.6g}"
        raise doc.error(
            f"leg {leg + 1}: the fixed segments ({fixed_text} mm) are "
            f"longer than the leg in the zero pose ({q0[leg]:.3f} mm)",
            "legs",
        )
    if stroke is not None and np.any(hexapod.check_stroke(q0)):
        raise doc.error(
            f"the zero pose leg lengths {q0.round(3).tolist()} are outside the stroke", "stroke"
        )
    singular = np.linalg.svd(hexapod.jacobian(np.zeros(6))[0], compute_uv=False)
    if not singular[-1] > DEGENERATE_RCOND * singular[0]:  # joints in one plane, a line
        raise doc.error(
            "the joints make no hexapod: the legs do not hold the platform in the zero pose "
            f"(reciprocal condition number of the Jacobian {singular[-1] / singular[0]:.1e}; "
            "joints in one plane or on one line?)",
            "platform_joints",
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
    t_ref = checked_temperature(
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
    if items:
        from hexatherm.core.effects import EFFECTS, make_effect
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


#: the keys of a hexapod file's ``calibration:`` record (an extension) and their kinds
CALIBRATION_KEYS = {
    "level": "level",
    "poses": "poses",
    "sessions": "texts",
    "n_poses": "whole",
    "twin_model": "text",
    "twin_model_sha256": "sha256",
    "leg_offsets_mm": "six",
    "leg_gains": "six",
    "chi_square_per_dof": "number",
    "hexatherm": "text",
    "written": "time",
}
#: what a calibration record's ``level`` may be: :data:`hexatherm.core.calibration.LEVELS`
#: (not imported: the calibration package's import costs seconds; a test checks they agree)
CALIBRATION_LEVELS = ("offsets", "joints", "joints+gains")
#: what a calibration record's ``poses`` may be (``hexatherm calibrate --poses``)
CALIBRATION_POSES = ("corrected", "conventional", "twin")
_SHA256 = re.compile(r"[0-9a-f]{64}")


def _check_calibration(doc: YamlDoc) -> None:
    """The optional ``calibration:`` record that ``hexatherm calibrate`` writes: where
    the geometry came from, and the actuators' offsets and gains (for the controller;
    the joints above are what the IGM and FGM use). Checked, not used."""
    key = "calibration"
    if doc.get(key, default=None) is None:
        return
    doc.check_keys(list(CALIBRATION_KEYS), key)
    record = doc.get(key)
    for name, kind in CALIBRATION_KEYS.items():
        if name not in record:
            continue
        if kind == "text":
            doc.string(key, name)
        elif kind == "level":
            doc.string(key, name, choices=CALIBRATION_LEVELS)
        elif kind == "poses":
            doc.string(key, name, choices=CALIBRATION_POSES)
        elif kind == "sha256":
            if not _SHA256.fullmatch(doc.string(key, name)):
                raise doc.error("expected a SHA-256: 64 hexadecimal digits", key, name)
        elif kind == "time":
            _check_written(doc, key, name)
        elif kind == "texts":
            items = doc.get(key, name)
            if not isinstance(items, list) or not all(isinstance(i, str) for i in items):
                raise doc.error("expected a list of texts", key, name)
        elif kind == "six":
            doc.vector(key, name, size=6)
        elif kind == "whole":
            value = doc.number(key, name)
            if value != int(value) or value < 1:
                raise doc.error(f"expected a whole number >= 1, got {value:g}", key, name)
        elif doc.number(key, name) < 0:
            raise doc.error("must not be negative", key, name)


def _check_written(doc: YamlDoc, *keys: str) -> None:
    """An ISO 8601 time with its UTC offset (as ``calibrate`` writes it), a valid date."""
    value = doc.get(*keys)
    text = value.isoformat() if isinstance(value, datetime) else value
    match = ISO_TIME.fullmatch(text) if isinstance(text, str) else None
    if match is None or match.group("offset") is None:
        raise doc.error(
            "expected an ISO 8601 time with its UTC offset (YYYY-MM-DDTHH:MM[:SS[.ffffff]]"
            f"+HH:MM), got {value!r}",
            *keys,
        )
    try:
        datetime.fromisoformat(text)
    except ValueError as exc:
        raise doc.error(f"not a valid date and time: {value!r} ({exc})", *keys) from None


def hexapod_to_yaml(hexapod: Hexapod, calibration: dict[str, Any] | None = None) -> str:
    """The hexapod file text of ``hexapod`` (reads back to the same model), with a
    ``calibration:`` record when given (keys of :data:`CALIBRATION_KEYS`)."""
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
    if calibration:
        doc["calibration"] = dict(calibration)
    return _dump(doc)
