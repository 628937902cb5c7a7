"""Glue of ``hexatherm register``: read a datum measurement, fit, build the balls file."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.datum import DatumFrame, datum_frame
from hexatherm.core.geometry import apply_transform, invert_transform
from hexatherm.core.spherefit import fit_spheres, probe_radius_mm
from hexatherm.errors import FitError, InputError
from hexatherm.io.csvfile import read_measurements
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


def _points(path: str | os.PathLike[str], step: str | None) -> Records:
    found = [r for r in read_measurements(path) if r.kind == "points"]
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


def register_balls(
    path: str | os.PathLike[str], datums: Datums, fixed_diameter: bool = False
) -> BallRegistration:
    """Fit the datums and the balls of one measurement; balls in the platform frame."""
    rec = _points(path, datums.step)

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
    radius = None
    if fixed_diameter:
        radius = np.array(
            [
                probe_radius_mm(datums.balls[n], datums.tip_diameter_mm, datums.probe_compensated)
                for n in names
            ]
        )
    try:
        fits = fit_spheres(np.concatenate(ball_points), groups, radius_mm=radius)
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
    return BallRegistration(
        balls, frame, platform2cmm, 2 * fits.radius_mm, fits.form_um, fits.n, distance
    )
