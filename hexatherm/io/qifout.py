"""Writing QIF 3 documents: the sphere features of a measurement plan (``plan --qif``).

:class:`QifDocument` builds a ``QIFDocument`` element by element, with the QIF ids a CMM
program links by: ``FileUnits`` (mm), one ``SphereFeatureDefinition`` per ball diameter,
a ``SphereFeatureNominal`` (the nominal centre, CMM coordinates) and a
``SphereFeatureItem`` (named ``<step>_<ball>``) per ball and step. :func:`qif_plan` adds an
ordered ``Plan`` (one ``MeasureSpecifiedFeatures`` step per feature, in the plan's
order). What it writes validates against the shipped QIF 3.0 schema (tested). Numbers are
written to the shortest digits that read back to the same double (:func:`numbers`).
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from lxml import etree

from hexatherm.io.qifschema import QIF_NS

_XSI = "http://www.w3.org/2001/XMLSchema-instance"


@dataclass(frozen=True)
class NominalSphere:
    """A ball at one step: its name (``<step>_<ball>``), nominal centre (mm, CMM frame)
    and diameter (mm)."""

    name: str
    xyz_mm: tuple[float, float, float]
    diameter_mm: float


def numbers(*values: float) -> str:
    """Numbers as QIF writes them: space-separated, the shortest digits that read back to
    the same double, without an exponent (``xs:decimal``, the type of QIF's diameters,
    uncertainties and factors, has none).

    >>> numbers(1.0, 0.1, -2.5e-07, 426.70691604407875)
    '1 0.1 -0.00000025 426.70691604407875'
    """
    return " ".join(np.format_float_positional(float(v), unique=True, trim="-") for v in values)


@dataclass
class QifDocument:
    """A QIF 3 document under construction (ids counted from 1).

    >>> doc = QifDocument()
    >>> items = doc.add_spheres([NominalSphere("O_B1", (1.0, 2.0, 3.0), 25.4)])
    >>> items
    {'O_B1': '3'}
    >>> b"<FeatureName>O_B1</FeatureName>" in doc.to_bytes()
    True
    """

    application: str = "hexatherm"
    #: the file's length unit: its name and its size in metres (every length is written in it)
    unit_name: str = "mm"
    metres_per_unit: float = 0.001
    next_id: int = 1
    features: list[Any] = field(default_factory=list)
    tail: list[Any] = field(default_factory=list)
    #: what the document's QPId (a UUID) is derived from: the same content, the same id
    identity: str = ""

    def new_id(self) -> str:
        value = self.next_id
        self.next_id += 1
        return str(value)

    def element(self, name: str, *children: Any, text: str | None = None, **attrs: str) -> Any:
        """A QIF element with children, text and attributes."""
        made = etree.Element(f"{{{QIF_NS}}}{name}", attrs)
        made.extend(children)
        if text is not None:
            made.text = text
        return made

    def length(self, *values_mm: float) -> str:
        """Lengths in mm, written in the file's unit."""
        return numbers(*(v / (self.metres_per_unit * 1000.0) for v in values_mm))

    def listing(self, name: str, children: Sequence[Any]) -> Any:
        """A QIF list element: its children and their count ``n``."""
        return self.element(name, *children, n=str(len(children)))

    def add_spheres(self, spheres: Sequence[NominalSphere]) -> dict[str, str]:
        """Definitions, nominals and items of ``spheres``; returns each name's item id."""
        e = self.element
        definitions: dict[float, str] = {}
        definition_elements, nominals, items = [], [], []
        for sphere in spheres:
            if sphere.diameter_mm not in definitions:
                definitions[sphere.diameter_mm] = self.new_id()
                definition_elements.append(
                    e(
                        "SphereFeatureDefinition",
                        e("InternalExternal", text="EXTERNAL"),
                        e("Diameter", text=self.length(sphere.diameter_mm)),
                        id=definitions[sphere.diameter_mm],
                    )
                )
        ids: dict[str, str] = {}
        for sphere in spheres:
            nominal_id, item_id = self.new_id(), self.new_id()
            nominals.append(
                e(
                    "SphereFeatureNominal",
                    e("FeatureDefinitionId", text=definitions[sphere.diameter_mm]),
                    e("Location", text=self.length(*sphere.xyz_mm)),
                    id=nominal_id,
                )
            )
            items.append(
                e(
                    "SphereFeatureItem",
                    e("FeatureNominalId", text=nominal_id),
                    e("FeatureName", text=sphere.name),
                    e("DeterminationMode", e("Checked", e("CheckDetails", e("Measured")))),
                    id=item_id,
                )
            )
            ids[sphere.name] = item_id
            self.identity += f"{sphere.name} {numbers(*sphere.xyz_mm, sphere.diameter_mm)};"
        self.features = [
            self.listing("FeatureDefinitions", definition_elements),
            self.listing("FeatureNominals", nominals),
            self.listing("FeatureItems", items),
        ]
        return ids

    def to_bytes(self) -> bytes:
        """The document, UTF-8, with its XML declaration."""
        e = self.element
        root = etree.Element(
            f"{{{QIF_NS}}}QIFDocument",
            {"versionQIF": "3.0.0", "idMax": str(self.next_id - 1)},
            nsmap={None: QIF_NS, "xsi": _XSI},
        )
        root.set(f"{{{_XSI}}}schemaLocation", f"{QIF_NS} ../QIFApplications/QIFDocument.xsd")
        root.append(e("QPId", text=str(uuid.uuid5(uuid.NAMESPACE_URL, self.identity))))
        root.append(e("Header", e("Application", e("Name", text=self.application))))
        root.append(
            e(
                "FileUnits",
                e(
                    "PrimaryUnits",
                    e(
                        "LinearUnit",
                        e("SIUnitName", text="meter"),
                        e("UnitName", text=self.unit_name),
                        e("UnitConversion", e("Factor", text=numbers(self.metres_per_unit))),
                    ),
                ),
            )
        )
        root.append(e("Features", *self.features))
        root.extend(self.tail)
        return bytes(
            etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)
        )


def qif_plan(spheres: Sequence[NominalSphere], *, application: str = "hexatherm plan") -> bytes:
    """A QIF 3 plan document: the spheres (nominals and items) and an ordered plan that
    measures them one by one, in the order given (the plan's steps, B1 to B3 each).

    >>> text = qif_plan([NominalSphere("O_B1", (0.0, 0.0, 240.0), 25.4)]).decode()
    >>> "<MeasureSpecifiedFeatures>" in text and "<SequenceNumber>1</SequenceNumber>" in text
    True
    """
    doc = QifDocument(application=application)
    items = doc.add_spheres(spheres)
    e = doc.element
    steps = [
        e(
            "NumberedPlanElement",
            e("SequenceNumber", text=str(number)),
            e(
                "MeasureSpecifiedFeatures",
                doc.listing("FeatureItemIds", [e("Id", text=items[s.name])]),
            ),
        )
        for number, s in enumerate(spheres, start=1)
    ]
    doc.tail = [e("Plan", e("OrderedPlanRoot", doc.listing("Steps", steps)))]
    return doc.to_bytes()
