"""Identification and tolerances: the session file's ``identification:`` and
``tolerances:`` mappings and the lab file (``hexatherm-lab/1``), all extensions.

A lab file holds what is the same on every report of a lab (the lab, its CMM, its
signatories, default tolerances, ``templates:`` the folder of its own report templates);
a session file's own ``identification:`` (and ``tolerances:``) add to it and win key by
key (``cmm.serial`` in the session replaces the lab's ``cmm.serial``; a session's
``signatures`` replace the lab's list). Every value
is read strictly: texts must be YAML strings (quote serial and report numbers, so that
``007`` stays ``007``), numbers numbers; a bad value is refused naming file, line and
field.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import TOLERANCE_UNITS, Identification, Tolerance

LAB_FORMAT = "hexatherm-lab/1"

#: text fields at the top of the mapping (a session's or a lab file's): who, where, what
#: (ISO/IEC 17025:2017 7.8.2.1: the customer's contact, the place of the measurement, the
#: item's receipt, the lab's procedure and deviations from it, external providers)
_TEXTS = (
    "lab",
    "address",
    "contact",
    "accreditation",
    "place",
    "customer",
    "customer_address",
    "operator",
    "report_number",
    "received",
    "procedure",
    "deviations",
    "external_providers",
)
#: sub-mappings and their text fields
_GROUPS = {
    "cmm": ("make", "model", "serial", "certificate", "mpe"),
    "hexapod": ("model", "serial", "condition"),
}
#: ambient conditions: key -> True for a number, False for a text
_AMBIENT = {"temperature_C": True, "humidity_percent": True, "note": False}
IDENTIFICATION_KEYS = (*_TEXTS, *_GROUPS, "ambient", "signatures")


def _text(doc: YamlDoc, *keys: Any) -> str:
    value = doc.get(*keys)
    if not isinstance(value, str):
        written = doc.scalars.get(tuple(keys), str(value))  # 007 as the file says it
        hint = f" (quote it: '{written}')" if isinstance(value, int | float | bool) else ""
        raise doc.error(f"expected a text{hint}, got {value!r}", *keys)
    if not value.strip():
        raise doc.error("expected a text, got an empty one", *keys)
    return value.strip()


def read_identification(doc: YamlDoc, *keys: Any) -> dict[str, Any]:
    """The identification fields of the mapping at ``keys`` (the document's top level for
    none), checked, as a flat dict ``{"lab": ..., "cmm.serial": ..., "signatures": [...]}``."""
    found: dict[str, Any] = {}
    for key in _TEXTS:
        if doc.get(*keys, key, default=None) is not None:
            found[key] = _text(doc, *keys, key)
    for group, names in _GROUPS.items():
        if doc.get(*keys, group, default=None) is None:
            continue
        doc.check_keys(list(names), *keys, group)
        for name in names:
            if doc.get(*keys, group, name, default=None) is not None:
                found[f"{group}.{name}"] = _text(doc, *keys, group, name)
    if doc.get(*keys, "ambient", default=None) is not None:
        doc.check_keys(list(_AMBIENT), *keys, "ambient")
        for name, numeric in _AMBIENT.items():
            if doc.get(*keys, "ambient", name, default=None) is None:
                continue
            if numeric:
                value = doc.number(*keys, "ambient", name)
                if name == "humidity_percent" and not 0 <= value <= 100:
                    raise doc.error(f"expected 0 to 100, got {value!r}", *keys, "ambient", name)
                found[f"ambient.{name}"] = value
            else:
                found[f"ambient.{name}"] = _text(doc, *keys, "ambient", name)
    if doc.get(*keys, "signatures", default=None) is not None:
        items = doc.get(*keys, "signatures")
        if not isinstance(items, list) or not items:
            raise doc.error(
                "expected a list of {role: ..., name: ...} mappings", *keys, "signatures"
            )
        signatures = []
        for i in range(len(items)):
            doc.check_keys(["role", "name"], *keys, "signatures", i)
            signatures.append(
                (
                    _text(doc, *keys, "signatures", i, "role"),
                    _text(doc, *keys, "signatures", i, "name"),
                )
            )
        found["signatures"] = signatures
    return found


def read_tolerances(doc: YamlDoc, *keys: Any) -> dict[str, Tolerance]:
    """The ``tolerances:`` mapping at ``keys``: ``Tx_um`` .. ``Rz_urad`` -> the half-width
    ``T`` of the tolerance zone ``[-T, T]`` of that deviation from the commanded pose
    (> 0), or its limits ``[lower, upper]`` (``lower < upper``: an asymmetric zone)."""
    doc.check_keys(list(TOLERANCE_UNITS), *keys)
    found: dict[str, Tolerance] = {}
    for key in doc.get(*keys):
        value = doc.get(*keys, key)
        if not isinstance(value, list):
            found[key] = doc.number(*keys, key, positive=True)
            continue
        if len(value) != 2:
            raise doc.error(f"expected T or [lower, upper], got {value!r}", *keys, key)
        lower, upper = doc.number(*keys, key, 0), doc.number(*keys, key, 1)
        if not lower < upper:
            raise doc.error(
                f"the lower limit {lower:g} is not below the upper {upper:g}", *keys, key
            )
        found[key] = (lower, upper)
    return found


def read_lab(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Tolerance]]:
    """A lab file: its identification fields (as :func:`read_identification`) and its
    tolerances (as :func:`read_tolerances`, empty without them)."""
    doc = YamlDoc.load(Path(path))
    doc.check_format(LAB_FORMAT)
    doc.check_keys(["format", *IDENTIFICATION_KEYS, "tolerances", "templates", *LAB_SETTINGS])
    tolerances = {}
    if doc.get("tolerances", default=None) is not None:
        tolerances = read_tolerances(doc, "tolerances")
    return {**read_identification(doc), **_lab_settings(doc)}, tolerances


#: what only a lab file sets: how its documents are numbered and titled, its decision rule
LAB_SETTINGS = ("numbering", "titles", "decision_rule")
#: the documents a lab titles (``titles:``), by the command that writes them
DOCUMENTS = ("report", "calibrate", "diagnose")
#: the fields a ``numbering:`` pattern may use
NUMBERING_FIELDS = ("session", "doc", "date", "time")


def _lab_settings(doc: YamlDoc) -> dict[str, Any]:
    """``numbering`` (a pattern of :data:`NUMBERING_FIELDS`), ``titles.<document>`` and
    ``decision_rule`` / ``guard_factor``, flat, checked."""
    import string

    from hexatherm.core.conformity import RULES

    found: dict[str, Any] = {}
    if doc.get("numbering", default=None) is not None:
        pattern = _text(doc, "numbering")
        try:
            names = [f for _, f, _, _ in string.Formatter().parse(pattern) if f is not None]
        except ValueError as exc:
            raise doc.error(f"not a pattern: {exc}", "numbering") from None
        bad = [n for n in names if n not in NUMBERING_FIELDS]
        if bad or not names:
            raise doc.error(
                f"a pattern of {{{'}, {'.join(NUMBERING_FIELDS)}}}"
                + (f", got {{{bad[0]}}}" if bad else ", got no field"),
                "numbering",
            )
        found["numbering"] = pattern
    if doc.get("titles", default=None) is not None:
        doc.check_keys(list(DOCUMENTS), "titles")
        for name in DOCUMENTS:
            if doc.get("titles", name, default=None) is not None:
                found[f"titles.{name}"] = _text(doc, "titles", name)
    if doc.get("decision_rule", default=None) is not None:
        doc.check_keys(["rule", "guard_factor"], "decision_rule")
        found["decision_rule"] = doc.string("decision_rule", "rule", choices=RULES)
        if doc.get("decision_rule", "guard_factor", default=None) is not None:
            r = doc.number("decision_rule", "guard_factor")
            if r < 0:
                raise doc.error(
                    f"expected a number >= 0, got {r:g}", "decision_rule", "guard_factor"
                )
            found["guard_factor"] = r
    return found


def lab_template_dir(path: str | os.PathLike[str]) -> Path | None:
    """The lab file's ``templates:`` folder (the lab's report templates), relative to the
    lab file's folder; None without it; not a folder: refused naming file, line and field."""
    doc = YamlDoc.load(Path(path))
    if doc.get("templates", default=None) is None:
        return None
    folder = Path(path).parent / _text(doc, "templates")
    if not folder.is_dir():
        raise doc.error(f"no folder {str(folder)!r} (relative to the lab file)", "templates")
    return folder


def identification(
    session_fields: dict[str, Any], lab_fields: dict[str, Any] | None = None
) -> Identification:
    """The identification of a report: the lab file's fields, the session's over them."""
    merged = {**(lab_fields or {}), **session_fields}
    return Identification(
        fields=tuple((k, v) for k, v in merged.items() if k != "signatures"),
        signatures=tuple(merged.get("signatures", ())),
    )
