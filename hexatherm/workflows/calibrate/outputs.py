"""The files ``hexatherm calibrate`` writes, and its table on screen.

- ``hexapod.yaml``: the calibrated geometry in the hexapod file contract (base joints in
  frame O, as ``process`` needs them; stroke, legs and effects of the nominal file),
  with a ``calibration:`` record: level, poses (and the twin's model file with its
  SHA-256 for ``twin`` poses), sessions, the actuators' leg offsets and
  gains (for the controller), chi-square per degree of freedom, version, time.
- ``parameters.csv``: every parameter of the level: ``parameter,unit,nominal,calibrated,
  u,change_um,change_ppm,u_um,u_ppm,max_abs_correlation`` (the base joints in the fit's
  gauge, see :mod:`hexatherm.core.calibration`).
- ``residuals.csv``: every target: ``target``, then measured minus commanded (what the
  nominal geometry leaves) and measured minus the calibrated prediction (held out when
  the level was chosen), um and urad.
- ``calibration.json``: level and how it was chosen (every level's BIC and held-out
  RMS), chi-square and degrees of freedom, singular values, condition number and the
  observability indices O1..O5, the pairs of parameters with |rho| > 0.9, the
  predicted-pose standard uncertainty at the targets (worst and RMS), and the claim for
  a new pose over the campaign's span (``new_pose_claim``: worst and typical standard
  uncertainty, the level's model floor and how it was estimated, and the claim by stroke
  region and along each axis of the campaign's box; see
  :mod:`hexatherm.workflows.calibrate.claim`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from hexatherm import __version__
from hexatherm.core.calibration import PARAMETER_NAMES, PARAMETER_UNITS
from hexatherm.core.residuals import POSE_COMPONENTS, rms
from hexatherm.io.config import hexapod_to_yaml
from hexatherm.io.csvout import csv_text
from hexatherm.io.provenance import now_iso
from hexatherm.workflows.calibrate.claim import (
    REGIONS,
    ClaimAxes,
    ClaimRegions,
    PoseClaim,
    claim_along_axes,
    claim_regions,
    pose_claim,
)
from hexatherm.workflows.calibrate.frames import campaign_frames_line, campaign_frames_record
from hexatherm.workflows.calibrate.recommend import Recommendation, controller_yaml, recommend
from hexatherm.workflows.calibrate.report import (
    StrokeMap,
    not_explained,
    report_html,
    stroke_map,
)
from hexatherm.workflows.calibrate.run import Calibration, machine_hexapod

if TYPE_CHECKING:
    from hexatherm.session import Tolerance

COMPONENTS = ("dTx_um", "dTy_um", "dTz_um", "dRx_urad", "dRy_urad", "dRz_urad")


def calibrated_hexapod_yaml(run: Calibration) -> str:
    """``hexapod.yaml`` with its ``calibration:`` record."""
    fit = run.fit
    record: dict[str, Any] = {
        "level": fit.level,
        "poses": run.campaign.poses,
        "sessions": [str(r.session.path) for r in run.campaign.results],
        "n_poses": len(run.campaign.labels),
        **twin_record(run),
        "leg_offsets_mm": [float(v) for v in fit.leg_offsets_mm],
        "leg_gains": [float(v) for v in fit.leg_gains],
        "chi_square_per_dof": float(fit.chi_square_per_dof),
        "hexatherm": __version__,
        "written": now_iso(),
    }
    return hexapod_to_yaml(machine_hexapod(run), record)


def twin_record(run: Calibration) -> dict[str, str]:
    """``twin_model`` (and ``twin_model_sha256`` when read from a file) of the record for
    ``twin`` poses; nothing otherwise."""
    twin = run.campaign.twin
    if twin is None:
        return {}
    record = {"twin_model": twin.path}
    if twin.sha256 is not None:
        record["twin_model_sha256"] = twin.sha256
    return record


#: parameters.csv's columns in each row's unit (mm or mm/mm), written at its resolution
ROW_UNIT_COLUMNS = ("nominal", "calibrated", "u", "U")
#: the resolution of parameters.csv's correlations
CORRELATION_RESOLUTION = 1e-4


def parameters_csv(run: Calibration, coverage_factor: float = 2.0) -> str:
    """``parameters.csv``'s text: lengths at 1e-7 mm, gains at 1e-10 (1e-4 ppm), changes
    and uncertainties at 1e-4 um or ppm, correlations at 1e-4."""
    return csv_text(
        parameters_frame(run, coverage_factor),
        row_unit=("unit", ROW_UNIT_COLUMNS),
        resolutions={"max_abs_correlation": CORRELATION_RESOLUTION},
    )


def parameters_frame(run: Calibration, coverage_factor: float = 2.0) -> pd.DataFrame:
    """One row per parameter of the fitted level; ``U``, ``U_um``, ``U_ppm``: the expanded
    uncertainties ``k u`` with ``k = coverage_factor``."""
    fit = run.fit
    mask = fit.model.mask
    nominal = fit.model.theta0
    value = fit.parameters
    u = fit.std_errors
    gain = np.array(PARAMETER_UNITS) != "mm"
    rho = np.abs(np.nan_to_num(fit.correlation))
    np.fill_diagonal(rho, 0.0)
    frame = pd.DataFrame(
        {
            "parameter": PARAMETER_NAMES,
            "unit": PARAMETER_UNITS,
            "nominal": nominal,
            "calibrated": value,
            "u": u,
            "change_um": np.where(gain, np.nan, (value - nominal) * 1e3),
            "change_ppm": np.where(gain, (value - nominal) * 1e6, np.nan),
            "u_um": np.where(gain, np.nan, u * 1e3),
            "u_ppm": np.where(gain, u * 1e6, np.nan),
            "max_abs_correlation": rho.max(axis=1),
            "coverage_factor": np.full(len(u), float(coverage_factor)),
            "U": coverage_factor * u,
            "U_um": np.where(gain, np.nan, coverage_factor * u * 1e3),
            "U_ppm": np.where(gain, coverage_factor * u * 1e6, np.nan),
        }
    )
    return frame[mask].reset_index(drop=True)


def residuals_frame(run: Calibration) -> pd.DataFrame:
    """Before (nominal) and after (calibrated) residuals of every target, um and urad."""
    frame = pd.DataFrame({"target": run.campaign.labels})
    for k, name in enumerate(COMPONENTS):
        frame[f"{name}_nominal"] = run.residuals_before_um_urad[:, k]
    for k, name in enumerate(COMPONENTS):
        frame[f"{name}_calibrated"] = run.residuals_after_um_urad[:, k]
    return frame


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _per_component(values: Any) -> dict[str, float | None]:
    return dict(zip(COMPONENTS, map(_finite, values), strict=True))


def claim_map_record(regions: ClaimRegions, axes: ClaimAxes) -> dict[str, Any]:
    """``new_pose_claim``'s ``by_region`` and ``along_axes`` (k = 1)."""
    edges = [0.0, *map(float, regions.bounds), None]
    return {
        "by_region": {
            "radius": "a pose's distance from the centre of the campaign's box in units of "
            "its half-widths, RMS over the components the campaign varies (0 at the centre, "
            "1 at a corner); the regions are thirds of the new poses",
            "regions": [
                {
                    "region": name,
                    "radius_from": edges[k],
                    "radius_to": edges[k + 1],
                    "n_poses": int(regions.counts[k]),
                    "rms_um_urad": _per_component(regions.rms_um_urad[k]),
                    "worst_um_urad": _per_component(regions.worst_um_urad[k]),
                }
                for k, name in enumerate(REGIONS)
            ],
        },
        "along_axes": [
            {
                "axis": axis,
                "unit": "mm" if k < 3 else "deg",
                "positions": [float(v) for v in axes.positions[k]],
                "u_um_urad": [
                    None if np.isnan(row).any() else _per_component(row)
                    for row in axes.sigma_um_urad[k]
                ],
            }
            for k, axis in enumerate(POSE_COMPONENTS)
        ],
    }


