"""The rigid part of a calibration as the frames a controller takes (issue 33 item 7).

A controller computes its leg lengths with its own (nominal) joints ``b_i`` (base) and
``p_i`` (platform): ``q_i = |M p_i - b_i|`` for the platform's pose ``M`` in its machine
frame. The calibration finds the real joints ``b'_i`` (frame O) and ``p'_i`` (the
platform frame the balls define). Their rigid part, the proper rigid motions ``A`` and
``C`` that best carry the nominal joints onto the calibrated ones in least squares
(``b'_i ~ A b_i``, ``p'_i ~ C p_i``: :func:`frame_correction`), is what a controller's
coordinate frames can absorb: with ``M = G X H^-1`` and ``G = A^-1``, ``H = C^-1``,

    q_i = |A^-1 X C p_i - b_i| = |X (C p_i) - A b_i| ~ |X p'_i - b'_i|,

so the platform reaches the commanded pose ``X`` (exactly, when the joints' error is
rigid). When it is not (the joints' non-rigid part, the leg offsets and gains), the
frames that serve best are those that bring the calibrated model's predicted poses
closest to the commanded ones over the campaign's targets (:func:`fit_frames`, least
squares in um and urad, started from no frames: Levenberg-Marquardt only takes steps
that lower the sum, so never worse than no frames), the rigid part's exact values for a
rigid error. ``G`` is the pose of the corrected *user*
(Symétrie) or *work* (PI) frame in the frame the poses were commanded in during the
calibration, ``H`` that of the corrected *object* (Symétrie) or *tool* (PI) frame in the
platform frame. A campaign measured with frames ``U0``, ``O0`` set is, relative to its
frame O (the platform at the origin step), a campaign with no frames of the nominal
hexapod whose base joints are moved by ``M0^-1 = O0 U0^-1`` and whose commanded poses
are ``O0 X O0^-1`` (:mod:`hexatherm.core.frames`, which ``run`` and ``process`` use too):
the same leg lengths, exactly; the controller then takes ``U0 O0^-1 G O0`` and ``H O0``
(:func:`corrected_frames`). What stays is not a frame: the controller's own
geometry parameters would take it (``controller.yaml``'s neutral form).

How the two makers compose the frames, as their public clients say (docs/calibrate.md,
"The controller's form", with the sources): Symétrie, ``platform in machine = U X O^-1``
(CGSE's ``HexapodSimulator``: user frame linked to the machine frame, object frame to the
platform frame, the pose the object's in the user frame; BLISS: the pose ``uTo``, the
platform ``mTp``), each frame ``[R t]`` with ``R = Rz Ry Rx`` (fixed axes, CGSE's
``sxyz``): hexatherm's ``symetrie`` convention. PI, the work-and-tool concept (work frame
fixed in space, tool frame moving with the platform, the pose the tool's in the work
frame, rotations about the tool's origin), poses with rotations ``U -> V -> W`` about axes
moving with the platform: hexatherm's ``pi`` convention.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares

from hexatherm.core.frames import campaign_transforms
from hexatherm.core.geometry import (
    Convention,
    apply_transform,
    check_poses,
    invert_transform,
    pose_from_transform,
    to_um_urad,
    transform_from_pose,
)
from hexatherm.core.registration import rigid_rows
from hexatherm.errors import CalibrationError
from hexatherm.typing import FloatArray

#: finite-difference step of :func:`fit_frames`' Jacobian, mm or deg
_STEP = 1e-6


@dataclass(frozen=True)
class FrameCorrection:
    """The rigid part of the joints' change and what it leaves.

    Attributes
    ----------
    base_fit, platform_fit : ndarray, shape (4, 4)
        ``A`` and ``C``: the proper rigid motions carrying the nominal base (platform)
        joints onto the calibrated ones, least squares.
    base_rest_mm, platform_rest_mm : ndarray, shape (6, 3)
        The calibrated joints minus the rigid motion of the nominal ones: the non-rigid
        part, which no frame takes.
    """

    base_fit: FloatArray
    platform_fit: FloatArray
    base_rest_mm: FloatArray
    platform_rest_mm: FloatArray

    def values(self, convention: Convention) -> FloatArray:
        """The 12 frame values (mm, deg) of ``G = A^-1`` then ``H = C^-1``."""
        frames = invert_transform(np.stack([self.base_fit, self.platform_fit]))
        return np.asarray(pose_from_transform(frames, convention), float).ravel()


def frame_correction(
    nominal_base_mm: npt.ArrayLike,
    nominal_platform_mm: npt.ArrayLike,
    base_mm: npt.ArrayLike,
    platform_mm: npt.ArrayLike,
) -> FrameCorrection:
    """The rigid part of the change from nominal to calibrated joints (6, 3 each).

    >>> import numpy as np
    >>> from hexatherm.core.geometry import transform_from_pose
    >>> b = np.array([[100.0, 0, 0], [0, 100, 0], [-100, 0, 0],
    ...               [0, -100, 0], [70, 70, 0], [-70, -70, 5]])
    >>> a = transform_from_pose([0.1, -0.2, 0.05, 0.01, -0.02, 0.03])
    >>> fit = frame_correction(b, b, b @ a[:3, :3].T + a[:3, 3], b)
    >>> bool(np.allclose(fit.base_fit, a, atol=1e-12))
    True
    >>> (fit.values("symetrie")[6:].round(12) + 0.0).tolist()
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    """
    out = []
    for nominal, calibrated in ((nominal_base_mm, base_mm), (nominal_platform_mm, platform_mm)):
        src = np.asarray(nominal, float).reshape(6, 3)
        dst = np.asarray(calibrated, float).reshape(6, 3)
        fit = rigid_rows(dst[None], src[None], np.ones(6))[0]
        out += [fit, dst - (src @ fit[:3, :3].T + fit[:3, 3])]
    return FrameCorrection(out[0], out[2], out[1], out[3])


def command(values: npt.ArrayLike, poses: npt.ArrayLike, convention: Convention) -> FloatArray:
    """The poses (N, 6) the controller's own geometry is given for commanded ``poses``
    once the frames ``values`` (12: ``G`` then ``H``) are set: ``G X H^-1``."""
    v = np.asarray(values, float)
    g, h = transform_from_pose(np.stack([v[:6], v[6:]]), convention)
    x = transform_from_pose(check_poses(poses), convention)
    return np.asarray(pose_from_transform(g @ x @ invert_transform(h), convention), float)


@dataclass(frozen=True)
class FramesFit:
    """The frames that bring predicted poses closest to the commanded ones.

    Attributes
    ----------
    values : ndarray, shape (12,)
        ``G`` (the corrected user/work frame in the commanding frame) then ``H`` (the
        corrected object/tool frame in the platform frame), mm and deg.
    residuals_um_urad : ndarray, shape (N, 6)
        Predicted minus commanded poses with the frames set.
    jacobian : ndarray, shape (6N, 12)
        Derivatives of the residuals by the values (um, urad per mm, deg).
    """

    values: FloatArray
    residuals_um_urad: FloatArray
    jacobian: FloatArray

    def covariance(self, by_parameters: npt.ArrayLike, covariance: npt.ArrayLike) -> FloatArray:
        """The values' covariance (12, 12) from the model parameters': ``by_parameters``
        the residuals' derivatives (6N, P) by them at the optimum, ``covariance`` (P, P).
        At the optimum ``J^T r = 0``; to first order the values move by
        ``-(J^T J)^-1 J^T (dr/dtheta) dtheta``."""
        j = self.jacobian
        d = -np.linalg.solve(j.T @ j, j.T @ np.asarray(by_parameters, float))
        return np.asarray(d @ np.asarray(covariance, float) @ d.T, float)


def fit_frames(
    predict: Callable[[FloatArray], FloatArray],
    commanded: npt.ArrayLike,
    convention: Convention,
    start: npt.ArrayLike | None = None,
) -> FramesFit:
    """The 12 frame values minimising ``sum |predict(G X H^-1) - X|^2`` (um and urad)
    over the commanded poses ``X`` (N, 6); ``predict`` maps the poses given to the
    controller's geometry (N, 6) to the poses reached (N, 6), both mm and deg."""
    x = np.atleast_2d(check_poses(commanded))
    if x.shape[0] < 2:
        raise CalibrationError("the frames need at least 2 commanded poses (12 values)")

    def residuals(v: FloatArray) -> FloatArray:
        return np.asarray(to_um_urad(predict(command(v, x, convention)) - x), float).ravel()

    v0 = np.zeros(12) if start is None else np.asarray(start, float)
    found = least_squares(residuals, v0, method="lm", diff_step=_STEP, xtol=1e-12, ftol=1e-12)
    v = np.asarray(found.x, float)
    jac = np.zeros((x.size, 12))
    for k in range(12):
        step = np.zeros(12)
        step[k] = _STEP
        jac[:, k] = (residuals(v + step) - residuals(v - step)) / (2 * _STEP)
    return FramesFit(v, residuals(v).reshape(-1, 6), jac)


