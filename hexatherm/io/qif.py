"""QIF 3 results (ANSI/DMSC QIF 3.0, ISO 23952): the sphere features a CMM measured.

What is read from a ``QIFDocument`` (docs/formats.md section 7.6):

* ``FileUnits/PrimaryUnits/LinearUnit``: the length unit (``UnitName``, and its
  ``UnitConversion`` to metres when given); every length is converted to mm;
* ``Features/FeatureItems/SphereFeatureItem``: the feature's name (required there), for
  the measurements that name their item by ``FeatureItemId``;
* ``Results/MeasurementResultsSet/MeasurementResults/MeasuredFeatures/SphereFeatureMeasurement``:
  the centre (``Location``, with its per-axis or combined uncertainty when stated), the
  diameter, the time (``TimeStamp``, else the results' ``InspectionTraceability/
  InspectionStart``), the name (``FeatureName``, else its item's) and
  the measured points (``PointList``, pointing into ``MeasuredPointSets``);
* the name is mapped to hexatherm's step and ball: by a map (session.yaml's
  ``feature_names``) when it names the feature, else by hexatherm's ``<step>_<ball>``.

A sphere with measured points gives points records (fitted as a points file is); one
without gives a centre. Every element read is validated against the shipped QIF 3.0
schema where it lies (:func:`~hexatherm.io.qifschema.check_element`); the file is parsed
safely in a stream (:func:`~hexatherm.io.qifschema.iter_elements`). Everything else in
the file (product definition, characteristics, other features) is read past.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.csvfile import U_UM_MAX
from hexatherm.io.files import MAX_MEASUREMENT_BYTES
from hexatherm.io.qifrecords import STEP_BALL, Sphere, sphere_records
from hexatherm.io.qifschema import QIF_NS, check_element, iter_elements, local_name
from hexatherm.io.records import Records, check_groups
from hexatherm.typing import FloatArray, IntArray

#: File suffixes taken as QIF whatever the content (any case)
QIF_SUFFIXES = (".qif",)
#: mm per unit of the length units known by name (``UnitName``, any case)
LENGTH_UNITS_MM = {
    "mm": 1.0,
    "millimeter": 1.0,
    "millimetre": 1.0,
    "cm": 10.0,
    "centimeter": 10.0,
    "m": 1000.0,
    "meter": 1000.0,
    "metre": 1000.0,
    "um": 1e-3,
    "micrometer": 1e-3,
    "micron": 1e-3,
    "in": 25.4,
    "inch": 25.4,
    "ft": 304.8,
    "foot": 304.8,
    "feet": 304.8,
}
_QIF_ROOT = re.compile(rb"<(?:[A-Za-z_][\w.-]*:)?QIFDocument[\s/>]")
#: The elements read whole: nothing inside them is dropped before they end
_WHOLE = frozenset(
    (
        "FileUnits",
        "SphereFeatureMeasurement",
        "MeasuredPointSet",
        "SphereFeatureItem",
        "InspectionTraceability",
    )
)
_CONTAINERS = {
    "SphereFeatureMeasurement": "MeasuredFeatures",
    "MeasuredPointSet": "MeasuredPointSets",
    "SphereFeatureItem": "FeatureItems",
}


def looks_like_qif(head: bytes) -> bool:
    """Whether the first bytes of a file open a QIF document (root element QIFDocument).

    >>> looks_like_qif(b'<?xml version="1.0"?>\\n<QIFDocument xmlns="x" versionQIF="3.0.0">')
    True
    >>> looks_like_qif(b"label,ball,x,y,z,time")
    False
    """
    return head.lstrip().startswith(b"<") and _QIF_ROOT.search(head) is not None


@dataclass
class QifRead:
    """What a QIF results file held: the records and, for ``inspect``, what was read.

    Attributes
    ----------
    records : list of Records
        Centres (spheres without points) and points (spheres with points).
    unit : str
        The file's length unit as it names it, and in mm (``'inch (25.4 mm)'``).
    spheres : list of Sphere
        Every sphere measurement mapped to a step and ball, in file order.
    skipped : list of (int, str)
        Line and name of the spheres the map reads past (mapped to nothing).
    others : dict of str to int
        How many feature measurements of other types were read past, by type.
    """

    records: list[Records]
    unit: str
    spheres: list[Sphere]
    skipped: list[tuple[int, str]]
    others: dict[str, int]


def read_qif(
    path: str | os.PathLike[str],
    *,
    names: Mapping[str, str | None] | None = None,
    keep_later: bool = False,
    limit: int = MAX_MEASUREMENT_BYTES,
) -> list[Records]:
    """The measurement records of a QIF 3 results file (see the module's notes).

    Parameters
    ----------
    path : str or path-like
        The QIF file.
    names : mapping of str to str or None, optional
        Feature name to hexatherm's ``<step>_<ball>``, or to None to read the feature
        past (session.yaml's ``feature_names``); a name not in it must follow
        ``<step>_<ball>``.
    keep_later : bool, optional
        As for the CSV reader: a ball measured twice in one step keeps the later.
    limit : int, optional
        The largest file read, bytes.

    Raises
    ------
    InputError
        In one line naming the file, the line and the element: not a QIF document, not
        results, a DTD, broken or truncated XML, an element that breaks the schema, an
        unknown or contradictory length unit, a sphere without a name, a name off the
        map and off hexatherm's naming, a sphere without a time, a centre or points
        missing.
    """
    return scan_qif(path, names=names, keep_later=keep_later, limit=limit).records


def scan_qif(
    path: str | os.PathLike[str],
    *,
    names: Mapping[str, str | None] | None = None,
    keep_later: bool = False,
    limit: int = MAX_MEASUREMENT_BYTES,
    unmapped: bool = False,
) -> QifRead:
    """As :func:`read_qif`, with what was read beside the records (for ``inspect``).

    ``unmapped``: a sphere whose name is off the map and off ``<step>_<ball>`` is kept in
    :attr:`QifRead.spheres` with an empty step and ball (and left out of the records)
    instead of being refused: ``inspect`` lists a file before its names are mapped."""
    return _Reader(os.fspath(path), names or {}, unmapped).read(keep_later, limit)


class _Reader:
    """The state of one streamed read."""

    def __init__(self, path: str, names: Mapping[str, str | None], unmapped: bool) -> None:
        self.path = path
        self.names = names
        self.unmapped = unmapped
        self.mm_per_unit: float | None = None
        self.units_mm: dict[str, float] = {}
        self.unit = "not stated"
        self.item_names: dict[str, str | None] = {}
        self.spheres: list[Sphere] = []
        self.skipped: list[tuple[int, str]] = []
        self.others: dict[str, int] = {}
        self.wanted: set[str] = set()
        self.point_sets: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.results_seen = False
        self.results_start: str | None = None
        self.untimed: list[tuple[Sphere, str | None]] = []
        self.mr_start: str | None = None

    def read(self, keep_later: bool, limit: int) -> QifRead:
        depth = hold = 0
        root_line = 1
        for event, element in iter_elements(self.path, limit=limit):
            if event == "start":
                depth += 1
                if depth == 1:
                    root_line = element.sourceline or 1
                    self._check_root(element)
                elif local_name(element) == "MeasurementResults":
                    self.mr_start = None
                hold += local_name(element) in _WHOLE
                continue
            self._end(element)
            hold -= local_name(element) in _WHOLE
            parent = element.getparent()
            if hold == 0 and (
                depth == 2 or (depth <= 6 and parent is not None and parent.get("n"))
            ):
                # an item of a QIF list (their parents count them: n="..."), or a child
                # of the root: read by now, dropped so that memory stays bounded
                element.clear(keep_tail=False)
                while element.getprevious() is not None:
                    del parent[0]
            depth -= 1
        if not self.results_seen:
            raise InputError(
                "a QIF document without Results (a plan or a product definition?): "
                "hexatherm reads measured features from QIF results",
                path=self.path,
                line=root_line,
                field="QIFDocument",
            )
        for sphere, start in self.untimed:
            sphere.time = start or self.results_start
            if sphere.time is None:
                raise InputError(
                    f"sphere {sphere.name!r} has no TimeStamp, and its results no "
                    "InspectionTraceability/InspectionStart: hexatherm needs each ball's time",
                    path=self.path,
                    line=sphere.line,
                    field="TimeStamp",
                )
        records = [
            check_groups(r, keep_later=keep_later)
            for r in sphere_records(self.path, self.spheres, self.point_sets)
        ]
        for sphere in self.spheres:  # the unnamed ones inspect lists: their point counts
            if not sphere.step:
                sphere.points = sum(
                    (len(self.point_sets.get(set_id, ())) if last is None else last) - first + 1
                    for set_id, first, last, _ in sphere.point_sets
                )
        return QifRead(records, self.unit, self.spheres, self.skipped, self.others)

    # -- the elements read ---------------------------------------------------------

    def _check_root(self, element: Any) -> None:
        if element.tag != f"{{{QIF_NS}}}QIFDocument":
            raise InputError(
                f"not a QIF 3 document: its root element is {element.tag!r}, expected "
                f"QIFDocument in namespace {QIF_NS}",
                path=self.path,
                line=element.sourceline,
                field=local_name(element) or "root",
            )

    def _end(self, element: Any) -> None:
        name = local_name(element)
        parent = element.getparent()
        within = local_name(parent) if parent is not None else ""
        if name in _CONTAINERS and within != _CONTAINERS[name]:
            return
        if name == "FileUnits" and within == "QIFDocument":
            check_element(element, self.path)
            self._units(element)
        elif name == "SphereFeatureItem":
            check_element(element, self.path)
            self.item_names[element.get("id", "")] = _child_text(element, "FeatureName")
        elif name == "Results" and within == "QIFDocument":
            self.results_seen = True
        elif name == "InspectionTraceability" and within in ("Results", "MeasurementResults"):
            start = _child_text(element, "InspectionStart")
            if within == "Results":
                self.results_start = start
            else:
                self.mr_start = start
        elif name == "SphereFeatureMeasurement":
            check_element(element, self.path)
            self._sphere(element)
        elif name.endswith("FeatureMeasurement") and within == "MeasuredFeatures":
            self.others[name] = self.others.get(name, 0) + 1
        elif name == "MeasuredPointSet" and element.get("id") in self.wanted:
            check_element(element, self.path)
            self._point_set(element)

    def _units(self, element: Any) -> None:
        primary = _find(element, "PrimaryUnits", "LinearUnit")
        if primary is None:
            return
        for linear in element.iter(f"{{{QIF_NS}}}LinearUnit"):
            unit = _child_text(linear, "UnitName") or ""
            self.units_mm[unit.lower()] = self._unit_mm(linear, unit)
        unit = _child_text(primary, "UnitName") or ""
        self.mm_per_unit = self.units_mm[unit.lower()]
        self.unit = f"{unit} ({self.mm_per_unit:g} mm)"

    def _unit_mm(self, linear: Any, unit: str) -> float:
        """mm per ``unit``, declared by a LinearUnit of FileUnits."""
        known = LENGTH_UNITS_MM.get(unit.lower())
        conversion = _find(linear, "UnitConversion")
        line = linear.sourceline
        if conversion is None:
            if known is None:
                raise InputError(
                    f"unknown length unit {unit!r} without a UnitConversion (known: "
                    f"{', '.join(sorted(LENGTH_UNITS_MM))})",
                    path=self.path,
                    line=line,
                    field="UnitName",
                )
            return known
        si = (_child_text(linear, "SIUnitName") or "meter").lower()
        factor = float(_child_text(conversion, "Factor") or "nan")
        offset = float(_child_text(conversion, "Offset") or "0")
        if si not in ("meter", "metre", "m") or offset != 0:
            raise InputError(
                f"length unit {unit!r} converted to {si!r} with offset {offset:g}: expected "
                "metres and no offset",
                path=self.path,
                line=line,
                field="UnitConversion",
            )
        mm = factor * 1000.0
        if known is not None and not math.isclose(mm, known, rel_tol=1e-6):
            raise InputError(
                f"unit {unit!r} converted by factor {factor:g} to metres, but a {unit} is "
                f"{known / 1000:g} m: the file contradicts itself",
                path=self.path,
                line=line,
                field="Factor",
            )
        return mm

    def _scale(self, element: Any) -> float:
        """mm per unit of a length element (its ``linearUnit`` or the file's)."""
        unit = element.get("linearUnit")
        if unit is not None:
            known = self.units_mm.get(unit.lower(), LENGTH_UNITS_MM.get(unit.lower()))
            if known is None:
                raise InputError(
                    f"unknown linearUnit {unit!r}",
                    path=self.path,
                    line=element.sourceline,
                    field=local_name(element),
                )
            return known
        if self.mm_per_unit is None:
            raise InputError(
                "the file states no length unit (no FileUnits/PrimaryUnits/LinearUnit) "
                "before its first length",
                path=self.path,
                line=element.sourceline,
                field=local_name(element),
            )
        return self.mm_per_unit

    def _sphere(self, element: Any) -> None:
        line = element.sourceline
        name = self._name(element)
        target = self.names[name] if name in self.names else name
        if target is None:
            self.skipped.append((line, name))
            return
        match = STEP_BALL.fullmatch(target)
        if match is not None:
            step, ball = match.group(1), match.group(2)
        elif self.unmapped and name not in self.names:
            step = ball = ""  # kept for inspect, out of the records
        else:
            where = "session.yaml's feature_names maps it to" if name in self.names else "named"
            raise InputError(
                f"sphere {where} {target!r}: not hexatherm's <step>_<ball> (each part "
                "[A-Za-z0-9-]+); map it in session.yaml's feature_names",
                path=self.path,
                line=line,
                field="FeatureName",
            )
        location = _find(element, "Location")
        diameter = _find(element, "Diameter")
        sphere = Sphere(
            line=line,
            name=name,
            step=step,
            ball=ball,
            xyz_mm=None,
            diameter_mm=math.nan,
            time=_child_text(element, "TimeStamp"),
        )
        if location is not None:
            scale = self._scale(location)
            xyz = [float(v) * scale for v in location.text.split()]
            sphere.xyz_mm = (xyz[0], xyz[1], xyz[2])
            sphere.u_mm, sphere.u_combined_mm = self._uncertainty(location, scale)
        if diameter is not None:
            sphere.diameter_mm = float(diameter.text) * self._scale(diameter)
        points = _find(element, "PointList")
        if points is not None:
            for ref in points:
                kind, target_id = local_name(ref), (ref.text or "").strip()
                if kind == "WholePointSetId":
                    sphere.point_sets.append((target_id, 1, None, ref.sourceline))
                elif kind == "RangePointSetId":
                    first, last = (int(v) for v in ref.get("range", "").split())
                    sphere.point_sets.append((target_id, first, last, ref.sourceline))
                elif kind == "SinglePointSetId":
                    index = int(ref.get("index", "0"))
                    sphere.point_sets.append((target_id, index, index, ref.sourceline))
                self.wanted.add(target_id)
        if location is None and not sphere.point_sets:
            raise InputError(
                f"sphere {name!r} has neither a Location (its centre) nor measured points",
                path=self.path,
                line=line,
                field="SphereFeatureMeasurement",
            )
        self.spheres.append(sphere)
        if sphere.time is None:
            self.untimed.append((sphere, self.mr_start))

    def _name(self, element: Any) -> str:
        name = _child_text(element, "FeatureName")
        item_id = _child_text(element, "FeatureItemId")
        if name is None and item_id is not None:
            name = self.item_names.get(item_id)
        if name is None:
            raise InputError(
                "a sphere without a name: neither its FeatureName nor its "
                f"SphereFeatureItem{f' {item_id}' if item_id else ''} names it",
                path=self.path,
                line=element.sourceline,
                field="FeatureName",
            )
        return name

    def _uncertainty(
        self, location: Any, scale: float
    ) -> tuple[tuple[float, float, float] | None, float]:
        axes = [location.get(f"{a}CombinedUncertainty") for a in "xyz"]
        combined = location.get("combinedUncertainty")
        per_axis = None
        if any(v is not None for v in axes):
            if any(v is None for v in axes):
                raise InputError(
                    "give xCombinedUncertainty, yCombinedUncertainty and "
                    "zCombinedUncertainty together (or combinedUncertainty)",
                    path=self.path,
                    line=location.sourceline,
                    field="Location",
                )
            u = [float(v) * scale for v in axes if v is not None]
            per_axis = (u[0], u[1], u[2])
        u_combined = math.nan if combined is None else float(combined) * scale
        for value in (*(per_axis or ()), u_combined):
            if not math.isnan(value) and not 0 < value * 1e3 <= U_UM_MAX:
                raise InputError(
                    f"a centre's uncertainty of {value * 1e3:g} um: must be > 0 and "
                    f"<= {U_UM_MAX:g} um",
                    path=self.path,
                    line=location.sourceline,
                    field="Location",
                )
        return per_axis, u_combined

    def _numbers(self, points: Any) -> tuple[FloatArray, IntArray]:
        """The points of a ``Points`` element (x y z ...), and each point's line (that of
        its first number)."""
        text = points.text or ""
        try:
            values = np.array(text.split(), dtype=np.float64)
        except ValueError:
            values = np.array([np.nan])
        if values.size % 3 or not np.all(np.isfinite(values)):
            raise InputError(
                f"{values.size} numbers, not all finite or not a whole number of points "
                "(x y z ...)",
                path=self.path,
                line=points.sourceline,
                field="Points",
            )
        rows = text.split("\n")
        counts = np.array([len(row.split()) for row in rows], dtype=np.int64)
        if np.all((counts == 0) | (counts == 3)):  # a point a line, as CMM software writes
            lines = np.flatnonzero(counts == 3)
        else:  # the line of each point's first number
            token_rows = np.repeat(np.arange(len(rows)), counts)
            lines = token_rows[0::3]
        return values.reshape(-1, 3), points.sourceline + lines.astype(np.int64)

    def _point_set(self, element: Any) -> None:
        points = _find(element, "Points")
        if points is None:
            raise InputError(
                "measured points given only as BinaryPoints: hexatherm reads Points",
                path=self.path,
                line=element.sourceline,
                field="MeasuredPointSet",
            )
        linear = _find(element, "Units", "LinearUnit")
        if linear is not None:  # the set's own unit (an OtherUnitsType)
            scale = self._unit_mm(linear, _child_text(linear, "UnitName") or "")
        else:
            scale = self._scale(points)
        values, lines = self._numbers(points)
        self.point_sets[element.get("id")] = (values * scale, lines)


def _find(element: Any, *names: str) -> Any:
    """The first descendant down the path of child names ``names``, or None."""
    found = element
    for name in names:
        found = found.find(f"{{{QIF_NS}}}{name}")
        if found is None:
            return None
    return found


def _child_text(element: Any, name: str) -> str | None:
    child = element.find(f"{{{QIF_NS}}}{name}")
    if child is None or child.text is None:
        return None
    return child.text.strip()
