"""Result tables of ``hexatherm process``: poses, legs, fits, quality and the screen table.

``poses.csv`` has the contract columns first (spec: "Results of hexatherm
process"), then these extensions, documented in docs/files.md:

* ``Tx_cmd_mm`` .. ``Rz_cmd_deg``: the commanded pose of the target;
* ``dq_leg1_um`` .. ``dq_leg6_um``: thermal growth of each leg at S_i (relative
  to the first reference), subtracted from its leg lengths;
* ``ref_before``, ``ref_after``: labels of the references used (``none``: none);
* ``dt_before_s``, ``dt_after_s``: ``t_S - t_before`` and ``t_after - t_S``;
* ``weight_after``: weight of the later reference in the time interpolation;
* ``interpolation`` (with ``--interpolation smooth`` only): ``smooth`` when the smooth
  fit of the growth was used, ``linear`` when the cross-validation fell back to the
  two neighbours;
* ``u_Tx_conv_mm`` .. ``u_Rz_conv_deg``, ``u_Tx_corr_mm`` .. ``u_Rz_corr_deg``:
  standard uncertainties (k = 1) of the conventional and corrected poses
  (:mod:`hexatherm.workflows.process.uncertainty`);
* the deviations from the commanded pose ``dTx_conv_um`` .., each followed by its
  standard uncertainty ``u_dTx_conv_um`` and its parts common to all targets (from O
  and R0) and of its own, ``u_common_dTx_conv_um`` and ``u_own_dTx_conv_um``.

Numbers are written at the resolution of their unit (:mod:`hexatherm.io.csvout`).

``covariance.csv`` has the covariance of every deviation between every pair of
targets (:func:`covariance_frame`).

``quality.csv`` has one row per step with the quality checks of
:mod:`hexatherm.workflows.process.quality` (:func:`quality_file_frame`: ``ok_*``
``True``/``False``, ``failed`` never empty, legs as whole numbers).

``legs.csv`` has one row per step: ``label,kind,time``, the step's measured pose
relative to O (``Tx_mm`` ...), its IGM leg lengths ``q_leg1_mm`` .. and, for
reference steps, the growth since R0 ``dq_leg1_um`` ..
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from hexatherm.core.geometry import to_um_urad
from hexatherm.core.plan import known_indices
from hexatherm.io.csvout import csv_bytes
from hexatherm.io.outputs import output_dir
from hexatherm.workflows.process.measured import nominal_fit_diameter_mm

if TYPE_CHECKING:
    from hexatherm.workflows.process.conformity import Conformity
    from hexatherm.workflows.process.pipeline import ProcessResult
    from hexatherm.workflows.process.quality import QualityReport
    from hexatherm.workflows.process.uncertainty import PoseUncertainty
    from hexatherm.workflows.process.views import Processed, Uncertain

POSE_NAMES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
POSE_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")
LEGS = range(1, 7)
#: the text of ``quality.csv``'s ``failed`` and ``poses.csv``'s ``ref_before`` /
#: ``ref_after`` where there is nothing to name: never empty, which pandas would read as
#: NaN (a column of floats in a session where nothing failed)
NONE_TEXT = "none"
#: ``quality.csv``'s ``growth_leg`` / ``warming_leg`` where the check names no leg (legs
#: are 1 to 6): a whole number, so the column reads as integers in every session
NO_LEG = 0
#: the resolution ``jacobian_rcond`` is written at: 1e-6 of a ratio at most 1, three
#: significant digits at the default limit of 0.01 (a condition number is known to a few
#: per cent, not to 17 digits)
RCOND_RESOLUTION = 1e-6


def pose_columns(tag: str) -> list[str]:
    """``Tx_<tag>_mm, ..., Rz_<tag>_deg`` (``tag`` may be empty)."""
    mid = f"_{tag}" if tag else ""
    return [f"{n}{mid}_{u}" for n, u in zip(POSE_NAMES, POSE_UNITS, strict=True)]


def deviation_columns(tag: str) -> list[str]:
    """``dTx_<tag>_um, ..., dRz_<tag>_urad``: pose minus commanded pose, um and urad."""
    units = ("um", "um", "um", "urad", "urad", "urad")
    return [f"d{n}_{tag}_{u}" for n, u in zip(POSE_NAMES, units, strict=True)]


CONTRACT_COLUMNS = ["label", "time", *pose_columns("conv"), *pose_columns("corr")]


def _times(result: ProcessResult, seconds: np.ndarray) -> list[str] | np.ndarray:
    if result.centres.time_kind == "iso":
        return result.centres.time_texts(seconds)
    return seconds


def poses_frame(
    result: ProcessResult,
    uncertainty: PoseUncertainty | None = None,
    twin: np.ndarray | None = None,
    conformity: Conformity | None = None,
) -> pd.DataFrame:
    """The ``poses.csv`` table, one row per target.

    ``u_*`` columns with ``uncertainty``; ``*_twin_*`` columns (after the contract
    columns) with ``twin``, the twin-corrected poses (M, 6); the conformity columns
    (:meth:`Conformity.columns`, last) with ``conformity``.
    """
    corr = result.correction
    plan = result.session.plan
    idx = corr.target_index
    labels = np.array(plan.labels, dtype=object)
    data: dict[str, object] = {
        "label": labels[idx],
        "time": _times(result, result.centres.times_s[idx]),
    }
    blocks = [(pose_columns("conv"), corr.conventional), (pose_columns("corr"), corr.corrected)]
    if twin is not None:
        blocks.append((pose_columns("twin"), np.asarray(twin)))
    blocks.append((pose_columns("cmd"), plan.poses[idx]))
    for cols, values in blocks:
        for j, col in enumerate(cols):
            data[col] = values[:, j]
    for leg in LEGS:
        data[f"dq_leg{leg}_um"] = corr.growth_mm[:, leg - 1] * 1e3
    data["ref_before"] = np.where(corr.before_index >= 0, labels[corr.before_index], NONE_TEXT)
    data["ref_after"] = np.where(corr.after_index >= 0, labels[corr.after_index], NONE_TEXT)
    data["dt_before_s"] = corr.dt_before_s
    data["dt_after_s"] = corr.dt_after_s
    data["weight_after"] = corr.weight_after
    if corr.smooth is not None:
        # --interpolation smooth: what the growth at R came from (the fallback is linear)
        data["interpolation"] = "smooth" if corr.smooth.used else "linear"
    if uncertainty is not None:
        for tag, values in (
            ("conv", uncertainty.conventional_u),
            ("corr", uncertainty.corrected_u),
        ):
            for j, col in enumerate(pose_columns(tag)):
                data[f"u_{col}"] = values[:, j]
    # the deviations from the commanded pose that the screen and the report show, um and
    # urad, each beside its standard uncertainty in the same unit
    commanded = plan.poses[idx]
    measured = [("conv", corr.conventional), ("corr", corr.corrected)]
    if twin is not None:
        measured.append(("twin", np.asarray(twin)))
    u_of = (
        {}
        if uncertainty is None
        else {
            "conv": to_um_urad(uncertainty.conventional_u),
            "corr": to_um_urad(uncertainty.corrected_u),
        }
    )
    parts_of: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if uncertainty is not None:
        common, own = uncertainty.common_u, uncertainty.own_u
        if common is not None and own is not None:
            for tag, half in (("conv", slice(0, 6)), ("corr", slice(6, 12))):
                parts_of[tag] = (to_um_urad(common[:, half]), to_um_urad(own[:, half]))
    for tag, values in measured:
        dev = to_um_urad(values - commanded)
        for j, col in enumerate(deviation_columns(tag)):
            data[col] = dev[:, j]
            if tag in u_of:
                data[f"u_{col}"] = u_of[tag][:, j]
            if tag in parts_of:
                data[f"u_common_{col}"] = parts_of[tag][0][:, j]
                data[f"u_own_{col}"] = parts_of[tag][1][:, j]
    if conformity is not None:
        data.update(conformity.columns())
    return pd.DataFrame(data)


def covariance_frame(result: ProcessResult, uncertainty: PoseUncertainty) -> pd.DataFrame:
    """The ``covariance.csv`` table: covariance of each deviation between two targets.

    One row per pair of targets ``label_a, label_b`` (``a`` not after ``b`` in the plan,
    each pair once, ``a = b`` included: there it is ``u^2``), then
    ``cov_dTx_conv_um2`` .. ``cov_dRz_conv_urad2``, ``cov_dTx_corr_um2`` ..
    ``cov_dRz_corr_urad2``: the covariance of that deviation (as in ``poses.csv``) of
    target a with the same of target b, um^2 and urad^2. Every pair shares O's and R0's
    noise; neighbours share a reference too, and two targets of one interval between
    references their interpolation's own error.
    """
    between = uncertainty.between_covariance
    if between is None:
        raise ValueError("the uncertainty has no between-target covariance")
    plan = result.session.plan
    labels = np.array(plan.labels, dtype=object)[result.correction.target_index]
    a, b = np.triu_indices(len(labels))
    data: dict[str, object] = {"label_a": labels[a], "label_b": labels[b]}
    # mm -> um and deg -> urad, squared
    to_unit2 = np.tile(
        [1e6, 1e6, 1e6, (np.pi / 180 * 1e6) ** 2, *[(np.pi / 180 * 1e6) ** 2] * 2], 2
    )
    names = [*deviation_columns("conv"), *deviation_columns("corr")]
    for y, name in enumerate(names):
        data[f"cov_{name}2"] = between[y, a, b] * to_unit2[y]
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
    nominal = nominal_fit_diameter_mm(balls)
    frames = []
    for rec in result.records:
        n = len(rec)
        nan = np.full(n, np.nan)
        diameter = rec.diameter_mm if rec.diameter_mm is not None else nan
        fitted = "n" in rec.extra
        frames.append(
            pd.DataFrame(
                {
                    "label": rec.label,
                    "ball": rec.ball,
                    "source": "points" if fitted else "centres",
                    "file": Path(rec.path).name,
                    "n": rec.extra.get("n", np.full(n, 1)),
                    "diameter_mm": diameter,
                    "diameter_dev_um": (diameter - nominal[known_indices(balls.names, rec.ball)])
                    * 1e3,
                    "form_um": rec.extra.get("form_um", nan),
                    "rms_um": rec.extra.get("rms_um", nan),
                    "cap_deg": rec.extra.get("cap_deg", nan),
                    "u_centre_um": rec.extra.get("u_um", nan),
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


def write_results(
    result: ProcessResult,
    out: str | Path,
    overwrite: bool = False,
    uncertainty: PoseUncertainty | None = None,
    quality: QualityReport | None = None,
    twin: np.ndarray | None = None,
    conformity: Conformity | None = None,
    extra_inputs: Sequence[Path] = (),
    notes: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Write ``poses.csv``, ``legs.csv``, ``fits.csv``, ``covariance.csv`` (and
    ``quality.csv``) into ``out``; ``extra_inputs`` are files read besides the session's
    (the ``--hexapod`` model of ``--method twin``), never replaced either.

    The folder is replaced atomically. ``uncertainty`` defaults to linear
    propagation (:func:`hexatherm.workflows.process.uncertainty.pose_uncertainty`); ``quality.csv``
    is written when ``quality`` is given (``hexatherm process`` always gives it);
    ``twin`` (M, 6) adds the twin-corrected poses (``process --method twin``);
    ``conformity`` the conformity columns (``process --tolerance``); ``notes`` go into
    ``provenance.json`` (what ``report`` says beyond the CSV files).
    """
    if uncertainty is None:
        from hexatherm.workflows.process.uncertainty import pose_uncertainty

        uncertainty = pose_uncertainty(result)
    tables = {
        "poses.csv": poses_frame(result, uncertainty, twin, conformity),
        "legs.csv": legs_frame(result),
        "fits.csv": fits_frame(result),
    }
    if uncertainty.between_covariance is not None:
        tables["covariance.csv"] = covariance_frame(result, uncertainty)
    if quality is not None:
        tables["quality.csv"] = quality_file_frame(quality)
    texts = {
        name: csv_bytes(frame, resolutions={"jacobian_rcond": RCOND_RESOLUTION})
        for name, frame in tables.items()
    }
    inputs = [*session_inputs(result), *extra_inputs]
    with output_dir(out, inputs=inputs, overwrite=overwrite, notes=notes) as tmp:
        for name, text in texts.items():
            (tmp / name).write_bytes(text)
    return [Path(out) / name for name in texts]


