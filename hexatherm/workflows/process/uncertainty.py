"""Standard uncertainties of the conventional and corrected poses of a processed session.

Glue between :class:`~hexatherm.workflows.process.pipeline.ProcessResult` and the pure math of
:mod:`hexatherm.core.propagation`. The covariance of every ball centre comes
from, in this order of preference:

1. the sphere fit of its probed points (``s^2 (J^T J)^-1``, the full 3x3
   covariance from the fit residuals);
2. the ``u_x_um``, ``u_y_um``, ``u_z_um``, ``r_xy``, ``r_xz``, ``r_yz`` columns of a
   centres file (its covariance, as ``fit-spheres`` writes it), else its ``u_um`` column
   shaped as a cap fit to the plan's touch pattern, its RMS over the axes the file's u
   (:mod:`~hexatherm.workflows.process.centrecov`);
3. the session's ``cmm:`` mapping (point noise, or MPE / 2): the covariance of
   a free-radius fit to ``points_per_ball`` points over a cap of
   ``cap_angle_deg`` around the CMM's +Z;
4. the registration residuals, pooled over all steps, with the shape of a cap fit:
   ``c * C_cap``, ``C_cap`` the covariance of a free-radius fit to the plan's points per
   ball over a 70 deg cap (unit noise), ``c`` such that the expected residuals
   ``c * sum tr(P C)`` (``P`` the projector off the rigid motions) equal the observed
   ones. Three coplanar balls leave residuals in their plane only, so a centre's error
   along the normal (the cap fit's largest, into Tz, Rx, Ry) is not seen by them. The
   references, measured again and again, see it: the z part of the shape is scaled to
   the scatter of their ball heights (:func:`reference_height_scale`, a Type A
   evaluation) when they have the degrees of freedom; else it rests on the assumed
   shape. The description says which.

It is then propagated through registration, IGM, correction and FGM, by the
linear law (GUM) or by Monte Carlo (GUM Supplement 1). Monte Carlo draws the
probed points themselves where the centres were fitted to them, and refits the
spheres (:func:`point_sampler`): it checks the fits' covariances as well as the
rest of the chain.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from hexatherm.core.curvature import CurvatureError
from hexatherm.core.propagation import (
    CentreSampler,
    PoseChain,
    TargetJacobian,
    covariance_root,
    draw_centres,
    monte_carlo_covariance,
)
from hexatherm.core.smoothbias import GrowthExcess
from hexatherm.core.spherefit import fit_spheres, refine_spheres
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.carryerror import CarryError, add_common
from hexatherm.workflows.process.centrecov import CentreCovariance, centre_covariance
from hexatherm.workflows.process.errorterms import error_terms, structured_covariance
from hexatherm.workflows.process.measured import fit_radii, point_groups, registration_weights
from hexatherm.workflows.process.pipeline import ProcessResult
from hexatherm.workflows.process.repeats import RepeatCheck, repeat_checks

if TYPE_CHECKING:  # the calibration's weights (and scipy.sparse): imported when used
    from hexatherm.core.calibration.weights import BandedCovariance

Method = Literal["linear", "monte-carlo"]
IntArray = npt.NDArray[np.intp]

__all__ = [
    "CentreCovariance",
    "RepeatCheck",
    "PoseUncertainty",
    "centre_covariance",
    "pose_chain",
    "pose_uncertainty",
]


@dataclass(frozen=True)
class PoseUncertainty:
    """Standard uncertainties (k = 1) of the M targets' poses.

    Attributes
    ----------
    conventional_u, corrected_u : ndarray, shape (M, 6)
        mm and deg, one row per target in ``result.correction.target_index`` order.
    covariance : ndarray, shape (M, 12, 12)
        Covariance of ``[conventional, corrected]`` of each target (the reported one).
    linear_covariance : ndarray, shape (M, 12, 12)
        By linear propagation (equal to ``covariance`` when ``method`` is linear).
    method : {"linear", "monte-carlo"}
    draws : int
        Monte Carlo draws (0 for linear).
    seed : int or None
        Seed of the Monte Carlo generator.
    centres : CentreCovariance
        The input covariances.
    drawn : {"", "points", "centres"}
        What the Monte Carlo draws: the probed points, refitted
        (:func:`point_sampler`), or the centres from their covariance (a session
        without probed points); empty for linear propagation.
    common_u, own_u : ndarray, shape (M, 12)
        The part of each standard uncertainty (mm, deg; conventional then corrected)
        common to all targets, from the noise of O and R0 that every target's pose
        carries, and the part of its own (its own step and its references);
        ``u^2 = common^2 + own^2``. By linear propagation; with Monte Carlo the linear
        shares of the variance applied to the Monte Carlo u.
    between_covariance : ndarray, shape (12, M, M), or None
        Covariance of each output between every pair of targets (mm^2, deg^2): the
        linear one; with Monte Carlo the linear correlations times the Monte Carlo u.
        Its diagonal is ``u^2``. None when not computed (``between``).
    repeats : tuple of RepeatCheck
        The scatter of repeated O and R0 against their claimed uncertainty.
    smooth_excess : GrowthExcess, optional
        With ``--interpolation smooth`` when the smooth fit is used: the fit's own error
        of the growth at R beyond the references' noise
        (:func:`~hexatherm.workflows.process.smootherror.smooth_excess`), in
        ``covariance``, ``linear_covariance`` and the corrected poses' own part.
    carry : CarryError, optional
        The error of carrying O and R0 to R0's thermal state (common to all targets), in
        ``covariance``, ``linear_covariance``, the common part and ``between_covariance``.
    curvature : CurvatureError, optional
        The straight line's own error between two references
        (:func:`~hexatherm.workflows.process.smootherror.curvature_excess`), in
        ``covariance``, ``linear_covariance``, the corrected poses' own part and
        ``between_covariance`` (shared by two targets of one interval).
    """

    conventional_u: FloatArray
    corrected_u: FloatArray
    covariance: FloatArray
    linear_covariance: FloatArray
    method: Method
    draws: int
    seed: int | None
    centres: CentreCovariance
    drawn: str = ""
    common_u: FloatArray | None = None
    own_u: FloatArray | None = None
    between_covariance: FloatArray | None = None
    repeats: tuple[RepeatCheck, ...] = ()
    smooth_excess: GrowthExcess | None = None
    carry: CarryError | None = None
    curvature: CurvatureError | None = None

    def ratio_to_linear(self) -> FloatArray:
        """Reported over linear standard uncertainty, (M, 12) (1 for the linear method)."""
        lin = np.sqrt(np.diagonal(self.linear_covariance, axis1=1, axis2=2))
        rep = np.sqrt(np.diagonal(self.covariance, axis1=1, axis2=2))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(lin > 0, rep / np.where(lin > 0, lin, 1.0), np.nan)


#: probed points refitted at once in a Monte Carlo batch: small enough that the refit's
#: arrays stay in the caches and are not paged in afresh for every chunk (2,000,000 took
#: 1.4 s of system time on the 122-step campaign, 200,000 0.2 s; issue 26). The draws
#: and every sphere's arithmetic are the same whatever the chunk: the results are too.
POINTS_PER_REFIT = 200_000


def point_sampler(result: ProcessResult, cov_mm2: FloatArray) -> CentreSampler | None:
    """Monte Carlo draws of the centres through the sphere fits (GUM Supplement 1 on the points).

    Every probed point is moved along its direction from its sphere's fitted
    centre by a draw of ``N(0, s^2)``, ``s`` the residual standard deviation of
    that fit (the noise the fit's covariance assumes); the spheres are refitted
    as ``process`` fits them (same free or fixed radii). Centres read as such,
    and those whose fit has no redundancy, are drawn from their covariance
    ``cov_mm2`` (N, k, 3, 3). A repeated O or R0 gets the mean of its measurements'
    refits, as ``process`` averages them. None when no centre comes from probed points,
    or when a repeated step has a measurement that is not refitted (then every centre is
    drawn from its covariance).
    """
    sources = [
        (fitted, raw)
        for fitted, raw in zip(result.records, result.points, strict=False)
        if raw is not None
    ]
    if not sources:
        return None
    step_index = {label: i for i, label in enumerate(result.session.plan.labels)}
    step_index.update({label: step_index[kept] for label, kept in result.repeat_of.items()})
    count = result.centres.measurements
    repeated = {step_index[g.label] for g in result.repeats}
    refitted = np.zeros(len(count), dtype=int)
    for fitted, _ in sources:
        ok = np.isfinite(np.asarray(fitted.extra["sigma_um"], dtype=float))
        for label in np.asarray(fitted.label)[ok]:
            refitted[step_index[str(label)]] += 1
    # each measurement's weight in its step's centres (R0's line without a log)
    weight_of = {
        label: float(w)
        for g in result.repeats
        for label, w in zip(
            g.labels,
            np.full(len(g.labels), 1.0 / len(g.labels)) if g.weights is None else g.weights,
            strict=True,
        )
    }
    k = len(result.session.balls.names)
    if any(refitted[i] != count[i] * k for i in repeated):
        return None  # a repeated step's measurement is not refitted: draw every centre
    ball_index = {name: j for j, name in enumerate(result.session.balls.names)}
    fits = []
    for fitted, raw in sources:
        groups, first = point_groups(raw)
        offset = raw.xyz_mm - fitted.xyz_mm[groups]
        normal = offset / np.linalg.norm(offset, axis=1)[:, None]
        sigma_mm = np.asarray(fitted.extra["sigma_um"], dtype=float) * 1e-3
        ok = np.isfinite(sigma_mm)
        step = np.array([step_index[s] for s in fitted.label])
        share = np.array([weight_of.get(s, 1.0) for s in fitted.label])
        ball = np.array([ball_index[b] for b in fitted.ball])
        radius = fit_radii(raw, first, result.session.balls, result.fixed_diameter_mm)
        fits.append(
            (
                raw.xyz_mm,
                normal * np.where(ok, sigma_mm, 0.0)[groups, None],
                groups,
                radius,
                step[ok],
                ball[ok],
                ok,
                fitted.xyz_mm,
                share[ok],
            )
        )
    centres = result.centres.centres_mm
    root = covariance_root(cov_mm2)
    averaged = sorted(repeated)

    def put(
        drawn: FloatArray,
        rows: slice,
        step: IntArray,
        ball: IntArray,
        c: FloatArray,
        share: FloatArray,
    ) -> None:
        """Refitted centres (d, n, 3) into ``drawn``; a repeat adds its share (weight)."""
        once = count[step] == 1
        drawn[rows, step[once], ball[once]] = c[:, once]
        if not once.all():
            view = np.moveaxis(drawn[rows], 0, 2)  # (N, k, d, 3), writes through
            np.add.at(
                view,
                (step[~once], ball[~once]),
                np.moveaxis(c[:, ~once] * share[~once, None], 0, 1),
            )

    def sample(rng: np.random.Generator, size: int) -> FloatArray:
        drawn = draw_centres(centres, root, rng, size)
        drawn[:, averaged] = 0.0  # the means of their measurements' refits, added below
        for xyz, noise_mm, groups, radius, step, ball, ok, fitted_mm, share in fits:
            chunk = max(1, POINTS_PER_REFIT // len(xyz))
            n_spheres = int(groups.max()) + 1
            counts = np.bincount(groups, minlength=n_spheres)
            if np.all(counts == counts[0]):
                # equal point counts: batched Gauss-Newton from the fitted spheres
                order = np.argsort(groups, kind="stable")
                per = (n_spheres, int(counts[0]), 3)
                xyz_s, noise_s = xyz[order].reshape(per), noise_mm[order].reshape(per)
                start = np.asarray(fitted_mm, dtype=float)
                r0 = (
                    np.linalg.norm(xyz_s - start[:, None], axis=-1).mean(axis=-1)
                    if radius is None
                    else np.broadcast_to(radius, (n_spheres,))
                )
                # x, y and z apart, each contiguous over the spheres' points: broadcast
                # against the draws along a last axis of 3, the sums ran 10x slower
                xyz_c = [np.ascontiguousarray(xyz_s[..., i]) for i in range(3)]
                noise_c = [np.ascontiguousarray(noise_s[..., i]) for i in range(3)]
                for first in range(0, size, chunk):
                    d = min(chunk, size - first)
                    z = rng.standard_normal((d, *per[:2]))
                    moved = np.empty((3, d, *per[:2]))  # moved[i] = xyz + noise z, coordinate i
                    for i in range(3):
                        np.add(xyz_c[i], np.multiply(noise_c[i], z, out=moved[i]), out=moved[i])
                    centre, _ = refine_spheres(
                        np.moveaxis(moved, 0, -1),
                        start,
                        r0,
                        fixed_radius=radius is not None,
                        normal_points_mm=xyz_s,
                    )
                    put(drawn, slice(first, first + d), step, ball, centre[:, ok], share)
                continue
            for first in range(0, size, chunk):
                d = min(chunk, size - first)
                moved = xyz + noise_mm * rng.standard_normal((d, len(xyz)))[..., None]
                all_groups = (groups + n_spheres * np.arange(d)[:, None]).reshape(-1)
                radii = (
                    None if radius is None else np.broadcast_to(radius, (d, n_spheres)).reshape(-1)
                )
                refit = fit_spheres(moved.reshape(-1, 3), all_groups, radius_mm=radii)
                put(
                    drawn,
                    slice(first, first + d),
                    step,
                    ball,
                    refit.centre_mm.reshape(d, n_spheres, 3)[:, ok],
                    share,
                )
        return drawn

    return sample


def pose_chain(result: ProcessResult) -> PoseChain:
    """The registration + correction chain of ``result`` as a function of the centres."""
    corr = result.correction
    return PoseChain(
        hexapod=result.session.hexapod,
        plan=result.session.plan,
        balls_mm=result.session.balls.centres_mm,
        before_index=corr.before_index,
        after_index=corr.after_index,
        weight_after=corr.weight_after,
        weights=registration_weights(result.centres.u_um),
        initial_poses=corr.corrected,
        growth_weights=corr.growth_weights,
        origin_shift=None if result.carry is None else result.carry.shift,
    )


#: the most targets whose covariance between every pair is computed (and written to
#: covariance.csv) unless asked for: M (M + 1) / 2 rows
BETWEEN_MAX_TARGETS = 200


def pose_uncertainty(
    result: ProcessResult,
    mc: int = 0,
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    between: bool | None = None,
) -> PoseUncertainty:
    """Standard uncertainties of the conventional and corrected poses of every target.

    Parameters
    ----------
    result : ProcessResult
    mc : int
        0 for linear propagation; otherwise the number of Monte Carlo draws
        (at least 2; GUM Supplement 1 suggests 10^5 for 95 % intervals, a few
        thousand are plenty for standard uncertainties).
    seed : int
        Seed of the Monte Carlo generator (``numpy.random.default_rng``).
    progress : callable, optional
        ``progress(draws_done, draws)`` during the Monte Carlo draws.
    between : bool, optional
        Whether to compute the covariance between every pair of targets (M^2: 120 MB
        of CSV for 1000 targets); default: up to :data:`BETWEEN_MAX_TARGETS` targets.

    Returns
    -------
    PoseUncertainty
    """
    centres = centre_covariance(result)
    chain = pose_chain(result)
    terms = error_terms(result, chain, centres.cov_mm2)
    jacobian, full, carried = terms.jacobian, terms.full, terms.carried
    linear = full.covariance(centres.cov_mm2)
    covariance, method, draws, drawn = linear, "linear", 0, ""
    if mc:
        sampler = point_sampler(result, centres.cov_mm2)
        covariance, _ = monte_carlo_covariance(
            chain,
            result.centres.centres_mm,
            centres.cov_mm2,
            mc,
            np.random.default_rng(seed),
            progress=progress,
            sample=sampler,
        )
        if full is not jacobian:  # the chain holds O's carry fixed: its part linear
            covariance = covariance + linear - jacobian.covariance(centres.cov_mm2)
        method, draws = "monte-carlo", int(mc)
        drawn = "centres" if sampler is None else "points"
    u = np.sqrt(np.clip(np.diagonal(covariance, axis1=1, axis2=2), 0.0, None))
    if between is None:
        between = len(result.correction.target_index) <= BETWEEN_MAX_TARGETS
    common_u, own_u, pairs = shared_parts(full, centres.cov_mm2, u, linear, between)
    covariance, linear, common_u, own_u, pairs = add_common(
        carried, covariance, linear, common_u, own_u, pairs
    )
    u = np.sqrt(np.clip(np.diagonal(covariance, axis1=1, axis2=2), 0.0, None))
    # the interpolation's own error (the smooth fit's, the straight line's): a target's
    # own part; the straight line's shared by the targets of one interval
    own = terms.own_blocks()
    if own is not None:
        added = np.zeros_like(linear)
        added[:, 6:, 6:] = own
        covariance, linear = covariance + added, linear + added
        extra = np.diagonal(added, axis1=1, axis2=2)  # (M, 12)
        u = np.sqrt(np.clip(np.diagonal(covariance, axis1=1, axis2=2), 0.0, None))
        own_u = np.sqrt(own_u**2 + extra)
        if pairs is not None:
            pairs[6:] += terms.between_targets()
    excess, curved = terms.excess, terms.curved
    return PoseUncertainty(
        conventional_u=u[:, :6],
        corrected_u=u[:, 6:],
        covariance=covariance,
        linear_covariance=linear,
        method=method,  # type: ignore[arg-type]
        draws=draws,
        seed=seed if mc else None,
        centres=centres,
        drawn=drawn,
        common_u=common_u,
        own_u=own_u,
        between_covariance=pairs,
        repeats=repeat_checks(result, centres.cov_mm2),
        smooth_excess=None if excess is None else excess[1],
        carry=carried,
        curvature=None if curved is None else curved[1],
    )


def joint_pose_covariance(result: ProcessResult, corrected: bool = True) -> FloatArray:
    """Covariance (6M, 6M) of all targets' corrected (or conventional) poses together, by
    linear propagation: target by target, mm and deg, every term between targets and
    components included (what a calibration weighs the poses with); the same terms as
    :func:`pose_uncertainty` (its ``covariance.csv``): O's carry to R0's state (with its
    noise in the propagation without a log), the smooth fit's own error on each
    corrected pose's own block, the straight line's own error shared by the targets of
    one interval."""
    centres = centre_covariance(result)
    terms = error_terms(result, pose_chain(result), centres.cov_mm2)
    outputs = slice(6, 12) if corrected else slice(0, 6)
    return terms.full.joint_covariance(centres.cov_mm2, outputs) + terms.joint(outputs)


def joint_pose_covariance_structured(
    result: ProcessResult, corrected: bool = True
) -> BandedCovariance | None:
    """:func:`joint_pose_covariance` with its structure (the O and R0 part and the carry's
    low-rank, the rest banded; None when it is not banded), for a calibration's
    whitening."""
    centres = centre_covariance(result)
    terms = error_terms(result, pose_chain(result), centres.cov_mm2)
    return structured_covariance(terms, centres.cov_mm2, slice(6, 12) if corrected else slice(0, 6))


def joint_pose_covariance_for_fit(
    result: ProcessResult, corrected: bool = True
) -> BandedCovariance | FloatArray:
    """What a calibration whitens the poses with: the covariance with its structure
    (:func:`joint_pose_covariance_structured`) where it has one, else dense
    (:func:`joint_pose_covariance`: the smooth growth, whose own error on each pose's
    block the structure does not carry), from one evaluation of the terms."""
    centres = centre_covariance(result)
    terms = error_terms(result, pose_chain(result), centres.cov_mm2)
    outputs = slice(6, 12) if corrected else slice(0, 6)
    structure = structured_covariance(terms, centres.cov_mm2, outputs)
    if structure is not None:
        return structure
    return terms.full.joint_covariance(centres.cov_mm2, outputs) + terms.joint(outputs)


def shared_parts(
    jacobian: TargetJacobian,
    centre_cov_mm2: FloatArray,
    u: FloatArray,
    linear: FloatArray | None = None,
    between: bool = True,
) -> tuple[FloatArray, FloatArray, FloatArray | None]:
    """Common and own parts of the standard uncertainties ``u`` (M, 12), and (with
    ``between``) the covariance (12, M, M) of each output between the targets.

    ``linear`` is ``jacobian.covariance(centre_cov_mm2)`` when the caller has it.

    The linear propagation splits each variance by source: O and R0, measured once
    and carried by every target (common), and the target's own step and references
    (own). The shares of the linear variance are applied to ``u`` (equal to the
    linear u unless ``u`` comes from Monte Carlo), and so are the linear correlations
    between targets: ``common^2 + own^2 = u^2`` and the covariance's diagonal is ``u^2``.
    """
    if linear is None:
        linear = jacobian.covariance(centre_cov_mm2)
    total = np.diagonal(linear, axis1=1, axis2=2)  # (M, 12)
    common = np.diagonal(
        jacobian.covariance(centre_cov_mm2, jacobian.common_parts), axis1=1, axis2=2
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, np.clip(common / np.where(total > 0, total, 1.0), 0, 1), 0.0)
    lin_u = np.sqrt(np.clip(total.T, 0.0, None))  # (12, M)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(lin_u > 0, u.T / np.where(lin_u > 0, lin_u, 1.0), 0.0)
    pairs = None
    if between:
        pairs = jacobian.between_targets(centre_cov_mm2) * scale[:, :, None] * scale[:, None, :]
    return u * np.sqrt(share), u * np.sqrt(1.0 - share), pairs
