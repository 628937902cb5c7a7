"""How the report writes numbers and units: fixed decimals per unit, nominal values exact.

Measured numbers get a fixed number of decimals set by their unit (:data:`DECIMALS`,
about a hundredth of what a CMM resolves), so a column lines up on its decimal
point; nominal values (a commanded pose, a limit) are written exactly as the
shortest text that reads back as the same float (``-16.441``, not ``-16.44``). Units
are written as a reader expects them (``µm``, ``µrad``, ``°C``); file column names
elsewhere keep their ASCII units.

>>> fixed(-12.34567, "um"), fixed(3.14159, "urad"), fixed(float("nan"), "um")
('-12.346', '3.14', '')
>>> exact(-16.441), exact(-13.004), exact(0.0), exact(-0.0), exact(2.5e-7)
('-16.441', '-13.004', '0', '0', '0.00000025')
>>> unit_text("um"), unit_text("degC"), unit_text("mm")
('µm', '°C', 'mm')
"""

from __future__ import annotations

import math

import numpy as np

#: decimals of a measured number, per unit (ASCII unit names, as in the files)
DECIMALS = {
    "um": 3,
    "urad": 2,
    "mm": 6,
    "deg": 7,
    "h": 3,
    "s": 1,
    "C": 3,
    "degC": 3,
    "K": 3,
    "": 4,
}

#: how a unit is written in the report
UNIT_TEXT = {"um": "µm", "urad": "µrad", "degC": "°C", "C": "°C", "deg": "°", "K": "K"}


def unit_text(unit: str) -> str:
    """``unit`` as the report writes it (``um`` -> ``µm``, ``degC`` -> ``°C``)."""
    return UNIT_TEXT.get(unit, unit)


def fixed(value: float, unit: str) -> str:
    """``value`` with the decimals of ``unit`` (:data:`DECIMALS`); empty when not finite.

    A value that rounds to zero is written without its sign.
    """
    value = float(value)
    if not math.isfinite(value):
        return ""
    text = format(value, f".{DECIMALS[unit]}f")
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def exact(value: float) -> str:
    """The shortest positional text that reads back as ``value`` (``0`` for ``-0.0``)."""
    value = float(value)
    if not math.isfinite(value):
        return str(value)
    if value == 0.0:
        return "0"
    return np.format_float_positional(value, trim="-")
