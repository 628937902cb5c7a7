"""The session file (``hexatherm-session/1``): files, quality limits, CMM noise, pose check."""

from __future__ import annotations

import dataclasses
import os
import warnings
from pathlib import Path
from typing import Any

from hexatherm.errors import InputWarning
from hexatherm.io.config.balls import read_balls
from hexatherm.io.config.hexapod import read_hexapod
from hexatherm.io.config.identity import (
    IDENTIFICATION_KEYS,
    read_identification,
    read_tolerances,
)
from hexatherm.io.config.plan import read_plan
from hexatherm.io.config.tablemap import read_format, read_utc_offset
from hexatherm.io.config.yamlout import _dump
from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import (
    QUALITY_ALIASES,
    CmmNoise,
    MeasurementFormat,
    QualityLimits,
    Session,
    Tolerance,
)

SESSION_FORMAT = "hexatherm-session/1"


def read_session(path: str | os.PathLike[str]) -> Session:
    """Read a session file, or the ``session.yaml`` of a session folder, and its configs."""
    path = Path(path)
    if path.is_dir():
        _check_session_folder(path)
        path = path / "session.yaml"
    doc = YamlDoc.load(path)
    _check_session_format(doc)
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
            "utc_offset",
            "identification",
            "tolerances",
            "feature_names",
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

    config_files = (existing("hexapod"), existing("balls"), existing("plan"))
    hexapod = read_hexapod(config_files[0])
    balls = read_balls(config_files[1])
    plan = read_plan(config_files[2])
    files = doc.get("measurements")
    if isinstance(files, str):
        raise doc.error("expected a list of files, e.g. [centres.csv]", "measurements")
    if not isinstance(files, list) or not files:
        raise doc.error("expected a non-empty list of measurement files", "measurements")
    measurements, formats, inside = _measurements(doc, files, balls.names, existing)
    temperatures = None
    if doc.get("temperatures", default=None) is not None:
        temperatures = existing("temperatures")
    ident: dict[str, Any] = {}
    if doc.get("identification", default=None) is not None:
        doc.check_keys(list(IDENTIFICATION_KEYS), "identification")
        ident = read_identification(doc, "identification")
    tolerances: dict[str, Tolerance] = {}
    if doc.get("tolerances", default=None) is not None:
        tolerances = read_tolerances(doc, "tolerances")
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
        config_files,
        _read_utc_offset(doc),
        ident,
        tolerances,
        formats,
        inside,
        _read_feature_names(doc),
    )


#: formats of hexatherm's other files -> what the file is, for a message
_OTHER_FORMATS = {
    "hexatherm-plan/1": "a plan file",
    "hexatherm-hexapod/1": "a hexapod file",
    "hexatherm-balls/1": "a balls file",
    "hexatherm-datums/1": "a datums file (for register)",
    "hexatherm-lab/1": "a lab file (for --lab)",
    "hexatherm-scenario/1": "a scenario (hexatherm simulate makes a session of it)",
}


def _check_session_folder(folder: Path) -> None:
    """A folder without ``session.yaml``: say what it looks like (a results folder ...)."""
    from hexatherm.errors import InputError

    if (folder / "session.yaml").exists():
        return
    session = next((p for p in folder.parents if (p / "session.yaml").is_file()), None)
    where = f"; its session is {session}" if session is not None else ""
    if (folder / "poses.csv").is_file():
        what = "a results folder (poses.csv: hexatherm process's output), not a session"
    elif (folder / "calibration.json").is_file():
        what = "a calibration output folder (hexatherm calibrate's), not a session"
    else:
        what = "not a session folder: no session.yaml in it"
    raise InputError(f"{what}{where}", path=folder)


def _check_session_format(doc: YamlDoc) -> None:
    """``format:`` must be the session's; another hexatherm file is named as what it is."""
    value = doc.get("format", default=None)
    if isinstance(value, str) and value in _OTHER_FORMATS:
        raise doc.error(
            f"this is {_OTHER_FORMATS[value]} ({value}), not a session file: give the "
            "session folder or its session.yaml",
            "format",
        )
    doc.check_format(SESSION_FORMAT)


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


def _read_utc_offset(doc: YamlDoc) -> float | None:
    """The optional ``utc_offset:`` of a session file, in seconds east of UTC."""
    return read_utc_offset(doc, "utc_offset")


