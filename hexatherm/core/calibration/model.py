"""The calibration's measurement model: parameters, levels, gauge, predictions and Jacobians.

See :mod:`hexatherm.core.calibration` for the model written out. This module holds the
parameter vector's layout (:data:`PARAMETER_NAMES`), the levels' masks, the gauge
(:func:`gauge_directions`, :func:`gauge_fixed`), the pose and leg-length predictions of
a geometry with their analytic Jacobians (:class:`CalibrationModel`), and the rigid
pose algebra they need (:func:`relative_pose`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

from hexatherm.core.calibration.derivatives import StandDerivatives
from hexatherm.core.geometry import (
    Convention,
    angles_from_rotation,
    check_poses,
    rotation_from_angles,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.errors import CalibrationError
from hexatherm.typing import BoolArray, FloatArray

Level = Literal["offsets", "joints", "joints+gains"]
#: the model levels, smallest first (each one's parameters contain the previous one's)
LEVELS: tuple[Level, ...] = ("offsets", "joints", "joints+gains")
#: length of the full parameter vector: 18 base, 18 platform, 6 offsets, 6 gains
N_PARAMETERS = 48
#: where each block of the parameter vector starts
BASE, PLATFORM, OFFSETS, GAINS = 0, 18, 36, 42
#: FGM tolerance of the predictions, mm (the hexapod's default is 1e-10)
PREDICTION_TOL_MM = 1e-11
#: the FGM starts from the last solution of the same poses when no parameter moved
#: further than this since (mm, or unit gain)
_WARM_START_MM = 0.5

_AXES = "xyz"
#: names of the 48 parameters, in the order of the parameter vector
PARAMETER_NAMES: tuple[str, ...] = (
    tuple(f"base{i + 1}_{a}_mm" for i in range(6) for a in _AXES)
    + tuple(f"platform{i + 1}_{a}_mm" for i in range(6) for a in _AXES)
    + tuple(f"leg{i + 1}_offset_mm" for i in range(6))
    + tuple(f"leg{i + 1}_gain" for i in range(6))
)
#: units of the 48 parameters (a gain is a ratio: 1e-6 is 1 ppm of the stroke)
PARAMETER_UNITS: tuple[str, ...] = ("mm",) * 42 + ("mm/mm",) * 6


def check_level(level: str) -> Level:
    """Return ``level`` if it is a model level, else raise CalibrationError.

    >>> check_level("joints")
    'joints'
    """
    for known in LEVELS:
        if level == known:
            return known
    raise CalibrationError(f"unknown calibration level {level!r}; expected one of {LEVELS}")


def level_mask(level: str) -> BoolArray:
    """Which of the 48 parameters a level fits, shape (48,).

    >>> [int(level_mask(level).sum()) for level in LEVELS]
    [6, 42, 48]
    """
    level = check_level(level)
    mask = np.zeros(N_PARAMETERS, dtype=bool)
    mask[OFFSETS:GAINS] = True
    if level != "offsets":
        mask[:OFFSETS] = True
    if level == "joints+gains":
        mask[GAINS:] = True
    return mask


def nominal_parameters(hexapod: Hexapod) -> FloatArray:
    """The parameter vector (48,) of a hexapod: its joints, zero offsets and gains."""
    theta = np.zeros(N_PARAMETERS)
    theta[BASE:PLATFORM] = np.asarray(hexapod.base_joints_mm, float).ravel()
    theta[PLATFORM:OFFSETS] = np.asarray(hexapod.platform_joints_mm, float).ravel()
    return theta


def split_parameters(
    theta: npt.ArrayLike,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Base joints (6, 3), platform joints (6, 3), leg offsets (6,) mm and gains (6,)."""
    t = _check_theta(theta)
    return (
        t[BASE:PLATFORM].reshape(6, 3),
        t[PLATFORM:OFFSETS].reshape(6, 3),
        t[OFFSETS:GAINS].copy(),
        t[GAINS:].copy(),
    )


