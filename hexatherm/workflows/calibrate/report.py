"""The calibration's report (``OUT/report.html``), from the template
``calibration.html.j2`` as ``report`` and ``diagnose`` (:mod:`hexatherm.workflows.report.render`:
a lab may override it), and the predicted-pose uncertainty over the stroke.

The page holds: the verdict (level, poses, chi-square per degree of freedom, residuals
before and after, the claimed uncertainty of a new pose over the stroke, worst and
typical, with the level's model floor: :mod:`hexatherm.workflows.calibrate.claim`); how
the level was chosen; the parameters with their expanded uncertainty ``U = k u`` (k = 2) and their
largest correlation, pairs above 0.9 flagged; the observability (singular values,
condition number, O1..O5); the map of the predicted uncertainty of a calibrated pose
over Tx, Ty (the other components at zero) and its worst value over the poses the
campaign spans; the claim for a new pose by stroke region and along each axis of the
campaign's box (the template's own block ``claim_map``); the residuals of every target
before and after; the provenance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.calibration import PARAMETER_UNITS
from hexatherm.core.calibration.fit import EXPLAINED_P
from hexatherm.core.residuals import rms
from hexatherm.io.csvout import ROW_RESOLUTION, fixed_text
from hexatherm.io.provenance import current_run, now_iso
from hexatherm.typing import FloatArray
from hexatherm.workflows.calibrate.claim import (
    AXIS_STEPS,
    REGIONS,
    ClaimAxes,
    ClaimRegions,
    PoseClaim,
    span_poses,
)
from hexatherm.workflows.calibrate.conformity import COVERAGE_FACTOR, conformity_part
from hexatherm.workflows.calibrate.recommend import recommend
from hexatherm.workflows.calibrate.run import Calibration
from hexatherm.workflows.process.conformity import decision_rule
from hexatherm.workflows.report.document import document, identification_block, template_variables
from hexatherm.workflows.report.page import (
    Cell,
    Table,
    figure,
    provenance,
    signature_table,
    table,
)
from hexatherm.workflows.report.render import render_page
from hexatherm.workflows.report.text import exact, fixed, unit_text

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from hexatherm.session import Tolerance

#: poses drawn over the campaign's span for the worst predicted uncertainty
N_STROKE_POSES = 2000
#: grid of the map over Tx, Ty
N_MAP = 31
COMPONENTS = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
UNITS = ("um",) * 3 + ("urad",) * 3


@dataclass(frozen=True)
class StrokeMap:
    """The predicted standard uncertainty of a calibrated pose over the stroke.

    Attributes
    ----------
    lower, upper : ndarray, shape (6,)
        The span of the campaign's commanded poses (mm, deg): where the map and the
        draws lie.
    poses : ndarray, shape (M, 6)
        Poses drawn uniformly in the span, inside the stroke (seeded, reproducible).
    sigma_um_urad : ndarray, shape (M, 6)
        Their predicted standard uncertainties (um, urad).
    tx, ty : ndarray, shape (N_MAP,)
        The map's grid (mm); the other components at zero (clipped to the span).
    map_um : ndarray, shape (N_MAP, N_MAP)
        The largest of sigma(Tx), sigma(Ty), sigma(Tz) on the grid (um; NaN out of
        the stroke), ``map_um[i, j]`` at ``ty[i], tx[j]``.
    """

    lower: FloatArray
    upper: FloatArray
    poses: FloatArray
    sigma_um_urad: FloatArray
    tx: FloatArray
    ty: FloatArray
    map_um: FloatArray

    @property
    def worst_um_urad(self) -> FloatArray:
        """The largest predicted sigma (6,) over the drawn poses, um and urad."""
        return np.asarray(self.sigma_um_urad.max(axis=0), float)


def stroke_map(run: Calibration, seed: int = 0) -> StrokeMap:
    """The predicted uncertainty over the poses the campaign spans (see :class:`StrokeMap`)."""
    fit = run.fit
    nominal = run.campaign.nominal
    commanded = run.campaign.commanded
    lower, upper = commanded.min(axis=0), commanded.max(axis=0)
    poses = span_poses(run, N_STROKE_POSES, seed)
    sigma = fit.predicted_sigma_um_urad(poses)
    tx = np.linspace(lower[0], upper[0], N_MAP)
    ty = np.linspace(lower[1], upper[1], N_MAP)
    grid = np.zeros((N_MAP * N_MAP, 6))
    grid[:, 0] = np.tile(tx, N_MAP)
    grid[:, 1] = np.repeat(ty, N_MAP)
    grid[:, 2:] = np.clip(0.0, lower[2:], upper[2:])
    on = ~nominal.check_stroke(nominal.igm(grid)).any(axis=1)
    values = np.full(grid.shape[0], np.nan)
    if on.any():
        values[on] = fit.predicted_sigma_um_urad(grid[on])[:, :3].max(axis=1)
    return StrokeMap(lower, upper, poses, sigma, tx, ty, values.reshape(N_MAP, N_MAP))


def _map_figure(stroke: StrokeMap, commanded: FloatArray) -> Figure:
    from hexatherm.workflows.report.figures import (
        WIDE_TICK_INTERVALS,
        _new_figure,
        few_ticks,
        in_view_locator,
    )

    fig = _new_figure(6.0, 4.6, left=0.11, right=0.9, bottom=0.12, top=0.9)
    ax = fig.add_subplot(1, 1, 1)
    image = ax.pcolormesh(stroke.tx, stroke.ty, stroke.map_um, shading="nearest", cmap="viridis")
    fig.colorbar(
        image,
        ax=ax,
        label="largest σ of Tx, Ty, Tz (µm)",
        ticks=in_view_locator(WIDE_TICK_INTERVALS),
    )
    few_ticks(ax, nbins=WIDE_TICK_INTERVALS)
    ax.plot(commanded[:, 0], commanded[:, 1], "w+", markersize=6, label="campaign targets")
    ax.set_xlabel("Tx (mm)")
    ax.set_ylabel("Ty (mm)")
    ax.set_title("Predicted uncertainty of a calibrated pose (Tz, Rx, Ry, Rz at 0)", fontsize=9)
    ax.legend(fontsize=8, loc="upper right")
    return fig


def _residual_figure(run: Calibration) -> Figure:
    """The residual of every target before and after, translation and rotation (the
    targets' axis shared, labelled under the lower panel)."""
    from hexatherm.workflows.report.figures import WIDE_TICK_INTERVALS, _new_figure, few_ticks

    fig = _new_figure(7.0, 5.4, left=0.1, right=0.98, bottom=0.1, top=0.93, hspace=0.35)
    n = len(run.campaign.labels)
    label = "calibrated (held out)" if run.heldout else "calibrated"
    axes = fig.subplots(2, 1, sharex=True)
    few_ticks(axes[0], "x", nbins=WIDE_TICK_INTERVALS)
    for row, (part, unit) in enumerate(((slice(0, 3), "µm"), (slice(3, 6), "µrad"))):
        ax = axes[row]
        before = np.linalg.norm(run.residuals_before_um_urad[:, part], axis=1)
        after = np.linalg.norm(run.residuals_after_um_urad[:, part], axis=1)
        x = np.arange(1, n + 1)
        ax.semilogy(x, before, "o--", color="#c44e52", label="nominal geometry")
        ax.semilogy(x, after, "s-", color="#4c72b0", label=label)
        what = "translation" if row == 0 else "rotation"
        ax.set_ylabel(f"|measured − predicted|\n{what} ({unit})")
        ax.legend(fontsize=8)
        if row == 0:
            ax.set_title("Residual of every target, before and after", fontsize=9)
        else:
            ax.set_xlabel("target")
    return fig


def _workspace_figure(run: Calibration) -> Figure:
    """The translation residual of every target at its commanded Tx, Ty: before and
    after, one colour scale."""
    from hexatherm.workflows.report.figures import (
        WIDE_TICK_INTERVALS,
        _new_figure,
        few_ticks,
        in_view_locator,
    )

    fig = _new_figure(7.6, 3.6, left=0.08, right=0.9, bottom=0.14, top=0.86, wspace=0.25)
    axes = fig.subplots(1, 2, sharey=True)  # Ty's tick labels on the left panel only
    few_ticks(axes[0], nbins=WIDE_TICK_INTERVALS)
    few_ticks(axes[1], "x", nbins=WIDE_TICK_INTERVALS)
    xy = run.campaign.commanded[:, :2]
    before = np.linalg.norm(run.residuals_before_um_urad[:, :3], axis=1)
    after = np.linalg.norm(run.residuals_after_um_urad[:, :3], axis=1)
    top = float(max(np.nanmax(before), np.nanmax(after), 1e-12))
    after_name = "calibrated (held out)" if run.heldout else "calibrated"
    images = []
    for k, (values, name) in enumerate(((before, "nominal geometry"), (after, after_name))):
        ax = axes[k]
        image = ax.scatter(
            xy[:, 0], xy[:, 1], c=values, vmin=0.0, vmax=top, cmap="viridis", s=28, gid=name
        )
        ax.set_xlabel("commanded Tx (mm)")
        if k == 0:
            ax.set_ylabel("commanded Ty (mm)")
        ax.set_title(name, fontsize=9)
        images.append(image)
    cax = fig.add_axes((0.92, 0.14, 0.02, 0.72))
    fig.colorbar(
        images[-1],
        cax=cax,
        label="|measured − predicted| translation (µm)",
        ticks=in_view_locator(WIDE_TICK_INTERVALS),
    )
    fig.suptitle("Residuals over the workspace (every target at its commanded Tx, Ty)", fontsize=10)
    return fig


def _correlation_figure(run: Calibration) -> Figure:
    """The fitted parameters' correlation matrix as a heatmap."""
    from hexatherm.workflows.report.figures import (
        WIDE_TICK_INTERVALS,
        _new_figure,
        in_view_locator,
    )

    fit = run.fit
    index = [i for i, m in enumerate(fit.model.mask) if m]
    rho = np.asarray(fit.correlation)[np.ix_(index, index)]
    fig = _new_figure(6.6, 5.8, left=0.16, right=0.94, bottom=0.16, top=0.94)
    ax = fig.add_subplot(1, 1, 1)
    image = ax.imshow(rho, vmin=-1.0, vmax=1.0, cmap="RdBu_r", interpolation="nearest")
    fig.colorbar(
        image, ax=ax, label="correlation ρ", shrink=0.85, ticks=in_view_locator(WIDE_TICK_INTERVALS)
    )
    names = list(fit.names)
    step = max(1, len(names) // 24)
    ticks = np.arange(0, len(names), step)
    ax.set_xticks(ticks, [names[i] for i in ticks], rotation=90, fontsize=6)
    ax.set_yticks(ticks, [names[i] for i in ticks], fontsize=6)
    ax.set_title(f"Correlation of the {len(names)} fitted parameters", fontsize=9)
    return fig


def not_explained(run: Calibration) -> str:
    """Why a calibration whose chi-square test fails is not to be trusted, in words."""
    fit = run.fit
    hint = (
        " (conventional poses carry the legs' drift: --poses corrected)"
        if run.campaign.poses == "conventional"
        else ""
    )
    return (
        f"the model does not explain these poses: chi2/dof {fit.chi_square_per_dof:.2f} for "
        f"{fit.dof} degrees of freedom, where chance alone exceeds "
        f"{fit.chi_square_limit_per_dof():.2f} once in {1 / EXPLAINED_P:.0f} "
        f"(p = {fit.chi_square_p:.2g}); the residuals are larger than the poses' "
        f"uncertainty says: a thermal error left in the poses{hint}, an effect the level "
        "does not model, or uncertainties stated too small. The parameters' uncertainties "
        "assume the model is right"
    )


def _components_text(values: FloatArray, k: float) -> str:
    return ", ".join(
        f"{c} {fixed(k * v, u)} {'µm' if u == 'um' else 'µrad'}"
        for c, v, u in zip(COMPONENTS, values, UNITS, strict=True)
    )


def claim_lines(
    stroke: StrokeMap, claim: PoseClaim | None, k: float, explained: bool = True
) -> list[str]:
    """The verdict's lines on what a new calibrated pose is claimed to be good to
    (``explained``: whether the model explains the poses, the chi-square test)."""
    if claim is None:
        return [
            f"Worst predicted uncertainty of a calibrated pose over the campaign's span "
            f"(U, k = {exact(k)}): {_components_text(stroke.worst_um_urad, k)} "
            f"({len(stroke.poses)} poses inside the stroke)."
        ]
    floor = claim.floor
    lines = [
        f"Claimed uncertainty of a new calibrated pose (one not measured) over the "
        f"campaign's span (U, k = {exact(k)}; {len(claim.poses)} poses inside the "
        f"stroke): worst {_components_text(claim.worst_um_urad, k)}; typical (RMS) "
        f"{_components_text(claim.typical_um_urad, k)}."
    ]
    if floor.note:
        lines.append(f"It holds no model floor: {floor.note}.")
    else:
        lines.append(
            f"It includes the level's model floor (k = 1) "
            f"{_components_text(floor.sigma_um_urad, 1.0)}, from {floor.method}."
        )
    if not explained:
        lines.append(
            "The model does not explain the poses (above): this claim covers only what "
            "it models, and the held-out residuals say more of the error than it does."
        )
    return lines


def claim_map_tables(
    claim_map: tuple[ClaimRegions, ClaimAxes] | None, k: float
) -> tuple[Table | None, Table | None]:
    """The claim for a new pose by stroke region and along each axis of the campaign's
    box, U = k u (the report's own block, ``claim_map``), or None without a claim."""
    if claim_map is None:
        return None, None
    regions, axes = claim_map
    edges = [0.0, *regions.bounds, np.inf]
    rows: list[list[Cell]] = []
    for i, name in enumerate(REGIONS):
        upper = "" if not np.isfinite(edges[i + 1]) else f"{edges[i + 1]:.2f}"
        reach = f"{edges[i]:.2f} – {upper}" if upper else f"above {edges[i]:.2f}"
        for what, values in (("RMS", regions.rms_um_urad[i]), ("worst", regions.worst_um_urad[i])):
            row: list[Cell] = [f"{name} third, {what}", reach, str(int(regions.counts[i]))]
            rows.append(row + [fixed(k * v, u) for v, u in zip(values, UNITS, strict=True)])
    by_region = table(
        [
            [("stroke region", 1), ("radius", 1), ("poses", 1)]
            + [
                (f"{c} ({'µm' if u == 'um' else 'µrad'})", 1)
                for c, u in zip(COMPONENTS, UNITS, strict=True)
            ]
        ],
        rows,
        caption=f"Claimed uncertainty U (k = {exact(k)}) of a new calibrated pose by stroke "
        "region: the new poses over the campaign's box in thirds by their distance from "
        "its centre (radius: in units of the box's half-widths, RMS over the components; "
        "0 at the centre, 1 at a corner). Each pose's claim is the parameters' "
        "uncertainty propagated to it and the model floor at it: both grow towards the "
        "ends of the stroke.",
    )
    arows: list[list[Cell]] = []
    for a, axis in enumerate(COMPONENTS):
        unit = "mm" if a < 3 else "deg"
        cells: list[Cell] = [axis]
        for j in range(len(AXIS_STEPS)):
            sigma = axes.sigma_um_urad[a, j]
            where = f"{axes.positions[a, j]:+.3g} {unit}"
            if np.isnan(sigma).any():
                cells.append(f"{where}: out of the stroke")
            else:
                cells.append(
                    f"{where}: {fixed(k * sigma[:3].max(), 'um')} µm, "
                    f"{fixed(k * sigma[3:].max(), 'urad')} µrad"
                )
        arows.append(cells)
    along = table(
        [[("axis", 1)] + [(f"{step:+g} × half-width", 1) for step in AXIS_STEPS]],
        arows,
        caption=f"Claimed uncertainty U (k = {exact(k)}) of a new calibrated pose along each "
        "axis of the campaign's box, the other components at its centre: the largest of "
        "Tx, Ty, Tz (µm) and of Rx, Ry, Rz (µrad) at each commanded value.",
    )
    return by_region, along


def sessions_text(run: Calibration) -> tuple[str, str]:
    """The hexapod (its name and file) and every session with the dates it was measured."""
    from hexatherm.workflows.report.html import session_dates

    results = run.campaign.results
    hexapod = f"{run.campaign.nominal.name} ({results[0].session.config_files[0].name})"
    sessions = "; ".join(f"{r.session.name} ({session_dates(r)})" for r in results)
    return hexapod, sessions


def sessions_folder(run: Calibration) -> Path:
    """The folder that holds every session of the campaign (paths are printed relative
    to it)."""
    import os

    folders = [str(r.session.path.parent.resolve()) for r in run.campaign.results]
    common = Path(os.path.commonpath(folders))
    return common.parent if str(common) in folders else common


def report_html(
    run: Calibration,
    stroke: StrokeMap,
    inputs: Sequence[Path],
    folder: Path,
    lab_fields: dict[str, object] | None = None,
    coverage_factor: float = COVERAGE_FACTOR,
    claim: PoseClaim | None = None,
    template_dir: Path | None = None,
    claim_map: tuple[ClaimRegions, ClaimAxes] | None = None,
    report_number: str | None = None,
    title: str | None = None,
    tolerances: dict[str, Tolerance] | None = None,
) -> str:
    """The calibration's report page (see the module text); ``lab_fields``: a lab file's
    identification (the sessions' own ``identification:`` over it, in the order given);
    ``coverage_factor``: k of every expanded uncertainty ``U = k u`` it prints; ``claim``:
    the claim for new poses (the parameters' part alone, over ``stroke``, without it);
    ``template_dir``: a lab's templates, over the package's; ``claim_map``: the claim by
    stroke region and along the axes (its tables); ``report_number``, ``title``:
    the document's own (``--report-number``, ``--title``; else the lab file's
    ``numbering:``, ``titles:``; :mod:`~hexatherm.workflows.report.document`);
    ``tolerances``: the lab's on the calibrated pose error (:mod:`.conformity`)."""
    from hexatherm.io.config.identity import identification
    from hexatherm.workflows.report.html import header_rows

    fit = run.fit
    obs = fit.observability
    k = coverage_factor
    before, after = (
        rms(run.residuals_before_um_urad, axis=0),
        rms(run.residuals_after_um_urad, axis=0),
    )
    how = "chosen by BIC and held-out folds" if run.choice is not None else "forced"
    hexapod, sessions = sessions_text(run)
    verdict = [
        f"Hexapod {hexapod}; sessions {sessions}.",
        f"Level {fit.level} ({how}): {obs.n_parameters} parameters ({obs.n_gauge} fixed by "
        f"the gauge) from {len(run.campaign.labels)} {run.campaign.poses} poses of "
        f"{len(run.campaign.results)} session(s).",
        f"chi²/dof {fit.chi_square_per_dof:.2f} (1: the residuals are as large as the poses' "
        "uncertainty says): "
        + (
            f"the model explains the poses (chi-square test, p = {fit.chi_square_p:.2g})."
            if fit.explains_poses
            else f"NOT EXPLAINED: {not_explained(run)}."
        ),
        "RMS residual Tx, Ty, Tz: nominal "
        + ", ".join(fixed(v, "um") for v in before[:3])
        + " µm; calibrated "
        + ", ".join(fixed(v, "um") for v in after[:3])
        + f" µm ({'held out' if run.heldout else 'in sample'}).",
        *claim_lines(stroke, claim, k, fit.explains_poses),
    ]
    pairs = fit.high_correlations()
    if pairs:
        verdict.append(
            f"{len(pairs)} pair(s) of parameters correlated beyond |ρ| = 0.9 (flagged below)."
        )
    levels = None
    if run.choice is not None:
        rows: list[list[Cell]] = []
        for score in run.choice.scores:
            rows.append(
                [
                    score.level + (" (chosen)" if score.level == fit.level else ""),
                    "" if score.fit is None else f"{score.bic:.1f}",
                    "" if score.fit is None else f"{score.heldout_rms_w:.2f}",
                    score.note,
                ]
            )
        levels = table(
            [[("level", 1), ("BIC", 1), ("held-out RMS (whitened)", 1), ("note", 1)]],
            rows,
            align="lrrl",
            caption="The next larger level is chosen when its BIC is lower by more than "
            "10 and its held-out RMS is lower.",
        )
    flagged = {a for a, _, _ in pairs} | {b for _, b, _ in pairs}
    names = fit.names
    index = [i for i, m in enumerate(fit.model.mask) if m]
    rho = np.abs(np.nan_to_num(fit.correlation))
    np.fill_diagonal(rho, 0.0)
    prows: list[list[Cell]] = []
    classes = []
    for name, i in zip(names, index, strict=True):
        gain = PARAMETER_UNITS[i] != "mm"
        scale, unit = (1e6, "ppm") if gain else (1e3, "um")
        prows.append(
            [
                name,
                exact(fit.model.theta0[i]),
                fixed_text(np.array([fit.parameters[i]]), ROW_RESOLUTION[PARAMETER_UNITS[i]])[0],
                fixed((fit.parameters[i] - fit.model.theta0[i]) * scale, "um"),
                fixed(k * fit.std_errors[i] * scale, "um"),
                unit_text(unit),
                f"{rho[i].max():.3f}",
            ]
        )
        classes.append("fail" if name in flagged else "")
    indices = obs.indices()
    merged: dict[str, object] = {}
    for result in run.campaign.results:
        merged.update(result.session.identification)
    ident = identification(merged, lab_fields)
    claim_regions_table, claim_axes_table = claim_map_tables(claim_map, k)
    fields = dict(ident.fields)
    issued = now_iso()
    results = run.campaign.results
    numbers = [r.session.identification.get("report_number") for r in results]
    doc = document(
        "calibrate",
        issued,
        fields,
        [None if n is None else str(n) for n in numbers],
        [r.session.name for r in results],
        report_number,
        title,
    )
    shown = [f"{r.session.name} (report {n})" for r, n in zip(results, numbers, strict=True) if n]
    base = sessions_folder(run)
    return render_page(
        "calibration.html.j2",
        template_dir,
        title=doc.title,
        subtitle=f"Geometry of the hexapod {hexapod} from the sessions {sessions}",
        **template_variables(doc, fields),
        ident_block=identification_block(
            doc,
            fields,
            f"hexapod {hexapod}"
            + "".join(
                f", {name} {fields[key]}"
                for key, name in (("hexapod.model", "model"), ("hexapod.serial", "serial"))
                if key in fields
            ),
            sessions,
            f"linear propagation (GUM) of the poses' covariance through the weighted least "
            f"squares; U = k·u with k = {exact(k)}",
            f"the calibrated parameters with U = k·u, the claimed uncertainty of a "
            f"new calibrated pose ({len(run.campaign.labels)} poses)"
            + (f"; the sessions' own reports: {', '.join(shown)}" if shown else ""),
            ident.signatures,
        ),
        header_rows=header_rows(doc, ident, sessions, hexapod),
        signatures=signature_table(ident.signatures, doc.issue_date),
        verdict=verdict,
        recommendation=recommend(run, coverage_factor),
        conformity=None
        if not tolerances
        else conformity_part(run, tolerances, coverage_factor, decision_rule(fields)),
        levels=levels,
        parameters=table(
            [
                [
                    ("parameter", 1),
                    ("nominal", 1),
                    ("calibrated", 1),
                    ("change", 1),
                    (f"U (k = {exact(k)})", 1),
                    ("unit of change, U", 1),
                    ("max |ρ|", 1),
                ]
            ],
            prows,
            row_classes=classes,
            caption="mm for joints and offsets, mm/mm for gains; changes and U in µm (ppm "
            "for gains). Highlighted: correlated beyond |ρ| = 0.9 with another parameter. "
            "Base joints in the fit's gauge (the least-squares rigid fit of the fitted base "
            "onto the nominal one); hexapod.yaml holds them in frame O.",
        ),
        observability=table(
            [[("figure", 1), ("value", 1)]],
            [[name, f"{value:.4g}"] for name, value in indices.items()]
            + [["rank", f"{obs.rank} of {obs.n_parameters}"]],
        ),
        singular_values=", ".join(f"{v:.3g}" for v in obs.singular_values),
        map_figure=figure(
            lambda: _map_figure(stroke, run.campaign.commanded),
            "predicted uncertainty map",
            "Largest predicted standard uncertainty (k = 1) of Tx, Ty, Tz of a pose the "
            "calibrated model predicts, from its parameters' uncertainty (the claim adds "
            "the level's model floor), over Tx and Ty with the other components at zero; "
            "blank: out of the stroke. Crosses: the campaign's targets (all components).",
        ),
        residual_figure=figure(
            lambda: _residual_figure(run),
            "residuals before and after",
            "Translation and rotation residual of every target: measured minus the nominal "
            "geometry's prediction (the commanded pose), and minus the calibrated model's.",
        ),
        workspace_figure=figure(
            lambda: _workspace_figure(run),
            "residuals over the workspace",
            "Translation residual of every target at its commanded Tx and Ty (all other "
            "components as commanded), before (nominal geometry) and after (calibrated), "
            "on one colour scale.",
        ),
        correlation_figure=figure(
            lambda: _correlation_figure(run),
            "correlation matrix of the parameters",
            "Correlation coefficient of every pair of fitted parameters (their covariance "
            "over the product of their standard uncertainties); near ±1: the campaign "
            "does not tell the two apart.",
        ),
        claim_regions=claim_regions_table,
        claim_axes=claim_axes_table,
        provenance=provenance(
            current_run(),
            inputs,
            base,
            issued,
            folder_name="the folder of the sessions",
            number=doc.number,
        ),
    )
