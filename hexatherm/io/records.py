"""Measured records: what a measurement file holds, whatever its format.

A measurement file (centres CSV, points CSV, DMIS output, a serial capture) is
read into one or more :class:`Records`: rows of ``(label, ball, x, y, z, time)``
in the CMM frame M, each with the line of the file it came from so that later
errors can point at it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Literal

import numpy as np
import numpy.typing as npt

RecordKind = Literal["centres", "points"]
TimeKind = Literal["iso", "seconds"]


@dataclass(frozen=True)
class Records:
    """Rows of measured ball centres or surface points from one file.

    Attributes
    ----------
    path : str
        The file the rows were read from (for messages).
    kind : {"centres", "points"}
        Ball centres (one row per step and ball) or probed surface points.
    label, ball : ndarray of str, shape (n,)
        Step label and ball name of each row.
    xyz_mm : ndarray, shape (n, 3)
        Coordinates in the CMM frame M, mm.
    time_s : ndarray, shape (n,)
        Time of each row in seconds: POSIX seconds (UTC) when ``time_kind`` is
        ``"iso"``, the file's own numbers when it is ``"seconds"``.
    time_kind : {"iso", "seconds"}
        How the file wrote its times.
    line : ndarray of int, shape (n,)
        1-based line of the file each row starts on.
    diameter_mm : ndarray, shape (n,), optional
        Fitted diameter of each centre row (NaN where the file gave none).
    ijk : ndarray, shape (n, 3), optional
        Probing direction of each point row (NaN where the file gave none).
    """

    path: str
    kind: RecordKind
    label: npt.NDArray[np.str_]
    ball: npt.NDArray[np.str_]
    xyz_mm: npt.NDArray[np.float64]
    time_s: npt.NDArray[np.float64]
    time_kind: TimeKind
    line: npt.NDArray[np.int64]
    diameter_mm: npt.NDArray[np.float64] | None = None
    ijk: npt.NDArray[np.float64] | None = None
    extra: dict[str, object] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.xyz_mm.shape[0])


def iso_to_seconds(text: str) -> float:
    """Parse an ISO 8601 timestamp into POSIX seconds; naive times are taken as UTC.

    >>> iso_to_seconds("2020-01-01T00:00:10")
    1577836810.0
    >>> iso_to_seconds("2020-01-01T01:00:10+01:00")
    1577836810.0
    """
    stamp = datetime.fromisoformat(text.strip())
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=UTC)
    return stamp.timestamp()


def seconds_to_iso(seconds: float) -> str:
    """Format POSIX seconds as an ISO 8601 UTC timestamp (microseconds kept).

    >>> seconds_to_iso(1577836810.25)
    '2020-01-01T00:00:10.250000'
    """
    stamp = datetime.fromtimestamp(float(seconds), tz=UTC).replace(tzinfo=None)
    return stamp.isoformat(timespec="microseconds")


def concat_records(records: list[Records]) -> Records:
    """Join records of one kind and time kind (the first one's path names the result)."""
    first = records[0]
    if any(r.kind != first.kind or r.time_kind != first.time_kind for r in records):
        raise ValueError("records of different kinds or time kinds cannot be joined")

    def join(name: str) -> npt.NDArray[np.float64] | None:
        values = [getattr(r, name) for r in records]
        return None if any(v is None for v in values) else np.concatenate(values)

    keys = set.intersection(*(set(r.extra) for r in records))
    extra: dict[str, object] = {
        key: np.concatenate([np.asarray(r.extra[key]) for r in records]) for key in keys
    }
    return Records(
        path=first.path,
        kind=first.kind,
        label=np.concatenate([r.label for r in records]),
        ball=np.concatenate([r.ball for r in records]),
        xyz_mm=np.concatenate([r.xyz_mm for r in records]),
        time_s=np.concatenate([r.time_s for r in records]),
        time_kind=first.time_kind,
        line=np.concatenate([r.line for r in records]),
        diameter_mm=join("diameter_mm"),
        ijk=join("ijk"),
        extra=extra,
    )