def claim_record(
    claim: PoseClaim, regions: ClaimRegions | None = None, axes: ClaimAxes | None = None
) -> dict[str, Any]:
    """``calibration.json``'s ``new_pose_claim``: what the calibration claims for a pose
    it was not fitted to, over the campaign's span (standard uncertainties, k = 1), with
    ``regions`` and ``axes`` by stroke region and along each axis."""
    floor = claim.floor
    per_component = _per_component
    extra = {} if regions is None or axes is None else claim_map_record(regions, axes)
    return {
        "meaning": "standard uncertainty (k = 1) of a pose the calibrated model predicts "
        "for a new commanded pose (not one of the campaign's), relative to O in the "
        "thermal state of R0: the parameters' uncertainty propagated to the pose and the "
        "level's model floor, over poses drawn uniformly in the campaign's span inside "
        "the stroke",
        "n_poses": len(claim.poses),
        "worst_um_urad": per_component(claim.worst_um_urad),
        "typical_rms_um_urad": per_component(claim.typical_um_urad),
        "parameters_rms_um_urad": per_component(rms(claim.parameters_um_urad, axis=0)),
        "floor_um_urad": per_component(floor.sigma_um_urad),
        "floor_method": floor.method,
        "floor_note": floor.note,
        "floor_growth_um_urad": per_component(floor.growth_um_urad),
        "leg_temperature_R0_C": [[float(v) for v in row] for row in floor.leg_temperature_C],
        "leg_temperature_O_C": [[float(v) for v in row] for row in floor.origin_temperature_C],
        "leg_reference_temperature_C": _finite(floor.reference_temperature_C),
        **extra,
    }


