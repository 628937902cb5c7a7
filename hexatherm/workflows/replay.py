"""Re-process recorded sessions and compare with their ``expected/`` results.

Every session folder that holds an ``expected/`` folder is processed again with
the default options; each CSV of ``expected/`` is compared with the new one:
same columns, same rows, text cells equal, numbers within a tolerance chosen by
the column's unit (:func:`~hexatherm.io.csvout.column_unit`: ``_mm``, ``_deg``,
``_um``, ``_urad``, ``_um2``, ``_urad2``, ``_ppm``, ``_C``, ``_s``; others relative
1e-9), at least 1.5 steps of the resolution the files are written at; a column
written at a resolution of its own (``jacobian_rcond``, a correlation) and
``parameters.csv``'s values in their row's unit likewise.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.io.csvout import ROW_RESOLUTION, column_unit
from hexatherm.workflows.calibrate.outputs import (
    CORRELATION_RESOLUTION,
    ROW_UNIT_COLUMNS,
    output_files,
)
from hexatherm.workflows.calibrate.run import calibrate, read_campaign
from hexatherm.workflows.process.outputs import RCOND_RESOLUTION, write_results
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.quality import quality_checks

#: absolute tolerance per unit (:func:`~hexatherm.io.csvout.column_unit`). Result files
#: are written at a resolution per unit (:data:`~hexatherm.io.csvout.RESOLUTION`): a
#: value sitting on a rounding boundary flips by one step for the tiniest change (another
#: BLAS, another CPU), so each tolerance is at least 1.5 steps (one step plus half a
#: step's margin); deg keeps its older, wider 1e-6 (10 steps) and seconds, written
#: exactly, 1e-6 s.
DEFAULT_TOLERANCES = {
    "mm": 1.5e-7,
    "deg": 1e-6,
    "um": 1.5e-4,
    "urad": 1.5e-3,
    "um2": 1.5e-6,
    "urad2": 1.5e-6,
    "ppm": 1.5e-4,
    "C": 1.5e-4,
    "degC": 1.5e-4,
    "s": 1e-6,
}


@dataclass
class Comparison:
    """Outcome of replaying one session."""

    session: str
    mismatches: list[str] = field(default_factory=list)
    worst: dict[str, float] = field(default_factory=dict)  # unit -> worst |difference|
    files: list[str] = field(default_factory=list)
    updated: list[str] = field(default_factory=list)  # files rewritten (update)
    repaired: bool = False  # update rewrote every mismatching file

    @property
    def ok(self) -> bool:
        return not self.mismatches


#: columns without a unit written at a resolution of their own (csv_text's
#: ``resolutions``): a tolerance of 1.5 steps, as the units'
WRITTEN_AT = {
    "max_abs_correlation": CORRELATION_RESOLUTION,
    "jacobian_rcond": RCOND_RESOLUTION,
}


def row_tolerance(unit: str, tolerances: dict[str, float]) -> float:
    """The tolerance of a value in ``unit`` named by its row (``parameters.csv``): the
    unit's, 1.5 steps of :data:`~hexatherm.io.csvout.ROW_RESOLUTION` for a gain (mm/mm),
    else relative 1e-9."""
    if unit in tolerances:
        return tolerances[unit]
    if unit in ROW_RESOLUTION:
        return 1.5 * ROW_RESOLUTION[unit]
    return 1e-9


def tolerance_for(column: str, tolerances: dict[str, float]) -> tuple[str, float]:
    """Unit and absolute tolerance of a column (unit ``rel`` means relative 1e-9)."""
    unit = column_unit(column)
    if unit in tolerances:
        return unit, tolerances[unit]
    return "rel", 1e-9


def compare_tables(
    name: str,
    expected: pd.DataFrame,
    got: pd.DataFrame,
    tolerances: dict[str, float],
    result: Comparison,
) -> None:
    """Compare two tables cell by cell, recording mismatches that name row and column."""
    if list(expected.columns) != list(got.columns):
        missing = [c for c in expected.columns if c not in got.columns]
        extra = [c for c in got.columns if c not in expected.columns]
        result.mismatches.append(
            f"{result.session}/{name}: columns differ (missing {missing}, new {extra})"
        )
        return
    if len(expected) != len(got):
        result.mismatches.append(
            f"{result.session}/{name}: {len(got)} rows, expected {len(expected)}"
        )
        return
    key = expected["label"].astype(str).tolist() if "label" in expected else None
    row_units = expected["unit"].astype(str).to_numpy() if "unit" in expected else None
    for column in expected.columns:
        a, b = expected[column], got[column]
        row_name = (lambda i: f"row {i + 2} ({key[i]})") if key else (lambda i: f"row {i + 2}")
        if pd.api.types.is_numeric_dtype(a) and pd.api.types.is_numeric_dtype(b):
            x, y = a.to_numpy(dtype=float), b.to_numpy(dtype=float)
            unit, tol = tolerance_for(column, tolerances)
            both_nan = np.isnan(x) & np.isnan(y)
            diff = np.where(both_nan, 0.0, np.abs(x - y))
            limit = tol if unit != "rel" else tol * np.maximum(np.abs(x), 1.0)
            if row_units is not None and column in ROW_UNIT_COLUMNS:
                # parameters.csv: each row's value in its own unit, at its resolution
                limit = np.array([row_tolerance(u, tolerances) for u in row_units])
                limit = np.where(np.isnan(limit), 1e-9 * np.maximum(np.abs(x), 1.0), limit)
                tol = float(np.max(limit))
            elif column in WRITTEN_AT:
                limit = tol = 1.5 * WRITTEN_AT[column]
            bad = ~(diff <= limit) & ~both_nan
            finite = diff[np.isfinite(diff)]
            if finite.size and unit != "rel":
                result.worst[unit] = max(result.worst.get(unit, 0.0), float(finite.max()))
            if np.any(bad):
                i = int(np.argmax(bad))
                result.mismatches.append(
                    f"{result.session}/{name}: {row_name(i)}, column {column}: "
                    f"expected {float(x[i])!r}, got {float(y[i])!r} "
                    f"(|diff| {diff[i]:.3g} > {tol:g})"
                )
        else:
            sa, sb = a.fillna("").astype(str), b.fillna("").astype(str)
            bad = (sa != sb).to_numpy()
            if np.any(bad):
                i = int(np.argmax(bad))
                result.mismatches.append(
                    f"{result.session}/{name}: {row_name(i)}, column {column}: "
                    f"expected {sa.iloc[i]!r}, got {sb.iloc[i]!r}"
                )


def replay_session(
    folder: Path, tolerances: dict[str, float] | None = None, update: bool = False
) -> Comparison:
    """Process ``folder`` and compare with (or, with ``update``, rewrite) ``expected/``.

    A session that does not process, or whose ``expected`` is not a folder, is a
    mismatch naming why. With ``update``, only the CSV files whose values moved beyond
    the tolerances (or that are new) are rewritten, and listed in
    ``Comparison.updated``; nothing else in ``expected/`` is touched (a CSV file that
    ``process`` no longer writes stays a mismatch, to be removed by hand).

    A session whose ``expected/`` holds a ``calibration/`` folder is a calibration
    campaign: it is also calibrated as ``hexatherm calibrate`` does (level chosen, the
    corrected poses), and ``parameters.csv`` and ``residuals.csv`` are compared there.
    """
    from hexatherm.errors import HexathermError

    tolerances = tolerances or DEFAULT_TOLERANCES
    result = Comparison(folder.name)
    expected_dir = folder / "expected"
    if expected_dir.is_symlink() or not expected_dir.is_dir():
        what = "a link" if expected_dir.is_symlink() else "not a folder"
        result.mismatches.append(f"{folder.name}/expected: {what}; expected/ must be a folder")
        return result
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        try:
            processed = process_session(folder)
            write_results(processed, out, quality=quality_checks(processed))
        except HexathermError as exc:
            result.mismatches.append(f"{folder.name}: does not process: {exc}")
            return result
        if (expected_dir / "calibration").is_dir():
            try:
                calibrated = calibrate(read_campaign([folder]))
            except HexathermError as exc:
                result.mismatches.append(f"{folder.name}: does not calibrate: {exc}")
                return result
            (out / "calibration").mkdir()
            for name, text in output_files(calibrated).items():
                if name.endswith(".csv"):
                    (out / "calibration" / name).write_text(text, encoding="utf-8")
        names = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.csv"))
        result.files = names
        changed: list[str] = []
        for name in names:
            got = pd.read_csv(out / name)
            exp_path = expected_dir / name
            if not exp_path.is_file():
                result.mismatches.append(f"{folder.name}/{name}: not in expected/")
                changed.append(name)
                continue
            before = len(result.mismatches)
            compare_tables(name, pd.read_csv(exp_path), got, tolerances, result)
            if len(result.mismatches) > before:
                changed.append(name)
        stale = sorted(
            p.relative_to(expected_dir).as_posix()
            for p in expected_dir.rglob("*.csv")
            if p.relative_to(expected_dir).as_posix() not in names
        )
        for name in stale:
            result.mismatches.append(f"{folder.name}/{name}: no longer written by process")
        if update:
            from hexatherm.io.atomic import atomic_write_text

            for name in changed:
                atomic_write_text(expected_dir / name, (out / name).read_text(encoding="utf-8"))
                result.updated.append(f"{folder.name}/expected/{name}")
            # a CSV that process no longer writes stays (it may be someone's): named above
            result.repaired = not stale
    return result


def find_sessions(root: Path) -> list[Path]:
    """Session folders under ``root`` (or ``root`` itself) that have an ``expected``
    entry (a folder, or anything else there, which :func:`replay_session` reports)."""
    candidates = (
        [root]
        if (root / "session.yaml").exists()
        else sorted(p for p in root.iterdir() if p.is_dir())
    )
    return [
        p
        for p in candidates
        if ((p / "expected").exists() or (p / "expected").is_symlink())
        and (p / "session.yaml").exists()
    ]


def format_worst(worst: dict[str, float]) -> str:
    """``mm 1.2e-12, deg 3e-13`` style summary."""
    return ", ".join(f"{unit} {value:.1e}" for unit, value in sorted(worst.items())) or "-"
