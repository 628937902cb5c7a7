"""A text table laid out as bytes, a block of rows at a time: what pandas'
``DataFrame.to_string(index=False, na_rep="", float_format=lambda v: f"{v:.4f}")`` writes,
the same bytes, for listings of millions of rows (``hexatherm inspect`` of a scanning
probe's points file: 2.4 million rows), without a Python string per cell.

pandas' layout, as these columns reproduce it: every column right-aligned to its widest
cell or its header, the columns joined by one space, a line per row. A numeric column's
header has a space before its name (pandas leaves room for a sign); integers are written
as ``f"{v:d}"``; floats with the format, NaN as nothing; texts as they are. A text that
pandas would escape (a tab, a line break) or that is not ASCII (a column's width counts
characters, not bytes) is not laid out here: :func:`text_column` returns None and the
caller lets pandas write the table.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.io.csvout import POW10, fixed_fields
from hexatherm.io.records import seconds_to_iso, seconds_to_iso_fields

#: rows laid out at a time: a block's bytes (a few MB), never the whole text
BLOCK_ROWS = 65_536
#: the decimals of every float column (the listing's ``float_format``)
DECIMALS = 4
_SPACE = ord(" ")


class Column(Protocol):
    """One column of a table: its cells right-aligned in a field of bytes."""

    #: integers and floats: pandas puts a space before the header's name
    numeric: bool

    def width(self) -> int:
        """The longest cell's length."""

    def cells(self, start: int, stop: int, width: int) -> npt.NDArray[np.uint8]:
        """The cells of rows ``start:stop``, right-aligned: shape ``(stop - start, width)``."""


def _blank_left(field: npt.NDArray[np.uint8], length: npt.NDArray[np.intp]) -> None:
    """Spaces left of each row's last ``length`` bytes, in place."""
    columns = np.arange(field.shape[1])
    field[columns < (field.shape[1] - length)[:, None]] = _SPACE


def _fit(field: npt.NDArray[np.uint8], width: int) -> npt.NDArray[np.uint8]:
    """Right-aligned fields cut or padded (spaces) on the left to ``width`` bytes (the
    bytes cut are spaces: ``width`` is at least every cell's length)."""
    have = field.shape[1]
    if have >= width:
        return field[:, have - width :]
    out = np.full((field.shape[0], width), _SPACE, np.uint8)
    out[:, width - have :] = field
    return out


class IntColumn:
    """Integers, ``f"{v:d}"``."""

    numeric = True

    def __init__(self, values: npt.ArrayLike) -> None:
        self.values = np.asarray(values, dtype=np.int64)

    def width(self) -> int:
        if not self.values.size:
            return 0
        return max(len(f"{int(self.values.min()):d}"), len(f"{int(self.values.max()):d}"))

    def cells(self, start: int, stop: int, width: int) -> npt.NDArray[np.uint8]:
        values = self.values[start:stop]
        if values.size and int(values.min()) == np.iinfo(np.int64).min:  # no magnitude
            field = np.full((values.size, width), _SPACE, np.uint8)
            for row, value in enumerate(values.tolist()):
                text = f"{value:d}".encode("ascii")
                field[row, width - len(text) :] = np.frombuffer(text, np.uint8)
            return field
        # every place's digit at once, the places left of a number's first digit blank
        magnitude = np.abs(values)
        places = min(width, POW10.size)
        digits = magnitude[:, None] // POW10[places - 1 :: -1] % 10
        field = np.full((values.size, width), _SPACE, np.uint8)
        field[:, width - places :] = digits + ord("0")
        count = np.searchsorted(POW10[1:], magnitude, side="right") + 1
        _blank_left(field, count)
        signs = np.flatnonzero(values < 0)
        field[signs, width - 1 - count[signs]] = ord("-")
        return field


class FloatColumn:
    """Floats with :data:`DECIMALS` decimals as Python's ``format`` writes them (``-0.0000``
    for a negative value that rounds to zero, ``inf``, ``-inf``), NaN as nothing: the
    digits by :func:`~hexatherm.io.csvout.fixed_fields`."""

    numeric = True

    def __init__(self, values: npt.ArrayLike) -> None:
        self.values = np.asarray(values, dtype=float)

    def width(self) -> int:
        # the text's length grows with the magnitude for each sign: the longest of a
        # sign is the text of its largest finite magnitude (infinities apart)
        values = self.values
        finite = values[np.isfinite(values)]
        texts = ["inf"] if np.any(values == np.inf) else []
        texts += ["-inf"] if np.any(values == -np.inf) else []
        for side in (finite[~np.signbit(finite)], finite[np.signbit(finite)]):
            if side.size:
                texts.append(f"{float(side[np.argmax(np.abs(side))]):.{DECIMALS}f}")
        return max(map(len, texts), default=0)

    def cells(self, start: int, stop: int, width: int) -> npt.NDArray[np.uint8]:
        values = self.values[start:stop]
        if np.isnan(values).all():  # na_rep: nothing (a points file's sizes)
            return np.full((values.size, width), _SPACE, np.uint8)
        field, length = fixed_fields(values, 10.0**-DECIMALS)
        length = length.astype(np.intp)
        # fixed_fields writes a value that rounds to zero as 0.0000; format keeps its sign
        have = field.shape[1]
        lost = np.flatnonzero(np.signbit(values) & ~np.isnan(values) & (length > 0))
        lost = lost[field[lost, have - length[lost]] != ord("-")]
        if lost.size:
            field[lost, have - length[lost] - 1] = ord("-")
            length[lost] += 1
        _blank_left(field, length)
        return _fit(field, width)


