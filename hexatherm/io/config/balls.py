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
        doc.check_keys(["centre", "diameter", "u_centre_um"], "balls", name)
        if doc.get("balls", name, "u_centre_um", default=None) is not None:
            # register's standard uncertainty of the centre (an extension; not used here)
            u = doc.vector("balls", name, "u_centre_um", size=3)
            if min(u) < 0:
                raise doc.error("must not be negative", "balls", name, "u_centre_um")
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


def balls_to_yaml(
    balls: Balls,
    u_centre_um: np.ndarray | None = None,
    resolution_mm: float | None = None,
) -> str:
    """The balls file text of ``balls``.

    ``u_centre_um`` (k, 3): each centre's standard uncertainty along x, y, z of the
    platform frame (``u_centre_um``, written at 1e-4 um); ``resolution_mm``: centres
    rounded to it (a power of ten; default: every digit).
    """
    from hexatherm.io.csvout import fixed_text  # only when written: readers go without it

    def centre(c: np.ndarray) -> list[float]:
        if resolution_mm is None:
            return [float(v) for v in c]
        return [float(t) for t in fixed_text(c, resolution_mm)]

    entries: dict[str, dict[str, object]] = {}
    for i, (n, c, d) in enumerate(
        zip(balls.names, balls.centres_mm, balls.diameters_mm, strict=True)
    ):
        entries[n] = {"centre": centre(c), "diameter": float(d)}
        if u_centre_um is not None:
            entries[n]["u_centre_um"] = [float(t) for t in fixed_text(u_centre_um[i], 1e-4)]
    doc = {
        "format": BALLS_FORMAT,
        "balls": entries,
        "probe": {
            "compensated": balls.probe_compensated,
            "tip_diameter": float(balls.tip_diameter_mm),
        },
    }
    return _dump(doc)
