"""Pose vectors, rotation conventions and homogeneous transforms.

A pose is ``[Tx, Ty, Tz, Rx, Ry, Rz]`` (mm, deg) of a frame B relative to a
frame A; its transform ``B2A`` maps coordinates in B to coordinates in A
(``p_A = B2A @ p_B``). Names of transforms follow that rule: ``platform2cmm``
takes platform coordinates to CMM coordinates, ``platform2origin`` is the pose of
the platform relative to frame O.

Two conventions:

``symetrie`` (default, "Euler type II", fixed axes)
    ``R = Rz(Rz) @ Ry(Ry) @ Rx(Rx)``, the same as scipy's
    ``Rotation.from_euler("xyz", [Rx, Ry, Rz], degrees=True)``.
``pi`` (mobile axes)
    ``R = Rx(Rx) @ Ry(Ry) @ Rz(Rz)``, scipy's ``from_euler("XYZ", ...)``.

Every function takes one pose ``(6,)`` or a stack ``(N, 6)`` and returns the
matching shape.

>>> import numpy as np
>>> T = transform_from_pose([1.0, 2.0, 3.0, 0.0, 0.0, 90.0])
>>> np.round(T @ [1.0, 0.0, 0.0, 1.0], 12)
array([1., 3., 3., 1.])
>>> pose_from_transform(T) + 0.0   # + 0.0 turns -0.0 into 0.0
array([ 1.,  2.,  3.,  0.,  0., 90.])
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import numpy.typing as npt

from hexatherm.typing import FloatArray

Convention = Literal["symetrie", "pi"]
CONVENTIONS: tuple[Convention, ...] = ("symetrie", "pi")


def check_convention(convention: str) -> Convention:
    """Return ``convention`` if it is a known rotation convention, else raise ValueError.

    >>> check_convention("pi")
    'pi'
    """
    if convention not in CONVENTIONS:
        raise ValueError(
            f"unknown rotation convention {convention!r}; expected one of {', '.join(CONVENTIONS)}"
        )
    return convention


def check_poses(poses: npt.ArrayLike, name: str = "pose") -> FloatArray:
    """Return ``poses`` as a float array of shape (6,) or (N, 6), checked finite.

    >>> check_poses([0, 0, 1, 0, 0, 0]).shape
    (6,)
    >>> check_poses([[0, 0, 1]])
    Traceback (most recent call last):
    ...
    ValueError: pose must have shape (6,) or (N, 6), got (1, 3)
    """
    array = np.asarray(poses, dtype=float)
    if array.ndim not in (1, 2) or array.shape[-1] != 6:
        raise ValueError(f"{name} must have shape (6,) or (N, 6), got {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = np.argwhere(~np.isfinite(np.atleast_2d(array)))[0]
        raise ValueError(f"{name} has a non-finite value (row {bad[0]}, component {bad[1]})")
    return array


def check_transforms(transforms: npt.ArrayLike, name: str = "transform") -> FloatArray:
    """Return ``transforms`` as (4, 4) or (N, 4, 4) rigid transforms, checked.

    The rotation part must be orthonormal with determinant +1 (to 1e-9) and the
    last row ``[0, 0, 0, 1]``.
    """
    array = np.asarray(transforms, dtype=float)
    if array.shape[-2:] != (4, 4) or array.ndim not in (2, 3):
        raise ValueError(f"{name} must have shape (4, 4) or (N, 4, 4), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} has a non-finite value")
    rot = array[..., :3, :3]
    err = np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3)).max(axis=(-1, -2))
    if np.any(err > 1e-9) or np.any(np.linalg.det(rot) < 0):
        raise ValueError(f"{name} has a rotation part that is not a proper rotation")
    if np.any(np.abs(array[..., 3, :] - [0.0, 0.0, 0.0, 1.0]) > 0):
        raise ValueError(f"{name} must have [0, 0, 0, 1] as last row")
    return array


def _rx(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], axis=-1).reshape(a.shape + (3, 3))


def _ry(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([c, z, s, z, o, z, -s, z, c], axis=-1).reshape(a.shape + (3, 3))


def _rz(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], axis=-1).reshape(a.shape + (3, 3))


def _drx(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    z = np.zeros_like(a)
    return np.stack([z, z, z, z, -s, -c, z, c, -s], axis=-1).reshape(a.shape + (3, 3))


def _dry(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    z = np.zeros_like(a)
    return np.stack([-s, z, c, z, z, z, -c, z, -s], axis=-1).reshape(a.shape + (3, 3))


def _drz(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    z = np.zeros_like(a)
    return np.stack([-s, -c, z, c, -s, z, z, z, z], axis=-1).reshape(a.shape + (3, 3))


def rotation_from_angles(angles_deg: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """Rotation matrices from ``[Rx, Ry, Rz]`` angles in degrees, shape (..., 3, 3).

    >>> import numpy as np
    >>> np.round(rotation_from_angles([0, 0, 90]), 12)
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    convention = check_convention(convention)
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))
    rx, ry, rz = _rx(a[..., 0]), _ry(a[..., 1]), _rz(a[..., 2])
    if convention == "symetrie":
        return rz @ ry @ rx
    return rx @ ry @ rz