class TextColumn:
    """Texts given once each (``texts``, ASCII) and a row's text by its code (``codes``,
    None: every row the first text)."""

    numeric = False

    def __init__(self, texts: Sequence[str], codes: npt.ArrayLike | None, rows: int) -> None:
        self.texts = list(texts)
        self.codes = None if codes is None else np.asarray(codes, dtype=np.intp)
        self.rows = rows
        self._tables: dict[int, npt.NDArray[np.uint8]] = {}

    def width(self) -> int:
        if self.codes is None:
            return len(self.texts[0]) if self.rows else 0
        used = np.flatnonzero(np.bincount(self.codes, minlength=len(self.texts)))
        return max((len(self.texts[i]) for i in used.tolist()), default=0)

    def cells(self, start: int, stop: int, width: int) -> npt.NDArray[np.uint8]:
        table = self._table(width)
        if self.codes is None:
            return np.broadcast_to(table[0], (stop - start, width))
        return table[self.codes[start:stop]]

    def _table(self, width: int) -> npt.NDArray[np.uint8]:
        """Every text right-aligned in ``width`` bytes (made once a width); a text no row
        uses may be longer: its last ``width`` bytes."""
        if self._tables.get(width) is None:
            texts = np.array(self.texts, dtype=np.bytes_)
            longest = max(width, texts.dtype.itemsize)
            field = np.strings.rjust(texts, longest).view(np.uint8).reshape(-1, longest)
            self._tables[width] = field[:, longest - width :]
        return self._tables[width]


def text_column(texts: Sequence[str], codes: npt.ArrayLike | None, rows: int) -> TextColumn | None:
    """A :class:`TextColumn`, or None when a text is not plain ASCII or holds a tab or a
    line break (pandas escapes those and counts characters: it lays the table out)."""
    for text in texts:
        if not text.isascii() or any(c in text for c in "\t\r\n"):
            return None
    return TextColumn(texts, codes, rows)


class IsoColumn:
    """POSIX seconds as ISO 8601 texts in UTC (``seconds_to_iso``), 26 characters."""

    numeric = False

    def __init__(self, seconds: npt.ArrayLike) -> None:
        self.seconds = np.asarray(seconds, dtype=float)

    def width(self) -> int:
        return 26 if self.seconds.size else 0

    def cells(self, start: int, stop: int, width: int) -> npt.NDArray[np.uint8]:
        seconds = self.seconds[start:stop]
        field = seconds_to_iso_fields(seconds)
        if field is None:  # before 1970: datetime writes them
            texts = b"".join(seconds_to_iso(v).encode("ascii") for v in seconds.tolist())
            field = np.frombuffer(texts, np.uint8).reshape(-1, 26).copy()
        return _fit(field, width)


def text_table(
    columns: Sequence[tuple[str, Column]], rows: int, block_rows: int | None = None
) -> Iterator[bytes]:
    """The table's text, the header line first, then ``block_rows`` lines at a time
    (default :data:`BLOCK_ROWS`); every line ends with a line break (``to_string``'s text
    and the one ``echo`` adds)."""
    block_rows = block_rows or BLOCK_ROWS
    heads = [(" " + name if column.numeric else name) for name, column in columns]
    widths = [
        max(len(head), column.width()) for head, (_, column) in zip(heads, columns, strict=True)
    ]
    yield (" ".join(h.rjust(w) for h, w in zip(heads, widths, strict=True)) + "\n").encode("ascii")
    line = sum(widths) + len(widths)  # the separators and the line break
    for start in range(0, rows, block_rows):
        stop = min(rows, start + block_rows)
        block = np.full((stop - start, line), _SPACE, np.uint8)
        at = 0
        for (_, column), width in zip(columns, widths, strict=True):
            block[:, at : at + width] = column.cells(start, stop, width)
            at += width + 1
        block[:, -1] = ord("\n")
        yield block.tobytes()
