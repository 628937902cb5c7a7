"""Hexapod kinematics: inverse and forward geometric models, vectorized over poses.

Frame O is the platform frame with the hexapod in its zero pose. Leg i runs from
base joint ``b_i`` (in O) to platform joint ``p_i`` (in the platform frame); for
a platform pose ``X`` relative to O with transform ``platform2origin = (R, t)``
its length is ``q_i = |t + R p_i - b_i|`` (IGM). The FGM inverts this by
Newton-Raphson with the analytic Jacobian ``dq/dX``. IGM, Jacobian and FGM take
an optional ``base_joints_mm`` override, one set (6, 3) or one per pose (N, 6,
3), for a base whose joints move (the twin's base expansion).

>>> import numpy as np
>>> hexapod = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200)
>>> q = hexapod.igm([[1.0, -2.0, 3.0, 0.1, -0.2, 0.3]])
>>> bool(np.allclose(hexapod.fgm(q), [[1.0, -2.0, 3.0, 0.1, -0.2, 0.3]], atol=1e-12))
True
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    Convention,
    check_convention,
    check_poses,
)
from hexatherm.core.thermal import LegThermalModel
from hexatherm.errors import ConvergenceError, SingularityError
from hexatherm.typing import FloatArray

#: FGM convergence tolerance on the leg lengths, mm
FGM_TOLERANCE_MM = 1e-10
#: reciprocal condition number of the Jacobian below which a pose is called singular
SINGULAR_RCOND = 1e-9


@dataclass(frozen=True)
class Hexapod:
    """Geometry and leg model of a hexapod.

    Attributes
    ----------
    name : str
    convention : {"symetrie", "pi"}
        Rotation convention of the pose vectors.
    base_joints_mm : ndarray, shape (6, 3)
        Base joints in frame O.
    platform_joints_mm : ndarray, shape (6, 3)
        Platform joints in the platform frame.
    stroke_mm : ndarray, shape (2,), optional
        Allowed leg lengths ``[min, max]``.
    legs : LegThermalModel, optional
        Thermal model of the legs.
    effects : tuple of dict
        ``thermal_model.effects`` of the hexapod file, kept as written.
    """

    name: str
    convention: Convention
    base_joints_mm: FloatArray
    platform_joints_mm: FloatArray
    stroke_mm: FloatArray | None = None
    legs: LegThermalModel | None = None
    effects: tuple[dict[str, Any], ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        check_convention(self.convention)
        for name in ("base_joints_mm", "platform_joints_mm"):
            joints = np.asarray(getattr(self, name), dtype=float)
            if joints.shape != (6, 3) or not np.all(np.isfinite(joints)):
                raise ValueError(f"{name} must be six finite [x, y, z], got shape {joints.shape}")
            object.__setattr__(self, name, joints)
        if self.stroke_mm is not None:
            stroke = np.asarray(self.stroke_mm, dtype=float)
            if stroke.shape != (2,) or not stroke[0] < stroke[1]:
                raise ValueError(f"stroke must be [min, max] with min < max, got {stroke}")
            object.__setattr__(self, "stroke_mm", stroke)

    @classmethod
    def symmetric(
        cls,
        *,
        base_radius_mm: float,
        platform_radius_mm: float,
        base_half_angle_deg: float,
        platform_half_angle_deg: float,
        height_mm: float,
        rotation_deg: float = 0.0,
        name: str = "symmetric",
        convention: Convention = "symetrie",
        legs: LegThermalModel | None = None,
        stroke_mm: tuple[float, float] | None = None,
    ) -> Hexapod:
        """A symmetric 6-6 hexapod with joints in pairs.

        Base joint pairs sit at ``+-base_half_angle`` around 0, 120 and 240 deg,
        platform joint pairs at ``+-platform_half_angle`` around 60, 180 and 300 deg
        (the whole layout turned by ``rotation_deg``), so each leg runs from a
        base pair to the neighbouring platform pair as on real hexapods. Base joints
        lie in the plane ``z = -height`` of frame O, platform joints in ``z = 0`` of
        the platform frame.
        """
        alpha, beta = base_half_angle_deg, platform_half_angle_deg
        base_ang = np.deg2rad(
            np.array([-alpha, alpha, 120 - alpha, 120 + alpha, 240 - alpha, 240 + alpha])
            + rotation_deg
        )
        plat_ang = np.deg2rad(
            np.array([-60 + beta, 60 - beta, 60 + beta, 180 - beta, 180 + beta, 300 - beta])
            + rotation_deg
        )
        base = np.column_stack(
            [
                base_radius_mm * np.cos(base_ang),
                base_radius_mm * np.sin(base_ang),
                np.full(6, -float(height_mm)),
            ]
        )
        plat = np.column_stack(
            [
                platform_radius_mm * np.cos(plat_ang),
                platform_radius_mm * np.sin(plat_ang),
                np.zeros(6),
            ]
        )
        return cls(
            name=name,
            convention=convention,
            base_joints_mm=base,
            platform_joints_mm=plat,
            stroke_mm=None if stroke_mm is None else np.asarray(stroke_mm, float),
            legs=legs,
        )

    # ------------------------------------------------------------------ IGM
    def base_joints_for(self, base_joints_mm: npt.ArrayLike | None, n_poses: int) -> FloatArray:
        """Base joints to use for ``n_poses`` poses: nominal, one override, or one per pose.

        Parameters
        ----------
        base_joints_mm : array_like, shape (6, 3) or (N, 6, 3), optional
            ``None`` for the hexapod's nominal base joints; one set for every pose;
            or one set per pose (a base that changes from pose to pose, e.g. with
            its temperature).
        n_poses : int

        Returns
        -------
        ndarray, shape (6, 3) or (N, 6, 3)
        """
        if base_joints_mm is None:
            return self.base_joints_mm
        base = np.asarray(base_joints_mm, dtype=float)
        if base.shape not in ((6, 3), (n_poses, 6, 3)):
            raise ValueError(
                f"base joints must have shape (6, 3) or ({n_poses}, 6, 3), got {base.shape}"
            )
        if not np.all(np.isfinite(base)):
            raise ValueError("base joints have a non-finite value")
        return base

    def leg_vectors(
        self, poses: npt.ArrayLike, base_joints_mm: npt.ArrayLike | None = None
    ) -> FloatArray:
        """Leg vectors ``t + R p_i - b_i`` in frame O, shape (N, 6, 3).

        ``base_joints_mm`` overrides the base joints (see :meth:`base_joints_for`).
        """
        x = np.atleast_2d(check_poses(poses))
        return self._legs(x, self.base_joints_for(base_joints_mm, x.shape[0]))[0]

    def _legs(
        self, x: FloatArray, base: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Leg vectors (N, 6, 3) of checked poses (N, 6), the rotated platform joints
        ``R p_i`` (N, 6, 3), and the cosines and sines of the angles (N, 3) each.

        ``R`` is written out from the angles' cosines and sines (the product of the
        three elementary rotations of :func:`~hexatherm.core.geometry.rotation_from_angles`,
        without its 3x3 matrix products).
        """
        angles = np.deg2rad(x[:, 3:])
        cos, sin = np.cos(angles), np.sin(angles)
        ca, cb, cc = cos[:, 0], cos[:, 1], cos[:, 2]
        sa, sb, sc = sin[:, 0], sin[:, 1], sin[:, 2]
        rot = np.empty((x.shape[0], 3, 3))
        if self.convention == "symetrie":  # Rz(c) Ry(b) Rx(a)
            rot[:, 0, 0] = cc * cb
            rot[:, 0, 1] = cc * sb * sa - sc * ca
            rot[:, 0, 2] = cc * sb * ca + sc * sa
            rot[:, 1, 0] = sc * cb
            rot[:, 1, 1] = sc * sb * sa + cc * ca
            rot[:, 1, 2] = sc * sb * ca - cc * sa
            rot[:, 2, 0] = -sb
            rot[:, 2, 1] = cb * sa
            rot[:, 2, 2] = cb * ca
        else:  # Rx(a) Ry(b) Rz(c)
            rot[:, 0, 0] = cb * cc
            rot[:, 0, 1] = -cb * sc
            rot[:, 0, 2] = sb
            rot[:, 1, 0] = sa * sb * cc + ca * sc
            rot[:, 1, 1] = ca * cc - sa * sb * sc
            rot[:, 1, 2] = -sa * cb
            rot[:, 2, 0] = sa * sc - ca * sb * cc
            rot[:, 2, 1] = ca * sb * sc + sa * cc
            rot[:, 2, 2] = ca * cb
        plat = self.platform_joints_mm @ np.swapaxes(rot, 1, 2)
        return plat + x[:, None, :3] - base, plat, cos, sin

    @staticmethod
    def _lengths(legs: FloatArray) -> FloatArray:
        """Lengths (N, 6) of leg vectors (N, 6, 3)."""
        return np.sqrt(np.einsum("nij,nij->ni", legs, legs))

    def igm(self, poses: npt.ArrayLike, base_joints_mm: npt.ArrayLike | None = None) -> FloatArray:
        """Leg lengths (N, 6) of platform poses (N, 6) relative to frame O (mm, deg).

        ``base_joints_mm`` overrides the base joints, for all poses (6, 3) or per
        pose (N, 6, 3).
        """
        return self._lengths(self.leg_vectors(poses, base_joints_mm))

    def jacobian(
        self, poses: npt.ArrayLike, base_joints_mm: npt.ArrayLike | None = None
    ) -> FloatArray:
        """Analytic Jacobian ``dq/dX`` (N, 6, 6): mm per mm and mm per degree.

        ``base_joints_mm`` overrides the base joints as in :meth:`igm`.
        """
        x = np.atleast_2d(check_poses(poses))
        legs, plat, cos, sin = self._legs(x, self.base_joints_for(base_joints_mm, x.shape[0]))
        return self._jacobian(legs, self._lengths(legs), plat, cos, sin)

    def _jacobian(
        self,
        legs: FloatArray,
        lengths: FloatArray,
        plat: FloatArray,
        cos: FloatArray,
        sin: FloatArray,
    ) -> FloatArray:
        """Jacobian (N, 6, 6) from what :meth:`_legs` returns and the leg lengths.

        With ``u_i`` the unit leg vectors, ``dq_i/dt = u_i`` and, since
        ``dR/da_k = [w_k]x R`` for the rotation axis ``w_k`` of angle ``a_k`` in frame O,
        ``dq_i/da_k = u_i . (w_k x R p_i) = w_k . (R p_i x u_i)`` (per degree).
        """
        jac = np.empty(legs.shape[:1] + (6, 6))
        units = jac[:, :, :3]
        np.divide(legs, lengths[..., None], out=units)
        ca, cb, cc = cos[:, 0], cos[:, 1], cos[:, 2]
        sa, sb = sin[:, 0], sin[:, 1]
        per_degree = np.pi / 180.0
        axes = np.zeros((legs.shape[0], 3, 3))  # axes[n, :, k]: w_k, per degree
        if self.convention == "symetrie":  # w = Rz Ry ex, Rz ey, ez
            sc = sin[:, 2]
            axes[:, 0, 0] = cc * cb * per_degree
            axes[:, 1, 0] = sc * cb * per_degree
            axes[:, 2, 0] = -sb * per_degree
            axes[:, 0, 1] = -sc * per_degree
            axes[:, 1, 1] = cc * per_degree
            axes[:, 2, 2] = per_degree
        else:  # w = ex, Rx ey, Rx Ry ez
            axes[:, 0, 0] = per_degree
            axes[:, 1, 1] = ca * per_degree
            axes[:, 2, 1] = sa * per_degree
            axes[:, 0, 2] = sb * per_degree
            axes[:, 1, 2] = -sa * cb * per_degree
            axes[:, 2, 2] = ca * cb * per_degree
        px, py, pz = plat[..., 0], plat[..., 1], plat[..., 2]
        ux, uy, uz = units[..., 0], units[..., 1], units[..., 2]
        moment = np.empty(units.shape)  # R p_i x u_i
        moment[..., 0] = py * uz - pz * uy
        moment[..., 1] = pz * ux - px * uz
        moment[..., 2] = px * uy - py * ux
        np.matmul(moment, axes, out=jac[:, :, 3:])
        return jac

    def zero_pose_leg_length_mm(self) -> FloatArray:
        """Leg lengths in the zero pose, shape (6,)."""
        return self.igm(np.zeros(6))[0]

    def check_stroke(self, q_mm: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Mask (N, 6) of leg lengths outside the stroke (all False when no stroke)."""
        q = np.atleast_2d(np.asarray(q_mm, dtype=float))
        if self.stroke_mm is None:
            return np.zeros(q.shape, dtype=bool)
        return (q < self.stroke_mm[0]) | (q > self.stroke_mm[1])

    # ------------------------------------------------------------------ FGM
    def fgm(
        self,
        q_mm: npt.ArrayLike,
        initial_poses: npt.ArrayLike | None = None,
        *,
        tol_mm: float = FGM_TOLERANCE_MM,
        max_iter: int = 30,
        base_joints_mm: npt.ArrayLike | None = None,
    ) -> FloatArray:
        """Platform poses (N, 6) from leg lengths (N, 6) by Newton-Raphson.

        Every pose is iterated until ``max|IGM(X) - q| <= tol_mm``. Raises
        :class:`SingularityError` when a Jacobian is singular (naming the pose)
        and :class:`ConvergenceError` when a pose does not converge (naming it
        and how far off it is): never a silent wrong answer. ``base_joints_mm``
        overrides the base joints, for all poses (6, 3) or per pose (N, 6, 3).
        """
        q = np.atleast_2d(np.asarray(q_mm, dtype=float))
        if q.ndim != 2 or q.shape[1] != 6:
            raise ValueError(f"leg lengths must have shape (N, 6), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError("leg lengths have a non-finite value")
        base = None
        if base_joints_mm is not None:
            base = np.broadcast_to(
                self.base_joints_for(base_joints_mm, q.shape[0]), (q.shape[0], 6, 3)
            )
        if initial_poses is None:
            x = np.zeros((q.shape[0], 6))
        else:
            x = np.array(np.broadcast_to(check_poses(initial_poses), q.shape), dtype=float)
        n = q.shape[0]
        rcond = np.full(n, np.inf)  # at each pose's final Jacobian, where computed
        # The poses still iterating, in index order, and what goes with them: leg
        # lengths, base joints, and for the conditioning check their last Jacobian and
        # a lower bound on its smallest singular value (NaN: none yet).
        active = np.arange(n)
        x_a, q_a = x.copy(), q
        base_a = self.base_joints_mm if base is None else base
        last_jac: FloatArray | None = None
        sigma_low = np.full(n, np.nan)
        for iteration in range(max_iter + 1):
            legs, plat, cos, sin = self._legs(x_a, base_a)
            lengths = self._lengths(legs)
            err = lengths - q_a
            worst = np.abs(err).max(axis=1)
            done = worst <= tol_mm
            # Every pose's Jacobian at its current pose: the Newton step of the poses
            # still iterating, the final conditioning check of the poses that are done.
            jac = self._jacobian(legs, lengths, plat, cos, sin)
            rcond_a, sigma_low, inverse = self._conditioning(jac, last_jac, sigma_low)
            if done.any():
                rcond[active[done]] = rcond_a[done]
                x[active[done]] = x_a[done]
                keep = ~done
                active, x_a, q_a, err, worst = (
                    active[keep],
                    x_a[keep],
                    q_a[keep],
                    err[keep],
                    worst[keep],
                )
                jac, rcond_a, sigma_low = jac[keep], rcond_a[keep], sigma_low[keep]
                if inverse is not None:
                    inverse = inverse[keep]
                if base is not None:
                    base_a = base_a[keep]
            if active.size == 0:
                self._raise_singular(rcond, np.arange(n))
                return x
            if iteration == max_iter:
                raise ConvergenceError(
                    f"FGM did not converge for {active.size} pose(s) in {max_iter} "
                    f"iterations; first: pose index {active[0]}, leg length residual "
                    f"{worst[0]:.3e} mm (tolerance {tol_mm:.0e} mm)"
                )
            self._raise_singular(rcond_a, active)
            if inverse is None:
                x_a = x_a - np.linalg.solve(jac, err[..., None])[..., 0]
            else:  # the inverses the conditioning check computed anyway
                x_a = x_a - (inverse @ err[..., None])[..., 0]
            last_jac = jac
        raise AssertionError("unreachable")  # pragma: no cover

    #: lower bound on the reciprocal condition above which a Jacobian needs no SVD
    _SURELY_REGULAR = 1e-6

    def _conditioning(
        self, jac: FloatArray, last_jac: FloatArray | None, sigma_low: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Reciprocal condition numbers of Jacobians (N, 6, 6), where they could be small.

        An SVD per pose and iteration would cost more than the rest of the FGM. Instead
        ``sigma_min(J) >= 1 / |J^-1|_F`` bounds the smallest singular value from below at
        a pose's first Jacobian, and Weyl's inequality ``sigma_min(J') >= sigma_min(J) -
        |J' - J|_F`` carries the bound over to its next Jacobian ``J'``; with
        ``sigma_max(J) <= |J|_F`` this bounds the reciprocal condition from below. Where
        the bound is not at least ``1e-6`` (a thousand times :data:`SINGULAR_RCOND`, far
        beyond rounding) a fresh bound is computed, and where even that one is not, the
        exact value by SVD; elsewhere the result is ``inf`` (surely regular).

        ``last_jac`` (N, 6, 6) holds each pose's previous Jacobian (None: none yet) and
        ``sigma_low`` (N,) the bound there (NaN: none yet). Returns the reciprocal
        conditions, the bounds at ``jac``, and the inverses of ``jac`` when every one
        was computed (else None).
        """
        norm = np.sqrt(np.einsum("nij,nij->n", jac, jac))
        if last_jac is None:
            low = np.full(jac.shape[0], np.nan)
        else:
            change = jac - last_jac
            low = sigma_low - np.sqrt(np.einsum("nij,nij->n", change, change))
        fresh = ~(low >= self._SURELY_REGULAR * norm)
        inverse = None
        if fresh.any():
            try:
                inverse = np.linalg.inv(jac if fresh.all() else jac[fresh])
                low[fresh] = 1.0 / np.sqrt(np.einsum("nij,nij->n", inverse, inverse))
            except np.linalg.LinAlgError:
                inverse = None
                low[fresh] = 0.0
        out = np.full(jac.shape[0], np.inf)
        unsure = ~(low >= self._SURELY_REGULAR * norm)
        if unsure.any():
            values = np.linalg.svd(jac[unsure], compute_uv=False)
            out[unsure] = values[:, -1] / values[:, 0]
        return out, low, inverse if inverse is not None and fresh.all() else None

    @staticmethod
    def _raise_singular(rcond: FloatArray, index: npt.NDArray[np.intp]) -> None:
        """SingularityError naming the first pose whose reciprocal condition is too small."""
        singular = ~(rcond >= SINGULAR_RCOND)
        if np.any(singular):
            raise SingularityError(
                f"FGM: singular Jacobian at pose index {index[singular][0]} "
                f"(reciprocal condition {rcond[singular][0]:.2e}; "
                f"{int(singular.sum())} pose(s) affected): the leg lengths do not "
                "determine the pose there"
            )
