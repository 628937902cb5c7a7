"""Uncertainty of the conventional and corrected poses, from the ball centres' covariances.

The measurand of target S_i is the 12-vector ``[conventional pose, corrected
pose]`` (mm, deg). It is a function of the measured ball centres of every
step, ``y = f(c)`` with ``c`` of shape (N, k, 3): each step's frame by the
rigid registration, its pose relative to O, the IGM, the growth at the
references, its scaling to S_i and the FGM (:class:`PoseChain`, the chain of
:func:`hexatherm.core.correction.correct` vectorized over many sets of centres).
The times, the registration weights and the hexapod model are taken as exact;
the centres are independent from ball to ball and step to step, each with its
own 3x3 covariance.

* **Linear propagation** (GUM): ``U_y = J U_c J^T`` (:func:`linear_covariance`).
  Target S_i depends on at most five steps: O, R0, S_i and its references
  before and after. ``J`` is put together by the chain rule, vectorized over
  the steps: the registration's analytic derivatives (the rotation's by the
  implicit function theorem on its optimality), the IGM's analytic Jacobian, the leg-by-leg
  derivatives of the correction, and the FGM as the inverse of the IGM's
  Jacobian at the corrected pose.
* **Monte Carlo** (GUM Supplement 1): the centres are drawn from
  ``N(c, U_c)`` with a seeded generator (or by a given sampler, e.g. refits of
  drawn probed points), the chain is run on every draw and the covariance of the
  outputs is the estimate (:func:`monte_carlo_covariance`).

>>> import numpy as np
>>> cov = cap_centre_covariance(25, 70.0, 1e-3)
>>> u_um = np.sqrt(np.diag(cov)) * 1e3
>>> bool(u_um[2] > u_um[0])  # a cap seen from above: z is the weak direction
True
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from hexatherm.core.carry import shifted_pose_derivative, shifted_poses
from hexatherm.core.correction import interpolated_growth, target_growth
from hexatherm.core.geometry import (
    angle_rates,
    cross_columns,
    invert_transform,
    pose_from_transform,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.registration import frame_derivatives, platform_frames
from hexatherm.core.touch import cap_directions
from hexatherm.typing import FloatArray

if TYPE_CHECKING:  # scipy.sparse and the calibration's weights: imported when used
    from scipy import sparse

    from hexatherm.core.calibration.weights import BandedCovariance

IntArray = npt.NDArray[np.intp]

#: outputs per target: conventional pose then corrected pose
OUTPUTS_PER_TARGET = 12
#: central-difference step on a centre coordinate, mm
DEFAULT_STEP_MM = 1e-3
#: Monte Carlo draws evaluated at once
DEFAULT_BATCH = 256
#: largest dense Jacobian (outputs x targets x coordinates) for the between-target
#: covariance; beyond it, sparse products
DENSE_BETWEEN_LIMIT = 4_000_000
#: fill of the joint covariance's factor above which its product is formed dense
DENSE_FACTOR_FILL = 0.1
#: ``sample(rng, size)``: Monte Carlo draws of all the centres, (size, N, k, 3)
CentreSampler = Callable[[np.random.Generator, int], FloatArray]


@dataclass(frozen=True)
class PoseChain:
    """Conventional and corrected poses of every target as a function of the centres only.

    Everything else is fixed: the references each target uses and their
    interpolation weights (set by the times), the registration weights, the
    hexapod. Calling the chain on centres of shape (..., N, k, 3) gives the
    outputs (..., M, 12): ``Tx..Rz`` conventional, then ``Tx..Rz`` corrected.

    Attributes
    ----------
    hexapod : Hexapod
        With its leg model.
    plan : Plan
    balls_mm : ndarray, shape (k, 3)
        Ball centres in the platform frame.
    before_index, after_index : ndarray of int, shape (M,)
        References used by each target (-1: none), as in
        :class:`~hexatherm.core.correction.Correction`.
    weight_after : ndarray, shape (M,)
    weights : ndarray, shape (N, k), optional
        Registration weights.
    initial_poses : ndarray, shape (M, 6), optional
        Start of the FGM iterations (the corrected poses of the nominal centres).
    growth_weights : ndarray, shape (M, 6, N), optional
        The smooth fit's weights of every step's leg lengths in the growth at each target
        (:class:`~hexatherm.core.correction.Correction`); None: the two neighbours.
    origin_shift : ndarray, shape (4, 4), optional
        O in R0's thermal state relative to O as measured: the corrected poses are
        expressed in it (:func:`hexatherm.core.correction.correct`); taken as exact here.
    """

    hexapod: Hexapod
    plan: Plan
    balls_mm: FloatArray
    before_index: IntArray
    after_index: IntArray
    weight_after: FloatArray
    weights: FloatArray | None = None
    initial_poses: FloatArray | None = None
    growth_weights: FloatArray | None = None
    origin_shift: FloatArray | None = None

    def __call__(self, centres_mm: npt.ArrayLike) -> FloatArray:
        """Outputs (..., M, 12) for centres (..., N, k, 3)."""
        c = np.asarray(centres_mm, dtype=float)
        lead, (n, k) = c.shape[:-3], c.shape[-3:-1]
        flat = c.reshape(-1, n, k, 3)
        frames = self.frames(flat)
        pose = pose_from_transform(
            invert_transform(frames[:, self.plan.origin_index])[:, None] @ frames,
            self.hexapod.convention,
        )  # (b, n, 6)
        out = self.outputs_from_poses(pose)
        return out.reshape(lead + out.shape[1:])

    def frames(self, centres_mm: FloatArray) -> FloatArray:
        """Platform frames in the CMM (..., N, 4, 4) of centres (..., N, k, 3)."""
        n, k = centres_mm.shape[-3:-1]
        flat = centres_mm.reshape(-1, k, 3)
        w = (
            None
            if self.weights is None
            else np.broadcast_to(self.weights, centres_mm.shape[:-1]).reshape(-1, k)
        )
        return platform_frames(flat, self.balls_mm, w).reshape(centres_mm.shape[:-2] + (4, 4))

    def pose_derivatives(
        self, centres_mm: FloatArray, steps: npt.ArrayLike | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The poses relative to O (S, 6) of ``steps`` (default: every step) and their
        derivatives (S, 6, 3k) by each step's own centres (O's frame held) and by O's
        (the step's frame held), analytic.

        The registration's derivatives (:func:`~hexatherm.core.registration.frame_derivatives`:
        a small rotation ``omega`` and a translation ``dt`` of each frame per centre
        coordinate) carried to the pose ``X_j = pose(O^-1 T_j)``: by the step's own
        centres ``omega_X = R_O^T omega_j``, ``dt_X = R_O^T dt_j``; by O's
        ``omega_X = -R_O^T omega_O``, ``dt_X = R_O^T ((t_j - t_O) x omega_O - dt_O)``;
        the angles by :func:`~hexatherm.core.geometry.angle_rates`. Only O and ``steps``
        are registered.
        """
        k = centres_mm.shape[1]
        origin = self.plan.origin_index
        rows = np.arange(centres_mm.shape[0]) if steps is None else np.asarray(steps, np.intp)
        rows = np.concatenate([[origin], rows])
        weights = self.weights
        if weights is not None and np.ndim(weights) == 2:
            weights = np.asarray(weights)[rows]
        frames, d_rot, d_trans = frame_derivatives(centres_mm[rows], self.balls_mm, weights)
        convention = self.hexapod.convention
        pose = pose_from_transform(invert_transform(frames[0]) @ frames[1:], convention)
        back = frames[0, :3, :3].T  # R_O^T
        rates = angle_rates(pose[:, 3:], convention)  # (S, 3, 3)
        d_rot, d_trans = d_rot.reshape(-1, 3, 3 * k), d_trans.reshape(-1, 3, 3 * k)
        own = np.concatenate([back @ d_trans[1:], rates @ (back @ d_rot[1:])], axis=1)
        lever = frames[1:, :3, 3] - frames[0, :3, 3]  # t_j - t_O, (S, 3)
        moved = cross_columns(lever, d_rot[0]) - d_trans[0]
        by_origin = np.concatenate([back @ moved, -(rates @ (back @ d_rot[0]))], axis=1)
        return pose, own, by_origin

    def fgm_start(self) -> FloatArray | None:
        """The FGM's start poses (M, 6): :attr:`initial_poses` relative to O as measured
        (where the FGM finds the corrected poses, before they are expressed in O carried
        to R0's state by :attr:`origin_shift`); None without them."""
        if self.initial_poses is None or self.origin_shift is None:
            return self.initial_poses
        back = invert_transform(np.asarray(self.origin_shift, dtype=float))
        return shifted_poses(back, self.initial_poses, self.hexapod.convention)

    def outputs_from_poses(self, pose: FloatArray) -> FloatArray:
        """Outputs (b, M, 12) from the poses (b, N, 6) of every step relative to O (the
        corrected ones in O carried to R0's state when :attr:`origin_shift` is set)."""
        b, n = pose.shape[:2]
        targets = self.plan.target_indices
        m = targets.size
        if m == 0:
            return np.zeros((b, 0, OUTPUTS_PER_TARGET))
        q = self.hexapod.igm(pose.reshape(-1, 6)).reshape(b, n, 6)
        legs = self.hexapod.legs
        if legs is None:
            raise ValueError("the hexapod has no leg model")
        q_r0 = q[:, self.plan.reference_indices[0]]
        if self.growth_weights is None:
            reference_growth = interpolated_growth(
                q, q_r0, self.before_index, self.after_index, self.weight_after
            )
        else:
            reference_growth = np.einsum("mln,bnl->bml", self.growth_weights, q) - q_r0[:, None, :]
        q_s = q[:, targets]
        corrected_q = q_s - target_growth(legs, reference_growth, q_r0[:, None], q_s)
        initial = self.fgm_start()
        start = pose[:, targets] if initial is None else np.broadcast_to(initial, (b, m, 6))
        corrected = self.hexapod.fgm(
            corrected_q.reshape(-1, 6), initial_poses=start.reshape(-1, 6)
        ).reshape(b, m, 6)
        if self.origin_shift is not None:
            corrected = shifted_poses(self.origin_shift, corrected, self.hexapod.convention)
        return np.concatenate([pose[:, targets], corrected], axis=-1)


