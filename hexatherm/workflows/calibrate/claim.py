"""The calibration's claim for new poses over the stroke: the parameters' uncertainty
at poses drawn over the campaign's span and the level's model floor
(:mod:`hexatherm.core.calibration.claim`), from the sessions' thermocouple logs at
their first reference R0.

The claim is a function of the pose (:func:`pose_claim` at any commanded poses): the
parameters' part grows towards the ends of the stroke, and so does the floor (what the
legs' growth leaves there). One number for the whole stroke over-claims the inner poses
and under-claims the outer ones (1.4x and 0.76x on the twin's campaigns), so the claim
is also given by stroke region (:func:`claim_regions`: inner, middle and outer thirds of
the poses by their distance from the centre of the campaign's box) and along each axis
of the box (:func:`claim_along_axes`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.calibration.claim import ModelFloor, combined_sigma, model_floor
from hexatherm.core.effects import ThermocoupleLog
from hexatherm.core.residuals import rms
from hexatherm.errors import InputError
from hexatherm.typing import FloatArray
from hexatherm.workflows.calibrate.run import Calibration

#: new poses drawn over the campaign's span for the claim (and the report's map)
N_SPAN_POSES = 2000
#: the leg temperatures at O and R0 are the trend of the log's samples this far around
TREND_MARGIN_S = 300.0


def span_poses(run: Calibration, n: int = N_SPAN_POSES, seed: int = 0) -> FloatArray:
    """New poses drawn uniformly in the span of the campaign's commanded poses (its
    smallest box, mm and deg), those whose legs stay inside the stroke (seeded).
    InputError naming the hexapod file's stroke when none does (a stroke that excludes
    the commanded poses themselves: no claim for a new pose can be evaluated)."""
    nominal = run.campaign.nominal
    commanded = run.campaign.commanded
    lower, upper = commanded.min(axis=0), commanded.max(axis=0)
    draws = np.random.default_rng(seed).uniform(lower, upper, (n, 6))
    inside = ~nominal.check_stroke(nominal.igm(draws)).any(axis=1)
    if not inside.any():
        out = int(nominal.check_stroke(nominal.igm(commanded)).any(axis=1).sum())
        stroke = ", ".join(f"{v:g}" for v in np.asarray(nominal.stroke_mm, float))
        session = run.campaign.results[0].session
        raise InputError(
            f"none of {n} poses drawn over the span of the campaign's commanded poses keeps "
            f"its legs inside the stroke [{stroke}] mm ({out} of the {len(commanded)} "
            "targets are outside it already): the claim for a new pose cannot be "
            "evaluated; is this the stroke of the hexapod the poses were commanded on?",
            path=str(session.config_files[0] if session.config_files else session.path),
            field="stroke",
        )
    return np.asarray(draws[inside], float)


@dataclass(frozen=True)
class PoseClaim:
    """What the calibration claims for a new pose over the campaign's span.

    Attributes
    ----------
    poses : ndarray, shape (M, 6)
        The new poses (:func:`span_poses`).
    parameters_um_urad : ndarray, shape (M, 6)
        The parameters' part of their standard uncertainty (um, urad).
    floor : ModelFloor
        The level's model floor, added to every pose.
    """

    poses: FloatArray
    parameters_um_urad: FloatArray
    floor: ModelFloor

    @property
    def sigma_um_urad(self) -> FloatArray:
        """The claimed standard uncertainty (M, 6) of each new pose (um, urad)."""
        return combined_sigma(self.parameters_um_urad, self.floor)

    @property
    def worst_um_urad(self) -> FloatArray:
        """Its largest value (6,) over the new poses."""
        return np.asarray(self.sigma_um_urad.max(axis=0), float)

    @property
    def typical_um_urad(self) -> FloatArray:
        """Its RMS (6,) over the new poses: what a new pose's error is on average."""
        return np.asarray(rms(self.sigma_um_urad, axis=0), float)


def leg_trend_C(
    times_s: FloatArray, legs_C: FloatArray, at_s: FloatArray, margin_s: float = TREND_MARGIN_S
) -> FloatArray:
    """Each leg's temperature (len(at_s), 6) at ``at_s`` from a straight line fitted (least
    squares) to the log's samples from ``margin_s`` before the first to ``margin_s``
    after the last of ``at_s``: the trend, without the thermocouples' noise of single
    samples (which would make a difference of two of them look like growth); the
    samples joined by straight lines where fewer than 3 fall in the window."""
    inside = (times_s >= at_s.min() - margin_s) & (times_s <= at_s.max() + margin_s)
    if np.count_nonzero(inside) < 3:
        return ThermocoupleLog(times_s, legs_C).legs_at(at_s)
    t = times_s[inside]
    mid = t.mean()
    design = np.column_stack([np.ones(t.size), t - mid])
    coef = np.linalg.lstsq(design, legs_C[inside], rcond=None)[0]  # (2, 6)
    return np.asarray(np.column_stack([np.ones(at_s.size), at_s - mid]) @ coef, float)


def r0_leg_temperatures(run: Calibration) -> tuple[FloatArray | None, str]:
    """Every session's leg temperatures at its R0 and at its origin step O (S, 2, 6)
    from its thermocouple log (:func:`leg_trend_C`), or None and why not."""
    rows = []
    for result in run.campaign.results:
        if result.temperatures is None:
            return None, f"{result.session.name} has no thermocouple log (temperatures:)"
        plan = result.session.plan
        refs = plan.reference_indices
        r0 = int(refs[0]) if refs.size else plan.origin_index
        temps = result.temperatures
        # O carried to R0's thermal state by process (issue 35): O's legs are R0's
        origin = r0 if result.carry is not None else plan.origin_index
        at = np.asarray(result.centres.times_s, float)[[r0, origin]]
        rows.append(leg_trend_C(np.asarray(temps.time_s, float), temps.legs_C, at))
    return np.asarray(rows, float), ""