def calibration_json(
    run: Calibration,
    stroke: StrokeMap | None = None,
    claim: PoseClaim | None = None,
    claim_map: tuple[ClaimRegions, ClaimAxes] | None = None,
    advice: Recommendation | None = None,
) -> str:
    """``calibration.json`` (see the module text); with ``stroke``, the predicted
    uncertainty over the campaign's span too; with ``claim``, the claim for new poses
    (by region and along the axes: ``claim_map``, computed when not given); with
    ``advice``, the recommendation and its tests."""
    fit = run.fit
    obs = fit.observability
    sigma = fit.predicted_sigma_um_urad(run.campaign.commanded)
    levels = []
    if run.choice is not None:
        for score in run.choice.scores:
            levels.append(
                {
                    "level": score.level,
                    "fitted": score.fit is not None,
                    "bic": _finite(score.bic),
                    "heldout_rms_whitened": _finite(score.heldout_rms_w),
                    "heldout_rms_um_urad": dict(
                        zip(COMPONENTS, map(_finite, score.heldout_rms_um_urad), strict=True)
                    )
                    if score.fit is not None
                    else None,
                    "note": score.note,
                }
            )
    doc = {
        "format": "hexatherm-calibration/1",
        "level": fit.level,
        "level_chosen": fit.level if run.choice is not None else None,
        "level_auto": run.choice is not None,
        "levels": levels,
        "poses": run.campaign.poses,
        "n_poses": len(run.campaign.labels),
        "residual_space": fit.residual_kind,
        "chi_square": float(fit.chi_square),
        "dof": int(fit.dof),
        "chi_square_per_dof": float(fit.chi_square_per_dof),
        "chi_square_p": float(fit.chi_square_p),
        "explains_poses": bool(fit.explains_poses),
        "controller_frames_during_campaign": campaign_frames_record(run),
        "rank": int(obs.rank),
        "n_parameters": int(obs.n_parameters),
        "gauge_freedoms": int(obs.n_gauge),
        "singular_values": [float(v) for v in obs.singular_values],
        "observability": {k: _finite(v) for k, v in obs.indices().items()},
        "high_correlations": [
            {"a": a, "b": b, "rho": rho} for a, b, rho in fit.high_correlations()
        ],
        "predicted_sigma_at_targets_um_urad": {
            "worst": dict(zip(COMPONENTS, map(float, sigma.max(axis=0)), strict=True)),
            "rms": dict(zip(COMPONENTS, map(float, rms(sigma, axis=0)), strict=True)),
        },
        "residual_rms_um_urad": {
            "nominal": dict(
                zip(COMPONENTS, map(float, rms(run.residuals_before_um_urad, axis=0)), strict=True)
            ),
            "calibrated": dict(
                zip(COMPONENTS, map(float, rms(run.residuals_after_um_urad, axis=0)), strict=True)
            ),
            "calibrated_heldout": run.heldout,
        },
    }
    if stroke is not None:
        doc["predicted_sigma_over_stroke_um_urad"] = {
            "worst": dict(zip(COMPONENTS, map(float, stroke.worst_um_urad), strict=True)),
            "n_poses": len(stroke.poses),
            "span_lower": [float(v) for v in stroke.lower],
            "span_upper": [float(v) for v in stroke.upper],
        }
    if claim is not None:
        if claim_map is None:
            claim_map = (claim_regions(run, claim), claim_along_axes(run))
        doc["new_pose_claim"] = claim_record(claim, *claim_map)
    if advice is not None:
        doc["recommendation"] = {
            "apply": advice.apply,
            "statement": advice.headline(),
            "parameters_chi_square": advice.changes.chi_square,
            "parameters_dof": advice.changes.dof,
            "parameters_p": advice.changes.p,
            "parameters_significant": advice.changes.significant,
            "residuals_heldout": advice.heldout,
            **{
                f"{name}_mean_square_reduction": {
                    "mean": imp.mean,
                    "u": _finite(imp.u),
                    "verdict": imp.verdict(advice.coverage_factor),
                }
                for name, imp in (
                    ("translation_um2", advice.translation),
                    ("rotation_urad2", advice.rotation),
                )
            },
        }
    return json.dumps(doc, indent=1, allow_nan=False) + "\n"