def join_parameters(
    base_joints_mm: npt.ArrayLike,
    platform_joints_mm: npt.ArrayLike,
    leg_offsets_mm: npt.ArrayLike | None = None,
    leg_gains: npt.ArrayLike | None = None,
) -> FloatArray:
    """The parameter vector (48,) of joints (6, 3) each, offsets and gains (6,) (default 0)."""
    theta = np.zeros(N_PARAMETERS)
    theta[BASE:PLATFORM] = np.broadcast_to(np.asarray(base_joints_mm, float), (6, 3)).ravel()
    theta[PLATFORM:OFFSETS] = np.broadcast_to(np.asarray(platform_joints_mm, float), (6, 3)).ravel()
    if leg_offsets_mm is not None:
        theta[OFFSETS:GAINS] = np.broadcast_to(np.asarray(leg_offsets_mm, float), (6,))
    if leg_gains is not None:
        theta[GAINS:] = np.broadcast_to(np.asarray(leg_gains, float), (6,))
    return _check_theta(theta)


def _check_theta(theta: npt.ArrayLike) -> FloatArray:
    t = np.asarray(theta, dtype=float)
    if t.shape != (N_PARAMETERS,):
        raise ValueError(f"parameters must have shape ({N_PARAMETERS},), got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError(
            f"parameter {PARAMETER_NAMES[int(np.argmin(np.isfinite(t)))]} is not finite"
        )
    return t


def true_leg_lengths(
    commanded_leg_mm: npt.ArrayLike,
    home_leg_mm: npt.ArrayLike,
    leg_offsets_mm: npt.ArrayLike,
    leg_gains: npt.ArrayLike,
) -> FloatArray:
    """Joint-to-joint leg lengths the actuators produce for commanded lengths, (N, 6) mm.

    ``q_true = q_cmd + dq + g (q_cmd - q_home)``: the offset ``dq`` is the error at the
    home (zero-pose) length ``q_home``, the gain ``g`` scales the travel from it.

    >>> true_leg_lengths([[101.0] * 6], [100.0] * 6, [0.01] * 6, [1e-3] * 6)[0, 0].round(6)
    np.float64(101.011)
    """
    q = np.atleast_2d(np.asarray(commanded_leg_mm, float))
    home = np.asarray(home_leg_mm, float)
    return q + np.asarray(leg_offsets_mm, float) + np.asarray(leg_gains, float) * (q - home)


def commanded_leg_lengths(
    true_leg_mm: npt.ArrayLike,
    home_leg_mm: npt.ArrayLike,
    leg_offsets_mm: npt.ArrayLike,
    leg_gains: npt.ArrayLike,
) -> FloatArray:
    """The inverse of :func:`true_leg_lengths`: what to command for true lengths, (N, 6) mm.

    >>> q = true_leg_lengths([[101.0] * 6], [100.0] * 6, [0.01] * 6, [1e-3] * 6)
    >>> commanded_leg_lengths(q, [100.0] * 6, [0.01] * 6, [1e-3] * 6)[0, 0].round(12)
    np.float64(101.0)
    """
    q = np.atleast_2d(np.asarray(true_leg_mm, float))
    home = np.asarray(home_leg_mm, float)
    gains = np.asarray(leg_gains, float)
    return home + (q - np.asarray(leg_offsets_mm, float) - home) / (1.0 + gains)


# ---------------------------------------------------------------------- gauge
def gauge_directions(base_joints_mm: npt.ArrayLike) -> FloatArray:
    """The six gauge directions (48, 6) at base joints (6, 3): rigid motions of the base.

    Columns 0-2 translate every base joint along x, y, z (1 mm); columns 3-5 turn
    them about the x, y, z axes of frame O through its origin (1 rad: ``e_k x b_i``).
    Platform joints, offsets and gains do not move.
    """
    base = np.asarray(base_joints_mm, float).reshape(6, 3)
    out = np.zeros((N_PARAMETERS, 6))
    for k in range(3):
        axis = np.eye(3)[k]
        out[BASE:PLATFORM, k] = np.tile(axis, 6)
        out[BASE:PLATFORM, 3 + k] = np.cross(axis, base).ravel()
    return out


