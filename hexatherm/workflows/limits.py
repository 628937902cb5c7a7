"""The one table of limits (:mod:`hexatherm.limits`), as the commands read it: each
command's checking options take their defaults from it and show it in ``--help``."""

from __future__ import annotations

from hexatherm.limits import (
    DEFAULT_MIN_RCOND,
    DISTANCE_REFUSAL_UM,
    QUALITY_ALIASES,
    QualityLimits,
    limits_text,
)

__all__ = [
    "DEFAULTS",
    "DEFAULT_MIN_RCOND",
    "DISTANCE_REFUSAL_UM",
    "QUALITY_ALIASES",
    "QualityLimits",
    "limits_text",
    "radius_limit_um",
]

#: the table's default limits
DEFAULTS = QualityLimits()


def radius_limit_um(limits: QualityLimits = DEFAULTS) -> float:
    """The limit on a fitted radius' deviation (um) that ``acquire`` and ``run`` check
    while measuring: half the table's diameter limit."""
    return limits.diameter_dev_um / 2
