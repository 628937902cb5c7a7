"""Uncertainty of the conventional and corrected poses, from the ball centres' covariances.

The measurand of target S_i is the 12-vector ``[conventional pose, corrected
pose]`` (mm, deg). It is a function of the measured ball centres of every
step, ``y = f(c)`` with ``c`` of shape (N, k, 3): each step's frame by the
rigid registration, its pose relative to O, the IGM, the growth at the
references, its scaling to S_i and the FGM (:class:`PoseChain`, the chain of
:func:`hexatherm.core.method.correct` vectorized over many sets of centres).
The times, the registration weights and the hexapod model are taken as exact;
the centres are independent from ball to ball and step to step, each with its
own 3x3 covariance.

* **Linear propagation** (GUM): ``U_y = J U_c J^T`` with the Jacobian ``J``
  by central differences (:func:`linear_covariance`). Target S_i depends on at
  most five steps: O, R0, S_i and its references before and after. The steps
  are coloured so that no target depends on two steps of one colour
  (:func:`colour_steps`: usually O; R0; the targets; every other reference;
  the others); perturbing one coordinate of all steps of a colour at once then
  gives the derivatives of every target by that coordinate of the one step it
  depends on. That is ``2 x colours x 3k`` evaluations of the vectorized chain,
  whatever the number of targets.
* **Monte Carlo** (GUM Supplement 1): the centres are drawn from
  ``N(c, U_c)`` with a seeded generator, the chain is run on every draw and
  the covariance of the outputs is the estimate (:func:`monte_carlo_covariance`).

>>> import numpy as np
>>> cov = cap_centre_covariance(25, 70.0, 1e-3)
>>> u_um = np.sqrt(np.diag(cov)) * 1e3
>>> bool(u_um[2] > u_um[0])  # a cap seen from above: z is the weak direction
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.registration import register
from hexatherm.core.twin import cap_directions

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

#: outputs per target: conventional pose then corrected pose
OUTPUTS_PER_TARGET = 12
#: central-difference step on a centre coordinate, mm
DEFAULT_STEP_MM = 1e-3
#: Monte Carlo draws evaluated at once
DEFAULT_BATCH = 256


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
        :class:`~hexatherm.core.method.Correction`.
    weight_after : ndarray, shape (M,)
    weights : ndarray, shape (N, k), optional
        Registration weights.
    initial_poses : ndarray, shape (M, 6), optional
        Start of the FGM iterations (the corrected poses of the nominal centres).
    """

    hexapod: Hexapod
    plan: Plan
    balls_mm: FloatArray
    before_index: IntArray
    after_index: IntArray
    weight_after: FloatArray
    weights: FloatArray | None = None
    initial_poses: FloatArray | None = None

    def __call__(self, centres_mm: npt.ArrayLike) -> FloatArray:
        """Outputs (..., M, 12) for centres (..., N, k, 3)."""
        c = np.asarray(centres_mm, dtype=float)
        lead, (n, k) = c.shape[:-3], c.shape[-3:-1]
        flat = c.reshape(-1, n, k, 3)
        b = flat.shape[0]
        w = None if self.weights is None else np.broadcast_to(self.weights, (b, n, k)).reshape(
            -1, k)
        frames = register(flat.reshape(-1, k, 3), self.balls_mm, w).platform2cmm.reshape(
            b, n, 4, 4)
        p2o = invert_transform(frames[:, self.plan.origin_index])[:, None] @ frames
        pose = pose_from_transform(p2o, self.hexapod.convention)  # (b, n, 6)
        targets, refs = self.plan.target_indices, self.plan.reference_indices
        m = targets.size
        if m == 0:
            return np.zeros(lead + (0, OUTPUTS_PER_TARGET))
        q = self.hexapod.igm(pose.reshape(-1, 6)).reshape(b, n, 6)
        q_r0 = q[:, refs[0]][:, None]  # (b, 1, 6)
        growth_r = q - q_r0
        before, after, w_after = self.before_index, self.after_index, self.weight_after
        g_before = np.where((before >= 0)[:, None], growth_r[:, np.maximum(before, 0)], 0.0)
        g_after = np.where((after >= 0)[:, None], growth_r[:, np.maximum(after, 0)], 0.0)
        reference_growth = (1.0 - w_after)[:, None] * g_before + w_after[:, None] * g_after
        legs = self.hexapod.legs
        if legs is None:
            raise ValueError("the hexapod has no leg model")
        q_s = q[:, targets]
        growth_s = legs.scale_growth(reference_growth, q_r0, q_s)
        growth_s = legs.scale_growth(reference_growth, q_r0, q_s - growth_s)
        start = pose[:, targets] if self.initial_poses is None else np.broadcast_to(
            self.initial_poses, (b, m, 6))
        corrected = self.hexapod.fgm((q_s - growth_s).reshape(-1, 6),
                                     initial_poses=start.reshape(-1, 6)).reshape(b, m, 6)
        out = np.concatenate([pose[:, targets], corrected], axis=-1)
        return out.reshape(lead + (m, OUTPUTS_PER_TARGET))


