"""Is a measured pose the pose that was commanded? The plausibility of measured steps.

Every step of a plan has a commanded pose; the CMM measures the platform frame of every
step, and ``process`` works on the poses relative to the origin step O. Thermal errors
are micrometres: a measured pose relative to O that is millimetres or degrees away from
the commanded pose relative to O is not a thermal error but a mistake in the data, and
a mistake that no other check sees: swapped step labels, a mirrored measurement (x and y
columns swapped: with three balls a mirror image registers with zero residual) or a plan
in other units. This module compares the two and names the likeliest cause.

The thermal growth the method reads at the references is bounded by physics too: a leg
whose length changed since R0 by more than its segments' expansion allows for the
temperatures its thermocouple logged is not a thermal error but a reference measured
away from its commanded pose (:func:`implied_warming_K`, :func:`temperature_span_K`).

Conventions: poses are ``[Tx, Ty, Tz, Rx, Ry, Rz]`` (mm, deg) in the hexapod's
convention (see :mod:`hexatherm.core.geometry`). The commanded pose of step S relative
to O is ``inv(T(O_cmd)) @ T(S_cmd)`` (the plan's poses less O's; exactly that when O is
the zero pose). The deviation of a step is ``measured - commanded - offset``, per
component, angles wrapped to (-180, 180] deg; its translation is the norm of the first
three components (mm), its rotation the largest absolute angle (deg).

The rotation tolerance of the default check is scaled to the commanded motion
(:meth:`PoseCheck.rotation_tolerance_deg`): :data:`ROTATION_FLOOR_DEG` plus
:data:`ROTATION_FRACTION` of the step's largest commanded angle relative to O. A plan in
another rotation convention than the hexapod's (Symetrie's fixed axes for PI's mobile
ones) moves the platform by the second-order difference of the two, 6.8 % of the
commanded angle at 8 deg (7.5 mrad): within the stroke-sized 1.04 deg, beyond this.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    check_convention,
    check_poses,
    invert_transform,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.thermal import LegThermalModel
from hexatherm.typing import BoolArray, FloatArray

__all__ = [
    "DEFAULT_TOLERANCE_FRACTION",
    "MIN_TOLERANCE_MM",
    "PoseCheck",
    "PoseDeviations",
    "ROTATION_FLOOR_DEG",
    "ROTATION_FRACTION",
    "SOLID_FRACTION",
    "UNIT_SCALES",
    "commanded_relative",
    "default_pose_tolerance",
    "implied_warming_K",
    "likeliest_cause",
    "mirrored",
    "pose_deviations",
    "temperature_span_K",
]

#: default translation tolerance as a fraction of the leg stroke (max - min leg length)
DEFAULT_TOLERANCE_FRACTION = 0.02
#: smallest default translation tolerance, mm (also the default without a stroke: 2 mm)
MIN_TOLERANCE_MM = 2.0
#: absolute part of the default rotation tolerance, deg (0.87 mrad): ten times the largest
#: rotation deviation of the shipped sessions at a commanded rotation of zero (0.0052 deg,
#: the legs' thermal tilt), and far above a positioning hexapod's accuracy (tens of urad)
ROTATION_FLOOR_DEG = 0.05
#: relative part of the default rotation tolerance, of the step's largest commanded angle:
#: three times the largest relative deviation of the shipped sessions (0.31 %, a geometry
#: 50 um off its file); a convention mix-up deviates by 6.8 % at 8 deg
ROTATION_FRACTION = 0.01
#: scale factors of unit mix-ups, (factor, what it looks like): measured = factor x commanded
UNIT_SCALES: tuple[tuple[float, str, str], ...] = (
    (25.4, "translations", "the plan's translations in inches, the measurements in mm?"),
    (1 / 25.4, "translations", "the plan's translations in mm, the measurements in inches?"),
    (1000.0, "translations", "the plan's translations in metres?"),
    (1e-3, "translations", "the plan's translations in micrometres?"),
    (180.0 / np.pi, "rotations", "the plan's rotations in radians?"),
    (np.pi / 180.0, "rotations", "the plan's rotations in milliradians or arc-minutes?"),
)


@dataclass(frozen=True)
class PoseCheck:
    """Tolerances of the measured-versus-commanded check, and a known offset.

    Attributes
    ----------
    tolerance_mm : float
        Largest translation deviation (norm of ``dTx, dTy, dTz``), mm; ``inf`` turns
        the check off.
    tolerance_deg : float
        Largest rotation deviation (largest ``|dRx|, |dRy|, |dRz|``), deg.
    offset : ndarray, shape (6,)
        A known, constant deviation of every step but O from its commanded pose
        relative to O (mm, deg), subtracted before comparing.
    rotation_floor_deg, rotation_fraction : float or None, float
        With a floor, a step's rotation tolerance is scaled to its commanded motion:
        ``min(tolerance_deg, rotation_floor_deg + rotation_fraction * max|angle|)``
        (:meth:`rotation_tolerance_deg`); None: ``tolerance_deg`` for every step.

    Examples
    --------
    >>> PoseCheck(2.0, 1.0).offset.tolist()
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    >>> scaled = PoseCheck(2.0, 1.0, rotation_floor_deg=0.05, rotation_fraction=0.01)
    >>> scaled.rotation_tolerance_deg([[0, 0, 0, 0, 0, 0], [1, 0, 0, 3, -8, 2]]).tolist()
    [0.05, 0.13]
    >>> PoseCheck(float("nan"), 1.0)
    Traceback (most recent call last):
    ...
    ValueError: pose tolerance_mm must be a number > 0 (inf turns the check off), got nan
    """

    tolerance_mm: float
    tolerance_deg: float
    offset: FloatArray = field(default_factory=lambda: np.zeros(6))
    rotation_floor_deg: float | None = None
    rotation_fraction: float = 0.0

    def __post_init__(self) -> None:
        fraction = self.rotation_fraction
        if (
            isinstance(fraction, bool)
            or not isinstance(fraction, int | float)
            or not (0 <= fraction < np.inf)
        ):
            raise ValueError(f"pose rotation_fraction must be a number >= 0, got {fraction!r}")
        names = ["tolerance_mm", "tolerance_deg"]
        if self.rotation_floor_deg is not None:
            names.append("rotation_floor_deg")
        for name in names:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
                raise ValueError(
                    f"pose {name} must be a number > 0 (inf turns the check off), got {value!r}"
                )
        offset = np.asarray(self.offset, dtype=float)
        if offset.shape != (6,) or not np.all(np.isfinite(offset)):
            raise ValueError(f"pose offset must be six finite numbers, got {self.offset!r}")
        object.__setattr__(self, "offset", offset)

    @property
    def enabled(self) -> bool:
        """Whether any tolerance is finite."""
        return bool(np.isfinite(self.tolerance_mm) or np.isfinite(self.tolerance_deg))

    @property
    def scaled(self) -> bool:
        """Whether the rotation tolerance is scaled to the commanded motion."""
        return self.rotation_floor_deg is not None and bool(np.isfinite(self.tolerance_deg))

    def rotation_tolerance_deg(self, commanded: npt.ArrayLike) -> FloatArray:
        """The rotation tolerance of each step, deg, from its commanded pose relative to O
        (N, 6): ``tolerance_deg``, or scaled (see the class)."""
        c = np.atleast_2d(np.asarray(commanded, dtype=float))
        tol = np.full(c.shape[0], float(self.tolerance_deg))
        if self.scaled:
            assert self.rotation_floor_deg is not None
            angle = np.abs(_wrap_deg(c[:, 3:])).max(axis=1, initial=0.0)
            tol = np.minimum(tol, self.rotation_floor_deg + self.rotation_fraction * angle)
        return tol


def default_pose_tolerance(
    stroke_mm: npt.ArrayLike | None, platform_joints_mm: npt.ArrayLike
) -> tuple[float, float]:
    """Default tolerances ``(mm, deg)`` sized from the hexapod's leg stroke.

    The translation tolerance is :data:`DEFAULT_TOLERANCE_FRACTION` of the stroke
    (``max - min`` leg length), at least :data:`MIN_TOLERANCE_MM`; the rotation
    tolerance is the angle that moves the platform's joints, at their mean radius
    ``r`` from the platform's centre, by as much: ``tol_mm / r`` rad.

    Parameters
    ----------
    stroke_mm : array_like, shape (2,), or None
        ``[min, max]`` leg length (None: :data:`MIN_TOLERANCE_MM`).
    platform_joints_mm : array_like, shape (6, 3)
        The platform's joints in the platform frame.

    Returns
    -------
    (float, float)
        Translation tolerance (mm), rotation tolerance (deg).

    Examples
    --------
    >>> joints = [[100.0 * np.cos(a), 100.0 * np.sin(a), 0.0] for a in np.arange(6) * np.pi / 3]
    >>> [round(v, 4) for v in default_pose_tolerance([220.0, 310.0], joints)]
    [2.0, 1.1459]
    >>> [round(v, 4) for v in default_pose_tolerance([200.0, 400.0], joints)]
    [4.0, 2.2918]
    """
    joints = np.asarray(platform_joints_mm, dtype=float)
    if joints.shape != (6, 3) or not np.all(np.isfinite(joints)):
        raise ValueError("platform_joints_mm must be six finite [x, y, z] joints")
    tol_mm = MIN_TOLERANCE_MM
    if stroke_mm is not None:
        stroke = np.asarray(stroke_mm, dtype=float)
        tol_mm = max(MIN_TOLERANCE_MM, DEFAULT_TOLERANCE_FRACTION * float(stroke[1] - stroke[0]))
    radius = float(np.linalg.norm(joints[:, :2] - joints[:, :2].mean(axis=0), axis=1).mean())
    if not radius > 0:
        raise ValueError("the platform's joints have no radius")
    return tol_mm, float(np.rad2deg(tol_mm / radius))


def commanded_relative(
    poses: npt.ArrayLike, origin_index: int = 0, convention: str = "symetrie"
) -> FloatArray:
    """The commanded pose of every step relative to the origin step, ``inv(T_O) @ T_S``.

    Parameters
    ----------
    poses : array_like, shape (N, 6)
        Commanded poses (the plan's), mm and deg.
    origin_index : int
    convention : {"symetrie", "pi"}

    Returns
    -------
    ndarray, shape (N, 6)
        mm and deg; equal to ``poses - poses[origin_index]`` when O is the zero pose.

    Examples
    --------
    >>> commanded_relative([[0, 0, 5, 0, 0, 0], [1, 2, 3, 0, 0, 10]]).round(9) + 0.0
    array([[ 0.,  0.,  0.,  0.,  0.,  0.],
           [ 1.,  2., -2.,  0.,  0., 10.]])
    """
    convention = check_convention(convention)
    p = check_poses(poses)
    if not -p.shape[0] <= origin_index < p.shape[0]:
        raise ValueError(f"origin_index {origin_index} out of range for {p.shape[0]} poses")
    frames = transform_from_pose(p, convention)
    return pose_from_transform(invert_transform(frames[origin_index]) @ frames, convention)


def _wrap_deg(angles: FloatArray) -> FloatArray:
    """Angles wrapped to [-180, 180) deg."""
    return (angles + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class PoseDeviations:
    """Measured minus commanded pose of every step, relative to O.

    Attributes
    ----------
    deviation : ndarray, shape (N, 6)
        ``measured - commanded - offset``, mm and deg (angles wrapped).
    translation_mm : ndarray, shape (N,)
        Norm of the translation deviation.
    rotation_deg : ndarray, shape (N,)
        Largest absolute angle deviation.
    failing : ndarray of bool, shape (N,)
        Beyond either tolerance.
    tolerance_deg : ndarray, shape (N,)
        Each step's rotation tolerance (:meth:`PoseCheck.rotation_tolerance_deg`).
    """

    deviation: FloatArray
    translation_mm: FloatArray
    rotation_deg: FloatArray
    failing: BoolArray
    tolerance_deg: FloatArray


def pose_deviations(
    measured: npt.ArrayLike, commanded: npt.ArrayLike, check: PoseCheck, origin_index: int = 0
) -> PoseDeviations:
    """Compare every step's measured pose relative to O with its commanded one.

    Parameters
    ----------
    measured, commanded : array_like, shape (N, 6)
        Poses relative to O, mm and deg (see :func:`commanded_relative`).
    check : PoseCheck
    origin_index : int
        O's step: its offset is not applied (its deviation is zero by construction).

    Returns
    -------
    PoseDeviations

    Examples
    --------
    >>> cmd = np.array([[0.0] * 6, [0, 0, 40, 0, 0, 0], [0, 0, 0, 0, 0, 0]])
    >>> meas = cmd + [[0] * 6, [0.01, 0, -80, 0, 0, 0], [0, 0, 0, 0, 0, 0.5]]
    >>> dev = pose_deviations(meas, cmd, PoseCheck(2.0, 1.0))
    >>> dev.failing.tolist(), dev.translation_mm.round(3).tolist()
    ([False, True, False], [0.0, 80.0, 0.0])
    """
    m, c = check_poses(measured, "measured"), check_poses(commanded, "commanded")
    if m.shape != c.shape:
        raise ValueError(f"measured {m.shape} and commanded {c.shape} poses differ in shape")
    offset = np.broadcast_to(check.offset, m.shape).copy()
    if m.shape[0]:
        offset[origin_index] = 0.0
    deviation = m - c - offset
    deviation[:, 3:] = _wrap_deg(deviation[:, 3:])
    translation = np.linalg.norm(deviation[:, :3], axis=1)
    rotation = np.abs(deviation[:, 3:]).max(axis=1, initial=0.0)
    tolerance = check.rotation_tolerance_deg(c)
    failing = (translation > check.tolerance_mm) | (rotation > tolerance)
    return PoseDeviations(deviation, translation, rotation, failing, tolerance)


#: balls span a solid (their handedness is their own) when the smallest singular value
#: of their centred positions is at least this share of the largest
SOLID_FRACTION = 0.05


def mirrored(centres_mm: npt.ArrayLike, balls_mm: npt.ArrayLike) -> BoolArray:
    """Whether each step's measured balls are a mirror image of the balls file's.

    A reflection is never a rotation, however small the motion: its determinant is -1.
    With four or more balls that span a solid (the smallest singular value of their
    centred positions at least :data:`SOLID_FRACTION` of the largest), the handedness is
    their own: a step is mirrored when the cross-covariance ``sum (b - b0)(c - c0)^T`` of
    the file's and the measured positions has a negative determinant (the best
    orthogonal map between them is a reflection). Three balls (or coplanar ones)
    register with zero residual on their mirror image, so the handedness is read
    against the one direction both frames share: up. The balls' polygon normal
    (Newell's method, in the balls file's order) points to the platform's +Z in the
    balls file; measured on a hexapod that stands on the CMM's table and is probed from
    above (as ``plan``'s DMIS program and ``run`` probe), it points to the CMM's +Z. A
    step whose measured normal points down while the file's points up (each more than
    30 deg from horizontal) is mirrored: x and y columns swapped, or one axis' sign
    flipped.

    Parameters
    ----------
    centres_mm : array_like, shape (N, k, 3)
        Measured ball centres of every step, CMM frame.
    balls_mm : array_like, shape (k, 3)
        The balls' centres in the platform frame, in the same order.

    Returns
    -------
    ndarray of bool, shape (N,)

    Examples
    --------
    >>> balls = np.array([[100.0, 0, 10], [-50, 86.6, 10], [-50, -86.6, 10]])
    >>> steps = np.stack([balls + [400, 300, 200], balls[:, [1, 0, 2]] + [400, 300, 200]])
    >>> mirrored(steps, balls).tolist()
    [False, True]

    Four balls on a solid: upside down is a rotation, a swap of x and y is not.

    >>> solid = np.vstack([balls, [0.0, 0.0, 60.0]])
    >>> flip = np.diag([1.0, -1.0, -1.0])  # 180 deg about x
    >>> mirrored(np.stack([solid @ flip.T, solid[:, [1, 0, 2]]]), solid).tolist()
    [False, True]
    """
    c = np.asarray(centres_mm, dtype=float)
    b = np.asarray(balls_mm, dtype=float)
    if c.ndim != 3 or c.shape[1:] != b.shape or b.ndim != 2 or b.shape[1] != 3:
        raise ValueError("centres_mm must be (N, k, 3) and balls_mm (k, 3)")
    rel_b = b - b.mean(axis=0)
    if b.shape[0] >= 4:
        sv = np.linalg.svd(rel_b, compute_uv=False)
        if sv[2] >= SOLID_FRACTION * sv[0]:
            rel_c = c - c.mean(axis=1, keepdims=True)
            return np.asarray(np.linalg.det(np.einsum("ki,nkj->nij", rel_b, rel_c)) < 0)

    def unit_normal(points: FloatArray) -> FloatArray:
        rel = points - points.mean(axis=-2, keepdims=True)
        n = np.cross(rel, np.roll(rel, -1, axis=-2)).sum(axis=-2)
        norm = np.linalg.norm(n, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(norm > 0, n / norm, 0.0)

    sin30 = 0.5
    nb, nm = unit_normal(b)[2], unit_normal(c)[:, 2]
    if abs(nb) <= sin30:
        return np.zeros(c.shape[0], dtype=bool)
    return (np.abs(nm) > sin30) & (np.sign(nm) != np.sign(nb))


def likeliest_cause(
    index: int,
    measured: npt.ArrayLike,
    commanded: npt.ArrayLike,
    check: PoseCheck,
    labels: tuple[str, ...] | list[str],
    is_mirrored: npt.ArrayLike | None = None,
    origin_index: int = 0,
) -> str:
    """The likeliest cause of step ``index``'s deviation, in words.

    In this order: a mirrored measurement (see :func:`mirrored`); swapped labels (the
    step's measured pose matches another step's commanded pose, within the
    tolerances); wrong units (the measured translations, or rotations, are one of
    :data:`UNIT_SCALES` times the commanded ones, within the tolerances, over every
    step); else a step measured at another pose than the plan's.

    Parameters
    ----------
    index : int
        The step.
    measured, commanded : array_like, shape (N, 6)
        Poses relative to O, mm and deg.
    check : PoseCheck
    labels : sequence of str
        Step labels, for the message.
    is_mirrored : array_like of bool, shape (N,), optional
    origin_index : int

    Returns
    -------
    str

    Examples
    --------
    >>> cmd = np.array([[0.0] * 6, [0, 0, 40, 0, 0, 0], [0, 0, 10, 0, 0, 0]])
    >>> meas = cmd[[0, 2, 1]]
    >>> likeliest_cause(1, meas, cmd, PoseCheck(2.0, 1.0), ["O", "S1", "S2"])
    'swapped labels: its measured pose is the commanded pose of S2 (and S2 measured as S1)'
    >>> likeliest_cause(1, cmd * 25.4, cmd, PoseCheck(2.0, 1.0), ["O", "S1", "S2"])
    "wrong units: measured translations = 25.4 x commanded (the plan's translations in inches, the measurements in mm?)"
    """  # noqa: E501
    m, c = check_poses(measured, "measured"), check_poses(commanded, "commanded")
    n = m.shape[0]
    if is_mirrored is not None and bool(np.asarray(is_mirrored)[index]):
        return (
            "mirrored axes: the measured balls are a mirror image of the balls file's "
            "(x and y columns swapped, or an axis' sign flipped?)"
        )
    # swapped labels: this step measured at another step's commanded pose
    others = np.array([j for j in range(n) if j != index and j != origin_index], dtype=np.intp)
    if others.size:
        dev = pose_deviations(
            np.repeat(m[index : index + 1], others.size, axis=0), c[others], check
        )
        matches = others[~dev.failing]
        # a pose that equals its own commanded one does not tell a swap apart
        matches = matches[np.abs(c[matches] - c[index]).max(axis=1) > 1e-9]
        if matches.size:
            # a mutual swap first: the other step measured at this one's commanded pose
            back = pose_deviations(
                m[matches], np.repeat(c[index : index + 1], matches.size, 0), check
            )
            mutual = matches[~back.failing]
            j = int(mutual[0] if mutual.size else matches[0])
            also = f" and {matches.size - 1} other step(s)" if matches.size > 1 else ""
            swap = f" (and {labels[j]} measured as {labels[index]})" if mutual.size else ""
            return (
                f"swapped labels: its measured pose is the commanded pose of {labels[j]}"
                f"{also}{swap}"
            )
    # wrong units, fitted over every step
    for factor, part, hint in UNIT_SCALES:
        cols = slice(0, 3) if part == "translations" else slice(3, 6)
        if np.abs(c[:, cols]).max(initial=0.0) == 0.0:
            continue
        scaled = c.copy()
        scaled[:, cols] *= factor
        if not pose_deviations(m, scaled, check, origin_index).failing.any():
            return f"wrong units: measured {part} = {factor:.4g} x commanded ({hint})"
    return (
        "the step was measured at another pose than the plan commands (a wrong plan or "
        "session, a move that did not happen, or a known offset to declare)"
    )


def implied_warming_K(
    legs: LegThermalModel, q_mm: npt.ArrayLike, growth_mm: npt.ArrayLike
) -> FloatArray:
    """The smallest temperature change that explains each leg's growth, K.

    A leg of segments (length ``L_s``, expansion coefficient ``cte_s``) whose segments
    all changed temperature by at most ``dT`` (either way) changed length by at most
    ``dT * sum_s |cte_s| L_s`` (:meth:`~hexatherm.core.thermal.LegThermalModel.
    bound_sensitivity_mm_per_K`, the variable segment at leg length ``q``). So a growth
    ``g`` needs ``|g| / sum_s |cte_s| L_s`` kelvin at least somewhere along the leg.

    Parameters
    ----------
    legs : LegThermalModel
    q_mm : array_like, shape (..., 6)
        Leg lengths (they set the variable segment's length).
    growth_mm : array_like, shape (..., 6)
        Change of each leg's length, mm.

    Returns
    -------
    ndarray, shape (..., 6)
        K, >= 0.

    Examples
    --------
    >>> model = LegThermalModel.uniform(
    ...     [("body", "aluminium", 23.1e-6, 160.0), ("screw", "steel", 11.5e-6, None)])
    >>> q = np.full(6, 268.0)  # 160 mm of aluminium, 108 mm of steel: 4.938 um/K
    >>> implied_warming_K(model, q, np.full(6, 0.004938)).round(6).tolist()[:2]
    [1.0, 1.0]
    >>> implied_warming_K(model, q, [0.5, 0, 0, 0, 0, -0.5]).round(1).tolist()
    [101.3, 0.0, 0.0, 0.0, 0.0, 101.3]
    """
    bound = legs.bound_sensitivity_mm_per_K(q_mm)
    growth = np.abs(np.asarray(growth_mm, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(growth > 0, growth / bound, 0.0)


def temperature_span_K(
    log_times_s: npt.ArrayLike, log_C: npt.ArrayLike, times_s: npt.ArrayLike
) -> FloatArray:
    """How far each channel's logged temperature ranged from the log's start up to each
    time: ``max - min`` over the log's rows up to it and its value interpolated there, K.

    A leg lags its thermocouple (its mass, the screw inside the body): its temperature
    at any time lies within the range its thermocouple went through before, so the
    change of the leg's temperature between two times up to ``t`` is at most this span.

    Parameters
    ----------
    log_times_s : array_like, shape (m,)
        The log's times, increasing.
    log_C : array_like, shape (m, c)
        Temperatures of each channel, degC.
    times_s : array_like, shape (n,)
        Times within the log.

    Returns
    -------
    ndarray, shape (n, c)

    Examples
    --------
    >>> t = [0.0, 10.0, 20.0, 30.0]
    >>> temps = np.array([[20.0], [25.0], [21.0], [22.0]])
    >>> temperature_span_K(t, temps, [5.0, 10.0, 30.0]).ravel().tolist()
    [2.5, 5.0, 5.0]
    """
    lt = np.asarray(log_times_s, dtype=float)
    lc = np.asarray(log_C, dtype=float)
    t = np.asarray(times_s, dtype=float)
    upto = np.clip(np.searchsorted(lt, t, side="right") - 1, 0, lt.size - 1)
    high = np.maximum.accumulate(lc, axis=0)[upto]
    low = np.minimum.accumulate(lc, axis=0)[upto]
    now = np.column_stack([np.interp(t, lt, lc[:, j]) for j in range(lc.shape[1])])
    return np.maximum(high, now) - np.minimum(low, now)