def pose_claim(
    run: Calibration,
    poses: FloatArray | None = None,
    parameters_um_urad: FloatArray | None = None,
) -> PoseClaim:
    """The claim over new ``poses`` (default :func:`span_poses`) whose parameters' part
    ``parameters_um_urad`` may be given (computed otherwise)."""
    if poses is None:
        poses = span_poses(run)
    if parameters_um_urad is None:
        parameters_um_urad = run.fit.predicted_sigma_um_urad(poses)
    campaign = run.campaign
    legs = campaign.nominal.legs
    temps, why = r0_leg_temperatures(run)
    if legs is None:
        floor = ModelFloor.none("the hexapod file has no leg model (legs:)")
    elif temps is None:
        floor = ModelFloor.none(why)
    else:
        session = np.concatenate(
            [
                np.full(r.correction.target_index.size, i, dtype=np.int64)
                for i, r in enumerate(campaign.results)
            ]
        )
        floor = model_floor(
            run.fit,
            campaign.commanded,
            campaign.weights_covariance,
            legs,
            temps[:, 0],
            temps[:, 1],
            session,
            poses,
        )
    return PoseClaim(poses, parameters_um_urad, floor)


#: the stroke regions of :func:`claim_regions`: thirds of the new poses by their radius
REGIONS = ("inner", "middle", "outer")
#: where :func:`claim_along_axes` evaluates the claim: fractions of the box's half-width
AXIS_STEPS = (-1.0, -0.5, 0.0, 0.5, 1.0)


def _box(run: Calibration) -> tuple[FloatArray, FloatArray]:
    """The centre and half-widths (6,) of the campaign's box (its commanded poses' span)."""
    commanded = run.campaign.commanded
    lower, upper = commanded.min(axis=0), commanded.max(axis=0)
    return (lower + upper) / 2, (upper - lower) / 2


def stroke_radius(run: Calibration, poses: FloatArray) -> FloatArray:
    """Each pose's distance (M,) from the centre of the campaign's box in units of its
    half-widths, RMS over the components the campaign varies: 0 at the centre, 1 at a
    corner, 1/sqrt(6) at the end of one axis."""
    centre, half = _box(run)
    varied = half > 1e-12
    if not varied.any():
        return np.zeros(len(poses))
    scaled = (np.atleast_2d(poses)[:, varied] - centre[varied]) / half[varied]
    return np.asarray(np.sqrt(np.mean(scaled**2, axis=1)), float)


@dataclass(frozen=True)
class ClaimRegions:
    """The claim by stroke region (:data:`REGIONS`).

    Attributes
    ----------
    bounds : ndarray, shape (2,)
        The radii (:func:`stroke_radius`) between inner and middle, middle and outer:
        the thirds of the claim's new poses.
    counts : ndarray of int, shape (3,)
        New poses in each region.
    rms_um_urad, worst_um_urad : ndarray, shape (3, 6)
        RMS and largest claimed standard uncertainty (k = 1) of the new poses in each.
    """

    bounds: FloatArray
    counts: npt.NDArray[np.intp]
    rms_um_urad: FloatArray
    worst_um_urad: FloatArray

    def region_of(self, radius: FloatArray) -> npt.NDArray[np.intp]:
        """The region (0 inner, 1 middle, 2 outer) of poses at ``radius``."""
        return np.asarray(np.digitize(radius, self.bounds), np.intp)


def claim_regions(run: Calibration, claim: PoseClaim) -> ClaimRegions:
    """The claim over its new poses by stroke region (thirds by radius)."""
    radius = stroke_radius(run, claim.poses)
    bounds = np.quantile(radius, [1 / 3, 2 / 3])
    region = np.digitize(radius, bounds)
    sigma = claim.sigma_um_urad
    rms_rows, worst_rows, counts = [], [], []
    for k in range(len(REGIONS)):
        mine = sigma[region == k]
        counts.append(len(mine))
        rms_rows.append(rms(mine, axis=0) if len(mine) else np.full(6, np.nan))
        worst_rows.append(mine.max(axis=0) if len(mine) else np.full(6, np.nan))
    return ClaimRegions(
        np.asarray(bounds, float),
        np.asarray(counts, np.intp),
        np.asarray(rms_rows, float),
        np.asarray(worst_rows, float),
    )


@dataclass(frozen=True)
class ClaimAxes:
    """The claim along each axis of the campaign's box, the other components at its
    centre.

    Attributes
    ----------
    positions : ndarray, shape (6, len(AXIS_STEPS))
        The commanded value of the axis (mm, deg) at each step.
    sigma_um_urad : ndarray, shape (6, len(AXIS_STEPS), 6)
        The claimed standard uncertainty (k = 1) of every component there (NaN: out of
        the stroke).
    """

    positions: FloatArray
    sigma_um_urad: FloatArray


def claim_along_axes(run: Calibration) -> ClaimAxes:
    """The claim (:func:`pose_claim`) along each axis of the campaign's box."""
    centre, half = _box(run)
    steps = np.asarray(AXIS_STEPS)
    poses = np.tile(centre, (6, len(steps), 1))
    for axis in range(6):
        poses[axis, :, axis] = centre[axis] + steps * half[axis]
    flat = poses.reshape(-1, 6)
    nominal = run.campaign.nominal
    inside = ~nominal.check_stroke(nominal.igm(flat)).any(axis=1)
    sigma = np.full(flat.shape, np.nan)
    if inside.any():
        sigma[inside] = pose_claim(run, flat[inside]).sigma_um_urad
    return ClaimAxes(poses[np.arange(6), :, np.arange(6)], sigma.reshape(6, len(steps), 6))
