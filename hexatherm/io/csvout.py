"""How hexatherm writes its result CSV files: numbers at a fixed resolution per unit.

A result column whose name carries a unit (:func:`column_unit`) is written with the
fixed decimals of that unit's resolution (:data:`RESOLUTION`), so that a file diffs
cleanly from one run, machine or version to the next: no exponent, no 17-digit
noise, a value that rounds to zero written without its sign, an empty cell for NaN.
The resolutions are at least as fine as the spec's "at least 1e-7 mm" for every
length, and far below what a CMM resolves. Columns without a unit (counts, weights,
correlations, condition numbers, flags, text) and seconds are written as before: the
shortest text that reads back as the same number.

Inputs that hexatherm writes (``simulate``'s measurement files and ``truth/``) are not
results: :func:`csv_text` with ``rounded=False`` writes them at full precision.

>>> column_unit("Tx_corr_mm"), column_unit("u_dRz_conv_urad"), column_unit("dTx_um_nominal")
('mm', 'urad', 'um')
>>> column_unit("cov_dTx_corr_um2"), column_unit("weight_after"), column_unit("x")
('um2', '', 'mm')
>>> fixed_text(np.array([1.23456789, -1e-12, np.nan, 2.6e-7, -3.0]), 1e-7)
['1.2345679', '0.0000000', '', '0.0000003', '-3.0000000']
>>> print(csv_text(pd.DataFrame({"label": ["S1"], "Tx_mm": [0.1 + 0.2], "n": [3]})), end="")
label,Tx_mm,n
S1,0.3000000,3
"""

from __future__ import annotations

import io
import math

import numpy as np
import pandas as pd

#: resolution of a written number, per unit suffix of its column
RESOLUTION = {
    "mm": 1e-7,
    "deg": 1e-7,
    "um": 1e-4,
    "urad": 1e-3,
    "um2": 1e-6,
    "urad2": 1e-6,
    "ppm": 1e-4,
    "C": 1e-4,
    "degC": 1e-4,
}

#: units that a column name may carry (those without a resolution are written exactly)
UNITS = frozenset([*RESOLUTION, "s"])

#: columns named by the spec without a unit suffix (a centres file's), and their unit
NAMED_UNITS = {"x": "mm", "y": "mm", "z": "mm", "diameter": "mm"}


def column_unit(column: str) -> str:
    """The unit of a column: its last ``_`` part that is a unit (``Tx_corr_mm``: ``mm``,
    ``dTx_um_nominal``: ``um``), the unit of a spec column named without one (``x``:
    ``mm``), or ``""``."""
    if column in NAMED_UNITS:
        return NAMED_UNITS[column]
    for part in reversed(column.split("_")[1:]):
        if part in UNITS:
            return part
    return ""


def resolution_of(column: str) -> float | None:
    """The resolution a column is written at (:data:`RESOLUTION`), None: written exactly."""
    return RESOLUTION.get(column_unit(column))


def fixed_text(values: np.ndarray, resolution: float) -> list[str]:
    """``values`` as fixed-decimal texts at ``resolution`` (a power of ten): correctly
    rounded, ``0.000`` for a value that rounds to zero (never ``-0.000``), ``""`` for
    NaN, ``inf``/``-inf`` as pandas writes them."""
    decimals = max(0, round(-math.log10(resolution)))
    fmt = f"{{:.{decimals}f}}".format
    texts = [fmt(v) for v in np.asarray(values, dtype=float).tolist()]
    negative_zero = fmt(-0.0)
    zero = fmt(0.0)
    for i, text in enumerate(texts):
        if text == negative_zero:
            texts[i] = zero
        elif text == "nan":
            texts[i] = ""
    return texts


def csv_text(frame: pd.DataFrame, rounded: bool = True) -> str:
    """CSV text of ``frame`` (no index, LF line ends).

    With ``rounded`` (results), every float column with a unit is written at its
    resolution (:func:`fixed_text`); the others, and every column without ``rounded``,
    as the shortest text that reads back as the same number.
    """
    if rounded:
        frame = frame.copy(deep=False)
        for column in frame.columns:
            step = resolution_of(str(column))
            if step is not None and pd.api.types.is_float_dtype(frame[column].dtype):
                frame[column] = fixed_text(frame[column].to_numpy(), step)
    buffer = io.StringIO()
    frame.to_csv(buffer, index=False, lineterminator="\n", float_format=None)
    return buffer.getvalue()
