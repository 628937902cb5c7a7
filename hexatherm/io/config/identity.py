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
from hexatherm.session import TOLERANCE_UNITS, Identification

LAB_FORMAT = "hexatherm-lab/1"

#: text fields at the top of the mapping
_TEXTS = ("lab", "address", "customer", "operator", "report_number")
#: sub-mappings and their text fields
_GROUPS = {
    "cmm": ("make", "model", "serial", "certificate", "mpe"),
    "hexapod": ("model", "serial"),
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


def read_tolerances(doc: YamlDoc, *keys: Any) -> dict[str, float]:
    """The ``tolerances:`` mapping at ``keys``: ``Tx_um`` .. ``Rz_urad`` -> the half-width of
    the tolerance zone of that deviation from the commanded pose (> 0)."""
    doc.check_keys(list(TOLERANCE_UNITS), *keys)
    found = {}
    for key in doc.get(*keys):
        found[key] = doc.number(*keys, key, positive=True)
    return found


def read_lab(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, float]]:
    """A lab file: its identification fields (as :func:`read_identification`) and its
    tolerances (as :func:`read_tolerances`, empty without them)."""
    doc = YamlDoc.load(Path(path))
    doc.check_format(LAB_FORMAT)
    doc.check_keys(["format", *IDENTIFICATION_KEYS, "tolerances", "templates"])
    tolerances = {}
    if doc.get("tolerances", default=None) is not None:
        tolerances = read_tolerances(doc, "tolerances")
    return read_identification(doc), tolerances


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
