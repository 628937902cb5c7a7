"""Writing the YAML contracts: numbers that round-trip, flow sequences, atomic files."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import yaml

from hexatherm.io.atomic import atomic_write_text


def _number(value: float) -> str:
    """Shortest round-tripping text of a number that every YAML reader takes as one."""
    value = float(value)
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    text = repr(value)
    if "e" in text and "." not in text:
        text = text.replace("e", ".0e")
    return text


def _flow(values: Any) -> str:
    return "[" + ", ".join(_number(v) for v in np.asarray(values, float)) + "]"


def _dump(doc: dict[str, Any]) -> str:
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write a config file atomically."""
    atomic_write_text(path, text)
