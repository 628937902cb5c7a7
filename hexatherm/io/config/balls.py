"""The balls file (``hexatherm-balls/1``): the balls' centres in the platform frame."""

from __future__ import annotations

import os

import numpy as np

from hexatherm.core.plan import NAME_PATTERN
from hexatherm.core.registration import check_ball_layout
from hexatherm.errors import RegistrationError
from hexatherm.io.config.yamlout import _dump
from hexatherm.io.yamlfile import YamlDoc
from hexatherm.session import Balls

BALLS_FORMAT = "hexatherm-balls/1"


def read_balls(path: str | os.PathLike[str]) -> Balls:
    """Read and validate a balls file (``format: hexatherm-balls/1``)."""
    doc = YamlDoc.load(path)
    doc.check_format(BALLS_FORMAT)
    doc.check_keys(["format", "balls", "probe"])
    balls = doc.get("balls")
    if not isinstance(balls, dict):
        raise doc.error("expected a mapping of ball names", "balls")
    names, centres, diameters = [], [], []
    for name in balls:
        if not NAME_PATTERN.fullmatch(name):
            raise doc.error("ball name must match [A-Za-z0-9-]+", "balls", name)
        doc.check_keys(["centre", "diameter"], "balls", name)
        names.append(name)
        centres.append(doc.vector("balls", name, "centre", size=3))
        diameters.append(doc.number("balls", name, "diameter", positive=True))
    if len(names) < 3:
        raise doc.error(f"at least three balls are needed, got {len(names)}", "balls")
    try:
        check_ball_layout(centres)
    except RegistrationError as exc:
        raise doc.error(str(exc), "balls") from None
    compensated, tip = True, 0.0
    if doc.get("probe", default=None) is not None:
        doc.check_keys(["compensated", "tip_diameter"], "probe")
        compensated = doc.get("probe", "compensated", default=True)
        if not isinstance(compensated, bool):
            raise doc.error(f"expected true or false, got {compensated!r}", "probe", "compensated")
        tip = doc.number("probe", "tip_diameter", default=0.0)
        if tip < 0:
            raise doc.error("must not be negative", "probe", "tip_diameter")
    return Balls(tuple(names), np.array(centres), np.array(diameters), compensated, tip)


def balls_to_yaml(balls: Balls) -> str:
    """The balls file text of ``balls``."""
    doc = {
        "format": BALLS_FORMAT,
        "balls": {
            n: {"centre": c.tolist(), "diameter": float(d)}
            for n, c, d in zip(balls.names, balls.centres_mm, balls.diameters_mm, strict=True)
        },
        "probe": {
            "compensated": balls.probe_compensated,
            "tip_diameter": float(balls.tip_diameter_mm),
        },
    }
    return _dump(doc)