def quality_file_frame(quality: QualityReport) -> pd.DataFrame:
    """``quality.csv``'s table, one dtype per column whatever the session (pandas reads
    it without cleaning): every ``ok_<check>`` a boolean, False exactly where the check
    ran and failed (where it could not run its value is empty and it passes, as the
    checks count it: the screen and the report say n/a); ``growth_leg`` and
    ``warming_leg`` whole numbers (:data:`NO_LEG` where no leg is named); ``failed`` the
    failed checks, ``;``-separated, :data:`NONE_TEXT` when none."""
    from hexatherm.workflows.process.quality import NA

    frame = quality.frame.copy()
    for column in frame.columns:
        if str(column).startswith("ok_"):
            cells = frame[column].to_numpy(dtype=object)
            # NA (the check could not run: it passes) or the cell's truth, cell by cell in C
            frame[column] = (cells == NA) | cells.astype(bool)
    for column in ("growth_leg", "warming_leg"):
        values = frame[column].tolist()
        frame[column] = np.array([int(v) if v != "" else NO_LEG for v in values])
    frame["failed"] = [text or NONE_TEXT for text in frame["failed"].tolist()]
    return frame


def session_inputs(result: ProcessResult) -> list[Path]:
    """The files the run read (:meth:`~hexatherm.session.Session.input_files`)."""
    return result.session.input_files()