def gauge_fixed(theta: npt.ArrayLike, reference_base_mm: npt.ArrayLike) -> FloatArray:
    """The gauge's representative of a geometry: its base moved rigidly onto the reference.

    The base joints are moved by the proper rigid motion that best fits them, in
    least squares, onto ``reference_base_mm`` (Kabsch); the rest is unchanged. The
    result has the same predictions (a rigid motion of the base changes no pose
    relative to O) and satisfies the gauge's six linear conditions
    ``sum_i db_i = 0`` and ``sum_i b0_i x db_i = 0`` (``db = b - b0``), which are the
    Kabsch fit's stationarity conditions.
    """
    t = _check_theta(theta).copy()
    ref = np.asarray(reference_base_mm, float).reshape(6, 3)
    base = t[BASE:PLATFORM].reshape(6, 3)
    base_mean, ref_mean = base.mean(axis=0), ref.mean(axis=0)
    cross = (ref - ref_mean).T @ (base - base_mean)  # sum ref_c base_c^T
    u, _, vt = np.linalg.svd(cross)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, 1.0, d]) @ vt
    t[BASE:PLATFORM] = ((base - base_mean) @ rot.T + ref_mean).ravel()
    return t


# ---------------------------------------------------------------------- pose algebra
def _skew(v: FloatArray) -> FloatArray:
    """Cross-product matrices (..., 3, 3) of vectors (..., 3)."""
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def angle_axes(angles_deg: npt.ArrayLike, convention: Convention) -> FloatArray:
    """Axes ``W`` (N, 3, 3) of the Euler angles, per degree: ``dR/da_k = [W[:, k]]x R``.

    A small rotation ``dphi`` (rad, frame of the pose's reference) changes the angles
    by ``W^-1 dphi`` degrees. ``symetrie``: ``W = [Rz Ry ex, Rz ey, ez]``; ``pi``:
    ``W = [ex, Rx ey, Rx Ry ez]``.
    """
    a = np.deg2rad(np.atleast_2d(np.asarray(angles_deg, float)))
    c, s = np.cos(a), np.sin(a)
    w = np.zeros(a.shape[:1] + (3, 3))
    if convention == "symetrie":
        w[:, 0, 0], w[:, 1, 0], w[:, 2, 0] = c[:, 2] * c[:, 1], s[:, 2] * c[:, 1], -s[:, 1]
        w[:, 0, 1], w[:, 1, 1] = -s[:, 2], c[:, 2]
        w[:, 2, 2] = 1.0
    else:
        w[:, 0, 0] = 1.0
        w[:, 1, 1], w[:, 2, 1] = c[:, 0], s[:, 0]
        w[:, 0, 2], w[:, 1, 2], w[:, 2, 2] = s[:, 1], -s[:, 0] * c[:, 1], c[:, 0] * c[:, 1]
    return w * (np.pi / 180.0)