def in_frame(points_mm: npt.ArrayLike, pose: npt.ArrayLike, convention: Convention) -> FloatArray:
    """Points (k, 3) given in a frame A, expressed in the frame whose pose in A is
    ``pose`` (6,): ``T(pose)^-1 p``."""
    frame = invert_transform(transform_from_pose(check_poses(pose), convention))
    return np.asarray(apply_transform(frame, points_mm), float)


def corrected_frames(
    values: npt.ArrayLike, convention: Convention, during: npt.ArrayLike | None = None
) -> FloatArray:
    """The 12 values (mm, deg, ``convention``) a controller is given: its user (work)
    frame's pose in the machine frame (ZERO), then its object (tool) frame's in the
    platform frame, from the fitted ``values`` (``G`` then ``H``, relative to the
    campaign's frame O: :func:`fit_frames` on poses from
    :func:`~hexatherm.core.frames.poses_from_origin`) and
    the frames ``U0``, ``O0`` set during the campaign (``during``: 12 values, mm and deg,
    Symétrie convention, as ``run.yaml`` records them; zero when not given):
    ``U0 O0^-1 G O0`` and ``H O0``.

    Commanding ``X`` then puts the platform at ``M0 G (O0 X O0^-1) H^-1`` in the
    machine frame, ``G (O0 X O0^-1) H^-1`` relative to frame O: what the fit made reach
    ``O0 X O0^-1``, the object frame at ``X`` from where it stood at the campaign's
    origin step. With zero frames, ``G`` and ``H``."""
    v = np.asarray(values, float)
    u0, o0 = campaign_transforms(np.zeros(12) if during is None else during)
    g, h = transform_from_pose(np.stack([v[:6], v[6:]]), convention)
    frames = np.stack([u0 @ invert_transform(o0) @ g @ o0, h @ o0])
    return np.asarray(pose_from_transform(frames, convention), float).ravel()


def frames_covariance(
    values: npt.ArrayLike,
    covariance: npt.ArrayLike,
    convention: Convention,
    during: npt.ArrayLike | None = None,
) -> FloatArray:
    """The covariance (12, 12) of :func:`corrected_frames` from the fitted values'
    (first order: central differences of 1e-6 mm, deg); the same with zero frames."""
    v = np.asarray(values, float)
    args = (convention, during)
    steps = np.eye(12) * _STEP
    jac = (
        np.stack([corrected_frames(v + d, *args) - corrected_frames(v - d, *args) for d in steps])
        / (2 * _STEP)
    ).T
    return np.asarray(jac @ np.asarray(covariance, float) @ jac.T, float)
