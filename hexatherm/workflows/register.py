"""Glue of ``hexatherm register``: read a datum measurement, fit, build the balls file."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.datum import DatumFrame, datum_frame
from hexatherm.core.geometry import apply_transform, invert_transform
from hexatherm.core.registration import check_ball_layout
from hexatherm.core.spherefit import fit_spheres, probe_radius_mm
from hexatherm.errors import FitError, InputError, RegistrationError
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.measurements import read_measurements
from hexatherm.io.records import Records
from hexatherm.session import Balls, Datums


@dataclass(frozen=True)
class BallRegistration:
    """The balls file and what it was made from."""

    balls: Balls
    frame: DatumFrame
    platform2cmm: npt.NDArray[np.float64]
    fitted_diameters_mm: npt.NDArray[np.float64]
    form_um: npt.NDArray[np.float64]
    n: npt.NDArray[np.int64]
    bore_distance_mm: float
    #: (k, 3, 3) each centre's covariance from its sphere fit, in the platform frame (mm^2);
    #: the datum frame's own uncertainty (common to every ball) is not in it
    cov_centre_mm2: npt.NDArray[np.float64] | None = None

    @property
    def u_centre_um(self) -> npt.NDArray[np.float64] | None:
        """(k, 3) standard uncertainty of each centre along the platform's x, y, z, um."""
        if self.cov_centre_mm2 is None:
            return None
        return np.sqrt(np.maximum(np.diagonal(self.cov_centre_mm2, axis1=1, axis2=2), 0)) * 1e3


def _check_diameters(
    rec: Records,
    names: list[str],
    fitted_mm: npt.NDArray[np.float64],
    nominal_mm: npt.NDArray[np.float64],
    datums: Datums,
    tolerance_um: float,
) -> None:
    """InputError for the first ball whose fitted diameter is off its nominal one."""
    deviation_um = (fitted_mm - nominal_mm) * 1e3
    bad = np.abs(deviation_um) > tolerance_um
    if not np.any(bad):
        return
    j = int(np.argmax(bad))
    first = int(np.argmax(rec.ball == names[j]))
    tip = "" if datums.probe_compensated else " (ball plus probe tip: uncompensated points)"
    raise InputError(
        f"ball {names[j]}: fitted diameter {fitted_mm[j]:.4f} mm is {deviation_um[j]:+.1f} um "
        f"from the nominal {nominal_mm[j]:.4f} mm{tip} (tolerance {tolerance_um:g} um, "
        "--diameter-tolerance-um): a wrong diameter in the datums file, another ball, or a "
        "wrong probe: setting",
        path=rec.path,
        line=int(rec.line[first]),
        field="ball",
    )


#: smallest accepted ratio of the top face points' spread across their main line to
#: their spread along it: below it the face's tilt about that line rests on the probe's
#: noise (three points of one scan line tilt the frame by tens of degrees)
MIN_PLANE_ASPECT = 0.1


def _check_plane_spread(rec: Records, plane: str) -> None:
    """InputError when the plane's points lie along a line (the frame's tilt about it is noise)."""
    mask = rec.ball == plane
    points = rec.xyz_mm[mask]
    if len(points) < 3 or not np.all(np.isfinite(points)):
        return  # the plane fit names these
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False) / np.sqrt(len(points))
    if spread[1] >= MIN_PLANE_ASPECT * spread[0]:
        return
    raise InputError(
        f"plane {plane}: its {len(points)} points lie along a line ({spread[1]:.4f} mm RMS "
        f"across it, {spread[0]:.3f} mm along it; at least {MIN_PLANE_ASPECT:g} of it "
        "across): the face's tilt about that line is undetermined; probe the face over "
        "its area",
        path=rec.path,
        line=int(rec.line[int(np.argmax(mask))]),
        field="ball",
    )


def _check_ball_places(
    rec: Records, names: list[str], centres_mm: npt.NDArray[np.float64], datums: Datums
) -> None:
    """InputError for two balls overlapping (one ball probed twice) or balls in a row."""
    diameters = np.array([datums.balls[n] for n in names])
    distance = np.linalg.norm(centres_mm[:, None, :] - centres_mm[None, :, :], axis=2)
    overlap = np.triu(distance < (diameters[:, None] + diameters[None, :]) / 2, k=1)
    if np.any(overlap):
        i, j = (int(k) for k in np.argwhere(overlap)[0])
        raise InputError(
            f"balls {names[i]} and {names[j]}: centres {distance[i, j]:.3f} mm apart, closer "
            "than their radii add up to: one ball probed twice, or a label given twice",
            path=rec.path,
            line=int(rec.line[int(np.argmax(rec.ball == names[j]))]),
            field="ball",
        )
    try:
        check_ball_layout(centres_mm)
    except RegistrationError as exc:
        raise InputError(f"{exc}: the balls file could not be used", path=rec.path) from None


def _points(path: str | os.PathLike[str], step: str | None, reading: ReadOptions) -> Records:
    read = read_measurements(
        path, allow_truncated=reading.allow_truncated, keep_later=reading.keep_later
    )
    found = [r for r in read if r.kind == "points"]
    if not found:
        raise InputError(
            "no probed points: register needs points on the datums and balls", path=os.fspath(path)
        )
    rec = found[0]
    labels = sorted(set(rec.label.tolist()))
    if step is None:
        if len(labels) != 1:
            raise InputError(
                f"several step labels ({', '.join(labels)}): name one with "
                "'step:' in the datums file",
                path=rec.path,
            )
        step = labels[0]
    if step not in labels:
        raise InputError(
            f"no records with step label {step!r} (found {', '.join(labels)})", path=rec.path
        )
    keep = rec.label == step
    return Records(
        rec.path,
        "points",
        rec.label[keep],
        rec.ball[keep],
        rec.xyz_mm[keep],
        rec.time_s[keep],
        rec.time_kind,
        rec.line[keep],
    )


