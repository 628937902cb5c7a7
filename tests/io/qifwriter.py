"""QIF 3 results written the way CMM software exports them (for the tests only).

A ``QIFDocument`` with ``FileUnits``, the spheres' definitions, nominals and items (named
by the items, as Calypso and PC-DMIS do, or on each measurement), and ``Results`` whose
``MeasuredFeatures`` hold one ``SphereFeatureMeasurement`` per step and ball (``Location``
with its uncertainty when given, ``Diameter``, ``TimeStamp``) and, for probed points, a
``PointList`` into ``MeasuredPointSets``. Built on :class:`hexatherm.io.qifout.QifDocument`
(the same features ``plan --qif`` writes); every file is validated by the tests against
the shipped schema.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from hexatherm.io.qifout import NominalSphere, QifDocument
from hexatherm.io.records import Records, seconds_to_iso

#: a length unit: its UnitName and its size in metres
UNITS = {"mm": ("mm", 0.001), "inch": ("inch", 0.0254)}


def results_qif(
    records: Records,
    *,
    unit: str = "mm",
    names: Callable[[str, str], str] = lambda step, ball: f"{step}_{ball}",
    name_on: str = "item",
    time_suffix: str = "",
    uncertainty_um: Mapping[str, np.ndarray] | None = None,
    location_offset_mm: float = 0.0,
) -> bytes:
    """A QIF 3 results document of a centres or points file's records.

    ``names(step, ball)`` names each feature (on its ``SphereFeatureItem``, or on the
    measurement when ``name_on`` is ``"measurement"``); ``time_suffix`` is appended to
    each ISO time (``"Z"``, ``"+01:00"``, or nothing); ``uncertainty_um`` gives
    ``x``, ``y``, ``z`` (per-axis) or ``combined`` per centre, um;
    ``location_offset_mm`` moves the Location of spheres given by points (a CMM's own
    fit, which hexatherm does not use) off their points.
    """
    unit_name, factor = UNITS[unit]
    label, ball = records.label, records.ball
    starts = np.flatnonzero(
        np.concatenate(([True], (label[1:] != label[:-1]) | (ball[1:] != ball[:-1])))
    )
    stops = np.append(starts[1:], len(records))
    groups = [(int(a), int(b)) for a, b in zip(starts, stops, strict=True)]
    diameters = (
        records.diameter_mm if records.diameter_mm is not None else np.full(len(records), 25.4)
    )
    spheres = []
    for a, b in groups:
        centre = records.xyz_mm[a:b].mean(axis=0)
        spheres.append(
            NominalSphere(
                names(str(label[a]), str(ball[a])),
                (float(centre[0]), float(centre[1]), float(centre[2])),
                25.4 if np.isnan(diameters[a]) else float(diameters[a]),
            )
        )
    doc = QifDocument(
        application="CMM software (a test's stand-in)", unit_name=unit_name, metres_per_unit=factor
    )
    item_ids = doc.add_spheres(spheres)
    e = doc.element
    measured, point_sets = [], []
    for index, ((a, b), sphere) in enumerate(zip(groups, spheres, strict=True)):
        children = [e("FeatureItemId", text=item_ids[sphere.name])]
        if name_on == "measurement":
            children.append(e("FeatureName", text=sphere.name))
        stamp = seconds_to_iso(float(records.time_s[a:b].mean())) + time_suffix
        children.append(e("TimeStamp", text=stamp))
        attrs: dict[str, str] = {}
        if records.kind == "points":
            set_id = doc.new_id()
            children.append(doc.listing("PointList", [e("WholePointSetId", text=set_id)]))
            xyz = np.array(sphere.xyz_mm) + location_offset_mm
            rows = "\n".join(doc.length(*p) for p in records.xyz_mm[a:b])
            point_sets.append(
                e(
                    "MeasuredPointSet",
                    e("Points", text="\n" + rows + "\n"),
                    e("Compensated", text="true"),
                    id=set_id,
                    count=str(b - a),
                )
            )
        else:
            xyz = records.xyz_mm[a]
            if uncertainty_um is not None:
                for key, values in uncertainty_um.items():
                    name = (
                        "combinedUncertainty" if key == "combined" else f"{key}CombinedUncertainty"
                    )
                    attrs[name] = doc.length(values[index] * 1e-3)
        children.append(e("Location", text=doc.length(*xyz), **attrs))
        if not np.isnan(diameters[a]):
            children.append(e("Diameter", text=doc.length(diameters[a])))
        measured.append(e("SphereFeatureMeasurement", *children, id=doc.new_id()))
    results_children = [doc.listing("MeasuredFeatures", measured)]
    if point_sets:
        results_children.append(doc.listing("MeasuredPointSets", point_sets))
    results_children.append(e("InspectionStatus", e("InspectionStatusEnum", text="UNDEFINED")))
    doc.tail = [
        e(
            "Results",
            doc.listing(
                "MeasurementResultsSet",
                [e("MeasurementResults", *results_children, id=doc.new_id())],
            ),
        )
    ]
    return doc.to_bytes()