def rotation_derivatives(angles_deg: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """Partial derivatives of the rotation matrix w.r.t. Rx, Ry, Rz, per degree.

    Returns shape (..., 3, 3, 3): index ``[..., k, :, :]`` is ``dR/dangle_k``.
    """
    convention = check_convention(convention)
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))
    x, y, z = a[..., 0], a[..., 1], a[..., 2]
    rx, ry, rz = _rx(x), _ry(y), _rz(z)
    drx, dry, drz = _drx(x), _dry(y), _drz(z)
    if convention == "symetrie":
        parts = [rz @ ry @ drx, rz @ dry @ rx, drz @ ry @ rx]
    else:
        parts = [drx @ ry @ rz, rx @ dry @ rz, rx @ ry @ drz]
    return np.stack(parts, axis=-3) * (np.pi / 180.0)


def _trig(
    angles_deg: npt.ArrayLike,
) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...], FloatArray]:
    """Cosines and sines of ``[Rx, Ry, Rz]`` (deg, (..., 3)), each (...,), and zeros
    (..., 3, 3) for the matrix made of them."""
    a = np.deg2rad(np.asarray(angles_deg, dtype=float))
    c, s = np.cos(a), np.sin(a)
    return (
        (c[..., 0], c[..., 1], c[..., 2]),
        (s[..., 0], s[..., 1], s[..., 2]),
        np.zeros(a.shape[:-1] + (3, 3)),
    )


