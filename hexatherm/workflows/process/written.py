"""A results folder that ``process`` wrote, read back: what ``report``'s page draws.

``report`` renders the numbers ``process`` wrote and computes none of them again (issue
34): :func:`read_written` turns ``poses.csv``, ``legs.csv`` and ``quality.csv`` (with the
options and notes of ``provenance.json``, and the session's own files: its plan, its
thermocouple log) into the few things the page asks of a processed session. A
:class:`WrittenResult` answers as a :class:`~hexatherm.workflows.process.pipeline.
ProcessResult` does where the page reads one (the steps' times, the targets' poses, the
legs at every step, the registration residuals, the temperatures), a
:class:`WrittenUncertainty` as a :class:`~hexatherm.workflows.process.uncertainty.
PoseUncertainty` (the u columns and their common and own parts), and the quality checks
are a :class:`~hexatherm.workflows.process.quality.QualityReport` again, whose limits are
the ones ``process`` recorded.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hexatherm.errors import ResultsError
from hexatherm.io.files import ReadOptions
from hexatherm.io.records import iso_to_seconds
from hexatherm.session import Session
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.quality import NA, QualityReport
from hexatherm.workflows.process.views import (
    CentresNote,
    WrittenCentres,
    WrittenCorrection,
    WrittenRegistration,
    WrittenResult,
    WrittenSteps,
    WrittenUncertainty,
)

POSE = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
UNITS = ("mm",) * 3 + ("deg",) * 3


def _column(frame: pd.DataFrame, name: str, path: Path) -> FloatArray:
    if name not in frame.columns:
        raise ResultsError(f"{path}: no column {name!r} (not a file process wrote)")
    try:
        return frame[name].to_numpy(dtype=float)
    except (TypeError, ValueError):
        raise ResultsError(f"{path}: column {name!r} is not numbers") from None


def _read_csv(path: Path) -> pd.DataFrame:
    if not path.is_file():
        raise ResultsError(f"{path} is missing from the results folder: run process again")
    try:
        return pd.read_csv(path, keep_default_na=True, na_values=[""])
    except (OSError, ValueError) as exc:
        raise ResultsError(f"{path}: not a CSV file process wrote ({exc})") from None


def _seconds(values: pd.Series, kind: str) -> FloatArray:
    if kind == "iso":
        return np.array([iso_to_seconds(str(v)) for v in values])
    return values.to_numpy(dtype=float)


def _to_mm_deg(um_urad: FloatArray) -> FloatArray:
    """(..., 6) in um and urad (the deviation columns) to mm and deg."""
    out = np.array(um_urad, dtype=float)
    out[..., :3] = out[..., :3] * 1e-3
    out[..., 3:] = np.rad2deg(out[..., 3:] * 1e-6)
    return out


def _poses(frame: pd.DataFrame, tag: str, path: Path, prefix: str = "") -> FloatArray:
    return np.column_stack(
        [_column(frame, f"{prefix}{n}_{tag}_{u}", path) for n, u in zip(POSE, UNITS, strict=True)]
    )


def _parts(frame: pd.DataFrame, part: str, path: Path) -> FloatArray | None:
    names = [
        f"u_{part}_d{n}_{tag}_{'um' if n[0] == 'T' else 'urad'}"
        for tag in ("conv", "corr")
        for n in POSE
    ]
    if not all(name in frame.columns for name in names):
        return None
    values = np.column_stack([_column(frame, name, path) for name in names])
    return np.concatenate([_to_mm_deg(values[:, :6]), _to_mm_deg(values[:, 6:])], axis=1)


def _quality(path: Path, session: Session, thresholds: tuple[str, ...]) -> QualityReport | None:
    """``quality.csv`` as the checks' report again: a check that could not run at a step
    (its value empty) is :data:`NA` there, ``failed`` empty where nothing failed."""
    from hexatherm.workflows.process.outputs import NO_LEG, NONE_TEXT
    from hexatherm.workflows.process.quality import CHECKS, parse_threshold, session_thresholds

    if not path.is_file():
        return None
    frame = _read_csv(path)
    for check, (column, _, _) in CHECKS.items():
        values = _column(frame, column, path)
        ok = frame[f"ok_{check}"].astype(str).str.lower() == "true"
        frame[f"ok_{check}"] = [
            NA if np.isnan(v) else bool(o) for v, o in zip(values, ok, strict=True)
        ]
    for column in ("growth_leg", "warming_leg"):
        frame[column] = [("" if int(v) == NO_LEG else int(v)) for v in frame[column]]
    frame["failed"] = [
        "" if str(text) in (NONE_TEXT, "nan") else str(text) for text in frame["failed"]
    ]
    overrides = dict(parse_threshold(t) for t in thresholds)
    return QualityReport(frame, session_thresholds(session, overrides))


def read_written(
    folder: Path,
    session: Session,
    options: Mapping[str, Any],
    notes: Mapping[str, Any],
    reading: ReadOptions,
) -> tuple[WrittenResult, WrittenUncertainty, QualityReport | None]:
    """The results folder ``folder`` that ``process`` wrote for ``session`` with
    ``options`` (its ``provenance.json``), read back; ResultsError naming a file that is
    not what process writes. With the controller's frames set during the session
    (``run.yaml``), the session is seen from its frame O as ``process`` saw it
    (:func:`~hexatherm.workflows.process.frames.session_in_origin`)."""
    from hexatherm.workflows.process.frames import session_frames, session_in_origin
    from hexatherm.workflows.process.measured import session_temperatures

    session = session_in_origin(session, session_frames(session).values)

    poses_path, legs_path = folder / "poses.csv", folder / "legs.csv"
    poses, legs = _read_csv(poses_path), _read_csv(legs_path)
    plan = session.plan
    if [str(v) for v in legs["label"]] != list(plan.labels):
        raise ResultsError(f"{legs_path}: its steps are not the session plan's: run process again")
    position = {label: i for i, label in enumerate(plan.labels)}
    try:
        target_index = np.array([position[str(v)] for v in poses["label"]], dtype=np.intp)
    except KeyError as exc:
        raise ResultsError(f"{poses_path}: step {exc} is not in the session's plan") from None
    temperatures = session_temperatures(session, reading)
    kind = "seconds" if temperatures is not None and temperatures.time_kind == "seconds" else None
    texts = legs["time"].astype(str)
    if kind is None:
        kind = "iso" if texts.str.contains("T").all() else "seconds"
    aware = None if kind != "iso" else bool(texts.str.endswith("+00:00").all())
    result = WrittenResult(
        session=session,
        centres=WrittenCentres(_seconds(legs["time"], kind), kind, aware),
        correction=WrittenCorrection(
            target_index, _poses(poses, "conv", poses_path), _poses(poses, "corr", poses_path)
        ),
        steps=WrittenSteps(
            np.column_stack([_column(legs, f"q_leg{i}_mm", legs_path) for i in range(1, 7)])
        ),
        registration=WrittenRegistration(_column(legs, "registration_rms_um", legs_path)),
        temperatures=temperatures,
        interpolation=str(options.get("interpolation", "linear")),
        warnings=tuple(str(w) for w in notes.get("warnings", ())),
    )
    mc = int(options.get("mc") or 0)
    uncertainty = WrittenUncertainty(
        conventional_u=_poses(poses, "conv", poses_path, "u_"),
        corrected_u=_poses(poses, "corr", poses_path, "u_"),
        common_u=_parts(poses, "common", poses_path),
        own_u=_parts(poses, "own", poses_path),
        method="monte-carlo" if mc else "linear",
        draws=mc,
        seed=int(options.get("seed") or 0) if mc else None,
        centres=CentresNote(str(notes.get("centres_uncertainty", "not recorded"))),
    )
    thresholds = tuple(options.get("quality_thresholds") or ())
    quality = _quality(folder / "quality.csv", session, thresholds)
    return result, uncertainty, quality