def relative_pose(
    a: npt.ArrayLike, b: npt.ArrayLike, convention: Convention
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Pose of B relative to A, ``inv(T(a)) T(b)``, with its derivatives by ``a`` and ``b``.

    Parameters
    ----------
    a, b : array_like, shape (N, 6) or (6,)
        Poses of frames A and B in a common frame (mm, deg); broadcast.
    convention : {"symetrie", "pi"}

    Returns
    -------
    pose : ndarray, shape (N, 6)
    d_a, d_b : ndarray, shape (N, 6, 6)
        ``d pose / d a`` and ``d pose / d b`` (mm and deg per mm and deg).

    Examples
    --------
    >>> pose, _, _ = relative_pose([1, 2, 3, 0, 0, 90], [1, 3, 3, 0, 0, 90], "symetrie")
    >>> (pose + 0.0).round(12).tolist()
    [[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]]
    """
    pa, pb = np.broadcast_arrays(np.atleast_2d(check_poses(a)), np.atleast_2d(check_poses(b)))
    ra, rb = (
        rotation_from_angles(pa[:, 3:], convention),
        rotation_from_angles(pb[:, 3:], convention),
    )
    ra_t = np.swapaxes(ra, 1, 2)
    rot = ra_t @ rb
    delta = pb[:, :3] - pa[:, :3]
    pose = np.concatenate(
        [np.einsum("nij,nj->ni", ra_t, delta), angles_from_rotation(rot, convention)], axis=1
    )
    w_a, w_b = angle_axes(pa[:, 3:], convention), angle_axes(pb[:, 3:], convention)
    w_inv = np.linalg.inv(angle_axes(pose[:, 3:], convention))
    n = pa.shape[0]
    d_a, d_b = np.zeros((n, 6, 6)), np.zeros((n, 6, 6))
    # t = Ra^T (tb - ta): dt = -Ra^T dta + Ra^T [tb - ta]x dphi_a
    d_a[:, :3, :3] = -ra_t
    d_a[:, :3, 3:] = ra_t @ _skew(delta) @ w_a
    # R = Ra^T Rb: a turn dphi_a of A turns B's relative frame by -Ra^T dphi_a
    d_a[:, 3:, 3:] = -w_inv @ ra_t @ w_a
    d_b[:, :3, :3] = ra_t
    d_b[:, 3:, 3:] = w_inv @ ra_t @ w_b
    return pose, d_a, d_b


def compose_pose(
    a: npt.ArrayLike, b: npt.ArrayLike, convention: Convention
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Pose ``T(a) T(b)`` with its derivatives by ``a`` and ``b`` (as :func:`relative_pose`).

    >>> pose, _, _ = compose_pose([1, 2, 3, 0, 0, 90], [1, 0, 0, 0, 0, 0], "symetrie")
    >>> (pose + 0.0).round(12).tolist()
    [[1.0, 3.0, 3.0, 0.0, 0.0, 90.0]]
    """
    pa, pb = np.broadcast_arrays(np.atleast_2d(check_poses(a)), np.atleast_2d(check_poses(b)))
    ra, rb = (
        rotation_from_angles(pa[:, 3:], convention),
        rotation_from_angles(pb[:, 3:], convention),
    )
    moved = np.einsum("nij,nj->ni", ra, pb[:, :3])
    pose = np.concatenate([moved + pa[:, :3], angles_from_rotation(ra @ rb, convention)], axis=1)
    w_a, w_b = angle_axes(pa[:, 3:], convention), angle_axes(pb[:, 3:], convention)
    w_inv = np.linalg.inv(angle_axes(pose[:, 3:], convention))
    n = pa.shape[0]
    d_a, d_b = np.zeros((n, 6, 6)), np.zeros((n, 6, 6))
    d_a[:, :3, :3] = np.eye(3)
    d_a[:, :3, 3:] = -_skew(moved) @ w_a
    d_a[:, 3:, 3:] = w_inv @ w_a
    d_b[:, :3, :3] = ra
    d_b[:, 3:, 3:] = w_inv @ ra @ w_b
    return pose, d_a, d_b


# ---------------------------------------------------------------------- the model
@dataclass(frozen=True)
class CalibrationModel:
    """The calibration's model at one level, about a nominal hexapod.

    The free coordinates ``z`` of a level map to the 48 parameters as
    ``theta = theta0 + basis @ z``: ``theta0`` the nominal parameters, ``basis``
    (48, n_free) orthonormal columns spanning the level's parameters less the
    gauge's six rigid motions of the base (for the ``joints`` levels; the
    ``offsets`` level keeps the base nominal and has no gauge).

    Attributes
    ----------
    nominal : Hexapod
        The hexapod file's geometry: its IGM gives the commanded leg lengths.
    level : {"offsets", "joints", "joints+gains"}
    """

    nominal: Hexapod
    level: Level
    theta0: FloatArray = field(init=False, repr=False)
    basis: FloatArray = field(init=False, repr=False)
    mask: BoolArray = field(init=False, repr=False)
    home_leg_mm: FloatArray = field(init=False, repr=False)
    _warm: dict[bytes, tuple[FloatArray, FloatArray]] = field(
        init=False, repr=False, compare=False, default_factory=dict
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "level", check_level(self.level))
        theta0 = nominal_parameters(self.nominal)
        mask = level_mask(self.level)
        columns = np.eye(N_PARAMETERS)[:, mask]
        if self.level != "offsets":
            # drop the gauge: the base block's complement of the rigid motions
            gauge = gauge_directions(self.nominal.base_joints_mm)[BASE:PLATFORM]
            u, _, _ = np.linalg.svd(gauge, full_matrices=True)
            columns = columns[:, 18:]  # everything but the base
            base = np.zeros((N_PARAMETERS, 12))
            base[BASE:PLATFORM] = u[:, 6:]
            columns = np.concatenate([base, columns], axis=1)
        object.__setattr__(self, "theta0", theta0)
        object.__setattr__(self, "basis", columns)
        object.__setattr__(self, "mask", mask)
        object.__setattr__(self, "home_leg_mm", self.nominal.zero_pose_leg_length_mm())

    @property
    def n_free(self) -> int:
        """Free coordinates: 6, 36 or 42."""
        return int(self.basis.shape[1])

    @property
    def n_gauge(self) -> int:
        """Freedoms the gauge fixes: 0 (offsets) or 6."""
        return 0 if self.level == "offsets" else 6

    @property
    def n_parameters(self) -> int:
        """The level's parameters: 6, 42 or 48 (``n_free + n_gauge``)."""
        return int(self.mask.sum())

    def parameters(self, z: npt.ArrayLike) -> FloatArray:
        """Parameters (48,) of free coordinates (n_free,)."""
        z = np.asarray(z, float)
        if z.shape != (self.n_free,):
            raise ValueError(f"coordinates must have shape ({self.n_free},), got {z.shape}")
        return self.theta0 + self.basis @ z

    def coordinates(self, theta: npt.ArrayLike) -> FloatArray:
        """Free coordinates (n_free,) of parameters (48,), their base moved into the gauge.

        Parameters the level does not fit must be nominal (CalibrationError if not).
        """
        t = _check_theta(theta)
        if self.level != "offsets":
            t = gauge_fixed(t, self.nominal.base_joints_mm)
        off = ~self.mask & (np.abs(t - self.theta0) > 1e-12)
        if off.any():
            raise CalibrationError(
                f"level {self.level!r} keeps {PARAMETER_NAMES[int(np.argmax(off))]} nominal, "
                "but the parameters given change it"
            )
        return np.asarray(self.basis.T @ (t - self.theta0), float)

    def hexapod(self, theta: npt.ArrayLike) -> Hexapod:
        """The joints of ``theta`` as a Hexapod (frames as given; no stroke, no legs)."""
        base, plat, _, _ = split_parameters(theta)
        return Hexapod(
            name=self.nominal.name,
            convention=self.nominal.convention,
            base_joints_mm=base,
            platform_joints_mm=plat,
        )

    def commanded_legs(self, commanded_poses: npt.ArrayLike) -> FloatArray:
        """Commanded leg lengths ``IGM_nominal(X_cmd)``, (N, 6) mm."""
        return self.nominal.igm(np.atleast_2d(check_poses(commanded_poses, "commanded pose")))

    def _true_legs(self, theta: FloatArray, q_cmd: FloatArray) -> tuple[FloatArray, FloatArray]:
        """True leg lengths (N, 6) and their derivatives (N, 6, 48) by the parameters."""
        _, _, offsets, gains = split_parameters(theta)
        travel = q_cmd - self.home_leg_mm
        q = q_cmd + offsets + gains * travel
        d = np.zeros(q.shape + (N_PARAMETERS,))
        legs = np.arange(6)
        d[:, legs, OFFSETS + legs] = 1.0
        d[:, legs, GAINS + legs] = travel
        return q, d

    @staticmethod
    def _igm_by_joints(geometry: Hexapod, poses: FloatArray) -> FloatArray:
        """``d IGM / d theta`` at fixed poses (N, 6, 48): the joints' part."""
        legs = geometry.leg_vectors(poses)
        units = legs / np.linalg.norm(legs, axis=2, keepdims=True)
        rot = rotation_from_angles(poses[:, 3:], geometry.convention)
        n = poses.shape[0]
        d_base = np.zeros((n, 6, 6, 3))
        d_plat = np.zeros((n, 6, 6, 3))
        leg = np.arange(6)
        d_base[:, leg, leg] = -units  # d|t + R p - b| / db = -u
        d_plat[:, leg, leg] = np.einsum("nji,nkj->nki", rot, units)  # R^T u
        out = np.zeros((n, 6, N_PARAMETERS))
        out[:, :, BASE:PLATFORM] = d_base.reshape(n, 6, 18)
        out[:, :, PLATFORM:OFFSETS] = d_plat.reshape(n, 6, 18)
        return out

    def _stand(
        self, geometry: Hexapod, theta: FloatArray, q_cmd: FloatArray, start: FloatArray
    ) -> tuple[FloatArray, StandDerivatives]:
        """Poses (N, 6) the geometry stands at for commanded legs, in its base frame, and
        their derivatives by the parameters (factored: :class:`StandDerivatives`). The
        FGM is :meth:`~hexatherm.core.hexapod.Hexapod.fgm_near`: plain Newton from a start
        whose legs are within a thousandth of a leg (a warm start), else the certified FGM.
        """
        _, _, offsets, gains = split_parameters(theta)
        travel = q_cmd - self.home_leg_mm
        q = q_cmd + offsets + gains * travel
        poses, jac = geometry.fgm_near(q, start, tol_mm=PREDICTION_TOL_MM)
        legs = geometry.leg_vectors(poses)
        units = legs / np.linalg.norm(legs, axis=2, keepdims=True)
        rot = rotation_from_angles(poses[:, 3:], geometry.convention)
        platform = np.einsum("nji,nkj->nki", rot, units)  # R^T u
        return poses, StandDerivatives(
            np.asarray(np.linalg.inv(jac), float), units, platform, travel
        )

    def _stand_with_origin(
        self, geometry: Hexapod, theta: FloatArray, x_cmd: FloatArray
    ) -> tuple[FloatArray, StandDerivatives]:
        """Frame O and the poses, (N + 1, 6) in the base frame, with derivatives.

        One FGM for O and the poses. Its start is the commanded pose (the zero pose for
        O), or, when the same poses were solved for parameters within
        :data:`_WARM_START_MM` of these, that solution: the FGM then needs one or two
        Newton steps (the fit evaluates the model many times at nearby parameters).
        """
        commanded = np.concatenate([np.zeros((1, 6)), x_cmd])
        key = commanded.tobytes()
        start = commanded
        previous = self._warm.get(key)
        if previous is not None and np.abs(previous[0] - theta).max() <= _WARM_START_MM:
            start = previous[1]
        q_cmd = np.concatenate([self.home_leg_mm[None], self.commanded_legs(x_cmd)])
        poses, d = self._stand(geometry, theta, q_cmd, start)
        if len(self._warm) >= 8:
            self._warm.clear()
        self._warm[key] = (theta.copy(), poses)
        return poses, d

    def origin(self, theta: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Frame O of a geometry: the pose (6,) it stands at for the zero command, in
        its base frame, and the derivatives (6, 48)."""
        t = _check_theta(theta)
        pose, d = self._stand(self.hexapod(t), t, self.home_leg_mm[None], np.zeros((1, 6)))
        return pose[0], d.times()[0]

    def predict(
        self, theta: npt.ArrayLike, commanded_poses: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Poses relative to O that a geometry reaches for commanded poses, and Jacobian.

        Parameters
        ----------
        theta : array_like, shape (48,)
        commanded_poses : array_like, shape (N, 6)
            mm, deg.

        Returns
        -------
        poses : ndarray, shape (N, 6)
            ``inv(T(FGM(q_true(0)))) T(FGM(q_true(X_cmd)))``, mm and deg.
        jacobian : ndarray, shape (N, 6, 48)
            Derivatives by all 48 parameters (mm and deg per mm, per unit gain).
        """
        t = _check_theta(theta)
        x_cmd = np.atleast_2d(check_poses(commanded_poses, "commanded pose"))
        stand, d = self._stand_with_origin(self.hexapod(t), t, x_cmd)
        poses, d_a, d_b = relative_pose(stand[0], stand[1:], self.nominal.convention)
        jac = d[1:].times(d_b)
        jac += (d_a.reshape(-1, 6) @ d[:1].times()[0]).reshape(jac.shape)
        return poses, jac

    def leg_residuals(
        self, theta: npt.ArrayLike, commanded_poses: npt.ArrayLike, measured_poses: npt.ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Leg-space residuals of measured poses, their Jacobian, and their derivative by
        the measurements.

        ``r_k = IGM_theta(T(O) X_meas_k) - q_true(X_cmd_k)``: the measured pose put into
        the geometry's base frame through its frame O, its legs, minus the legs the
        actuators produced.

        Returns
        -------
        residuals : ndarray, shape (N, 6)
            mm.
        jacobian : ndarray, shape (N, 6, 48)
            ``d r / d theta``.
        by_measurement : ndarray, shape (N, 6, 6)
            ``d r / d X_meas`` (mm per mm and per deg), for the residuals' covariance.
        """
        t = _check_theta(theta)
        x_cmd = np.atleast_2d(check_poses(commanded_poses, "commanded pose"))
        x_meas = np.atleast_2d(check_poses(measured_poses, "measured pose"))
        if x_meas.shape != x_cmd.shape:
            raise ValueError(f"measured poses {x_meas.shape} do not match {x_cmd.shape}")
        geometry = self.hexapod(t)
        origin, d_origin = self.origin(t)  # (6,) and (6, 48)
        placed, d_a, d_b = compose_pose(origin, x_meas, self.nominal.convention)
        legs_jac = geometry.jacobian(placed)
        q_true, d_true = self._true_legs(t, self.commanded_legs(x_cmd))
        residuals = geometry.igm(placed) - q_true
        jacobian = self._igm_by_joints(geometry, placed) + legs_jac @ d_a @ d_origin - d_true
        return residuals, jacobian, legs_jac @ d_b

    def calibrated_hexapod(self, theta: npt.ArrayLike) -> Hexapod:
        """The geometry as a hexapod in frame O: what ``process`` needs.

        Its base joints are moved into frame O (the platform frame at the zero
        command), so that ``IGM(0)`` is the true zero-pose legs ``q_home + dq`` and its
        IGM of a pose relative to O gives the true joint-to-joint lengths. Name,
        convention, stroke, leg model and effects are the nominal hexapod's.
        """
        t = _check_theta(theta)
        base, plat, _, _ = split_parameters(t)
        origin, _ = self.origin(t)
        rot = rotation_from_angles(origin[3:], self.nominal.convention)
        base_in_o = (base - origin[:3]) @ rot  # R^T (b - t), row-wise
        return Hexapod(
            name=self.nominal.name,
            convention=self.nominal.convention,
            base_joints_mm=base_in_o,
            platform_joints_mm=plat,
            stroke_mm=self.nominal.stroke_mm,
            legs=self.nominal.legs,
            effects=self.nominal.effects,
        )
