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
    rounded (as Python's ``format``), ``0.000`` for a value that rounds to zero (never
    ``-0.000``), ``""`` for NaN, ``inf``/``-inf`` as pandas writes them."""
    field, length = fixed_fields(np.asarray(values, dtype=float).ravel(), resolution)
    width = field.shape[-1]
    rows = zip(field, length.tolist(), strict=True)
    return [bytes(row[width - n :]).decode("ascii") for row, n in rows]


def _format_fixed(values: np.ndarray, decimals: int) -> list[str]:
    """Python's ``format``, value by value: the cells the digits below cannot be sure of."""
    fmt = f"{{:.{decimals}f}}".format
    negative_zero, zero = fmt(-0.0), fmt(0.0)
    texts = [fmt(v) for v in values.tolist()]
    return [zero if t == negative_zero else "" if t == "nan" else t for t in texts]


#: the texts ``0000`` to ``9999``, four bytes each: decimal digits four at a time (made
#: by numpy at import: 10,000 formats were 2-4 ms of every command's start)
_FOUR = np.arange(10000)
_DIGITS4 = (
    np.stack([_FOUR // 1000, _FOUR // 100 % 10, _FOUR // 10 % 10, _FOUR % 10], 1) + 48
).astype(np.uint8)
#: :data:`_DIGITS4`'s rows as one 4-byte word each: a gather of words, not of 4-byte rows
_DIGITS4_WORDS = _DIGITS4.view(np.uint32).ravel()
#: 1, 10, ..., 10**18: an int64's places (also the listings' of :mod:`hexatherm.io.texttable`)
POW10 = 10 ** np.arange(19, dtype=np.int64)
#: below 2**50 steps a scaled double is within 2**-3 of a whole step and its rounding
#: error (at most 2**-53 of it) can be told from a half step; beyond, ``format`` writes it
_SCALED_LIMIT = 2.0**50


def _digits(n: np.ndarray, count: int) -> np.ndarray:
    """The last ``count`` decimal digits of each ``n`` (int64, >= 0) as ASCII, zero
    padded: shape ``n.shape + (count,)``."""
    chunks = -(-count // 4)
    words = np.empty((*n.shape, chunks), np.uint32)
    rest = n
    for k in range(chunks):
        rest, low = np.divmod(rest, 10000)
        words[..., chunks - 1 - k] = _DIGITS4_WORDS[low]
    # the words' bytes in memory order are the four digits' texts, whatever the byte order
    return words.view(np.uint8)[..., 4 * chunks - count :]


def fixed_fields(values: np.ndarray, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fixed_text`'s texts as ASCII bytes, right-aligned in one field per value:
    ``(field, length)``, ``field`` of shape ``values.shape + (width,)`` (uint8), the text
    of a value its last ``length`` bytes.

    Each value is scaled to whole steps (``10**decimals`` is exact in a double) and
    rounded half to even; the product's rounding error is at most 2**-53 of it, so where
    the scaled value lies farther than 2**-50 of itself from a half step, it rounds as
    the exact binary value does. NaN is an empty text. A value closer to a half step, at
    or beyond 2**50 steps, or infinite is written by Python's ``format``
    (:func:`_format_fixed`), as are all values at zero decimals."""
    decimals = max(0, round(-math.log10(resolution)))
    values = np.asarray(values, dtype=float)
    scale = 10.0**decimals
    with np.errstate(invalid="ignore", over="ignore"):
        scaled = values * scale
        rounded = np.rint(scaled)
        tie = np.abs(scaled - np.floor(scaled) - 0.5) <= np.abs(scaled) * 2.0**-50
        sure = (np.abs(scaled) < _SCALED_LIMIT) & ~tie & (decimals > 0)
    missing = np.isnan(values)
    magnitude = np.abs(np.where(sure, rounded, 0.0)).astype(np.int64)
    negative = sure & (rounded < 0)
    whole, fraction = np.divmod(magnitude, 10**decimals)
    whole_digits = np.searchsorted(POW10[1:], whole, side="right") + 1
    most = int(whole_digits.max()) if whole_digits.size else 1
    width = 1 + most + 1 + decimals
    field = np.empty((*values.shape, width), np.uint8)
    field[..., 1 : 1 + most] = _digits(whole, most)
    field[..., 1 + most] = ord(".")
    field[..., 2 + most :] = _digits(fraction, decimals)
    length = np.where(missing, 0, whole_digits + 1 + decimals + negative)
    signs = np.nonzero(negative)
    field[(*signs, width - length[signs])] = ord("-")
    unsure = np.nonzero(~(sure | missing))
    if unsure[0].size:
        texts = [t.encode("ascii") for t in _format_fixed(values[unsure], decimals)]
        longest = max(map(len, texts))
        if longest > width:
            pad = np.zeros((*values.shape, longest - width), np.uint8)
            field, width = np.concatenate([pad, field], axis=-1), longest
        for *at, text in zip(*(i.tolist() for i in unsure), texts, strict=True):
            field[(*at, slice(width - len(text), width))] = np.frombuffer(text, np.uint8)
            length[tuple(at)] = len(text)
    return field, length


#: what makes a cell need quotes in a CSV file
_QUOTE = re.compile(r'[,"\n\r]')


def _cells(column: pd.Series) -> list[str] | None:
    """The texts of a column as pandas' ``to_csv`` writes them (floats as the shortest
    text that reads back as the same number), or None for a column this writer leaves to
    pandas (quotes, mixed types)."""
    dtype = column.dtype
    if dtype == np.float64:
        return ["" if v != v else repr(v) for v in column.tolist()]
    if dtype == np.bool_:
        return ["True" if v else "False" for v in column.tolist()]
    if dtype == np.int64:
        return list(map(str, column.tolist()))
    if pd.api.types.is_object_dtype(dtype) or pd.api.types.is_string_dtype(dtype):
        cells = column.tolist()
        kinds = set(map(type, cells))
        if kinds <= {str, bool}:
            # text, flags, or flags with "" where a check does not apply
            texts = cells
            if bool in kinds:
                texts = [v if type(v) is str else ("True" if v else "False") for v in cells]
            return None if _QUOTE.search("".join(texts)) else texts
    return None


def _text_field(texts: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """Texts as UTF-8 bytes, left-aligned in one field per row, and the mask of their
    bytes (None for a text holding a NUL, which a numpy bytes field cannot end with)."""
    joined = "".join(texts)
    if "\x00" in joined:
        return None
    data = np.array(texts if joined.isascii() else [t.encode("utf-8") for t in texts], "S")
    return data.view(np.uint8).reshape(len(texts), data.dtype.itemsize), _used(data)


def _column_field(column: pd.Series) -> tuple[np.ndarray, np.ndarray] | None:
    """``_text_field(_cells(column))`` (None where that is None) without a Python text
    per cell where the column allows: flags from their two texts, whole numbers
    converted by numpy (``str`` of an int64), a column of pandas' ``str`` dtype laid out
    once per distinct text (:func:`pandas.factorize`) and gathered to its rows. A long
    campaign's labels, kinds, times and file names repeat: 10,000 targets write 650,000
    such cells."""
    dtype = column.dtype
    if dtype == np.int64:
        data = column.to_numpy().astype("S21")  # as str(n) writes each
        return data.view(np.uint8).reshape(data.size, 21), _used(data)
    if dtype == np.bool_:
        texts, codes = ["False", "True"], column.to_numpy().astype(np.intp)
    elif isinstance(dtype, pd.StringDtype):
        codes, uniques = pd.factorize(column)
        texts = uniques.tolist()  # str, each: the dtype holds nothing else but NA
        if (codes.size and codes.min() < 0) or _QUOTE.search("".join(texts)):
            return None  # a missing text, or one to quote: pandas writes it
    else:
        cells = _cells(column)
        return None if cells is None else _text_field(cells)
    distinct = _text_field(texts)
    if distinct is None:
        return None
    return distinct[0][codes], distinct[1][codes]


def _used(data: np.ndarray) -> np.ndarray:
    """The mask of the bytes of a numpy bytes array's texts, a row each."""
    return np.arange(data.dtype.itemsize) < np.strings.str_len(data)[:, None]


def _table_bytes(
    frame: pd.DataFrame, steps: Sequence[float | None], given: Mapping[int, list[str]]
) -> bytes | None:
    """The rows of ``frame`` as CSV bytes (each line ended by LF), every cell as
    :func:`_cells` writes it (``given``: a column's texts), or None when a column is left
    to pandas. The cells are laid side by side in fixed fields with a mask of the bytes
    that are written, and the masked bytes taken in row order: no text per cell is
    built (the fixed-decimal columns of one resolution are formatted together,
    :func:`fixed_fields`)."""
    n, count = frame.shape
    fields: list[tuple[np.ndarray, np.ndarray] | None] = [None] * count
    fixed: dict[float, list[int]] = {}
    floats: dict[int, np.ndarray] = {}
    # the columns in order, each once (``items``, not ``iloc`` per column: its indexing
    # machinery costs more than the column of a 1000-row table)
    for j, (_, column) in enumerate(frame.items()):
        step = steps[j]
        if j not in given and column.dtype == np.float64 and step is not None:
            fixed.setdefault(step, []).append(j)
            floats[j] = column.to_numpy()
            continue
        if j in given:
            fields[j] = _text_field(given[j])
        else:
            fields[j] = _column_field(column)
        if fields[j] is None:
            return None
    for step, columns in fixed.items():
        block = np.column_stack([floats[j] for j in columns])
        field, length = fixed_fields(block, step)
        width = field.shape[-1]
        used = np.arange(width) >= width - length[..., None]
        for i, j in enumerate(columns):
            fields[j] = (field[:, i], used[:, i])
    comma = np.full((n, 1), ord(","), np.uint8)
    end = np.full((n, 1), ord("\n"), np.uint8)
    every = np.ones((n, 1), bool)
    pieces: list[np.ndarray] = []
    masks: list[np.ndarray] = []
    for j, cell in enumerate(fields):
        assert cell is not None
        pieces += [cell[0], comma if j < count - 1 else end]
        masks += [cell[1], every]
    table = np.concatenate(pieces, axis=1)
    return table[np.concatenate(masks, axis=1)].tobytes()


def csv_text(
    frame: pd.DataFrame,
    rounded: bool = True,
    row_unit: tuple[str, Sequence[str]] | None = None,
    resolutions: Mapping[str, float] | None = None,
) -> str:
    """CSV text of ``frame`` (:func:`csv_bytes`, decoded)."""
    out = _csv(frame, rounded, row_unit, resolutions)
    return out.decode("utf-8") if isinstance(out, bytes) else out


def csv_bytes(
    frame: pd.DataFrame,
    rounded: bool = True,
    row_unit: tuple[str, Sequence[str]] | None = None,
    resolutions: Mapping[str, float] | None = None,
) -> bytes:
    """:func:`csv_text` as the UTF-8 bytes a file of it holds: a table laid out here is
    not decoded into a text to be encoded again when it is written (a 10,000-target
    campaign's tables are 19 MB)."""
    out = _csv(frame, rounded, row_unit, resolutions)
    return out if isinstance(out, bytes) else out.encode("utf-8")


def _csv(
    frame: pd.DataFrame,
    rounded: bool,
    row_unit: tuple[str, Sequence[str]] | None,
    resolutions: Mapping[str, float] | None,
) -> bytes | str:
    """CSV text of ``frame`` (no index, LF line ends), as pandas' ``to_csv`` writes it.

    With ``rounded`` (results), every float column with a unit is written at its
    resolution (:func:`fixed_text`); the others, and every column without ``rounded``,
    as the shortest text that reads back as the same number. Columns of text, whole
    numbers, flags and floats are laid out here (:func:`_table_bytes`, the same bytes as
    ``to_csv``, several times faster); a frame with anything else (a cell that needs
    quotes, mixed types) goes to pandas.

    ``row_unit`` = ``(unit column, columns)``: those float columns hold each row's value
    in the unit its unit column names (``parameters.csv``: ``mm`` or ``mm/mm``) and are
    written at that unit's resolution, row by row. ``resolutions``: the resolution of
    further columns without a unit (a correlation), by name.

    The text is given as bytes (UTF-8) when laid out here, as pandas' text else.
    """
    names = [str(c) for c in frame.columns]
    steps = [resolution_of(c) if rounded else None for c in names]
    if rounded and resolutions:
        steps = [resolutions.get(c, step) for c, step in zip(names, steps, strict=True)]
    given: dict[int, list[str]] = {}
    if rounded and row_unit is not None:
        units = frame[row_unit[0]].astype(str).tolist()
        for column in row_unit[1]:
            j = names.index(column)
            values = frame[column].to_numpy(dtype=float)
            given[j] = [
                fixed_text(np.array([v]), ROW_RESOLUTION[unit])[0]
                for v, unit in zip(values, units, strict=True)
            ]
            steps[j] = None
    if len(names) > 1 and not _QUOTE.search("".join(names)):
        body = _table_bytes(frame, steps, given)
        if body is not None:
            return (",".join(names) + "\n").encode("utf-8") + body
    frame = frame.copy(deep=False)
    for j, step in enumerate(steps):
        if step is not None and pd.api.types.is_float_dtype(frame.iloc[:, j].dtype):
            frame[frame.columns[j]] = fixed_text(frame.iloc[:, j].to_numpy(), step)
        elif j in given:
            frame[frame.columns[j]] = given[j]
    buffer = io.StringIO()
    frame.to_csv(buffer, index=False, lineterminator="\n", float_format=None)
    return buffer.getvalue()
