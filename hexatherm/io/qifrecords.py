"""The records of what the QIF reader read (:mod:`hexatherm.io.qif`): a centre per sphere
given by its Location, the points of a sphere given by measured points."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.records import Records, iso_to_seconds
from hexatherm.typing import FloatArray, IntArray

_FRACTION = re.compile(r"(\.\d{6})\d+")
#: hexatherm's feature names: ``<step>_<ball>``, each part ``[A-Za-z0-9-]+`` (as in DMIS)
STEP_BALL = re.compile(r"([A-Za-z0-9-]+)_([A-Za-z0-9-]+)")


@dataclass
class Sphere:
    """One sphere feature measurement, as read (lengths in mm)."""

    line: int
    name: str
    step: str
    ball: str
    xyz_mm: tuple[float, float, float] | None
    diameter_mm: float
    time: str | None
    u_mm: tuple[float, float, float] | None = None
    u_combined_mm: float = math.nan
    point_sets: list[tuple[str, int, int | None, int]] = field(default_factory=list)
    points: int = 0


def sphere_records(
    path: str, spheres: list[Sphere], point_sets: Mapping[str, tuple[FloatArray, IntArray]]
) -> list[Records]:
    """The centres records of the spheres without points and the points records of those
    with, from what :mod:`hexatherm.io.qif` read (InputError naming file, line and element)."""
    spheres = [s for s in spheres if s.step]  # those named (inspect keeps the others)
    centres = [s for s in spheres if not s.point_sets]
    pointed = [s for s in spheres if s.point_sets]
    times = {s.time for s in spheres if s.time is not None}
    aware = {_aware(t) for t in times}
    if len(aware) > 1:
        first = next(s for s in spheres if s.time is not None and _aware(s.time))
        raise InputError(
            "times with a UTC offset and times without one in one file: naive times "
            "would be taken as UTC; give every TimeStamp an offset or none",
            path=path,
            line=first.line,
            field="TimeStamp",
        )
    time_aware = aware.pop() if aware else None
    out: list[Records] = []
    if centres:
        out.append(_centre_records(path, centres, time_aware))
    if pointed:
        out.append(_point_records(path, pointed, point_sets, time_aware))
    return out


def _seconds(path: str, sphere: Sphere) -> float:
    """POSIX seconds of a sphere's time (naive: taken as UTC, as every reader does)."""
    text = _FRACTION.sub(r"\1", sphere.time or "").replace("Z", "+00:00")
    try:
        return iso_to_seconds(text)
    except ValueError:
        raise InputError(
            f"not an xs:dateTime: {sphere.time!r}",
            path=path,
            line=sphere.line,
            field="TimeStamp",
        ) from None


def _centre_records(path: str, spheres: list[Sphere], aware: bool | None) -> Records:
    extra: dict[str, object] = {}
    if any(s.u_mm is not None for s in spheres):
        u = np.array([s.u_mm or (math.nan,) * 3 for s in spheres], dtype=np.float64)
        cov = np.zeros((len(spheres), 3, 3))
        cov[:, [0, 1, 2], [0, 1, 2]] = u**2
        extra["cov_centre_mm2"] = cov
        extra["cov_from_file"] = ~np.isnan(u[:, 0])
    combined = np.array([s.u_combined_mm for s in spheres], dtype=np.float64)
    if not np.all(np.isnan(combined)):
        extra["u_um"] = combined * 1e3
    return Records(
        path=path,
        kind="centres",
        label=np.array([s.step for s in spheres], dtype=np.str_),
        ball=np.array([s.ball for s in spheres], dtype=np.str_),
        xyz_mm=np.array([s.xyz_mm for s in spheres], dtype=np.float64).reshape(-1, 3),
        time_s=np.array([_seconds(path, s) for s in spheres], dtype=np.float64),
        time_kind="iso",
        line=np.array([s.line for s in spheres], dtype=np.int64),
        diameter_mm=np.array([s.diameter_mm for s in spheres], dtype=np.float64),
        extra=extra,
        time_aware=aware,
    )


def _point_records(
    path: str,
    spheres: list[Sphere],
    point_sets: Mapping[str, tuple[FloatArray, IntArray]],
    aware: bool | None,
) -> Records:
    """The points of the spheres, as arrays made per sphere and per range of a point set
    (no Python object per point: a scanning session has millions)."""
    xyz: list[np.ndarray] = []
    line: list[np.ndarray] = []
    ranges: list[tuple[str, int, int]] = []  # (set id, first, last) of each PointList entry
    counts: list[int] = []
    seconds: list[float] = []
    for sphere in spheres:
        seconds.append(_seconds(path, sphere))
        count = 0
        for set_id, first, last, ref_line in sphere.point_sets:
            if set_id not in point_sets:
                raise InputError(
                    f"sphere {sphere.name!r} points at MeasuredPointSet {set_id!r}, "
                    "which the results do not hold",
                    path=path,
                    line=ref_line,
                    field="PointList",
                )
            values, lines = point_sets[set_id]
            stop = len(values) if last is None else last
            if not 1 <= first <= stop <= len(values):
                raise InputError(
                    f"points {first} to {stop} of MeasuredPointSet {set_id!r}, which "
                    f"holds {len(values)}",
                    path=path,
                    line=ref_line,
                    field="PointList",
                )
            xyz.append(values[first - 1 : stop])
            line.append(lines[first - 1 : stop])
            ranges.append((set_id, first, stop))
            count += stop - first + 1
        sphere.points = count
        counts.append(count)
    per_sphere = np.array(counts, dtype=np.int64)
    n = int(per_sphere.sum())
    return Records(
        path=path,
        kind="points",
        label=np.repeat(np.array([s.step for s in spheres], dtype=np.str_), per_sphere),
        ball=np.repeat(np.array([s.ball for s in spheres], dtype=np.str_), per_sphere),
        xyz_mm=np.concatenate(xyz).reshape(-1, 3),
        time_s=np.repeat(np.array(seconds, dtype=np.float64), per_sphere),
        time_kind="iso",
        line=np.concatenate(line).astype(np.int64),
        ijk=np.full((n, 3), math.nan),
        extra={"n": _point_numbers(ranges)},
        time_aware=aware,
    )


def _point_numbers(ranges: list[tuple[str, int, int]]) -> np.ndarray:
    """``<set id>-<index>`` of every point of the ranges ``(set id, first, last)``, as
    ``np.array`` of those strings gives them (the same width).

    >>> _point_numbers([("7", 1, 3), ("12", 9, 10)]).tolist()
    ['7-1', '7-2', '7-3', '12-9', '12-10']
    """
    sizes = np.array([last - first + 1 for _, first, last in ranges], dtype=np.int64)
    starts = np.array([first for _, first, _ in ranges], dtype=np.int64)
    ends = np.cumsum(sizes)
    index = np.arange(int(ends[-1]), dtype=np.int64) - np.repeat(ends - sizes - starts, sizes)
    prefix = np.repeat(np.array([f"{set_id}-" for set_id, _, _ in ranges], dtype=np.str_), sizes)
    digits = len(str(max(last for _, _, last in ranges)))
    width = max(len(set_id) + 1 + len(str(last)) for set_id, _, last in ranges)
    numbers = np.char.add(prefix, index.astype(f"<U{digits}"))
    return numbers.astype(f"<U{width}", copy=False)


def _aware(text: str) -> bool:
    return text.endswith("Z") or re.search(r"[+-]\d\d:\d\d$", text) is not None
