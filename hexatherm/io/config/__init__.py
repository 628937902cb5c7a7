"""Readers and writers of the YAML contracts: hexapod, balls, plan, session and datums files.

Every reader checks the ``format:`` key, rejects unknown keys and bad values with
an :class:`~hexatherm.errors.InputError` that names the file, the line and the
field, and returns the core's typed objects (or the session types of
:mod:`hexatherm.session`). One module per file contract; this package gathers them.
"""

from hexatherm.io.config.balls import BALLS_FORMAT, balls_to_yaml, read_balls
from hexatherm.io.config.datums import DATUMS_FORMAT, read_datums
from hexatherm.io.config.hexapod import (
    CTE_RANGE_PER_K,
    HEXAPOD_FORMAT,
    TEMPERATURE_RANGE_C,
    hexapod_to_yaml,
    read_hexapod,
    read_hexapod_text,
)
from hexatherm.io.config.plan import DEFAULT_POINTS_PER_BALL, PLAN_FORMAT, plan_to_yaml, read_plan
from hexatherm.io.config.session import (
    SESSION_FORMAT,
    read_pose_check,
    read_session,
    session_to_yaml,
)
from hexatherm.io.config.yamlout import write_text

__all__ = [
    "BALLS_FORMAT",
    "CTE_RANGE_PER_K",
    "DATUMS_FORMAT",
    "DEFAULT_POINTS_PER_BALL",
    "EFFECT_PARAMETERS",
    "HEXAPOD_FORMAT",
    "PLAN_FORMAT",
    "SESSION_FORMAT",
    "TEMPERATURE_RANGE_C",
    "balls_to_yaml",
    "hexapod_to_yaml",
    "plan_to_yaml",
    "read_balls",
    "read_datums",
    "read_hexapod",
    "read_hexapod_text",
    "read_plan",
    "read_pose_check",
    "read_session",
    "session_to_yaml",
    "write_text",
]


def __getattr__(name: str) -> object:
    """``EFFECT_PARAMETERS`` of :mod:`hexatherm.io.config.hexapod`, made on first use."""
    if name == "EFFECT_PARAMETERS":
        from hexatherm.io.config import hexapod

        return hexapod.EFFECT_PARAMETERS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
