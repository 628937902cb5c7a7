"""Result tables of ``hexatherm process``: ``poses.csv``, ``legs.csv`` and the screen table.

``poses.csv`` has the contract columns first (spec: "Results of hexatherm
process"), then these extensions, documented in the README:

* ``Tx_cmd_mm`` .. ``Rz_cmd_deg``: the commanded pose of the target;
* ``dq_leg1_um`` .. ``dq_leg6_um``: thermal growth of each leg at S_i (relative
  to the first reference), subtracted from its leg lengths;
* ``ref_before``, ``ref_after``: labels of the references used (empty: none);
* ``dt_before_s``, ``dt_after_s``: ``t_S - t_before`` and ``t_after - t_S``;
* ``weight_after``: weight of the later reference in the time interpolation.

``legs.csv`` has one row per step: ``label,kind,time``, the step's measured pose
relative to O (``Tx_mm`` ...), its IGM leg lengths ``q_leg1_mm`` .. and, for
reference steps, the growth since R0 ``dq_leg1_um`` ..
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.io.atomic import atomic_output_dir
from hexatherm.io.records import seconds_to_iso
from hexatherm.pipeline import ProcessResult, nominal_fit_diameter_mm

POSE_NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
POSE_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")
LEGS = range(1, 7)


def pose_columns(tag: str) -> list[str]:
    """``Tx_<tag>_mm, ..., Rz_<tag>_deg`` (``tag`` may be empty)."""
    mid = f"_{tag}" if tag else ""
    return [f"{n}{mid}_{u}" for n, u in zip(POSE_NAMES, POSE_UNITS, strict=True)]


CONTRACT_COLUMNS = ["label", "time", *pose_columns("conv"), *pose_columns("corr")]


def _times(result: ProcessResult, seconds: np.ndarray) -> list[str] | np.ndarray:
    if result.centres.time_kind == "iso":
        return [seconds_to_iso(s) for s in seconds]
    return seconds


def poses_frame(result: ProcessResult) -> pd.DataFrame:
    """The ``poses.csv`` table, one row per target."""
    corr = result.correction
    plan = result.session.plan
    idx = corr.target_index
    labels = np.array(plan.labels, dtype=object)
    data: dict[str, object] = {
        "label": labels[idx],
        "time": _times(result, result.centres.times_s[idx]),
    }
    for cols, values in ((pose_columns("conv"), corr.conventional),
                         (pose_columns("corr"), corr.corrected),
                         (pose_columns("cmd"), plan.poses[idx])):
        for j, col in enumerate(cols):
            data[col] = values[:, j]
    for leg in LEGS:
        data[f"dq_leg{leg}_um"] = corr.growth_mm[:, leg - 1] * 1e3
    data["ref_before"] = np.where(corr.before_index >= 0, labels[corr.before_index], "")
    data["ref_after"] = np.where(corr.after_index >= 0, labels[corr.after_index], "")
    data["dt_before_s"] = corr.dt_before_s
    data["dt_after_s"] = corr.dt_after_s
    data["weight_after"] = corr.weight_after
    return pd.DataFrame(data)


def legs_frame(result: ProcessResult) -> pd.DataFrame:
    """The ``legs.csv`` table, one row per step."""
    plan = result.session.plan
    steps = result.steps
    data: dict[str, object] = {
        "label": list(plan.labels),
        "kind": list(plan.kinds),
        "time": _times(result, result.centres.times_s),
    }
    for j, col in enumerate(pose_columns("")):
        data[col] = steps.pose[:, j]
    for leg in LEGS:
        data[f"q_leg{leg}_mm"] = steps.q_mm[:, leg - 1]
    refs = plan.reference_indices
    growth = np.full_like(steps.q_mm, np.nan)
    if refs.size:
        growth[refs] = (steps.q_mm[refs] - steps.q_mm[refs[0]]) * 1e3
    for leg in LEGS:
        data[f"dq_leg{leg}_um"] = growth[:, leg - 1]
    data["registration_rms_um"] = result.registration.rms_um
    return pd.DataFrame(data)


def fits_frame(result: ProcessResult) -> pd.DataFrame:
    """The ``fits.csv`` table: quality of every ball centre, one row per step and ball.

    ``source`` is ``points`` (fitted by hexatherm) or ``centres`` (given by the
    file); ``diameter_dev_um`` is the fitted diameter minus the nominal one (ball
    diameter, plus the tip's when points are not probe-compensated).
    """
    balls = result.session.balls
    nominal = dict(zip(balls.names, nominal_fit_diameter_mm(balls), strict=True))
    frames = []
    for rec in result.records:
        n = len(rec)
        nan = np.full(n, np.nan)
        diameter = rec.diameter_mm if rec.diameter_mm is not None else nan
        fitted = "n" in rec.extra
        frames.append(pd.DataFrame({
            "label": rec.label, "ball": rec.ball,
            "source": "points" if fitted else "centres",
            "file": Path(rec.path).name,
            "n": rec.extra.get("n", np.full(n, 1)),
            "diameter_mm": diameter,
            "diameter_dev_um": (diameter - np.array([nominal[b] for b in rec.ball])) * 1e3,
            "form_um": rec.extra.get("form_um", nan),
            "rms_um": rec.extra.get("rms_um", nan),
            "cap_deg": rec.extra.get("cap_deg", nan),
            "u_centre_um": rec.extra.get("u_um", nan),
        }))
    return pd.concat(frames, ignore_index=True)


def to_csv_text(frame: pd.DataFrame) -> str:
    """CSV text with numbers written to round-trip exactly (shortest repr)."""
    buffer = io.StringIO()
    frame.to_csv(buffer, index=False, lineterminator="\n", float_format=None)
    return buffer.getvalue()


def write_results(result: ProcessResult, out: str | Path, overwrite: bool = False) -> list[Path]:
    """Write ``poses.csv``, ``legs.csv``, ``fits.csv`` into ``out``, replacing it atomically."""
    tables = {"poses.csv": poses_frame(result), "legs.csv": legs_frame(result),
              "fits.csv": fits_frame(result)}
    texts = {name: to_csv_text(frame) for name, frame in tables.items()}
    with atomic_output_dir(out, overwrite=overwrite) as tmp:
        for name, text in texts.items():
            (tmp / name).write_text(text, encoding="utf-8", newline="")
    return [Path(out) / name for name in texts]


def deviation_table(result: ProcessResult) -> str:
    """Side-by-side table of conventional and corrected deviations from the commanded pose.

    Translations in micrometres, rotations in microradians.
    """
    corr = result.correction
    plan = result.session.plan
    cmd = plan.poses[corr.target_index]

    def deviations(pose: np.ndarray) -> np.ndarray:
        dev = pose - cmd
        return np.column_stack([dev[:, :3] * 1e3, np.deg2rad(dev[:, 3:]) * 1e6])

    conv, cor = deviations(corr.conventional), deviations(corr.corrected)
    labels = [plan.labels[i] for i in corr.target_index]
    width = max([5, *map(len, labels)])
    names = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
    block = " ".join(f"{n:>8}" for n in names)
    lines = [
        f"{'':{width}}  {'conventional - commanded':^53}  |  {'corrected - commanded':^53}",
        f"{'step':{width}}  {block}  |  {block}",
        f"{'':{width}}  {'(um)':>26} {'(urad)':>26}  |  {'(um)':>26} {'(urad)':>26}",
    ]
    for label, a, b in zip(labels, conv, cor, strict=True):
        left = " ".join(f"{v:8.3f}" for v in a)
        right = " ".join(f"{v:8.3f}" for v in b)
        lines.append(f"{label:{width}}  {left}  |  {right}")
    if len(labels) > 1:
        lines.append(
            f"{'spread':{width}}  " + " ".join(f"{v:8.3f}" for v in np.ptp(conv, axis=0))
            + "  |  " + " ".join(f"{v:8.3f}" for v in np.ptp(cor, axis=0))
        )
    return "\n".join(lines)