def output_difference(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """``a - b`` for outputs (..., 12), angles wrapped into [-180, 180) deg."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    for start in (3, 9):
        d[..., start:start + 3] = (d[..., start:start + 3] + 180.0) % 360.0 - 180.0
    return d


def dependencies(plan: Plan, before_index: npt.ArrayLike, after_index: npt.ArrayLike
                 ) -> IntArray:
    """The steps each target's outputs depend on, (M, 5): O, R0, S, before, after.

    -1 marks a reference that is not used and a step already named earlier in
    the row (e.g. R0 as the reference before the first target).
    """
    targets, refs = plan.target_indices, plan.reference_indices
    m = targets.size
    r0 = refs[0] if refs.size else -1
    deps = np.column_stack([np.full(m, plan.origin_index), np.full(m, r0), targets,
                            np.asarray(before_index, dtype=np.intp).reshape(m),
                            np.asarray(after_index, dtype=np.intp).reshape(m)]).astype(np.intp)
    for j in range(1, deps.shape[1]):
        repeated = (deps[:, j:j + 1] == deps[:, :j]).any(axis=1)
        deps[repeated, j] = -1
    return deps


def colour_steps(deps: npt.ArrayLike, n_steps: int) -> IntArray:
    """Colour the steps so that no row of ``deps`` holds two steps of one colour.

    Greedy colouring of the graph joining the steps of every row, in step
    order; steps no output depends on get -1.

    >>> colour_steps([[0, 1, 2, -1, 3], [0, 1, 4, 3, 5], [0, 1, 6, 5, 7]], 8).tolist()
    [0, 1, 2, 3, 2, 4, 2, 3]
    """
    rows = np.asarray(deps, dtype=np.intp)
    neighbours: list[set[int]] = [set() for _ in range(n_steps)]
    for row in rows:
        members = [int(s) for s in row if s >= 0]
        for s in members:
            neighbours[s].update(members)
    colour = np.full(n_steps, -1, dtype=np.intp)
    for s in range(n_steps):
        if not neighbours[s]:
            continue
        taken = {int(colour[t]) for t in neighbours[s] if t != s}
        colour[s] = next(c for c in range(n_steps + 1) if c not in taken)
    return colour


def linear_covariance(
    chain: PoseChain,
    centres_mm: npt.ArrayLike,
    centre_cov_mm2: npt.ArrayLike,
    step_mm: float = DEFAULT_STEP_MM,
) -> FloatArray:
    """Covariance (M, 12, 12) of every target's outputs by linear propagation.

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
    c = np.asarray(centres_mm, dtype=float)
    cov = np.asarray(centre_cov_mm2, dtype=float)
    n, k = c.shape[:2]
    deps = dependencies(chain.plan, chain.before_index, chain.after_index)
    m = deps.shape[0]
    if m == 0:
        return np.zeros((0, OUTPUTS_PER_TARGET, OUTPUTS_PER_TARGET))
    colour = colour_steps(deps, n)
    n_colours = int(colour.max()) + 1
    # perturbed centres: (colour, ball, axis, sign, N, k, 3)
    pert = np.broadcast_to(c, (n_colours, k, 3, 2, n, k, 3)).copy()
    for col in range(n_colours):
        steps = colour == col
        for ball in range(k):
            for axis in range(3):
                pert[col, ball, axis, 0, steps, ball, axis] += step_mm
                pert[col, ball, axis, 1, steps, ball, axis] -= step_mm
    out = chain(pert)  # (C, k, 3, 2, M, 12)
    jac = output_difference(out[:, :, :, 0], out[:, :, :, 1]) / (2 * step_mm)  # (C, k, 3, M, 12)
    # the step of each colour each target depends on
    step_of = np.full((n_colours, m), -1, dtype=np.intp)
    for j in range(deps.shape[1]):
        ok = deps[:, j] >= 0
        step_of[colour[deps[ok, j]], np.flatnonzero(ok)] = deps[ok, j]
    gathered = np.where((step_of >= 0)[..., None, None, None],
                        cov[np.maximum(step_of, 0)], 0.0)  # (C, M, k, 3, 3)
    return np.einsum("cbamy,cmbae,cbemz->myz", jac, gathered, jac, optimize=True)


def monte_carlo_covariance(
    chain: PoseChain,
    centres_mm: npt.ArrayLike,
    centre_cov_mm2: npt.ArrayLike,
    draws: int,
    rng: np.random.Generator,
    batch: int = DEFAULT_BATCH,
) -> tuple[FloatArray, FloatArray]:
    """Covariance (M, 12, 12) and mean (M, 12) of the outputs over Monte Carlo draws.

    Every centre is drawn from the normal distribution with its covariance;
    the outputs' deviations from the chain's value at the measured centres
    (angles wrapped) give the sample covariance (``draws - 1`` degrees of freedom).
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
        z = rng.standard_normal((size,) + c.shape)
        sample = c + np.einsum("nkij,dnkj->dnki", root, z)
        d = output_difference(chain(sample), nominal)  # (size, M, 12)
        total += d.sum(axis=0)
        outer += np.einsum("dmy,dmz->myz", d, d)
        done += size
    mean = total / draws
    covariance = (outer - draws * np.einsum("my,mz->myz", mean, mean)) / (draws - 1)
    return covariance, nominal + mean


def covariance_root(cov_mm2: npt.ArrayLike) -> FloatArray:
    """A square root ``L`` (``L L^T = cov``) of symmetric positive semi-definite matrices."""
    cov = np.asarray(cov_mm2, dtype=float)
    values, vectors = np.linalg.eigh((cov + np.swapaxes(cov, -1, -2)) / 2)
    return vectors * np.sqrt(np.clip(values, 0.0, None))[..., None, :]


def cap_centre_covariance(n_points: int, cap_angle_deg: float, sigma_mm: float,
                          free_radius: bool = True) -> FloatArray:
    """Covariance (3, 3) of a sphere fit's centre for points spread over an upper cap.

    The points are ``n_points`` directions over the cap around +Z (the
    pattern of :func:`hexatherm.core.twin.cap_directions`), each with noise
    ``sigma_mm`` along the normal: ``sigma^2 (J^T J)^-1`` of the geometric fit,
    the radius a free parameter (or fixed).
    """
    dirs = cap_directions(n_points, cap_angle_deg)
    jac = np.column_stack([-dirs, -np.ones(n_points)]) if free_radius else -dirs
    inv = np.linalg.inv(jac.T @ jac)
    return sigma_mm**2 * inv[:3, :3]


def pooled_registration_variance(residuals_mm: npt.ArrayLike) -> float:
    """Variance (mm^2) per coordinate of a centre from unweighted registration residuals.

    Each step of k balls leaves ``3k - 6`` degrees of freedom after the rigid
    fit: ``s^2 = sum |r|^2 / (N (3k - 6))``.

    >>> import numpy as np
    >>> pooled_registration_variance(np.full((2, 3, 3), 0.001))
    3e-06
    """
    r = np.asarray(residuals_mm, dtype=float)
    n, k = r.shape[:2]
    dof = n * (3 * k - 6)
    return float((r**2).sum() / dof) if dof > 0 else float("nan")