def output_files(
    run: Calibration,
    inputs: Sequence[Path] | None = None,
    folder: Path | None = None,
    lab_fields: dict[str, object] | None = None,
    coverage_factor: float = 2.0,
    template_dir: Path | None = None,
    report_number: str | None = None,
    title: str | None = None,
    tolerances: dict[str, Tolerance] | None = None,
) -> dict[str, str]:
    """Every file of the output folder, name -> text; with ``inputs`` (the files the run
    read) the report too, and the predicted uncertainty over the stroke; the claim for
    new poses (:func:`~hexatherm.workflows.calibrate.claim.pose_claim`) always (``folder``: the
    output folder, for the report's relative paths; ``lab_fields``: a lab file's
    identification for the report's header; ``coverage_factor``: k of the expanded
    uncertainties of ``parameters.csv`` and the report; ``template_dir``: a lab's
    templates for the report; ``report_number``, ``title``: the report's own;
    ``tolerances``: the lab's on the calibrated pose error, judged in the report)."""
    stroke = None if inputs is None else stroke_map(run)
    if stroke is None:
        claim = pose_claim(run)
    else:
        claim = pose_claim(run, stroke.poses, stroke.sigma_um_urad)
    claim_map = (claim_regions(run, claim), claim_along_axes(run))
    advice = recommend(run, coverage_factor)
    files = {
        "hexapod.yaml": calibrated_hexapod_yaml(run),
        "parameters.csv": parameters_csv(run, coverage_factor),
        "residuals.csv": csv_text(residuals_frame(run)),
        "calibration.json": calibration_json(run, stroke, claim, claim_map, advice),
    }
    if advice.apply:  # the controller's form, only when it is to be applied
        files["controller.yaml"] = controller_yaml(run, coverage_factor)
    if stroke is not None and inputs is not None:
        files["report.html"] = report_html(
            run,
            stroke,
            inputs,
            folder or Path("."),
            lab_fields,
            coverage_factor,
            claim,
            template_dir,
            claim_map,
            report_number,
            title,
            tolerances,
        )
    return files


