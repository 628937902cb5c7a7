"""Any measurement file: centres or points CSV, DMIS output or QIF results (by extension or
content)."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.csvtext import read_text
from hexatherm.io.files import open_bounded
from hexatherm.io.records import Records
from hexatherm.session import MeasurementFormat

#: the farthest a measured coordinate may lie from the CMM's origin, mm: 100 m, beyond any
#: CMM or laser tracker (a file written in um, or a number run wild, lies beyond)
COORDINATE_MAX_MM = 1e5


def check_coordinates(records: Records) -> Records:
    """``records``, or an InputError naming the first coordinate farther than
    :data:`COORDINATE_MAX_MM` from the CMM's origin (file, line and field ``x``, ``y`` or
    ``z``).

    >>> import numpy as np
    >>> rec = Records("c.csv", "centres", np.array(["O"]), np.array(["B1"]),
    ...               np.array([[426.7, 406.9, 2.4e5]]), np.zeros(1), "seconds", np.array([2]))
    >>> try:
    ...     check_coordinates(rec)
    ... except InputError as error:
    ...     print(error)
    c.csv:2: field 'z': 240000 mm: farther than 100 m from the CMM's origin (a file in um?)
    """
    far = ~(np.abs(records.xyz_mm) <= COORDINATE_MAX_MM)
    if np.any(far):
        row, axis = (int(i) for i in np.argwhere(far)[0])
        raise InputError(
            f"{records.xyz_mm[row, axis]:g} mm: farther than {COORDINATE_MAX_MM / 1e3:g} m "
            "from the CMM's origin (a file in um?)",
            path=records.path,
            line=int(records.line[row]),
            field="xyz"[axis],
        )
    return records


def read_measurements(
    path: str | os.PathLike[str],
    *,
    progress: Callable[[int, int], None] | None = None,
    allow_truncated: bool = False,
    keep_later: bool = False,
    spec: MeasurementFormat | None = None,
    labels: Sequence[str] | None = None,
    names: Mapping[str, str | None] | None = None,
) -> list[Records]:
    """Read any measurement file: centres/points CSV, DMIS output or QIF 3 results (by
    extension or content: :func:`is_qif`).

    ``spec``: the session's format of a mapped entry (a column map, a folder of Calypso
    runs; :func:`read_mapped`), ``labels`` the plan's steps it may need.

    ``progress(lines_done, lines_total)``, when given, is called now and then while a
    DMIS file is read the slow way (one with continuations or comments: seconds for
    a hundred thousand points); a CSV file or a plain DMIS file reports once, done.
    ``allow_truncated`` and ``keep_later``: as for :func:`read_measurement_csv` and
    :func:`~hexatherm.io.dmis.read_dmis` (a DMIS file without ``ENDFIL``).
    ``names``: a QIF file's feature names to ``<step>_<ball>`` (session.yaml's
    ``feature_names``; :func:`~hexatherm.io.qif.read_qif`).
    """
    path = os.fspath(path)
    if spec is not None:
        return read_mapped(path, spec, labels, allow_truncated, keep_later)
    suffix = Path(path).suffix.lower()
    if is_qif(path):
        from hexatherm.io.qif import read_qif

        records = read_qif(path, names=names, keep_later=keep_later)
        if progress is not None:
            progress(1, 1)
        return [check_coordinates(r) for r in records]
    # the DMIS and QIF readers (lxml) are imported only for a file that may be one
    dmis = False
    if suffix != ".csv":
        from hexatherm.io.dmis import DMIS_SUFFIXES, looks_like_dmis

        dmis = suffix in DMIS_SUFFIXES or looks_like_dmis(read_text(path)[:4096])
    if dmis:
        from hexatherm.io.dmis import read_dmis

        records = read_dmis(
            path, progress=progress, allow_truncated=allow_truncated, keep_later=keep_later
        )
    else:
        records = [
            read_measurement_csv(path, allow_truncated=allow_truncated, keep_later=keep_later)
        ]
        if progress is not None:
            progress(len(records[0]) + 1, len(records[0]) + 1)
    return [check_coordinates(r) for r in records]


def read_mapped(
    path: str,
    spec: MeasurementFormat,
    labels: Sequence[str] | None,
    allow_truncated: bool,
    keep_later: bool,
) -> list[Records]:
    """A measurement entry that ``session.yaml`` maps (an extension): a table through a
    column map (:mod:`hexatherm.io.tables`) or a folder of Calypso runs
    (:mod:`hexatherm.io.calypso`), coordinates checked."""
    from hexatherm.io.calypso import read_calypso
    from hexatherm.io.tables import read_table

    if spec.kind == "calypso":
        found = read_calypso(
            path, spec, labels, allow_truncated=allow_truncated, keep_later=keep_later
        )
    else:
        found = [read_table(path, spec, allow_truncated=allow_truncated, keep_later=keep_later)]
    return [check_coordinates(r) for r in found]


def is_qif(path: str | os.PathLike[str]) -> bool:
    """Whether a measurement file is read as QIF: suffix ``.qif`` (any case), or, unless it
    is ``.csv`` or a DMIS suffix, a first 4 KiB that opens a ``QIFDocument``."""
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return False
    from hexatherm.io.dmis import DMIS_SUFFIXES

    if suffix in DMIS_SUFFIXES:
        return False
    from hexatherm.io.qif import QIF_SUFFIXES, looks_like_qif

    if suffix in QIF_SUFFIXES:
        return True
    with open_bounded(path) as stream:
        return looks_like_qif(stream.read(4096))
