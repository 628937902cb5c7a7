"""Any measurement file: centres or points CSV, or DMIS output (by extension or content)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from hexatherm.io.csvfile import read_measurement_csv, read_text
from hexatherm.io.dmis import looks_like_dmis, read_dmis
from hexatherm.io.records import Records


def read_measurements(
    path: str | os.PathLike[str],
    *,
    progress: Callable[[int, int], None] | None = None,
    allow_truncated: bool = False,
    keep_later: bool = False,
) -> list[Records]:
    """Read any measurement file: centres/points CSV or DMIS output (by extension or content).

    ``progress(lines_done, lines_total)``, when given, is called now and then while a
    DMIS file is read the slow way (one with continuations or comments: seconds for
    a hundred thousand points); a CSV file or a plain DMIS file reports once, done.
    ``allow_truncated`` and ``keep_later``: as for :func:`read_measurement_csv` and
    :func:`~hexatherm.io.dmis.read_dmis` (a DMIS file without ``ENDFIL``).
    """
    path = os.fspath(path)
    suffix = Path(path).suffix.lower()
    if suffix in (".dmo", ".dms", ".dmi"):
        return read_dmis(
            path, progress=progress, allow_truncated=allow_truncated, keep_later=keep_later
        )
    if suffix != ".csv":
        text = read_text(path)
        if looks_like_dmis(text[:4096]):
            return read_dmis(
                path, progress=progress, allow_truncated=allow_truncated, keep_later=keep_later
            )
    records = [read_measurement_csv(path, allow_truncated=allow_truncated, keep_later=keep_later)]
    if progress is not None:
        progress(len(records[0]) + 1, len(records[0]) + 1)
    return records
