"""Hexapod kinematics: inverse and forward geometric models, vectorized over poses.

Frame O is the platform frame with the hexapod in its zero pose. Leg i runs from
base joint ``b_i`` (in O) to platform joint ``p_i`` (in the platform frame); for
a platform pose ``X`` relative to O with transform ``platform2origin = (R, t)``
its length is ``q_i = |t + R p_i - b_i|`` (IGM). The FGM inverts this by
Newton-Raphson with the analytic Jacobian ``dq/dX``, following the legs from a
start pose with every step certified (Kantorovich), so that it never returns a
pose of another assembly mode (:meth:`Hexapod.fgm`). IGM, Jacobian and FGM take
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
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    Convention,
    check_convention,
    check_poses,
)
from hexatherm.core.thermal import LegThermalModel
from hexatherm.errors import AssemblyModeError, ConvergenceError, SingularityError
from hexatherm.typing import FloatArray

#: FGM convergence tolerance on the leg lengths, mm
FGM_TOLERANCE_MM = 1e-10
#: reciprocal condition number of the Jacobian below which a pose is called singular
SINGULAR_RCOND = 1e-9
#: most Newton steps per pose of the FGM (path steps and final iterations)
FGM_MAX_ITER = 100
#: how far (mm) the FGM accepts leg lengths beyond the stroke
STROKE_TOLERANCE_MM = 0.1
#: :meth:`Hexapod.fgm_near`: the farthest (mm, any leg) its start poses' legs may be from
#: the leg lengths for plain Newton, and its most steps; beyond either, :meth:`Hexapod.fgm`
NEAR_MM = 0.1
NEAR_STEPS = 4
#: Kantorovich's h = beta L eta allowed per FGM step (the theorem needs h <= 1/2)
_KANTOROVICH_H = 0.45
#: the certified ball changes no leg by more than this fraction of the shortest
_BALL_FRACTION = 0.1


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
    def fgm_near(
        self, q_mm: npt.ArrayLike, poses_mm: npt.ArrayLike, tol_mm: float = FGM_TOLERANCE_MM
    ) -> tuple[FloatArray, FloatArray]:
        """The FGM of leg lengths ``q_mm`` (N, 6) from poses ``poses_mm`` (N, 6) already
        next to them (the corrected poses a correction found, where a Jacobian is to be
        evaluated): plain Newton while every start's legs are within :data:`NEAR_MM` of
        ``q_mm`` (a thousandth of a leg: deep inside the region where the certified
        :meth:`fgm` takes its first step to the end, on the same assembly mode) and every
        pose reaches ``max|IGM(X) - q| <= tol_mm`` within :data:`NEAR_STEPS` steps; else
        :meth:`fgm` from them. Returns the poses and the IGM's Jacobian (N, 6, 6) there,
        which the last check computed anyway.

        >>> hexapod = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
        ...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200)
        >>> pose = np.array([[1.0, -2.0, 3.0, 0.5, -0.4, 0.3]])
        >>> x, jac = hexapod.fgm_near(hexapod.igm(pose), pose + 1e-4)
        >>> bool(np.abs(x - pose).max() < 1e-9), jac.shape
        (True, (1, 6, 6))
        """
        q = np.asarray(q_mm, dtype=float)
        start = np.asarray(check_poses(poses_mm), dtype=float)
        x = start
        base = self.base_joints_mm
        for step in range(NEAR_STEPS + 1):
            legs, plat, cos, sin = self._legs(x, base)
            lengths = self._lengths(legs)
            jac = self._jacobian(legs, lengths, plat, cos, sin)
            resid = lengths - q
            worst = np.abs(resid).max(axis=1)
            if step == 0 and not np.all(worst <= NEAR_MM):
                break
            if np.all(worst <= tol_mm):
                return x, jac
            if step == NEAR_STEPS:
                break
            try:
                x = x - np.linalg.solve(jac, resid[..., None])[..., 0]
            except np.linalg.LinAlgError:
                break
        x = self.fgm(q, initial_poses=start, tol_mm=tol_mm)
        return x, self.jacobian(x)

    def fgm(
        self,
        q_mm: npt.ArrayLike,
        initial_poses: npt.ArrayLike | None = None,
        *,
        tol_mm: float = FGM_TOLERANCE_MM,
        max_iter: int = FGM_MAX_ITER,
        base_joints_mm: npt.ArrayLike | None = None,
        stroke_check: bool | None = None,
        stroke_tolerance_mm: float = STROKE_TOLERANCE_MM,
        start: FgmStart | None = None,
    ) -> FloatArray:
        """Platform poses (N, 6) from leg lengths (N, 6): the pose reached from the start.

        Leg lengths alone do not determine a pose: a hexapod has several assembly
        modes, poses with the same leg lengths. The pose returned is the one the
        platform reaches from its start pose ``X0`` (``initial_poses``, default the
        zero pose) when its legs move from ``q0 = IGM(X0)`` to ``q`` along the
        straight line ``q(s) = q0 + s (q - q0)``, ``0 <= s <= 1``, without meeting a
        singularity on the way, and it is certified to be that one: never a pose
        of another assembly mode.

        The iteration is Newton-Raphson on that path (the analytic Jacobian), with
        every step certified by Kantorovich's theorem: at an iterate ``x`` with
        ``beta >= |J(x)^-1|`` and ``L`` a Lipschitz constant of ``J`` near ``x``
        (bounded from the geometry, :meth:`_curvature_bound`), a step aimed at
        ``q(s')`` of length ``eta`` with ``h = beta L eta <= 0.45`` has exactly one
        solution within ``1 / (beta L)`` of ``x`` for every ``q(s)`` it spans, on
        a path free of singularities; the step to ``s'`` is the longest that keeps
        ``h <= 0.45``. From a start close to the answer (``process``'s case) the
        first step reaches ``s = 1`` and this is plain Newton; from far away it
        takes as many steps as the path needs. Every pose is iterated until
        ``max|IGM(X) - q| <= tol_mm``; lengths and angles are in the units of
        :meth:`igm` (mm, deg).

        Parameters
        ----------
        q_mm : array_like, shape (6,) or (N, 6)
            Leg lengths, mm.
        initial_poses : array_like, shape (6,) or (N, 6), optional
            Start poses ``X0`` (mm, deg); default the zero pose.
        tol_mm : float
            Tolerance on the leg lengths, mm.
        max_iter : int
            Most Newton steps per pose (path steps and final iterations).
        base_joints_mm : array_like, shape (6, 3) or (N, 6, 3), optional
            Base joints override, for all poses or per pose (see :meth:`igm`).
        stroke_check : bool, optional
            Refuse leg lengths beyond the hexapod's stroke by more than
            ``stroke_tolerance_mm`` (:class:`AssemblyModeError`): the hexapod cannot
            be there, and which assembly mode is meant cannot be told. By default
            (None) checked when no start pose is given, where the FGM picks the
            assembly mode itself; a caller that gives start poses (a simulation of
            commanded poses, the correction of measured ones) vouches for the
            branch, and the path from its start is certified either way. A hexapod
            without a stroke is never checked.
        stroke_tolerance_mm : float
            mm beyond the stroke still accepted (thermal growth, say).
        start : FgmStart, optional
            What the first iteration computes at the start poses, done once
            (:meth:`fgm_start`) for many calls from the same poses and base joints (a
            fit's twin runs): its poses are the start poses (``initial_poses`` must be
            None; for ``stroke_check`` a start counts as start poses given) and ``q_mm``
            may hold several sets of them (N a multiple of its poses, set after set).
            The result is the same, bit for bit.

        Returns
        -------
        ndarray, shape (N, 6)
            Platform poses relative to frame O, mm and deg.

        Raises
        ------
        AssemblyModeError
            Legs out of the stroke, or a path step that cannot be certified (the
            pose named by its index).
        SingularityError
            A Jacobian on the way is singular (naming the pose).
        ConvergenceError
            A pose not reached within ``max_iter`` steps (naming it and how far
            off it is): never a silent wrong answer.

        Examples
        --------
        Leg lengths beyond the stroke are refused, naming the pose:

        >>> hexapod = Hexapod.symmetric(base_radius_mm=150, platform_radius_mm=100,
        ...     base_half_angle_deg=10, platform_half_angle_deg=10, height_mm=200,
        ...     stroke_mm=(200.0, 260.0))
        >>> q = hexapod.igm([[0.0, 0.0, 5.0, 0, 0, 0], [0.0, 0.0, 80.0, 0, 0, 0]])
        >>> try:
        ...     hexapod.fgm(q)
        ... except AssemblyModeError as error:
        ...     print(error.index, str(error)[:34])
        1 FGM: pose index 1 has leg 1 at 296
        """
        q = np.atleast_2d(np.asarray(q_mm, dtype=float))
        if q.ndim != 2 or q.shape[1] != 6:
            raise ValueError(f"leg lengths must have shape (N, 6), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError("leg lengths have a non-finite value")
        if not (np.isfinite(tol_mm) and tol_mm > 0):
            raise ValueError(f"tol_mm must be positive, got {tol_mm}")
        if max_iter < 0:
            raise ValueError(f"max_iter must be >= 0, got {max_iter}")
        if stroke_check or (stroke_check is None and initial_poses is None and start is None):
            self._check_fgm_stroke(q, stroke_tolerance_mm)
        n = q.shape[0]
        base = None
        if base_joints_mm is not None:
            base = np.broadcast_to(self.base_joints_for(base_joints_mm, n), (n, 6, 3))
        if start is not None:
            if initial_poses is not None or base is not None or n % start.poses.shape[0]:
                raise ValueError(
                    "fgm: a start goes without initial_poses and base joints, and its "
                    f"poses ({start.poses.shape[0]}) must divide the leg lengths ({n})"
                )
            start = start.repeated(n // start.poses.shape[0])
            x = start.poses.copy()
        elif initial_poses is None:
            x = np.zeros((n, 6))
        else:
            x = np.array(np.broadcast_to(check_poses(initial_poses), q.shape), dtype=float)
        bound = self._curvature_bound()
        # The poses still iterating, in index order, and what goes with them: final
        # leg lengths, base joints, the leg change of the whole path and how far along
        # it they are (s = 1: on the final stretch, plain Newton), a bound on their
        # distance to the exact path point (scaled mm) and, on the final stretch, a
        # lower bound on sigma_min(J D^-1) there.
        active = np.arange(n)
        x_a, q_a = x.copy(), q
        dq_a = np.zeros_like(q)
        s_a = np.zeros(n)
        e_a = np.zeros(n)
        floor_a = np.zeros(n)
        base_a = self.base_joints_mm if base is None else base
        for iteration in range(max_iter + 1):
            frame: _PathFrame | None = None
            if iteration == 0 and start is not None:
                # every pose is on the path at s = 0: the frame is all start's
                lengths, frame, jac = start.lengths, start.frame, start.jacobian
            else:
                legs, plat, cos, sin = self._legs(x_a, base_a)
                lengths = self._lengths(legs)
                jac = self._jacobian(legs, lengths, plat, cos, sin)
            if iteration == 0:
                dq_a = q_a - lengths  # the path starts at the start pose's legs
            resid = lengths - q_a
            worst = np.abs(resid).max(axis=1)
            on_path = s_a < 1.0
            to_end = ~on_path
            rcond = np.full(active.size, np.inf)
            if to_end.any():  # certified earlier: Newton converges inside the ball
                rcond[to_end] = self._final_rcond(jac[to_end], floor_a[to_end], bound)
            if on_path.any():
                if frame is None:
                    frame = self._path_frame(jac[on_path], lengths[on_path], sin[on_path, 1], bound)
                path = self._path_step(
                    frame,
                    resid[on_path] + (1.0 - s_a[on_path, None]) * dq_a[on_path],
                    dq_a[on_path],
                    s_a[on_path],
                    e_a[on_path],
                )
                rcond[on_path] = path.rcond
                self._raise_singular(rcond, active)
                if path.uncertified.any():
                    raise self._uncertified(active[on_path], s_a[on_path], path)
                to_end[on_path] = path.to_end
            else:
                self._raise_singular(rcond, active)
            done = to_end & (worst <= tol_mm)
            if done.all():
                x[active] = x_a
                return x
            if iteration == max_iter:
                keep = ~done
                raise self._not_converged(active[keep], worst[keep], s_a[keep], max_iter, tol_mm)
            x[active[done]] = x_a[done]
            step = np.zeros_like(x_a)
            if on_path.any():
                step[on_path] = np.einsum("nij,nj->ni", path.inverse, path.target)
                e_a[on_path] = path.error_bound
                floor_a[on_path] = path.sigma_floor
                s_a[on_path] = np.where(path.to_end, 1.0, s_a[on_path] + path.d)
            newton = ~on_path & ~done
            if newton.any():
                step[newton] = np.linalg.solve(jac[newton], resid[newton, :, None])[..., 0]
            keep = ~done
            active, x_a, q_a, dq_a = active[keep], (x_a - step)[keep], q_a[keep], dq_a[keep]
            s_a, e_a, floor_a = s_a[keep], e_a[keep], floor_a[keep]
            if base is not None:
                base_a = base_a[keep]
        raise AssertionError("unreachable")  # pragma: no cover

    def _check_fgm_stroke(self, q: FloatArray, tolerance_mm: float) -> None:
        """AssemblyModeError naming the first pose with a leg beyond the stroke."""
        if self.stroke_mm is None:
            return
        if not (np.isfinite(tolerance_mm) and tolerance_mm >= 0):
            raise ValueError(f"stroke_tolerance_mm must be >= 0, got {tolerance_mm}")
        low, high = self.stroke_mm
        outside = (q < low - tolerance_mm) | (q > high + tolerance_mm)
        if outside.any():
            pose, leg = np.argwhere(outside)[0]
            raise AssemblyModeError(
                f"FGM: pose index {pose} has leg {leg + 1} at {q[pose, leg]:.2f} mm, outside "
                f"the stroke [{low:g}, {high:g}] mm by more than {tolerance_mm:g} mm: the "
                "hexapod cannot be there",
                index=int(pose),
            )

    def _curvature_bound(self) -> _Curvature:
        """Constants of the bound on how fast the Jacobian changes (Kantorovich's ``L``).

        Poses are measured in scaled coordinates: mm of translation, and for the
        angles mm of arc at radius ``rho`` (the largest platform joint radius), so
        ``D = diag(1, 1, 1, c, c, c)`` with ``c = rho pi / 180`` mm per degree.

        Along a line in pose space with translation rate ``dt`` and Euler-angle
        rates ``da`` (rad), leg ``i`` (vector ``v``, unit ``u``, length ``q``,
        platform joint at radius ``P_i``) has ``q'' = (|v'|^2 - (u.v')^2) / q +
        u.v''``, ``v' = dt + w x Rp_i`` and ``v'' = dw/ds x Rp_i + w x (w x Rp_i)``,
        ``w`` the angular velocity. For both conventions the Euler axes give
        ``|w|^2 <= (1 + |sin b|) |da|^2`` (``b`` the second angle) and ``|dw/ds| <=
        |da|^2``. With ``|da| = |dtheta| / rho`` in scaled coordinates, the Hessian
        of ``q_i`` is bounded by ``(1 + (1 + sb) P_i^2 / rho^2) / q + (2 + sb)
        P_i / rho^2`` (``sb`` a bound on ``|sin b|``), the change of the Jacobian
        by the root sum of squares of the six, and a leg's length changes at most
        ``sqrt(1 + 2 P_i^2 / rho^2)`` mm per scaled mm.
        """
        radii = np.linalg.norm(self.platform_joints_mm, axis=1)
        rho = float(radii.max()) if radii.max() > 0 else 1.0
        ratio_sq = (radii / rho) ** 2
        return _Curvature(
            scale=np.array([1.0, 1.0, 1.0] + [rho * np.pi / 180.0] * 3),
            ratio_sq=ratio_sq,
            ratio_rho=radii / rho**2,
            rho=rho,
            gradient=float(np.sqrt(1.0 + 2.0 * ratio_sq.max())),
        )

    def fgm_start(self, initial_poses: npt.ArrayLike) -> FgmStart:
        """What :meth:`fgm`'s first iteration computes at the start poses (N, 6) with
        the hexapod's own base joints, for ``fgm(q, start=...)`` (see there)."""
        x = np.array(np.atleast_2d(check_poses(initial_poses)), dtype=float)
        legs, plat, cos, sin = self._legs(x, self.base_joints_mm)
        lengths = self._lengths(legs)
        jac = self._jacobian(legs, lengths, plat, cos, sin)
        frame = self._path_frame(jac, lengths, sin[:, 1], self._curvature_bound())
        return FgmStart(x, lengths, jac, frame)

    def _path_frame(
        self, jac: FloatArray, lengths: FloatArray, sin_b: FloatArray, bound: _Curvature
    ) -> _PathFrame:
        """What a path step (:meth:`_path_step`) needs of the iterates' Jacobians (M,):
        their conditioning, inverses and the certified ball, whatever the target."""
        rcond, _, inverse = self._conditioning(jac)
        if inverse is None:  # exactly singular: rcond 0, the caller raises
            inverse = np.zeros_like(jac)
        # (a singular J gives infinities here: rcond is 0 and the caller raises)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            scaled_inv = inverse * bound.scale[None, :, None]  # D J^-1
            beta = self._spectral_bound(scaled_inv)
            q_min = lengths.min(axis=1)
            ball_cap = _BALL_FRACTION * q_min / bound.gradient  # every leg > (1 - 0.1) q_min
            sb = np.minimum(np.abs(sin_b) + ball_cap / bound.rho, 1.0)
            hess = (1.0 + (1.0 + sb)[:, None] * bound.ratio_sq) / (
                (1.0 - _BALL_FRACTION) * q_min[:, None]
            ) + (2.0 + sb)[:, None] * bound.ratio_rho
            lip = np.maximum(np.sqrt(np.einsum("ni,ni->n", hess, hess)), 1.0 / (beta * ball_cap))
            radius = 1.0 / (beta * lip)
        return _PathFrame(rcond, inverse, scaled_inv, beta, lip, radius, _KANTOROVICH_H * radius)

    @staticmethod
    def _path_step(
        frame: _PathFrame, err: FloatArray, dq: FloatArray, s: FloatArray, e: FloatArray
    ) -> _PathStep:
        """The certified Newton step along the leg path of poses (M,) (see :meth:`fgm`).

        ``frame`` is :meth:`_path_frame`'s at the iterates, ``err`` (M, 6) is ``IGM(x) -
        q(s)``, ``dq`` (M, 6) the leg change of the whole path, ``e`` (M,) the bound on
        the distance from ``x`` to the exact path point.
        """
        scaled_inv, beta, lip = frame.scaled_inverse, frame.beta, frame.lip
        radius, allowed = frame.radius, frame.allowed
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            corr = np.einsum("nij,nj->ni", scaled_inv, err)  # Newton step to stay at s
            tang = np.einsum("nij,nj->ni", scaled_inv, dq)  # per unit of s
            corr_norm = np.sqrt(np.einsum("ni,ni->n", corr, corr))
            uncertified = ~((corr_norm <= allowed) & (e < radius))
            # the longest step d along the path with |corr - d tang| <= allowed
            tt = np.einsum("ni,ni->n", tang, tang)
            ct = np.einsum("ni,ni->n", corr, tang)
            disc = np.maximum(ct**2 - tt * (corr_norm**2 - allowed**2), 0.0)
            d_max = np.where(tt > 0, (ct + np.sqrt(disc)) / np.where(tt > 0, tt, 1.0), np.inf)
            to_end = d_max >= 1.0 - s
            d = np.where(to_end, 1.0 - s, d_max)
            scaled_step = corr - d[:, None] * tang
            h = beta * lip * np.sqrt(np.einsum("ni,ni->n", scaled_step, scaled_step))
            root = np.sqrt(np.maximum(1.0 - 2.0 * h, 0.0))
            error_bound = 2.0 * h**2 / (1.0 + root) ** 2 / (beta * lip)  # r- minus the step
        return _PathStep(
            rcond=frame.rcond,
            inverse=frame.inverse,
            target=err - d[:, None] * dq,
            d=d,
            to_end=to_end,
            uncertified=uncertified,
            error_bound=error_bound,
            sigma_floor=root / beta,  # sigma_min(J D^-1) in the ball the iterates keep to
            correction=corr_norm,
            allowed=allowed,
            distance=e,
            radius=radius,
        )

    def _final_rcond(
        self, jac: FloatArray, sigma_floor: FloatArray, bound: _Curvature
    ) -> FloatArray:
        """Reciprocal conditions (M,) of Jacobians on the certified final stretch.

        ``sigma_min(J) >= sigma_min(J D^-1) min(D)``, with the floor certified by the
        path step; only where that is not surely regular, an SVD.
        """
        norm = np.sqrt(np.einsum("nij,nij->n", jac, jac))
        low = sigma_floor * min(1.0, float(bound.scale[3])) / norm
        out = np.full(jac.shape[0], np.inf)
        unsure = ~(low >= self._SURELY_REGULAR)
        if unsure.any():
            values = np.linalg.svd(jac[unsure], compute_uv=False)
            out[unsure] = values[:, -1] / values[:, 0]
        return out

    @staticmethod
    def _spectral_bound(matrices: FloatArray) -> FloatArray:
        """Upper bounds (N,) on the spectral norms of matrices (N, 6, 6).

        ``|M|_2^2 = lambda_max(G)`` with ``G = M^T M``, and ``lambda_max(G)^2 <=
        |G^2|_F``: within a few per cent of the exact value when the singular
        values are spread, never below it, and cheaper than an SVD.
        """
        gram = np.matmul(np.swapaxes(matrices, 1, 2), matrices)
        square = np.matmul(gram, gram)
        return np.sqrt(np.sqrt(np.sqrt(np.einsum("nij,nij->n", square, square))))

    #: lower bound on the reciprocal condition above which a Jacobian needs no SVD
    _SURELY_REGULAR = 1e-6

    def _conditioning(
        self,
        jac: FloatArray,
        last_jac: FloatArray | None = None,
        sigma_low: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Reciprocal condition numbers of Jacobians (N, 6, 6), where they could be small.

        An SVD per pose would cost more than the rest of the FGM. Instead
        ``sigma_min(J) >= 1 / |J^-1|_F`` bounds the smallest singular value from below,
        or, given the previous Jacobians ``last_jac`` and the bounds ``sigma_low`` there
        (NaN: none), Weyl's inequality ``sigma_min(J') >= sigma_min(J) - |J' - J|_F``
        carries the bound over; with ``sigma_max(J) <= |J|_F`` this bounds the
        reciprocal condition from below. Where the bound is not at least ``1e-6`` (a
        thousand times :data:`SINGULAR_RCOND`, far beyond rounding) a fresh bound is
        computed, and where even that one is not, the exact value by SVD; elsewhere
        the result is ``inf`` (surely regular).

        Returns the reciprocal conditions, the bounds at ``jac``, and the inverses of
        ``jac`` when every one was computed (else None; an exactly singular Jacobian
        has bound 0).
        """
        norm = np.sqrt(np.einsum("nij,nij->n", jac, jac))
        if last_jac is None or sigma_low is None:
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

    @staticmethod
    def _uncertified(
        index: npt.NDArray[np.intp], s: FloatArray, path: _PathStep
    ) -> AssemblyModeError:
        """AssemblyModeError naming the first pose whose path step cannot be certified."""
        k = int(np.argmax(path.uncertified))
        return AssemblyModeError(
            f"FGM: pose index {index[k]} cannot be followed from its start pose "
            f"({100 * s[k]:.0f} % of the way; correction {path.correction[k]:.2e} mm, "
            f"allowed {path.allowed[k]:.2e} mm; distance bound {path.distance[k]:.2e} mm, "
            f"certified radius {path.radius[k]:.2e} mm): near a singularity, which "
            "assembly mode it reaches is not certain; start closer to the pose",
            index=int(index[k]),
        )

    @staticmethod
    def _not_converged(
        index: npt.NDArray[np.intp],
        worst: FloatArray,
        s: FloatArray,
        max_iter: int,
        tol_mm: float,
    ) -> ConvergenceError:
        """ConvergenceError naming the first pose not done within ``max_iter`` steps."""
        message = (
            f"FGM did not converge for {index.size} pose(s) in {max_iter} iterations; "
            f"first: pose index {index[0]}, leg length residual {worst[0]:.3e} mm "
            f"(tolerance {tol_mm:.0e} mm)"
        )
        if s[0] < 1.0:
            message += (
                f", {100 * s[0]:.0f} % of the way from its start pose (the path nears a "
                "singularity or is long: raise max_iter or start closer)"
            )
        return ConvergenceError(message)


class _Curvature(NamedTuple):
    """Geometry constants of :meth:`Hexapod._curvature_bound`."""

    scale: FloatArray  # (6,) D's diagonal: mm per mm and mm of arc per degree
    ratio_sq: FloatArray  # (6,) P_i^2 / rho^2
    ratio_rho: FloatArray  # (6,) P_i / rho^2, 1/mm
    rho: float  # mm
    gradient: float  # bound on |dq_i / dx| in scaled coordinates


class _PathFrame(NamedTuple):
    """What a certified path step needs of the Jacobians at poses (M,), any target."""

    rcond: FloatArray  # reciprocal condition of J (inf: surely regular)
    inverse: FloatArray  # (M, 6, 6) J^-1
    scaled_inverse: FloatArray  # (M, 6, 6) D J^-1
    beta: FloatArray  # bound on |D J^-1|
    lip: FloatArray  # Lipschitz constant of J in the ball
    radius: FloatArray  # radius of the certified ball, scaled mm
    allowed: FloatArray  # largest certified step, scaled mm

    def repeated(self, times: int) -> _PathFrame:
        return _PathFrame(*(np.tile(a, (times,) + (1,) * (a.ndim - 1)) for a in self))


@dataclass(frozen=True)
class FgmStart:
    """:meth:`Hexapod.fgm`'s first iteration at start poses (N,), for many calls.

    Attributes
    ----------
    poses : ndarray, shape (N, 6)
    lengths : ndarray, shape (N, 6)
        Their leg lengths.
    jacobian : ndarray, shape (N, 6, 6)
    frame : _PathFrame
        The path step's conditioning, inverses and certified ball there.
    """

    poses: FloatArray
    lengths: FloatArray
    jacobian: FloatArray
    frame: _PathFrame

    def repeated(self, times: int) -> FgmStart:
        """The same start for ``times`` sets of the poses, set after set."""
        if times == 1:
            return self
        return FgmStart(
            np.tile(self.poses, (times, 1)),
            np.tile(self.lengths, (times, 1)),
            np.tile(self.jacobian, (times, 1, 1)),
            self.frame.repeated(times),
        )


class _PathStep(NamedTuple):
    """One certified step of :meth:`Hexapod.fgm`'s path, for poses (M,)."""

    rcond: FloatArray  # reciprocal condition of J (inf: surely regular)
    inverse: FloatArray  # (M, 6, 6) J^-1
    target: FloatArray  # (M, 6) what the step removes: IGM(x) - q(s + d)
    d: FloatArray  # the step along the path
    to_end: npt.NDArray[np.bool_]  # the step reaches s = 1
    uncertified: npt.NDArray[np.bool_]
    error_bound: FloatArray  # distance from the new x to the exact path point, scaled mm
    sigma_floor: FloatArray  # lower bound on sigma_min(J D^-1) where Newton goes on
    correction: FloatArray  # |D J^-1 (IGM(x) - q(s))|, scaled mm
    allowed: FloatArray  # largest certified step, scaled mm
    distance: FloatArray  # bound on the distance from x to the exact path point
    radius: FloatArray  # radius of the certified ball, scaled mm