def _measurements(
    doc: YamlDoc,
    files: list[Any],
    ball_names: tuple[str, ...],
    existing: Any,
) -> tuple[tuple[Path, ...], dict[Path, MeasurementFormat], tuple[Path, ...]]:
    """The ``measurements:`` entries: each a file name (hexatherm's CSV or DMIS) or a
    mapping (a table through a column map, a folder of Calypso runs: an extension).
    Returns the paths, the formats of the mapped ones, and the files inside folders."""
    paths: list[Path] = []
    formats: dict[Path, MeasurementFormat] = {}
    inside: list[Path] = []
    for i, entry in enumerate(files):
        if not isinstance(entry, dict):
            paths.append(existing("measurements", i))
            continue
        spec = read_format(doc, i, ball_names)
        target = doc.resolve(doc.string("measurements", i, "file"))
        if spec.kind == "calypso":
            if not target.is_dir():
                raise doc.error(
                    f"not a folder: {target} (format: calypso reads a folder of "
                    "<name>_chr.txt and <name>_hdr.txt runs)",
                    "measurements",
                    i,
                    "file",
                )
            runs = sorted(target.glob("*_chr.txt"))
            inside += [p for r in runs for p in _run_files(r)]
        elif not target.is_file():
            raise doc.error(f"file not found: {target}", "measurements", i, "file")
        if target in formats:
            raise doc.error(f"{target.name} is given twice", "measurements", i, "file")
        paths.append(target)
        formats[target] = spec
    return tuple(paths), formats, tuple(inside)


def _run_files(chr_file: Path) -> list[Path]:
    """A Calypso run's files that exist: ``_chr``, ``_hdr``, ``_fet``."""
    stem = chr_file.name[: -len("_chr.txt")]
    files = (chr_file.parent / f"{stem}_{kind}.txt" for kind in ("chr", "hdr", "fet"))
    return [p for p in files if p.is_file()]


def read_feature_names(path: str | os.PathLike[str]) -> dict[str, str | None]:
    """The ``feature_names:`` map of a session file (or folder) alone, the rest of it
    unchecked (for ``inspect --session``)."""
    path = Path(path)
    doc = YamlDoc.load(path / "session.yaml" if path.is_dir() else path)
    _check_session_format(doc)
    return _read_feature_names(doc)


def _read_feature_names(doc: YamlDoc) -> dict[str, str | None]:
    """The optional ``feature_names:`` of a session file: a CMM's feature name (as its QIF
    results file gives it) -> hexatherm's ``<step>_<ball>``, or null to read it past."""
    names = doc.get("feature_names", default=None)
    if names is None:
        return {}
    from hexatherm.io.qifrecords import STEP_BALL

    if not isinstance(names, dict) or not names:
        raise doc.error(
            "expected a mapping of feature names to <step>_<ball> (or null), "
            "e.g. {'Kugel 1 Pos 0': O_B1}",
            "feature_names",
        )
    out: dict[str, str | None] = {}
    for key, value in names.items():
        if not isinstance(key, str):
            raise doc.error(f"a feature name must be text (quote it), got {key!r}", "feature_names")
        if value is not None and not (isinstance(value, str) and STEP_BALL.fullmatch(value)):
            raise doc.error(
                f"expected <step>_<ball> (each part [A-Za-z0-9-]+) or null, got {value!r}",
                "feature_names",
                key,
            )
        out[key] = value
    return out


def _read_quality(doc: YamlDoc) -> dict[str, float]:
    """The optional ``quality:`` mapping of a session file: check name -> limit (>= 0;
    ``.inf`` turns a check off, as does 0 for ``min_rcond``)."""
    if doc.get("quality", default=None) is None:
        return {}
    names = [f.name for f in dataclasses.fields(QualityLimits)]
    doc.check_keys([*names, *QUALITY_ALIASES], "quality")
    limits = {}
    for name in doc.get("quality"):
        value = doc.get("quality", name)
        if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 0:
            raise doc.error(
                f"expected a number >= 0 (.inf turns the check off), got {value!r}", "quality", name
            )
        if name == "min_rcond" and value > 1:
            raise doc.error(
                f"a reciprocal condition number is at most 1, got {value!r} (it would fail "
                "every target; 0 turns the check off)",
                "quality",
                name,
            )
        if name in QUALITY_ALIASES:
            new, factor = QUALITY_ALIASES[name]
            if new in doc.get("quality"):
                raise doc.error(
                    f"give {new} or {name} (its half, of old), not both", "quality", name
                )
            warnings.warn(
                InputWarning(
                    f"{doc.path}:{doc.line('quality', name)}: quality.{name} is a radius limit; "
                    f"read as {new}: {float(value) * factor:g} (the check compares diameters now)"
                ),
                stacklevel=2,
            )
            name, value = new, float(value) * factor
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
    stated = doc.get("cmm", "cap_angle_deg", default=None) is not None
    return CmmNoise(sigma, points, cap, stated)


def session_to_yaml(
    name: str,
    hexapod: str,
    balls: str,
    plan: str,
    measurements: list[str],
    temperatures: str | None = None,
    cmm: dict[str, float] | None = None,
    utc_offset: str | None = None,
) -> str:
    """The session file text (paths relative to the session file).

    ``cmm`` is the optional ``cmm:`` mapping, e.g. ``{"mpe_um": 1.0}``; ``utc_offset``
    the optional offset of the files' naive times, e.g. ``"+00:00"``.
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
    if utc_offset is not None:
        doc["utc_offset"] = utc_offset
    if cmm:
        doc["cmm"] = dict(cmm)
    return _dump(doc)
