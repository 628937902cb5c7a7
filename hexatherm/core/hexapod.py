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
    rotation_derivatives,
    rotation_from_angles,
)
from hexatherm.core.thermal import LegThermalModel
from hexatherm.errors import ConvergenceError, SingularityError

FloatArray = npt.NDArray[np.float64]

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
            [base_radius_mm * np.cos(base_ang), base_radius_mm * np.sin(base_ang),
             np.full(6, -float(height_mm))]
        )
        plat = np.column_stack(
            [platform_radius_mm * np.cos(plat_ang), platform_radius_mm * np.sin(plat_ang),
             np.zeros(6)]
        )
        return cls(name=name, convention=convention, base_joints_mm=base,
                   platform_joints_mm=plat, stroke_mm=None if stroke_mm is None
                   else np.asarray(stroke_mm, float), legs=legs)

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
            raise ValueError(f"base joints must have shape (6, 3) or ({n_poses}, 6, 3), got "
                             f"{base.shape}")
        if not np.all(np.isfinite(base)):
            raise ValueError("base joints have a non-finite value")
        return base

    def leg_vectors(self, poses: npt.ArrayLike,
                    base_joints_mm: npt.ArrayLike | None = None) -> FloatArray:
        """Leg vectors ``t + R p_i - b_i`` in frame O, shape (N, 6, 3).

        ``base_joints_mm`` overrides the base joints (see :meth:`base_joints_for`).
        """
        x = np.atleast_2d(check_poses(poses))
        rot = rotation_from_angles(x[:, 3:], self.convention)
        plat = np.einsum("nij,kj->nki", rot, self.platform_joints_mm)
        return plat + x[:, None, :3] - self.base_joints_for(base_joints_mm, x.shape[0])

    def igm(self, poses: npt.ArrayLike, base_joints_mm: npt.ArrayLike | None = None
            ) -> FloatArray:
        """Leg lengths (N, 6) of platform poses (N, 6) relative to frame O (mm, deg).

        ``base_joints_mm`` overrides the base joints, for all poses (6, 3) or per
        pose (N, 6, 3).
        """
        return np.linalg.norm(self.leg_vectors(poses, base_joints_mm), axis=-1)

    def jacobian(self, poses: npt.ArrayLike, base_joints_mm: npt.ArrayLike | None = None
                 ) -> FloatArray:
        """Analytic Jacobian ``dq/dX`` (N, 6, 6): mm per mm and mm per degree.

        ``base_joints_mm`` overrides the base joints as in :meth:`igm`.
        """
        x = np.atleast_2d(check_poses(poses))
        legs = self.leg_vectors(x, base_joints_mm)
        units = legs / np.linalg.norm(legs, axis=-1, keepdims=True)
        d_rot = rotation_derivatives(x[:, 3:], self.convention)  # (N, 3, 3, 3)
        d_plat = np.einsum("nkij,lj->nlki", d_rot, self.platform_joints_mm)  # (N, 6, 3, 3)
        jac = np.empty(x.shape[:1] + (6, 6))
        jac[:, :, :3] = units
        jac[:, :, 3:] = np.einsum("nli,nlki->nlk", units, d_plat)
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
            base = np.broadcast_to(self.base_joints_for(base_joints_mm, q.shape[0]),
                                   (q.shape[0], 6, 3))
        if initial_poses is None:
            x = np.zeros((q.shape[0], 6))
        else:
            x = np.array(np.broadcast_to(check_poses(initial_poses), q.shape), dtype=float)
        active = np.arange(q.shape[0])
        for iteration in range(max_iter + 1):
            err = self.igm(x[active], None if base is None else base[active]) - q[active]
            worst = np.abs(err).max(axis=1)
            done = worst <= tol_mm
            active, err, worst = active[~done], err[~done], worst[~done]
            if active.size == 0:
                self._check_conditioning(x, np.arange(x.shape[0]), base)
                return x
            if iteration == max_iter:
                raise ConvergenceError(
                    f"FGM did not converge for {active.size} pose(s) in {max_iter} "
                    f"iterations; first: pose index {active[0]}, leg length residual "
                    f"{worst[0]:.3e} mm (tolerance {tol_mm:.0e} mm)"
                )
            jac = self._check_conditioning(x, active, base)
            x[active] -= np.linalg.solve(jac, err[..., None])[..., 0]
        raise AssertionError("unreachable")  # pragma: no cover

    def _check_conditioning(self, x: FloatArray, index: npt.NDArray[np.intp],
                            base: FloatArray | None = None) -> FloatArray:
        """Jacobians at poses ``x[index]``; SingularityError when one is (nearly) singular."""
        jac = self.jacobian(x[index], None if base is None else base[index])
        singular_values = np.linalg.svd(jac, compute_uv=False)
        rcond = singular_values[:, -1] / singular_values[:, 0]
        singular = ~(rcond >= SINGULAR_RCOND)
        if np.any(singular):
            raise SingularityError(
                f"FGM: singular Jacobian at pose index {index[singular][0]} "
                f"(reciprocal condition {rcond[singular][0]:.2e}; "
                f"{int(singular.sum())} pose(s) affected): the leg lengths do not "
                "determine the pose there"
            )
        return jac
