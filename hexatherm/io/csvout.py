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
import re
from collections.abc import Mapping, Sequence

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

#: resolution of a row's unit (csv_text's ``row_unit``): the units above and a gain's
ROW_RESOLUTION = {**RESOLUTION, "mm/mm": 1e-10}

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
    rounded (Python's ``format``), ``0.000`` for a value that rounds to zero (never
    ``-0.000``), ``""`` for NaN, ``inf``/``-inf`` as pandas writes them."""
    decimals = max(0, round(-math.log10(resolution)))
    fmt = f"{{:.{decimals}f}}".format
    negative_zero, zero = fmt(-0.0), fmt(0.0)
    texts = [fmt(v) for v in np.asarray(values, dtype=float).ravel().tolist()]
    return [zero if t == negative_zero else "" if t == "nan" else t for t in texts]


#: what makes a cell need quotes in a CSV file
_QUOTE = re.compile(r'[,"\n\r]')


def _cells(column: pd.Series, step: float | None) -> list[str] | None:
    """The texts of a column as pandas' ``to_csv`` writes them (floats at ``step`` when
    given), or None for a column this writer leaves to pandas (quotes, mixed types)."""
    dtype = column.dtype
    if dtype == np.float64:
        if step is not None:
            return fixed_text(column.to_numpy(), step)
        return ["" if v != v else repr(v) for v in column.tolist()]
    if dtype == np.bool_:
        return ["True" if v else "False" for v in column.tolist()]
    if dtype == np.int64:
        return list(map(str, column.tolist()))
    if pd.api.types.is_object_dtype(dtype) or pd.api.types.is_string_dtype(dtype):
        cells = column.tolist()
        if all(type(v) is str or type(v) is bool for v in cells):
            # text, flags, or flags with "" where a check does not apply
            texts = [v if type(v) is str else ("True" if v else "False") for v in cells]
            return None if _QUOTE.search("".join(texts)) else texts
    return None


def csv_text(
    frame: pd.DataFrame,
    rounded: bool = True,
    row_unit: tuple[str, Sequence[str]] | None = None,
    resolutions: Mapping[str, float] | None = None,
) -> str:
    """CSV text of ``frame`` (no index, LF line ends), as pandas' ``to_csv`` writes it.

    With ``rounded`` (results), every float column with a unit is written at its
    resolution (:func:`fixed_text`); the others, and every column without ``rounded``,
    as the shortest text that reads back as the same number. Columns of text, whole
    numbers, flags and floats are joined here (five times faster than ``to_csv``);
    a frame with anything else (a cell that needs quotes, mixed types) goes to pandas.

    ``row_unit`` = ``(unit column, columns)``: those float columns hold each row's value
    in the unit its unit column names (``parameters.csv``: ``mm`` or ``mm/mm``) and are
    written at that unit's resolution, row by row. ``resolutions``: the resolution of
    further columns without a unit (a correlation), by name.
    """
    names = [str(c) for c in frame.columns]
    steps = [resolution_of(c) if rounded else None for c in names]
    if rounded and resolutions:
        steps = [resolutions.get(c, step) for c, step in zip(names, steps, strict=True)]
    cells = [_cells(frame.iloc[:, j], steps[j]) for j in range(len(names))]
    if rounded and row_unit is not None:
        units = frame[row_unit[0]].astype(str).tolist()
        for column in row_unit[1]:
            j = names.index(column)
            values = frame[column].to_numpy(dtype=float)
            cells[j] = [
                fixed_text(np.array([v]), ROW_RESOLUTION[unit])[0]
                for v, unit in zip(values, units, strict=True)
            ]
            steps[j] = None
    if len(names) > 1 and not _QUOTE.search("".join(names)) and all(c is not None for c in cells):
        rows = map(",".join, zip(*cells, strict=True))
        return "\n".join([",".join(names), *rows]) + "\n"
    frame = frame.copy(deep=False)
    for j, step in enumerate(steps):
        if step is not None and pd.api.types.is_float_dtype(frame.iloc[:, j].dtype):
            frame[frame.columns[j]] = fixed_text(frame.iloc[:, j].to_numpy(), step)
        elif rounded and row_unit is not None and names[j] in row_unit[1]:
            frame[frame.columns[j]] = cells[j]
    buffer = io.StringIO()
    frame.to_csv(buffer, index=False, lineterminator="\n", float_format=None)
    return buffer.getvalue()
