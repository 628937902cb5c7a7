"""The datums file (``hexatherm-datums/1``, an extension): the 3-2-1 alignment of ``register``."""

from __future__ import annotations

import os

import numpy as np

from hexatherm.core.plan import NAME_PATTERN
from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import Datums

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
