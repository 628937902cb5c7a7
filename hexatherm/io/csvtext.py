"""The text of a CSV file, before its columns mean anything: UTF-8 decoding, ``;``
separators, a last line cut short, and the frame of stripped cells that every CSV
reader (:mod:`hexatherm.io.csvfile`, :mod:`hexatherm.io.temperatures`) starts from."""

from __future__ import annotations

import csv
import io
import os
import re
import warnings

import numpy as np
import pandas as pd

from hexatherm.errors import InputError, InputWarning
from hexatherm.io.files import read_bytes, refuse_utf16


def read_text(path: str | os.PathLike[str]) -> str:
    """A CSV file's text as UTF-8 (BOM allowed), any line ending, with ``,`` separators
    (:func:`semicolons_to_commas`); InputError when it is not a regular file of a sane
    size, unreadable, UTF-16 or otherwise not UTF-8, or binary."""
    path = os.fspath(path)
    return decode_text(read_bytes(path), path)


def decode_text(raw: bytes, path: str) -> str:
    """:func:`read_text` of a file's bytes read before."""
    refuse_utf16(raw, path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(f"not UTF-8 text ({exc.reason})", path=path, line=line) from None
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise InputError("NUL byte: not a text file", path=path, line=line)
    return semicolons_to_commas(text)


def semicolons_to_commas(text: str) -> str:
    """The text of a CSV file written with ``;`` separators (and ``,`` decimal commas,
    as a European spreadsheet exports it) as the same file with ``,`` and ``.``.

    The separator is told from the first line that is neither blank nor a ``#``
    comment: ``;`` and no ``,`` there means a semicolon file. Every character keeps its
    line, so messages name the same lines and fields. Names (steps, balls, columns)
    hold neither character.

    >>> semicolons_to_commas("Tx;Ty;Tz;Rx;Ry;Rz\\n1,5;0;0;0;0;0,25\\n")
    'Tx,Ty,Tz,Rx,Ry,Rz\\n1.5,0,0,0,0,0.25\\n'
    >>> semicolons_to_commas("label,ball,x\\nO,B1,1.5\\n")  # a comma file: as it is
    'label,ball,x\\nO,B1,1.5\\n'
    """
    start = 0
    while start < len(text):
        # from the top, a piece at a time, not the whole text (a 20 MB file) split
        ends = [i for i in (text.find("\n", start), text.find("\r", start)) if i >= 0]
        end = min(ends, default=len(text))
        for line in text[start:end].splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                if ";" in line and "," not in line:
                    return text.replace(",", ".").replace(";", ",")
                return text
        start = end + 1
    return text


def complete_lines(text: str, path: str, allow_truncated: bool) -> str:
    """``text`` (line ends made LF) when its last line ends with a line break; else
    InputError naming the line and the field it ends in, or with ``allow_truncated``
    the text without that line and an :class:`InputWarning`."""
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    cut = text.rfind("\n") + 1
    last = text[cut:]
    if not last.strip():
        return text
    line = text.count("\n", 0, cut) + 1
    header = text.partition("\n")[0].split(",")
    index = last.count(",")
    field = header[index].strip() if line > 1 and index < len(header) else None
    inside = f", inside field '{field}'" if field else ""
    if allow_truncated:
        warnings.warn(
            InputWarning(
                f"{path}:{line}: the file ends without a line break{inside}: "
                "its last line dropped (cut short?)"
            ),
            stacklevel=3,
        )
        return text[:cut]
    raise InputError(
        f"the file ends without a line break{inside}: cut short? (a complete file ends "
        "with a line break; --allow-truncated drops this line)",
        path=path,
        line=line,
        field=field,
    )


def csv_frame(text: str, path: str) -> pd.DataFrame:
    """All cells as stripped strings; row ``r`` of the result is file line ``r + 2``."""
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    if not text.strip():
        raise InputError("empty file: expected a header line", path=path, line=1)
    # before pandas, which renames a repeated column ("air", "air.1") instead of saying so
    try:
        first = next(csv.reader(io.StringIO(text.partition("\n")[0])), [])
    except csv.Error:
        first = []  # pandas names what is wrong with it
    header = [name.strip() for name in first]
    seen: set[str] = set()
    for number, name in enumerate(header, 1):
        if not name:
            raise InputError(f"column {number} of the header has no name", path=path, line=1)
        if name in seen:
            raise InputError(
                f"column {name!r} appears twice in the header", path=path, line=1, field=name
            )
        seen.add(name)
    try:
        frame = pd.read_csv(
            io.StringIO(text),
            dtype=str,
            keep_default_na=False,
            skip_blank_lines=False,
            skipinitialspace=True,
            engine="c",
        )
    except pd.errors.ParserError as exc:
        found = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", str(exc))
        if found:
            expected, line, saw = (int(g) for g in found.groups())
            raise InputError(
                f"expected {expected} comma-separated fields, found {saw}", path=path, line=line
            ) from None
        raise InputError(f"malformed CSV: {exc}", path=path) from None
    except (ValueError, pd.errors.EmptyDataError) as exc:
        raise InputError(f"malformed CSV: {exc}", path=path, line=1) from None
    frame.columns = [str(c).strip() for c in frame.columns]
    if '"' not in text:
        _refuse_short_rows(text, list(frame.columns), path)
    frame.index = np.arange(len(frame)) + 2
    frame = frame.fillna("")
    return frame.apply(lambda col: col.str.strip())


def _refuse_short_rows(text: str, columns: list[str], path: str) -> None:
    """A row with fewer fields than the header (pandas would fill them in as empty): cut
    short, or a value missing without its comma. Blank lines are left alone."""
    expected = len(columns) - 1
    for number, line in enumerate(text.split("\n")[1:], start=2):
        found = line.count(",")
        if found < expected and line.strip():
            raise InputError(
                f"expected {expected + 1} comma-separated fields, found {found + 1}: "
                f"'{columns[found + 1]}' and after are missing (cut short?)",
                path=path,
                line=number,
                field=columns[found + 1],
            )