def angle_rates(angles_deg: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """The change of ``[Rx, Ry, Rz]`` (deg) per small rotation ``omega`` (rad) applied on
    the left, ``R -> (I + [omega]x) R``: matrices (..., 3, 3), the inverse of
    :func:`angle_velocities` (whose column k is ``vee(dR/dangle_k R^T)``, from
    :func:`rotation_derivatives`), in closed form: for ``R = Rz Ry Rx`` (symetrie)

        ``[[cz/cy, sz/cy, 0], [-sz, cz, 0], [sy cz/cy, sy sz/cy, 1]]``

    and for ``R = Rx Ry Rz`` (pi) ``[[1, sy sx/cy, -sy cx/cy], [0, cx, sx], [0, -sx/cy,
    cx/cy]]``, times ``180/pi`` (``c``, ``s`` the cosines and sines of the angles; the
    determinant of the velocities is ``cy``: singular only at the gimbal lock).

    >>> import numpy as np
    >>> np.round(angle_rates([0, 0, 0]), 6) + 0.0  # at zero: 180/pi deg per rad, axis by axis
    array([[57.29578,  0.     ,  0.     ],
           [ 0.     , 57.29578,  0.     ],
           [ 0.     ,  0.     , 57.29578]])
    """
    convention = check_convention(convention)
    (cx, cy, cz), (sx, sy, sz), out = _trig(angles_deg)
    per_deg = 180.0 / np.pi
    secant = per_deg / cy
    if convention == "symetrie":
        out[..., 0, 0], out[..., 0, 1] = cz * secant, sz * secant
        out[..., 1, 0], out[..., 1, 1] = -sz * per_deg, cz * per_deg
        out[..., 2, 0], out[..., 2, 1] = sy * cz * secant, sy * sz * secant
        out[..., 2, 2] = per_deg
    else:
        out[..., 0, 0] = per_deg
        out[..., 0, 1], out[..., 0, 2] = sy * sx * secant, -sy * cx * secant
        out[..., 1, 1], out[..., 1, 2] = cx * per_deg, sx * per_deg
        out[..., 2, 1], out[..., 2, 2] = -sx * secant, cx * secant
    return out


def angle_velocities(angles_deg: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """The small rotation ``omega`` (rad, applied on the left: ``R -> (I + [omega]x) R``)
    per degree of each of ``[Rx, Ry, Rz]``: matrices (..., 3, 3) whose column k is
    ``vee(dR/dangle_k R^T)``, the inverse of :func:`angle_rates`, in closed form: the
    columns are ``Rz Ry e_x``, ``Rz e_y``, ``e_z`` for ``R = Rz Ry Rx`` (symetrie) and
    ``e_x``, ``Rx e_y``, ``Rx Ry e_z`` for ``R = Rx Ry Rz`` (pi), times ``pi/180``.

    >>> import numpy as np
    >>> bool(np.allclose(angle_velocities([10, -20, 30]) @ angle_rates([10, -20, 30]), np.eye(3)))
    True
    """
    convention = check_convention(convention)
    (cx, cy, cz), (sx, sy, sz), out = _trig(angles_deg)
    rad = np.pi / 180.0
    if convention == "symetrie":
        out[..., 0, 0], out[..., 1, 0], out[..., 2, 0] = cz * cy * rad, sz * cy * rad, -sy * rad
        out[..., 0, 1], out[..., 1, 1] = -sz * rad, cz * rad
        out[..., 2, 2] = rad
    else:
        out[..., 0, 0] = rad
        out[..., 1, 1], out[..., 2, 1] = cx * rad, sx * rad
        out[..., 0, 2], out[..., 1, 2], out[..., 2, 2] = sy * rad, -sx * cy * rad, cx * cy * rad
    return out


def inverse3(m: npt.ArrayLike) -> FloatArray:
    """Inverses (N, 3, 3) of the matrices ``m`` (N, 3, 3) by their adjugates (LAPACK's call
    per matrix costs more than the arithmetic): the registration's rotation Hessians,
    the sphere fits' normal matrices. A matrix whose determinant is near zero against
    its size (``|det| <= 1e-8 max|m|^3``, where the adjugate's rounding would show) is
    inverted by LAPACK's :func:`numpy.linalg.inv` instead (raising ``LinAlgError`` on a
    singular one).

    >>> import numpy as np
    >>> m = np.array([[[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]]])
    >>> bool(np.allclose(inverse3(m) @ m, np.eye(3), atol=1e-15))
    True
    """
    m = np.asarray(m, dtype=float)
    a, b, c = m[:, 0, 0], m[:, 0, 1], m[:, 0, 2]
    d, e, f = m[:, 1, 0], m[:, 1, 1], m[:, 1, 2]
    g, h, i = m[:, 2, 0], m[:, 2, 1], m[:, 2, 2]
    adj = np.empty_like(m)
    adj[:, 0, 0], adj[:, 0, 1], adj[:, 0, 2] = e * i - f * h, c * h - b * i, b * f - c * e
    adj[:, 1, 0], adj[:, 1, 1], adj[:, 1, 2] = f * g - d * i, a * i - c * g, c * d - a * f
    adj[:, 2, 0], adj[:, 2, 1], adj[:, 2, 2] = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * adj[:, 0, 0] + b * adj[:, 1, 0] + c * adj[:, 2, 0]
    size = np.abs(m).max(axis=(1, 2)) if m.shape[0] else np.zeros(0)
    doubt = ~(np.abs(det) > 1e-8 * size**3)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = adj / det[:, None, None]
    if doubt.any():
        out[doubt] = np.linalg.inv(m[doubt])
    return out


def cross_columns(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """``a x b_j`` for every column ``b_j`` of ``b``: ``a`` (..., 3), ``b`` (..., 3, n)
    (the leading axes broadcast), the result (..., 3, n) contiguous. The products and
    differences of :func:`numpy.cross` (``a1 b2 - a2 b1``, ...: the same numbers), without
    its moves of the axis to the end and back and its copies (the registration's and
    the poses' derivatives: a lever by 3k columns of 20,000 steps).

    >>> import numpy as np
    >>> a, b = np.array([[1.0, 2.0, 3.0]]), np.array([[[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]])
    >>> bool(np.array_equal(cross_columns(a, b), np.cross(a[:, :, None], b, axis=1)))
    True
    """
    a = np.asarray(a, dtype=float)[..., :, None]
    b = np.asarray(b, dtype=float)
    a0, a1, a2 = a[..., 0, :], a[..., 1, :], a[..., 2, :]
    b0, b1, b2 = b[..., 0, :], b[..., 1, :], b[..., 2, :]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-2)


def angles_from_rotation(rotation: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """``[Rx, Ry, Rz]`` in degrees from rotation matrices (..., 3, 3).

    Angles are in (-180, 180]; ``Ry`` is in [-90, 90] (hexapod rotations are far
    from the gimbal lock at ``Ry = +-90``).
    """
    convention = check_convention(convention)
    r = np.asarray(rotation, dtype=float)
    if convention == "symetrie":
        ry = np.arctan2(-r[..., 2, 0], np.hypot(r[..., 0, 0], r[..., 1, 0]))
        rx = np.arctan2(r[..., 2, 1], r[..., 2, 2])
        rz = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    else:
        ry = np.arctan2(r[..., 0, 2], np.hypot(r[..., 0, 0], r[..., 0, 1]))
        rx = np.arctan2(-r[..., 1, 2], r[..., 2, 2])
        rz = np.arctan2(-r[..., 0, 1], r[..., 0, 0])
    return np.rad2deg(np.stack([rx, ry, rz], axis=-1))


def transform_from_pose(poses: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """4x4 transforms ``B2A`` from pose vectors of B relative to A, shape (..., 4, 4)."""
    p = check_poses(poses)
    out = np.zeros(p.shape[:-1] + (4, 4))
    out[..., :3, :3] = rotation_from_angles(p[..., 3:], convention)
    out[..., :3, 3] = p[..., :3]
    out[..., 3, 3] = 1.0
    return out


def pose_from_transform(transforms: npt.ArrayLike, convention: str = "symetrie") -> FloatArray:
    """Pose vectors ``[Tx, Ty, Tz, Rx, Ry, Rz]`` (mm, deg) from 4x4 transforms."""
    t = np.asarray(transforms, dtype=float)
    if t.shape[-2:] != (4, 4):
        raise ValueError(f"transform must have shape (..., 4, 4), got {t.shape}")
    return np.concatenate([t[..., :3, 3], angles_from_rotation(t[..., :3, :3], convention)], -1)


def invert_transform(transforms: npt.ArrayLike) -> FloatArray:
    """Inverse of rigid transforms (..., 4, 4), exact for the rigid structure.

    >>> import numpy as np
    >>> A2B = transform_from_pose([1, 2, 3, 10, 20, 30])
    >>> np.allclose(invert_transform(A2B) @ A2B, np.eye(4))
    True
    """
    t = np.asarray(transforms, dtype=float)
    out = np.zeros_like(t)
    rot_t = np.swapaxes(t[..., :3, :3], -1, -2)
    out[..., :3, :3] = rot_t
    out[..., :3, 3] = -(rot_t @ t[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def relative_transform(a2m: npt.ArrayLike, b2m: npt.ArrayLike) -> FloatArray:
    """``B2A`` from two frames known in a common frame M: ``inv(A2M) @ B2M``."""
    return invert_transform(a2m) @ np.asarray(b2m, dtype=float)


def apply_transform(transforms: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """Apply transforms (..., 4, 4) to points (..., k, 3); broadcasts over the leading axes."""
    t = np.asarray(transforms, dtype=float)
    p = np.asarray(points, dtype=float)
    return np.einsum("...ij,...kj->...ki", t[..., :3, :3], p) + t[..., None, :3, 3]


def to_um_urad(values_mm_deg: npt.ArrayLike) -> FloatArray:
    """Poses or pose differences ``(..., 6)`` in mm and deg -> um and urad.

    >>> to_um_urad([0.001, 0, 0, 180 / np.pi * 1e-6, 0, 0]).round(9).tolist()
    [1.0, 0.0, 0.0, 1.0, 0.0, 0.0]
    """
    values = np.asarray(values_mm_deg, dtype=float)
    return np.concatenate([values[..., :3] * 1e3, np.deg2rad(values[..., 3:]) * 1e6], axis=-1)