#: the resolution of the centres register writes (as every length of a result file)
BALLS_RESOLUTION_MM = 1e-7

#: largest deviation of a ball's fitted diameter from its nominal one, um (``register``)
DIAMETER_TOLERANCE_UM = 20.0


def register_balls(
    path: str | os.PathLike[str],
    datums: Datums,
    fixed_diameter: bool = False,
    diameter_tolerance_um: float = DIAMETER_TOLERANCE_UM,
    reading: ReadOptions = STRICT,
) -> BallRegistration:
    """Fit the datums and the balls of one measurement; balls in the platform frame.

    Every ball's diameter fitted with a free radius (plus the probe tip's when the
    points are not compensated) is compared with the datums file's nominal one: a
    wrong nominal diameter moves every centre fitted with a fixed radius (a 1 mm error
    moves it about 0.7 mm over a 70 deg cap), and the balls file carries it into every
    session. Beyond ``diameter_tolerance_um`` (um, ``inf`` turns the check off) an
    InputError names the measurement file, the ball's first line and both diameters.
    ``reading`` says what the reader may read past (:class:`~hexatherm.io.files.ReadOptions`).
    """
    if not diameter_tolerance_um >= 0:
        raise ValueError(f"diameter_tolerance_um must be >= 0, got {diameter_tolerance_um!r}")
    rec = _points(path, datums.step, reading)

    def feature(name: str) -> npt.NDArray[np.float64]:
        mask = rec.ball == name
        if not mask.any():
            raise InputError(
                f"no points of feature {name!r} (found "
                f"{', '.join(sorted(set(rec.ball.tolist())))})",
                path=rec.path,
            )
        return rec.xyz_mm[mask]

    names = list(datums.balls)
    tip_r = 0.0 if datums.probe_compensated else datums.tip_diameter_mm / 2
    ball_points = [feature(n) for n in names]
    groups = np.concatenate([np.full(len(p), i) for i, p in enumerate(ball_points)])
    nominal_mm = np.array(
        [
            2 * probe_radius_mm(datums.balls[n], datums.tip_diameter_mm, datums.probe_compensated)
            for n in names
        ]
    )
    radius = nominal_mm / 2 if fixed_diameter else None
    points = np.concatenate(ball_points)
    try:
        try:
            free = fit_spheres(points, groups)
        except FitError:
            if radius is None:
                raise
            free = None  # too few points for a free radius (a fixed one takes 3): no check
        if free is not None:
            _check_diameters(
                rec, names, 2 * free.radius_mm, nominal_mm, datums, diameter_tolerance_um
            )
        fits = (
            fit_spheres(points, groups, radius_mm=radius)
            if free is None or radius is not None
            else free
        )
        _check_ball_places(rec, names, fits.centre_mm, datums)
        _check_plane_spread(rec, datums.plane)
        towards = fits.centre_mm.mean(axis=0) - feature(datums.plane).mean(axis=0)
        frame = datum_frame(
            feature(datums.plane),
            feature(datums.bores[0]),
            feature(datums.bores[1]),
            towards=towards,
            tip_radius_mm=tip_r,
        )
    except FitError as exc:
        what = f"ball {names[exc.index]}: " if exc.index is not None else ""
        raise InputError(f"{what}{exc}", path=rec.path) from None
    offset = np.eye(4)
    offset[:3, 3] = datums.origin_offset_mm
    platform2cmm = frame.datum2cmm @ offset
    centres = apply_transform(invert_transform(platform2cmm), fits.centre_mm)
    balls = Balls(
        tuple(names),
        centres,
        np.array([datums.balls[n] for n in names]),
        datums.probe_compensated,
        datums.tip_diameter_mm,
    )
    distance = float(np.linalg.norm(frame.bores[1].centre_mm - frame.bores[0].centre_mm))
    rotation = platform2cmm[:3, :3]  # cmm = R p + t: cov_p = R^T cov_cmm R
    cov = np.einsum("ji,mjk,kl->mil", rotation, fits.cov_centre_mm2, rotation)
    return BallRegistration(
        balls, frame, platform2cmm, 2 * fits.radius_mm, fits.form_um, fits.n, distance, cov
    )


def register(
    measurement: os.PathLike[str],
    datums_path: os.PathLike[str],
    out: os.PathLike[str],
    fixed_diameter: bool,
    diameter_tolerance_um: float,
    overwrite: bool,
    reading: ReadOptions,
) -> BallRegistration:
    """``hexatherm register``: the output checked before any work, the datums read, the
    frame built and the balls registered, the balls file written to ``out``."""
    from hexatherm.io.config import balls_to_yaml, read_datums
    from hexatherm.io.outputs import check_output_settled, write_output_file

    inputs = [measurement, datums_path]
    check_output_settled(out, kind="file", inputs=inputs, overwrite=overwrite)
    datums = read_datums(datums_path)
    result = register_balls(measurement, datums, fixed_diameter, diameter_tolerance_um, reading)
    text = balls_to_yaml(result.balls, result.u_centre_um, BALLS_RESOLUTION_MM)
    write_output_file(out, text, inputs=inputs, overwrite=overwrite)
    return result