def claim_lines(calibration_json_text: str, coverage_factor: float = 2.0) -> list[str]:
    """What the terminal shows of ``calibration.json``'s ``new_pose_claim``: the worst
    and typical U = k u of a new pose over the span, and the floor in it."""
    record = json.loads(calibration_json_text)["new_pose_claim"]
    k = coverage_factor
    head = f"new pose, U (k = {k:g})"
    lines = [f"{head:19} " + " ".join(f"{c:>9}" for c in COMPONENTS)]
    for name, key in (("worst", "worst_um_urad"), ("typical", "typical_rms_um_urad")):
        values = [k * v for v in record[key].values()]
        lines.append(f"{'  ' + name:19} " + " ".join(f"{v:9.3f}" for v in values))
    for region in record.get("by_region", {}).get("regions", []):
        cells = " ".join(
            f"{'':>9}" if v is None else f"{k * v:9.3f}" for v in region["rms_um_urad"].values()
        )
        lines.append(f"{'  ' + region['region'] + ' third':19} {cells}   (RMS)")
    floor = " ".join(f"{v:9.3f}" for v in record["floor_um_urad"].values())
    lines.append(
        f"{'  floor (k = 1)':19} {floor}"
        + (f"   (none: {record['floor_note']})" if record["floor_note"] else "   (in the U)")
    )
    return lines


def span_lines(run: Calibration) -> list[str]:
    """A warning when the campaign's commanded poses never vary some components: the
    new poses of the claim (drawn in their span) do not either."""
    span = np.ptp(run.campaign.commanded, axis=0)
    flat = [c for c, v in zip(POSE_COMPONENTS, span, strict=True) if v < 1e-9]
    if not flat:
        return []
    return [
        f"warning: the campaign's commanded poses never vary {', '.join(flat)}: the claim "
        "for a new pose holds only at their one value"
    ]


def unexplained_claim_lines(run: Calibration) -> list[str]:
    """A warning under the new-pose claim when the chi-square test fails: the U above
    then covers only what the model models (the report says the same beside its claim)."""
    if run.fit.explains_poses:
        return []
    after = "held-out" if run.heldout else "in-sample"
    return [
        "warning: the model does not explain the poses (chi-square, above): this U covers "
        f"only what the model models; the {after} RMS of the calibrated residuals says "
        "more of a new pose's error"
    ]


def summary_lines(run: Calibration) -> list[str]:
    """What the terminal shows: level, fit, residuals before and after."""
    fit = run.fit
    obs = fit.observability
    how = "chosen by BIC and held-out folds" if run.choice is not None else "forced"
    lines = [
        campaign_frames_line(run),
        f"level {fit.level} ({how}): {obs.n_parameters} parameters ({obs.n_gauge} fixed by the "
        f"gauge) from {len(run.campaign.labels)} {run.campaign.poses} poses; chi2/dof "
        f"{fit.chi_square_per_dof:.2f}, condition number {obs.condition_number:.3g}",
    ]
    if run.choice is not None:
        for score in run.choice.scores:
            if score.fit is None:
                lines.append(f"  {score.level:13} not fitted: {score.note}")
            else:
                lines.append(
                    f"  {score.level:13} BIC {score.bic:10.1f}  held-out RMS (whitened) "
                    f"{score.heldout_rms_w:.2f}"
                )
    after = "held out" if run.heldout else "in sample"
    lines.append(f"{'RMS':10} " + " ".join(f"{c:>9}" for c in COMPONENTS))
    lines.append(
        f"{'nominal':10} "
        + " ".join(f"{v:9.3f}" for v in rms(run.residuals_before_um_urad, axis=0))
    )
    lines.append(
        f"{'calibrated':10} "
        + " ".join(f"{v:9.3f}" for v in rms(run.residuals_after_um_urad, axis=0))
        + f"   ({after})"
    )
    if not fit.explains_poses:
        lines.append(f"warning: {not_explained(run)}")
    for a, b, rho in fit.high_correlations()[:5]:
        lines.append(f"warning: {a} and {b} are correlated (rho = {rho:+.3f})")
    advice = recommend(run)
    return [*lines, advice.headline(), *(f"  {line}" for line in advice.reasons())]
