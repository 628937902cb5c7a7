"""The covariance of every ball centre of a processed session, and where it came from.

See :mod:`hexatherm.workflows.process.uncertainty` for the order of the sources. A
centres file's scalar ``u_um`` (what most CMM software states for a sphere) is not read
as isotropic: a cap fit's centre is about twice as uncertain along the cap's axis as
across it, so the scalar gets the shape of a free-radius fit to the plan's touch pattern
(its points per ball over the cap of the session's ``cmm:`` mapping, default 70 deg),
scaled so that its RMS over the three axes, ``sqrt(trace / 3)``, is the file's ``u`` (the
scalar ``fit-spheres`` writes and hexatherm reads back). The screen says what was assumed
(a warning). Scaling the z part to the references' heights (as for centres without u) was
tried: over 100 replicas it claimed the same on average and covered less (93 % within
2u against 95 %), its 9 degrees of freedom making every replica's u noisier.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.capshape import cap_for_lateral
from hexatherm.core.propagation import cap_centre_covariance, cap_height_floor, residual_scale
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.heights import (
    FEW_HEIGHT_DOF,
    HeightScale,
    reference_height_scale,
)
from hexatherm.workflows.process.pipeline import ProcessResult

__all__ = ["DEFAULT_CAP_ANGLE_DEG", "CentreCovariance", "centre_covariance"]

#: cap half-angle assumed for centres given without an uncertainty (as ``cmm:``'s default)
DEFAULT_CAP_ANGLE_DEG = 70.0
#: chance level of the registration residuals' lateral scatter beyond the assumed cap's
#: when ``cmm:`` states no cap: above it a shallower cap is taken (0.05: 1.01x Tx and
#: 1.05x Tz expected over-claim when the assumed cap is right, 0.96-1.03 at 45-62 deg;
#: at 0.1, one replica in ten of a 70 deg pattern widened by chance: Rx 1.19x over 100)
CAP_CHECK_P = 0.05


@dataclass(frozen=True)
class CentreCovariance:
    """Covariance of every ball centre and where it came from.

    Attributes
    ----------
    cov_mm2 : ndarray, shape (N, k, 3, 3)
    source : ndarray of str, shape (N, k)
        ``fit``, ``file``, ``cmm`` or ``registration`` (see the module docstring).
    description : str
        One line saying which sources were used, with their figures.
    """

    cov_mm2: FloatArray
    source: npt.NDArray[np.str_]
    description: str

    @property
    def u_um(self) -> FloatArray:
        """RMS standard uncertainty per coordinate of each centre, ``sqrt(trace / 3)``, um."""
        return np.sqrt(np.trace(self.cov_mm2, axis1=-2, axis2=-1) / 3) * 1e3


def heights_of(
    result: ProcessResult, shape: FloatArray, assumed_z_mm2: float
) -> tuple[HeightScale, bool]:
    """The references' height scatter against the z variance ``assumed_z_mm2`` of one
    measurement of the cap ``shape`` (:func:`reference_height_scale`), not used when it
    scatters less than any free-radius upper-cap fit allows (the second value, True)."""
    height = reference_height_scale(result, assumed_z_mm2)
    floor = cap_height_floor(height.dof, shape) if height.used else 0.0
    too_flat = height.ratio < floor
    if too_flat:
        height = dataclasses.replace(
            height,
            used=False,
            ratio=1.0,
            text="",
            why=(
                f"the references' ball heights ({height.dof} degrees of freedom) "
                "scatter less than a free-radius fit over an upper cap allows (z part "
                f"{height.ratio:.3g} of the assumed cap's in variance, below "
                f"{floor:.3g}: references repeating the "
                "same centres?): not the CMM's noise"
            ),
        )
    return height, bool(too_flat)


def unstated_cap(
    result: ProcessResult, points: int, sigma_mm: float, per_step: FloatArray
) -> tuple[FloatArray, str]:
    """The ``cmm:`` centre covariance (3, 3) of one measurement when the session did not
    state the cap: the assumed cap's, unless the data shows a shallower one, with a
    warning either way.

    A shallower cap than the assumed one makes a fit's centre more uncertain across (1.6x
    in variance at 50 deg) and far more along the cap's axis (3.4x), and the stated point
    noise then under-claims. The registration residuals, pooled over the steps
    (:func:`residual_scale`), show the centres' lateral variance over the assumed cap's,
    blind to the platform's thermal motion; when it exceeds chance (:data:`CAP_CHECK_P`,
    chi-square of their degrees of freedom), the cap of that lateral variance
    (:func:`cap_for_lateral`) gives the centres' covariance, its axial part included. The
    references' heights are not used here: a heating that bends between references
    enlarges their scatter, and the smooth fit's own error then reads as noise. Never
    narrower than the assumed cap: the stated point noise stands as the floor.
    """
    from scipy.special import chdtri  # not scipy.stats: its import is slow

    assumed = cap_centre_covariance(points, DEFAULT_CAP_ANGLE_DEG, sigma_mm)
    n, k = result.centres.centres_mm.shape[:2]
    lateral, _ = residual_scale(
        result.registration.residuals_mm,
        result.centres.centres_mm,
        per_step[:, :, None, None] * assumed,
    )
    dof = n * (3 * k - 6)
    chance = float(chdtri(dof, CAP_CHECK_P)) / dof if dof > 0 else np.inf
    shallower = lateral > chance
    cap = cap_for_lateral(points, DEFAULT_CAP_ANGLE_DEG, lateral) if shallower else None
    single = assumed if cap is None else cap_centre_covariance(points, cap, sigma_mm)
    u_xyz = np.sqrt(np.diag(single)) * 1e3
    text = (
        f"warning: cmm: states no cap_angle_deg, a {DEFAULT_CAP_ANGLE_DEG:g} deg cap is "
        f"assumed; the registration residuals show {lateral:.3g}x its lateral variance "
        f"({dof} degrees of freedom, chance up to {chance:.3g}x at p = {CAP_CHECK_P:g}): "
        + (
            f"taken as a {cap:.3g} deg cap, u widened to {u_xyz[0]:.3g}, {u_xyz[1]:.3g}, "
            f"{u_xyz[2]:.3g} um in x, y, z"
            if cap is not None
            else "u kept (no shallower cap shows)"
        )
        + "; state cap_angle_deg (the probing's half-angle) in cmm:"
    )
    return single, text


def centre_covariance(result: ProcessResult) -> CentreCovariance:
    """Covariance (N, k, 3, 3) of every ball centre of ``result``, with its source."""
    centres = result.centres
    n, k = centres.centres_mm.shape[:2]
    cov = np.full((n, k, 3, 3), np.nan)
    source = np.full((n, k), "", dtype=object)
    parts = []
    if centres.cov_mm2 is not None:
        given = np.isfinite(centres.cov_mm2).all(axis=(-2, -1))
        cov[given] = centres.cov_mm2[given]
        in_file = np.zeros((n, k), dtype=bool)
        if centres.cov_from_file is not None:
            in_file = given & centres.cov_from_file
        for mask, name, what in (
            (given & ~in_file, "fit", "sphere fits of the probed points"),
            (in_file, "file covariance", "u_x_um .. r_yz of the centres file"),
        ):
            source[mask] = name
            if mask.any():
                u_xyz = np.sqrt(np.median(np.diagonal(cov[mask], axis1=-2, axis2=-1), 0)) * 1e3
                parts.append(
                    f"{what} ({int(mask.sum())} centres, u {u_xyz[0]:.3g}, {u_xyz[1]:.3g}, "
                    f"{u_xyz[2]:.3g} um median in x, y, z)"
                )
    file = (source == "") & np.isfinite(centres.u_um)
    cmm = result.session.cmm
    if file.any():
        # a sphere fit's scalar u: the shape of a cap fit to the plan's touch pattern,
        # its RMS over the axes (sqrt(trace / 3)) the file's u
        points = (cmm.points_per_ball if cmm is not None else None) or (
            result.session.plan.points_per_ball
        )
        cap = DEFAULT_CAP_ANGLE_DEG if cmm is None else cmm.cap_angle_deg
        shape = cap_centre_covariance(points, cap, 1.0)
        shape = shape / (np.trace(shape) / 3)
        cov[file] = (centres.u_um[file] * 1e-3)[:, None, None] ** 2 * shape
        source[file] = "file"
        ratios = np.sqrt(np.diag(shape))
        parts.append(
            f"u_um of the centres file ({int(file.sum())} centres), shaped as a free-radius "
            f"cap fit: u in x, y, z {ratios[0]:.2f}, {ratios[1]:.2f}, {ratios[2]:.2f} x the "
            "file's u (its RMS over the axes)"
        )
        parts.append(
            "warning: the centres file's u_um is one number per centre; its shape is "
            f"assumed, a free-radius fit to {points} points over a {cap:g} deg cap"
            + (
                " (the plan's points, cmm:'s default cap)"
                if cmm is None
                else ("" if cmm.cap_stated else " (cmm:'s default cap)")
            )
            + "; u_x_um .. r_yz columns state the covariance"
        )
    rest = source == ""
    # steps combining repeated measurements (O, R0): 1/n of one measurement's covariance
    # for a mean, sum l^2 for R0's line at its last time (no log)
    per_step = np.broadcast_to(centres.variance_factor[:, None], (n, k))
    if rest.any() and cmm is not None:
        points = cmm.points_per_ball or result.session.plan.points_per_ball
        sigma = cmm.point_noise_um * 1e-3
        single = cap_centre_covariance(points, cmm.cap_angle_deg, sigma)
        checked = ""
        if not cmm.cap_stated:
            single, checked = unstated_cap(result, points, sigma, per_step)
        cov[rest] = per_step[rest][:, None, None] * single
        source[rest] = "cmm"
        parts.append(
            f"session cmm: point noise {cmm.point_noise_um:g} um, {points} points "
            f"over a {cmm.cap_angle_deg:g} deg cap ({int(rest.sum())} centres)"
        )
        if checked:
            parts.append(checked)
    elif rest.any():
        # the residuals see only part of a centre's error (three coplanar balls: nothing
        # along the plane's normal), and a cap fit's error is largest along the cap's
        # axis: keep the shape of a cap fit's covariance and scale it to the residuals
        points = result.session.plan.points_per_ball
        shape = cap_centre_covariance(points, DEFAULT_CAP_ANGLE_DEG, 1.0)
        step_shape = per_step[:, :, None, None] * shape  # (N, k, 3, 3)
        scale, seen = residual_scale(
            result.registration.residuals_mm, centres.centres_mm, step_shape
        )
        # along the cap's axis (z) the residuals see nothing: the references' heights,
        # measured again and again over the session, do (a Type A evaluation)
        height, too_flat = heights_of(result, shape, scale * shape[2, 2])
        if height.used:
            axis_scale = np.array([1.0, 1.0, np.sqrt(height.ratio)])
            shape = shape * np.outer(axis_scale, axis_scale)
            step_shape = per_step[:, :, None, None] * shape
        cov[rest] = scale * step_shape[rest]
        source[rest] = "registration"
        u_xyz = np.sqrt(np.diag(scale * shape)) * 1e3
        parts.append(
            "registration residuals pooled over "
            f"{n} steps ({int(rest.sum())} centres), with the covariance shape of a "
            f"free-radius fit to {points} points over a {DEFAULT_CAP_ANGLE_DEG:g} deg cap"
            f"{height.text}: u {u_xyz[0]:.3g}, {u_xyz[1]:.3g}, {u_xyz[2]:.3g} um in x, y, z"
        )
        if height.used and height.dof < FEW_HEIGHT_DOF:
            from scipy.special import stdtrit  # not scipy.stats: its import is slow

            parts.append(
                f"warning: the centres' error along the cap's axis (Tz, Rx, Ry) rests on "
                f"{height.dof} degrees of freedom of the references' heights: for 95 % take "
                f"k = {float(stdtrit(height.dof, 0.975)):.2f} (Student's t), not 2"
            )
        if (seen < 0.9 or too_flat) and not height.used:
            parts.append(
                f"warning: {height.why}; the residuals see {seen:.0%} of that shape (none "
                "of a centre's error normal to the balls' plane): the uncertainty of Tz, Rx, "
                "Ry rests on the assumed cap; give cmm: in session.yaml or u_um in the "
                "centres file to state the CMM's noise"
            )
    return CentreCovariance(cov, source.astype(str), "; ".join(parts))
