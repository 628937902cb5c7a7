"""A flat listing of the features of any measurement file (for ``hexatherm inspect``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.csvtext import read_text
from hexatherm.io.dmis import DMIS_SUFFIXES, looks_like_dmis, read_dmis_features
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.records import seconds_to_iso

COLUMNS = ["line", "label", "type", "x_mm", "y_mm", "z_mm", "size_mm", "time"]


def feature_table(path: str | os.PathLike[str], reading: ReadOptions = STRICT) -> pd.DataFrame:
    """Every feature of a DMIS output or a centres/points CSV, one row each (``reading``:
    a file cut short, a ball probed twice in one step, as the other commands read it)."""
    path = Path(path)
    if path.suffix.lower() in DMIS_SUFFIXES or (
        path.suffix.lower() != ".csv" and looks_like_dmis(read_text(path)[:4096])
    ):
        rows = []
        for feat in read_dmis_features(path, allow_truncated=reading.allow_truncated):
            xyz = feat.xyz_mm if feat.xyz_mm is not None else (np.nan,) * 3
            rows.append(
                [
                    feat.line,
                    feat.label,
                    feat.type,
                    *xyz,
                    np.nan if feat.size_mm is None else feat.size_mm,
                    "" if feat.time is None else feat.time.isoformat(),
                ]
            )
        return pd.DataFrame(rows, columns=COLUMNS)
    rec = read_measurement_csv(
        path, allow_truncated=reading.allow_truncated, keep_later=reading.keep_later
    )
    times = [seconds_to_iso(t) for t in rec.time_s] if rec.time_kind == "iso" else rec.time_s
    return pd.DataFrame(
        {
            "line": rec.line,
            "label": np.char.add(np.char.add(rec.label, "_"), rec.ball),
            "type": "SPHERE" if rec.kind == "centres" else "POINT",
            "x_mm": rec.xyz_mm[:, 0],
            "y_mm": rec.xyz_mm[:, 1],
            "z_mm": rec.xyz_mm[:, 2],
            "size_mm": rec.diameter_mm if rec.diameter_mm is not None else np.nan,
            "time": times,
        }
    )[COLUMNS]


def program_without_actuals(path: str | os.PathLike[str], table: pd.DataFrame) -> bool:
    """Whether ``path`` is a DMIS program (nominal ``F(...)`` features and ``MEAS``
    statements, as ``plan --dmis`` writes) rather than a CMM's output: it has no actual
    feature ``FA(...)`` to list."""
    if len(table):
        return False
    text = read_text(Path(path))
    if not looks_like_dmis(text[:4096]):
        return False
    lines = [line.lstrip().upper() for line in text.splitlines()]
    return any(line.startswith("MEAS/") for line in lines) and not any(
        line.startswith("FA(") for line in lines
    )