#: the most targets the screen table shows whole; of a longer campaign it shows the first
#: and last :data:`SCREEN_ENDS` and says where all of them are (pandas' ``display.max_rows``
#: and ``min_rows`` alike: 10,000 targets are 20,000 lines no one reads on a terminal)
SCREEN_TARGETS = 60
#: targets shown at each end of a shortened screen table
SCREEN_ENDS = 5


def deviation_table(
    result: ProcessResult,
    twin: np.ndarray | None = None,
    uncertainty: PoseUncertainty | None = None,
    coverage_factor: float = 2.0,
    poses_csv: str | Path | None = None,
) -> str:
    """Side-by-side table of conventional and corrected deviations from the commanded pose.

    Translations in micrometres, rotations in microradians; with ``twin`` (M, 6) a
    third block: the poses corrected by the twin from the thermocouples. With
    ``uncertainty`` every target's row is followed by its expanded uncertainties
    ``U = k u`` (``coverage_factor``), each under its value (the twin's block has none).
    The last row is the spread (max - min) of every column over all the targets.

    With ``poses_csv`` (the file that holds every target's deviations) a campaign of more
    than :data:`SCREEN_TARGETS` targets is shortened to its first and last
    :data:`SCREEN_ENDS` targets, a line between them saying how many more there are and
    where they all are.
    """
    corr = result.correction
    plan = result.session.plan
    cmd = plan.poses[corr.target_index]

    def deviations(pose: np.ndarray) -> np.ndarray:
        return to_um_urad(pose - cmd)

    tables = [deviations(corr.conventional), deviations(corr.corrected)]
    titles = ["conventional - commanded", "corrected - commanded"]
    expanded: list[np.ndarray | None] = [None, None]
    if uncertainty is not None:
        expanded = [
            coverage_factor * to_um_urad(uncertainty.conventional_u),
            coverage_factor * to_um_urad(uncertainty.corrected_u),
        ]
    if twin is not None:
        tables.append(deviations(np.asarray(twin)))
        titles.append("twin-corrected - commanded")
        expanded.append(None)
    labels = [plan.labels[i] for i in corr.target_index]
    u_label = f"U k={coverage_factor:g}"
    width = max([5, len(u_label) + 2, *map(len, labels)])
    names = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
    block = " ".join(f"{n:>8}" for n in names)
    units = f"{'(um)':>26} {'(urad)':>26}"
    lines = [
        f"{'':{width}}  " + "  |  ".join(f"{t:^53}" for t in titles),
        f"{'step':{width}}  " + "  |  ".join(block for _ in titles),
        f"{'':{width}}  " + "  |  ".join(units for _ in titles),
    ]
    shown = np.arange(len(labels))
    if poses_csv is not None and len(labels) > SCREEN_TARGETS:
        shown = np.r_[0:SCREEN_ENDS, len(labels) - SCREEN_ENDS : len(labels)]
    # Python floats, one format per row: numpy scalars format the same, several times slower
    row_text = " ".join(["{:8.3f}"] * 6).format
    values = [table[shown].tolist() for table in tables]
    u_values = [None if u is None else u[shown].tolist() for u in expanded]
    u_head = f"{'  ' + u_label:{width}}  "
    for row, i in enumerate(shown.tolist()):
        if row == SCREEN_ENDS and len(shown) < len(labels):
            lines.append(
                f"... {len(labels) - len(shown):,} more targets: every target's deviations "
                f"(dTx_conv_um ...) and standard uncertainties (u_dTx_conv_um ...) are in "
                f"{poses_csv}"
            )
        lines.append(f"{labels[i]:{width}}  " + "  |  ".join(row_text(*v[row]) for v in values))
        if uncertainty is not None:
            lines.append(
                u_head
                + "  |  ".join(
                    " " * 53
                    if u is None
                    else " ".join(f"{'±' + format(v, '.3f'):>8}" for v in u[row])
                    for u in u_values
                )
            )
    if len(labels) > 1:
        lines.append(
            f"{'spread':{width}}  "
            + "  |  ".join(" ".join(f"{v:8.3f}" for v in np.ptp(table, axis=0)) for table in tables)
        )
    return "\n".join(lines)