def output_difference(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """``a - b`` for outputs (..., 12), angles wrapped into [-180, 180) deg."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    for start in (3, 9):
        d[..., start : start + 3] = (d[..., start : start + 3] + 180.0) % 360.0 - 180.0
    return d


@dataclass(frozen=True)
class TargetJacobian:
    """Derivatives of every target's outputs by the centres of the steps it depends on.

    Attributes
    ----------
    jac : ndarray, shape (M, 5, 12, k, 3)
        ``d output / d centre`` of target m by the centres of its part p (mm/mm, deg/mm):
        O, R0, the target, its reference before, its reference after. A step that plays
        two parts (R0 as the reference before the first targets) holds the sum in its
        first part; the later part is zero and its step -1.
    steps : ndarray of int, shape (M, 5)
        Step index of each part (-1: not used, or merged into an earlier part).
    common_parts : tuple of int
        The parts that are O and R0 for every target (their noise moves every target's
        pose): ``(0, 1)``; with the smooth growth the parts are O, the target, then every
        reference (R0 first): ``(0, 2)``.
    """

    jac: FloatArray
    steps: IntArray
    common_parts: tuple[int, ...] = (0, 1)

    #: parts shared by every target with the two neighbours: O and R0
    COMMON_PARTS = (0, 1)

    def with_parts(self, steps: npt.ArrayLike, parts: npt.ArrayLike) -> TargetJacobian:
        """This Jacobian plus derivatives of every target's outputs by the centres of more
        steps (``parts`` (M, S, 12, k, 3) by ``steps`` (S,), e.g. O's carry, which reads
        some references): each added to the part of a target that holds its step, else
        in a new part, common to every target.

        >>> jac = TargetJacobian(np.ones((1, 2, 12, 1, 3)), np.array([[0, 1]]))
        >>> more = jac.with_parts([1, 4], np.ones((1, 2, 12, 1, 3)))
        >>> more.steps.tolist(), more.jac[0, :, 0, 0, 0].tolist(), more.common_parts
        ([[0, 1, 4]], [1.0, 2.0, 1.0], (0, 1, 2))
        """
        jac, own = self.jac.copy(), self.steps.copy()
        added = np.asarray(parts, dtype=float)
        new_jac, new_steps = [], []
        for step, d in zip(np.asarray(steps, dtype=np.intp), np.moveaxis(added, 1, 0), strict=True):
            hit = own == step  # at most one part per target holds a step
            held = hit.any(axis=1)
            jac[hit] += d[held]
            if not held.all():
                new_jac.append(np.where(held[:, None, None, None], 0.0, d))
                new_steps.append(np.where(held, -1, step))
        if not new_jac:
            return TargetJacobian(jac, own, self.common_parts)
        first = jac.shape[1]
        return TargetJacobian(
            np.concatenate([jac, np.stack(new_jac, axis=1)], axis=1),
            np.concatenate([own, np.stack(new_steps, axis=1)], axis=1),
            self.common_parts + tuple(range(first, first + len(new_jac))),
        )

    def covariance(self, centre_cov_mm2: npt.ArrayLike, parts: tuple[int, ...] = ()) -> FloatArray:
        """Covariance (M, 12, 12) of every target's outputs (from the given parts only).

        The centres are independent from step to step, so the covariance is a sum over
        the parts; ``parts`` (default: all) picks some of them, e.g.
        :attr:`common_parts`.
        """
        cov = np.asarray(centre_cov_mm2, dtype=float)
        jac, steps = self.jac, self.steps
        if parts:  # those parts alone (the others would add products of zeros)
            picked = sorted(set(parts))
            jac, steps = jac[:, picked], steps[:, picked]
        m, _, n_out, k = jac.shape[:4]
        live = steps >= 0
        part_cov = np.where(live[..., None, None, None], cov[np.maximum(steps, 0)], 0.0)
        # J U J^T as two batched products (einsum's own path copied the operands about)
        by_ball = np.swapaxes(jac, 2, 3)  # (M, P, k, 12, 3)
        weighted = (by_ball @ part_cov).transpose(0, 3, 1, 2, 4).reshape(m, n_out, -1)
        plain = by_ball.transpose(0, 3, 1, 2, 4).reshape(m, n_out, -1)
        return np.asarray(weighted @ np.swapaxes(plain, 1, 2))

    def between_targets(self, centre_cov_mm2: npt.ArrayLike) -> FloatArray:
        """Covariance (12, M, M) of each output between every pair of targets.

        ``C[y, a, b] = sum_steps J_a,s,y U_s J_b,s,y^T`` over the steps both targets
        depend on (O and R0 for every pair, a shared reference for neighbours); the
        diagonal ``C[y, a, a]`` is the variance of :meth:`covariance`. Sparse products:
        each target has at most five steps.
        """
        cov = np.asarray(centre_cov_mm2, dtype=float)
        m, n_parts, n_out, k = self.jac.shape[:4]
        n = cov.shape[0]
        live = self.steps >= 0
        at = np.maximum(self.steps, 0)
        root = covariance_root(cov)  # (N, k, 3, 3)
        # whitened: J L, (M, 5, 12, k, 3); then C = (J L)(J L)^T over shared coordinates
        white = np.einsum("mpybi,mpbij->mpybj", self.jac, root[at])
        white = np.where(live[:, :, None, None, None], white, 0.0)
        coord = at[:, :, None, None] * (3 * k) + np.arange(3 * k).reshape(1, 1, k, 3)
        rows = np.broadcast_to(np.arange(m)[:, None, None, None], coord.shape).ravel()
        cols = coord.ravel()
        values = np.moveaxis(white, 2, 0).reshape(n_out, -1)  # (12, M*P*k*3)
        if n_out * m * n * 3 * k <= DENSE_BETWEEN_LIMIT:
            # small sessions: dense (a target's parts are distinct steps: no repeated cell)
            dense = np.zeros((n_out, m, n * 3 * k))
            keep = values.any(axis=0)
            dense[:, rows[keep], cols[keep]] = values[:, keep]
            return np.asarray(dense @ np.swapaxes(dense, 1, 2))
        from scipy import sparse  # here: the dense path (a report's session) needs none

        out = np.empty((n_out, m, m))
        for y in range(n_out):
            a = sparse.csr_matrix((white[:, :, y].ravel(), (rows, cols)), shape=(m, n * 3 * k))
            out[y] = (a @ a.T).toarray()
        return out

    def joint_covariance(self, centre_cov_mm2: npt.ArrayLike, outputs: slice) -> FloatArray:
        """Covariance (M*d, M*d) of the ``outputs`` (d of the 12) of all targets together,
        target by target (rows ``d*a .. d*a+d-1`` are target a's), every cross term
        between targets and components included (a calibration's weights).

        >>> jac = np.zeros((2, 5, 12, 1, 3)); jac[:, 0, 0, 0, 0] = 1.0  # both see O's x
        >>> steps = np.array([[0, -1, -1, -1, -1]] * 2)
        >>> TargetJacobian(jac, steps).joint_covariance(np.eye(3)[None, None], slice(0, 2))
        array([[1., 0., 1., 0.],
               [0., 0., 0., 0.],
               [1., 0., 1., 0.],
               [0., 0., 0., 0.]])
        """
        a = self._joint_factor(centre_cov_mm2, outputs)
        if a.nnz > DENSE_FACTOR_FILL * a.shape[0] * a.shape[1]:
            # every reference moves every target (the smooth growth): half the factor is
            # filled, and BLAS forms its product 18x faster than a sparse product
            dense = a.toarray()
            return np.asarray(dense @ dense.T)
        return np.asarray((a @ a.T).toarray())

    def joint_covariance_structured(
        self, centre_cov_mm2: npt.ArrayLike, outputs: slice
    ) -> BandedCovariance | None:
        """:meth:`joint_covariance` with its structure: the steps of the
        :attr:`common_parts` (O and R0) as the low-rank part, the others (each
        target's own step and neighbouring references) as a band; None when that
        part is not banded (the smooth growth: every reference moves every target).
        """
        from hexatherm.core.calibration.weights import BandedCovariance

        a = self._joint_factor(centre_cov_mm2, outputs)
        k = self.jac.shape[3]
        steps = self.steps[:, list(self.common_parts)]
        shared = np.unique(steps[steps >= 0])
        columns = (shared[:, None] * (3 * k) + np.arange(3 * k)).ravel()
        return BandedCovariance.from_factor(a, columns, block=a.shape[0] // self.jac.shape[0])

    def _joint_factor(self, centre_cov_mm2: npt.ArrayLike, outputs: slice) -> sparse.csr_matrix:
        """``A`` (M*d, N*3k), sparse, with ``A A^T`` the :meth:`joint_covariance`: a
        column per centre coordinate of every step (whitened by its covariance)."""
        from scipy import sparse

        cov = np.asarray(centre_cov_mm2, dtype=float)
        m, n_parts, n_out, k = self.jac.shape[:4]
        n = cov.shape[0]
        picked = np.arange(n_out)[outputs]
        d = picked.size
        live = self.steps >= 0
        at = np.maximum(self.steps, 0)
        root = covariance_root(cov)  # (N, k, 3, 3)
        white = np.einsum("mpybi,mpbij->mpybj", self.jac[:, :, picked], root[at])
        white = np.where(live[:, :, None, None, None], white, 0.0)  # (M, P, d, k, 3)
        rows = np.arange(m)[:, None, None, None, None] * d + np.arange(d)[None, None, :, None, None]
        cols = at[:, :, None, None, None] * (3 * k) + np.arange(3 * k).reshape(1, 1, 1, k, 3)
        rows, cols = np.broadcast_arrays(rows, cols)
        a = sparse.csr_matrix(
            (white.ravel(), (rows.ravel(), cols.ravel())), shape=(m * d, n * 3 * k)
        )  # duplicates (a step in two parts of one target) are summed
        return a


def linear_covariance(
    chain: PoseChain,
    centres_mm: npt.ArrayLike,
    centre_cov_mm2: npt.ArrayLike,
    step_mm: float = DEFAULT_STEP_MM,
) -> FloatArray:
    """Covariance (M, 12, 12) of every target's outputs by linear propagation.

    ``target_jacobian(chain, centres_mm, step_mm).covariance(centre_cov_mm2)``: see
    :func:`target_jacobian`.

    Parameters
    ----------
    chain : PoseChain
    centres_mm : array_like, shape (N, k, 3)
        The measured centres.
    centre_cov_mm2 : array_like, shape (N, k, 3, 3)
        Covariance of each centre (finite; independent centres).
    step_mm : float
        Central-difference step on each coordinate.

    Returns
    -------
    ndarray, shape (M, 12, 12)
    """
    return target_jacobian(chain, centres_mm, step_mm).covariance(centre_cov_mm2)


def target_jacobian(
    chain: PoseChain,
    centres_mm: npt.ArrayLike,
    step_mm: float = DEFAULT_STEP_MM,
) -> TargetJacobian:
    """Jacobian of every target's outputs by the centres of the steps it depends on.

    The Jacobian of target S_i's outputs by the centres of the (at most) five
    steps they depend on (O, R0, S_i, its references before and after) is put
    together by the chain rule, vectorized over the steps:

    1. ``dX_j/dc_j`` and ``dX_j/dc_O``: the pose of every step j relative to O by
       its own centres and by O's, from the registration's analytic derivative
       (:meth:`PoseChain.pose_derivatives`; were central differences, ``2 x 3k``
       registrations of every step: the same to about 1e-9 relative);
    2. ``dq_j = J(X_j) dX_j`` with the IGM's analytic Jacobian ``J``;
    3. the growth at the references and its scaling to the target, leg by leg:
       ``q_corr = q_S - g(G, q_R0, q_S)`` with
       ``G = (1 - w)(q_B - q_R0) + w (q_A - q_R0)``; the partial derivatives of
       ``q_corr`` by ``G``, ``q_R0`` and ``q_S`` are diagonal (central differences);
    4. ``dX_corr = J(X_corr)^-1 dq_corr`` (the FGM inverts the IGM), ``X_corr`` the FGM
       of the corrected legs by Newton from the chain's corrected poses
       (:meth:`~hexatherm.core.hexapod.Hexapod.fgm_near`, which gives ``J`` too).

    A step that plays two parts for a target (R0 as the reference before the
    first targets) gets the sum of both Jacobians. The result equals the
    Jacobian of :class:`PoseChain` by brute force (a test checks it).

    Parameters
    ----------
    chain : PoseChain
    centres_mm : array_like, shape (N, k, 3)
        The measured centres.
    step_mm : float
        Central-difference step of the correction's leg-by-leg derivatives (mm).

    Returns
    -------
    TargetJacobian
    """
    c = np.asarray(centres_mm, dtype=float)
    n, k = c.shape[:2]
    plan, hexapod = chain.plan, chain.hexapod
    targets, origin = plan.target_indices, plan.origin_index
    m = targets.size
    if m == 0:
        return TargetJacobian(
            np.zeros((0, 5, OUTPUTS_PER_TARGET, k, 3)), np.zeros((0, 5), dtype=np.intp)
        )
    legs = hexapod.legs
    if legs is None:
        raise ValueError("the hexapod has no leg model")
    # 1. poses relative to O and their derivatives by each step's own centres and by O's
    pose, dpose_own, dpose_origin = chain.pose_derivatives(c)
    dpose_own[origin] = 0.0  # O's pose relative to itself is zero whatever its centres
    dpose_origin[origin] = 0.0
    jac_igm = hexapod.jacobian(pose)
    dq_own, dq_origin = jac_igm @ dpose_own, jac_igm @ dpose_origin  # (N, 6, 3k)
    # 3. the correction's leg-by-leg partial derivatives, (M, 6) each
    q = hexapod.igm(pose)
    r0 = plan.reference_indices[0]
    before, after, w_after = chain.before_index, chain.after_index, chain.weight_after
    if chain.growth_weights is None:
        growth = interpolated_growth(q, q[r0], before, after, w_after)
    else:
        growth = np.einsum("mln,nl->ml", chain.growth_weights, q) - q[r0]
    q_s = q[targets]

    def q_corr(g: FloatArray, q_r0: FloatArray, qs: FloatArray) -> FloatArray:
        return np.asarray(qs - target_growth(legs, g, q_r0, qs), dtype=float)

    h = step_mm
    q_r0 = np.broadcast_to(q[r0], q_s.shape)
    d_growth = (q_corr(growth + h, q_r0, q_s) - q_corr(growth - h, q_r0, q_s)) / (2 * h)
    d_r0 = (q_corr(growth, q_r0 + h, q_s) - q_corr(growth, q_r0 - h, q_s)) / (2 * h)
    d_s = (q_corr(growth, q_r0, q_s + h) - q_corr(growth, q_r0, q_s - h)) / (2 * h)
    # 4. the corrected poses (relative to O as measured) and the IGM's Jacobian there:
    # the FGM of the corrected legs, from the chain's corrected poses brought back there
    start = chain.fgm_start()
    unshifted, jac_fgm = hexapod.fgm_near(
        q_corr(growth, q_r0, q_s), pose[targets] if start is None else start
    )
    jac_fgm_inv = np.asarray(np.linalg.inv(jac_fgm), float)
    if chain.origin_shift is not None:
        # the corrected poses expressed in O carried to R0's state: a fixed rigid shift
        by_pose = shifted_pose_derivative(chain.origin_shift, unshifted, hexapod.convention)
        jac_fgm_inv = by_pose @ jac_fgm_inv
    if chain.growth_weights is not None:
        return _smooth_jacobian(
            chain,
            dpose_own,
            dpose_origin,
            dq_own,
            dq_origin,
            d_growth,
            d_r0,
            d_s,
            jac_fgm_inv,
            k,
        )
    w_before = np.where(before >= 0, 1.0 - w_after, 0.0)[:, None]
    w_after_used = np.where(after >= 0, w_after, 0.0)[:, None]
    # coefficient of dq of each part: O (none: through the others), R0, S, before, after
    coef = np.stack(
        [
            np.zeros_like(d_s),
            d_r0 - d_growth * (w_before + w_after_used),
            d_s,
            d_growth * w_before,
            d_growth * w_after_used,
        ],
        axis=1,
    )  # (M, 5, 6)
    steps = np.column_stack([np.full(m, origin), np.full(m, r0), targets, before, after]).astype(
        np.intp
    )  # (M, 5)
    used = (steps >= 0) & (np.arange(5) != 0)
    at = np.maximum(steps, 0)
    # 4. dq_corr and the outputs by each part's centres: (M, 5, 12, 3k)
    dq_corr = dq_own[at]  # one array, scaled and cleared in place (were three of its size)
    dq_corr *= coef[..., None]
    dq_corr[~used] = 0.0
    dq_corr[:, 0] = np.einsum("mpl,mplj->mlj", np.where(used[..., None], coef, 0.0), dq_origin[at])
    jac = np.zeros((m, 5, OUTPUTS_PER_TARGET, 3 * k))
    jac[:, 0, :6] = dpose_origin[targets]
    jac[:, 2, :6] = dpose_own[targets]
    jac[:, :, 6:] = jac_fgm_inv[:, None] @ dq_corr
    # a step in two parts: one Jacobian, the sum
    for part in range(1, 5):
        for earlier in range(part):
            same = (steps[:, part] == steps[:, earlier]) & (steps[:, part] >= 0)
            jac[same, earlier] += jac[same, part]
            jac[same, part] = 0.0
            steps[same, part] = -1
    jac[steps < 0] = 0.0
    return TargetJacobian(jac.reshape(m, 5, OUTPUTS_PER_TARGET, k, 3), steps)


def _smooth_jacobian(
    chain: PoseChain,
    dpose_own: FloatArray,
    dpose_origin: FloatArray,
    dq_own: FloatArray,
    dq_origin: FloatArray,
    d_growth: FloatArray,
    d_r0: FloatArray,
    d_s: FloatArray,
    jac_fgm_inv: FloatArray,
    k: int,
) -> TargetJacobian:
    """The Jacobian when the growth is the smooth fit over every reference: parts O, the
    target, then every reference (R0 first), each with its weight per leg."""
    plan = chain.plan
    assert chain.growth_weights is not None
    targets, origin, refs = plan.target_indices, plan.origin_index, plan.reference_indices
    m, n_refs = targets.size, refs.size
    w = chain.growth_weights[:, :, refs]  # (M, 6, R)
    # coefficient of dq of each reference per leg; R0 also through q_R0 (rows of w sum to 1)
    coef = d_growth[:, :, None] * w  # (M, 6, R)
    coef[:, :, 0] += d_r0 - d_growth
    parts = 2 + n_refs
    steps = np.empty((m, parts), dtype=np.intp)
    steps[:, 0], steps[:, 1], steps[:, 2:] = origin, targets, refs
    dq_corr = np.zeros((m, parts, 6, 3 * k))
    dq_corr[:, 1] = d_s[:, :, None] * dq_own[targets]
    dq_corr[:, 2:] = np.moveaxis(coef, 2, 1)[..., None] * dq_own[refs][None]
    # O through every step it places: the target and every reference
    dq_corr[:, 0] = d_s[:, :, None] * dq_origin[targets] + np.einsum(
        "mlr,rlj->mlj", coef, dq_origin[refs]
    )
    jac = np.zeros((m, parts, OUTPUTS_PER_TARGET, 3 * k))
    jac[:, 0, :6] = dpose_origin[targets]
    jac[:, 1, :6] = dpose_own[targets]
    jac[:, :, 6:] = jac_fgm_inv[:, None] @ dq_corr
    return TargetJacobian(jac.reshape(m, parts, OUTPUTS_PER_TARGET, k, 3), steps, (0, 2))


def monte_carlo_covariance(
    chain: PoseChain,
    centres_mm: npt.ArrayLike,
    centre_cov_mm2: npt.ArrayLike,
    draws: int,
    rng: np.random.Generator,
    batch: int = DEFAULT_BATCH,
    progress: Callable[[int, int], None] | None = None,
    sample: CentreSampler | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Covariance (M, 12, 12) and mean (M, 12) of the outputs over Monte Carlo draws.

    Every centre is drawn from the normal distribution with its covariance, or
    by ``sample(rng, size)`` when given (centres (size, N, k, 3), e.g. refitted to
    drawn probed points); the outputs' deviations from the chain's value at the
    measured centres (angles wrapped) give the sample covariance (``draws - 1``
    degrees of freedom). The draws are evaluated ``batch`` at a time;
    ``progress(done, draws)``, when given, is called after each batch.
    """
    if draws < 2:
        raise ValueError(f"Monte Carlo needs at least 2 draws, got {draws}")
    c = np.asarray(centres_mm, dtype=float)
    root = covariance_root(centre_cov_mm2)  # (N, k, 3, 3)
    nominal = chain(c)
    total = np.zeros(nominal.shape)
    outer = np.zeros(nominal.shape + (OUTPUTS_PER_TARGET,))
    done = 0
    while done < draws:
        size = min(batch, draws - done)
        drawn = draw_centres(c, root, rng, size) if sample is None else sample(rng, size)
        d = output_difference(chain(drawn), nominal)  # (size, M, 12)
        total += d.sum(axis=0)
        outer += np.einsum("dmy,dmz->myz", d, d)
        done += size
        if progress is not None:
            progress(done, draws)
    mean = total / draws
    covariance = (outer - draws * np.einsum("my,mz->myz", mean, mean)) / (draws - 1)
    return covariance, nominal + mean


def draw_centres(
    centres_mm: FloatArray, root: FloatArray, rng: np.random.Generator, size: int
) -> FloatArray:
    """``size`` draws (size, N, k, 3) of normal centres: mean ``centres_mm`` (N, k, 3),
    covariance ``root root^T`` (``root`` from :func:`covariance_root`)."""
    z = rng.standard_normal((size,) + centres_mm.shape)
    return centres_mm + np.einsum("nkij,dnkj->dnki", root, z)


def covariance_root(cov_mm2: npt.ArrayLike) -> FloatArray:
    """A square root ``L`` (``L L^T = cov``) of symmetric positive semi-definite matrices."""
    cov = np.asarray(cov_mm2, dtype=float)
    values, vectors = np.linalg.eigh((cov + np.swapaxes(cov, -1, -2)) / 2)
    return vectors * np.sqrt(np.clip(values, 0.0, None))[..., None, :]


def cap_centre_covariance(
    n_points: int, cap_angle_deg: float, sigma_mm: float, free_radius: bool = True
) -> FloatArray:
    """Covariance (3, 3) of a sphere fit's centre for points spread over an upper cap.

    The points are ``n_points`` directions over the cap around +Z (the
    pattern of :func:`hexatherm.core.touch.cap_directions`), each with noise
    ``sigma_mm`` along the normal: ``sigma^2 (J^T J)^-1`` of the geometric fit,
    the radius a free parameter (or fixed).
    """
    dirs = cap_directions(n_points, cap_angle_deg)
    jac = np.column_stack([-dirs, -np.ones(n_points)]) if free_radius else -dirs
    inv = np.linalg.inv(jac.T @ jac)
    return sigma_mm**2 * inv[:3, :3]


def rigid_residual_projector(centres_mm: npt.ArrayLike) -> FloatArray:
    """Projector (N, 3k, 3k) onto what an unweighted rigid registration leaves as residual.

    For a step whose k ball centres sit at ``c_j`` (mm), the rigid motions move them
    along the columns of ``A`` (3k, 6): ``[I, -[c_j - c_mean]x]`` for ball j. The
    residuals of a least-squares rigid fit are ``P e`` with ``P = I - A A^+``, ``e`` the
    centres' errors; so ``E|r|^2 = tr(P Sigma)`` for errors of covariance ``Sigma``.
    Three balls leave ``3k - 6 = 3`` residual freedoms, all in the balls' plane: no
    residual sees an error normal to that plane.

    >>> import numpy as np
    >>> P = rigid_residual_projector([[[0, 90, 30], [-73.6, -42.5, 30], [82.3, -47.5, 30]]])
    >>> round(float(np.trace(P[0])), 9), bool(np.allclose(P[0] @ P[0], P[0]))
    (3.0, True)
    >>> z = np.kron(np.eye(3), np.diag([0.0, 0.0, 1.0]))   # errors along z only
    >>> abs(float(np.trace(P[0] @ z))) < 1e-12
    True
    """
    c = np.asarray(centres_mm, dtype=float)
    if c.ndim != 3 or c.shape[-1] != 3 or c.shape[1] < 3:
        raise ValueError(f"need centres of shape (N, k >= 3, 3), got {c.shape}")
    n, k = c.shape[:2]
    d = c - c.mean(axis=1, keepdims=True)
    a = np.zeros((n, k, 3, 6))
    a[..., :3] = np.eye(3)
    # -[d]x: the derivative of a small rotation w applied to d is w x d = -[d]x w
    a[..., 0, 4], a[..., 0, 5] = d[..., 2], -d[..., 1]
    a[..., 1, 3], a[..., 1, 5] = -d[..., 2], d[..., 0]
    a[..., 2, 3], a[..., 2, 4] = d[..., 1], -d[..., 0]
    motions = a.reshape(n, 3 * k, 6)
    return np.eye(3 * k) - motions @ np.linalg.pinv(motions)


def residual_scale(
    residuals_mm: npt.ArrayLike, centres_mm: npt.ArrayLike, shape_cov: npt.ArrayLike
) -> tuple[float, float]:
    """The scale ``c`` of centre covariances ``c * shape_cov`` that the residuals show.

    The unweighted registration residuals of N steps hold ``E sum |r|^2 =
    c * sum_steps tr(P_step Sigma_step)`` (:func:`rigid_residual_projector`,
    ``Sigma_step`` block-diagonal of ``shape_cov``); solved for ``c``. Also returned,
    ``seen``: how much of the shape the residuals see, ``sum tr(P Sigma)`` over what
    isotropic errors of the same total variance would give (``(3k - 6)/(3k) tr Sigma``):
    1 for isotropic errors, well below 1 when the shape's largest variance lies where no
    residual looks (the normal of three coplanar balls). Then the scale of that part
    rests on the assumed shape alone.

    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> c = np.tile([[[0, 90, 30], [-73.6, -42.5, 30], [82.3, -47.5, 30]]], (4000, 1, 1))
    >>> P = rigid_residual_projector(c)
    >>> e = rng.normal(size=(4000, 9)) * np.tile([1e-3, 1e-3, 3e-3], 3)
    >>> r = np.einsum("nij,nj->ni", P, e).reshape(4000, 3, 3)
    >>> scale, seen = residual_scale(r, c, np.diag([1.0, 1.0, 9.0]) * 1e-6)
    >>> abs(scale - 1.0) < 0.03, round(seen, 2)
    (True, 0.27)
    """
    r = np.asarray(residuals_mm, dtype=float)
    c = np.asarray(centres_mm, dtype=float)
    shape = np.asarray(shape_cov, dtype=float)
    if r.shape != c.shape:
        raise ValueError(f"residuals {r.shape} and centres {c.shape} differ in shape")
    n, k = c.shape[:2]
    block = np.broadcast_to(shape, (n, k, 3, 3))
    sigma = np.zeros((n, 3 * k, 3 * k))
    for j in range(k):
        sigma[:, 3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = block[:, j]
    proj = rigid_residual_projector(c)
    expected = float(np.einsum("nij,nji->", proj, sigma))
    if not expected > 0:
        return float("nan"), 0.0
    scale = float((r**2).sum()) / expected
    isotropic = (3 * k - 6) / (3 * k) * float(np.trace(sigma, axis1=1, axis2=2).sum())
    return scale, expected / isotropic


def reference_scatter(
    times_s: npt.ArrayLike, values: npt.ArrayLike, weights: npt.ArrayLike | None = None
) -> tuple[float, int]:
    """Type A variance of repeated measurements that drift smoothly: ``(s^2, dof)``.

    Each inner measurement is compared with the straight line in time through its two
    neighbours (the linear interpolation the correction itself relies on):
    ``e_i = v_i - ((1 - f) v_(i-1) + f v_(i+1))``, ``f`` the time fraction. For noise of
    variance ``s^2 / w`` (``w`` the weights: a measurement averaging n repeats weighs
    n), ``E e_i^2 = s^2 (1/w_i + (1 - f)^2 / w_(i-1) + f^2 / w_(i+1))``; ``s^2`` is the
    mean of ``e_i^2`` over that factor, pooled over the columns of ``values``, with
    ``dof = (n - 2) * columns`` (neighbouring differences share measurements: unbiased,
    with somewhat fewer effective degrees of freedom). A drift that bends between two
    neighbours adds to ``s^2``: the estimate errs on the safe side. A measurement whose
    two neighbours share one time is left out (no line through them; ``dof`` counts the
    rest). ``(nan, 0)`` for fewer than 3 measurements, or none left.

    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> t = np.sort(rng.uniform(0, 3600, 400))
    >>> v = 5e-3 * np.sin(t / 3600)[:, None] + rng.normal(scale=1e-3, size=(400, 3))
    >>> s2, dof = reference_scatter(t, v)
    >>> bool(abs(np.sqrt(s2) * 1e3 - 1.0) < 0.05), dof
    (True, 1194)
    >>> reference_scatter(np.zeros(5), np.ones((5, 3)))
    (nan, 0)
    """
    t = np.asarray(times_s, dtype=float)
    v = np.asarray(values, dtype=float)
    v = v.reshape(len(t), -1)
    w = np.ones(len(t)) if weights is None else np.asarray(weights, dtype=float)
    if len(t) < 3:
        return float("nan"), 0
    keep = np.flatnonzero(t[2:] - t[:-2] > 0)  # neighbours at one time draw no line
    if not keep.size:
        return float("nan"), 0
    # every measurement kept (the usual case: a log's times all differ): the three as
    # views, not gathered (a thermocouple log's 283,000 rows x 6 legs, twice a run)
    whole = keep.size == len(t) - 2
    before, mid, after = (
        (slice(0, -2), slice(1, -1), slice(2, None)) if whole else (keep, keep + 1, keep + 2)
    )
    f = (t[mid] - t[before]) / (t[after] - t[before])
    e = v[mid] - ((1 - f)[:, None] * v[before] + f[:, None] * v[after])
    factor = 1 / w[mid] + (1 - f) ** 2 / w[before] + f**2 / w[after]
    return float((e**2 / factor[:, None]).mean()), int(e.size)


#: chance below which the references' height scatter is held too small to be the CMM's noise
HEIGHT_FLOOR_P = 1e-3


def cap_height_floor(dof: int, shape: FloatArray) -> float:
    """Smallest plausible z scale of the cap ``shape`` (3, 3) from repeated ball heights.

    A free-radius sphere fit to points whose normals ``n`` point up (``n_z`` in [0, 1]),
    noise along the normals, pattern symmetric in x and y, has centre information
    ``var(n_z)`` per point along z (the radius takes the mean) and ``(1 - E n_z^2) / 2``
    across; as ``n_z^2 <= n_z``, ``var(n_z) <= a (1 - a)`` with ``a = E n_z^2``, so the
    centre's z variance is at least ``1 / (2a) >= 1/2`` of its lateral one, whatever the
    touch pattern. A Type A variance of ``dof`` degrees of freedom falls below its
    expectation times ``chi2.ppf(p, dof) / dof`` with chance ``p``
    (:data:`HEIGHT_FLOOR_P`): the returned ratio (z variance over ``shape``'s) is half the
    shape's lateral variance over its z variance, times that factor. (A fixed-radius fit
    over a small cap can be surer along z: its centres then get the assumed cap, which
    claims more.)

    >>> import numpy as np
    >>> round(cap_height_floor(27, np.diag([1.0, 1.0, 2.0])), 3)
    0.091
    """
    from scipy.special import chdtri  # not scipy.stats: 0.35 s to import (docs/speed.md)

    lateral = 0.5 * (shape[0, 0] + shape[1, 1])
    quantile = chdtri(dof, 1.0 - HEIGHT_FLOOR_P)  # chi2.ppf(HEIGHT_FLOOR_P, dof)
    return float(0.5 * lateral / shape[2, 2] * quantile / dof)