def insignificant_corrections(
    result: Processed, uncertainty: Uncertain, coverage_factor: float = 2.0
) -> list[tuple[str, float, float]]:
    """The components whose thermal correction (the largest |corrected - conventional|
    over the targets) is smaller than the corrected poses' expanded uncertainty (their
    median ``U = k u`` over the targets): ``(name, correction, U)``, um or urad. There
    the correction is not significant: the pose is not known better than it moved."""
    corr = result.correction
    effect = np.abs(to_um_urad(corr.corrected - corr.conventional)).max(axis=0)
    big_u = coverage_factor * np.median(to_um_urad(uncertainty.corrected_u), axis=0)
    names = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
    return [
        (names[j], float(effect[j]), float(big_u[j]))
        for j in range(6)
        if effect.size and effect[j] < big_u[j]
    ]


def significance_lines(
    result: ProcessResult, uncertainty: PoseUncertainty, coverage_factor: float = 2.0
) -> list[str]:
    """The screen's word on the correction's significance, one line per component where
    it is smaller than its U (none: every correction exceeds its U)."""
    lines = []
    for name, effect, big_u in insignificant_corrections(result, uncertainty, coverage_factor):
        unit = "um" if name[0] == "T" else "urad"
        lines.append(
            f"not significant: the thermal correction of {name} (at most {effect:.3f} {unit}) "
            f"is smaller than its U ({big_u:.3f} {unit}, k = {coverage_factor:g}, median over "
            f"the targets): on {name} the corrected pose is not known better than the "
            "correction moved it"
        )
    return lines
