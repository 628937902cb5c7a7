"""What the poses' covariance holds beyond the targets' Jacobian of the centres, made once
for :func:`~hexatherm.workflows.process.uncertainty.pose_uncertainty` (``poses.csv``'s u,
``covariance.csv``) and a calibration's weights
(:func:`~hexatherm.workflows.process.uncertainty.joint_pose_covariance`), so that both
hold the same terms: O's carry to R0's thermal state (common to every target; without a
log its noise in the Jacobian), the smooth fit's own error and the straight line's own
error between references (each shared by the targets of one interval: the smooth fit's
with a log, and past the last reference without one).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.curvature import CurvatureError
from hexatherm.core.propagation import PoseChain, TargetJacobian, target_jacobian
from hexatherm.core.smoothbias import leg_derivatives, own_leg_covariance
from hexatherm.typing import FloatArray, IntArray
from hexatherm.workflows.process.carryerror import CarryError, carry_error
from hexatherm.workflows.process.pipeline import ProcessResult
from hexatherm.workflows.process.smootherror import SmoothExcess, curvature_excess, smooth_excess

if TYPE_CHECKING:  # the calibration's weights (and scipy.sparse): imported when used
    from hexatherm.core.calibration.weights import BandedCovariance

__all__ = ["ErrorTerms", "error_terms", "structured_covariance"]


@dataclass(frozen=True)
class ErrorTerms:
    """What the poses' covariance holds beyond the targets' Jacobian of the centres: its
    parts, made once for :func:`~hexatherm.workflows.process.uncertainty.pose_uncertainty`
    and the calibration's weights
    (:func:`~hexatherm.workflows.process.uncertainty.joint_pose_covariance`), so that both
    hold the same.

    Attributes
    ----------
    jacobian : TargetJacobian
        The targets' outputs by the centres (O's carry held fixed).
    full : TargetJacobian
        The same with O's carry as a function of the centres it reads (without a log;
        else ``jacobian``).
    carried : CarryError, optional
        The carry of O and R0 to R0's thermal state beyond the propagation (common).
    excess : SmoothExcess, optional
        The smooth fit's own error on each corrected pose, and its part shared by the
        targets of one interval (with a log; without, past the last reference).
    curved : (ndarray (M, 6, K), CurvatureError), optional
        The straight line's own error of each corrected pose, as vectors ``F`` (mm,
        deg; K = 1, or 7 where the legs' histories differ: their own parts leg by leg):
        ``F F^T`` its own, ``F_a F_b^T`` between two targets of one interval.
    """

    jacobian: TargetJacobian
    full: TargetJacobian
    carried: CarryError | None
    excess: SmoothExcess | None
    curved: tuple[FloatArray, CurvatureError] | None

    def own_blocks(self) -> FloatArray | None:
        """Each corrected pose's covariance (M, 6, 6) from the interpolation's own error
        (the smooth fit's, the straight line's); None: none."""
        out = None if self.excess is None else self.excess.cov
        if self.curved is not None:
            f = self.curved[0]
            out = np.einsum("mpk,mqk->mpq", f, f) + (0.0 if out is None else out)
        return out

    def shared(self) -> list[tuple[IntArray, IntArray, FloatArray]]:
        """The interpolation's own errors shared within an interval (the straight line's,
        the smooth fit's): for each, the pairs of distinct targets of one interval
        (``a``, ``b``: both orders) and the targets' error vectors ``V`` (M, 6, K):
        ``V_a V_b^T`` their covariance."""
        terms = []
        if self.curved is not None:
            terms.append((self.curved[0], self.curved[1].interval))
        if self.excess is not None:
            terms.append((self.excess.vectors, self.excess.interval))
        out = []
        for vectors, interval in terms:
            assert interval is not None
            a, b = interval_pairs(interval)
            out.append((np.r_[a, b], np.r_[b, a], vectors))
        return out

    def between_targets(self) -> FloatArray:
        """The corrected outputs' covariance (6, M, M) between targets from the
        interpolation's own error (the diagonal: :meth:`own_blocks`')."""
        own = self.own_blocks()
        assert own is not None
        m = own.shape[0]
        out = np.zeros((6, m, m))
        out[:, np.arange(m), np.arange(m)] = np.diagonal(own, axis1=1, axis2=2).T
        for a, b, v in self.shared():
            out[:, a, b] += np.einsum("pyk,pyk->yp", v[a], v[b])
        return out

    def joint(self, outputs: slice) -> FloatArray:
        """The covariance (M d, M d) of all targets' ``outputs`` together beyond the
        propagation's (every term between targets and components)."""
        m = self.jacobian.jac.shape[0]
        d = len(range(12)[outputs])
        out = np.zeros((m * d, m * d))
        if self.carried is not None:
            factor = self.carried.factor[:, outputs].reshape(m * d, -1)
            out += factor @ factor.T
        if outputs != slice(6, 12):
            return out
        blocks = out.reshape(m, 6, m, 6)  # a view: target, output, target, output
        own = self.own_blocks()
        if own is not None:
            blocks[np.arange(m), :, np.arange(m)] += own
        for a, b, v in self.shared():
            blocks[a, :, b] += v[a] @ np.swapaxes(v[b], 1, 2)
        return out


def interval_pairs(interval: IntArray) -> tuple[IntArray, IntArray]:
    """The pairs (``a``, ``b``; each once) of distinct targets of one interval (-1:
    none); as many as there are, not M^2 (the targets in order of their interval, each
    beside the next ones of its run)."""
    order = np.argsort(interval, kind="stable")
    runs = interval[order]
    a, b = [np.zeros(0, np.intp)], [np.zeros(0, np.intp)]
    for lag in range(1, order.size):
        same = (runs[lag:] == runs[:-lag]) & (runs[lag:] >= 0)
        if not same.any():  # no run longer than lag
            break
        a.append(order[:-lag][same])
        b.append(order[lag:][same])
    return np.concatenate(a), np.concatenate(b)


def error_terms(result: ProcessResult, chain: PoseChain, centre_cov_mm2: FloatArray) -> ErrorTerms:
    """The targets' Jacobian and what the covariance holds beyond it (:class:`ErrorTerms`)."""
    jacobian = target_jacobian(chain, result.centres.centres_mm)
    refs = result.session.plan.reference_indices
    # the references' legs by their own centres and O's: the carry's, the smooth fit's and
    # the straight line's errors read them (made once)
    derivatives = leg_derivatives(chain, result.centres.centres_mm, refs)
    legs_cov = own_leg_covariance(
        chain, result.centres.centres_mm, centre_cov_mm2, refs, derivatives[0]
    )
    carried = carry_error(result, chain, jacobian, centre_cov_mm2, legs_cov, derivatives)
    # without a log O's carry reads the references: a function of their centres
    full = jacobian if carried is None or carried.jacobian is None else carried.jacobian
    excess = smooth_excess(result, chain, centre_cov_mm2, legs_cov)
    curved = curvature_excess(result, chain, legs_cov)
    return ErrorTerms(jacobian, full, carried, excess, curved)


def structured_covariance(
    terms: ErrorTerms, centre_cov_mm2: FloatArray, outputs: slice
) -> BandedCovariance | None:
    """The structured joint covariance of ``terms`` (None: not banded, or the smooth
    growth's own error, which it does not carry)."""
    if terms.excess is not None and outputs == slice(6, 12):
        return None
    structure = terms.full.joint_covariance_structured(centre_cov_mm2, outputs)
    if structure is None:
        return None
    m = terms.jacobian.jac.shape[0]
    d = len(range(12)[outputs])
    common = None
    if terms.carried is not None:
        common = terms.carried.factor[:, outputs].reshape(m * d, -1)
        common = common[:, np.any(common != 0.0, axis=0)]  # R0's: zero unless repeated
    banded = None
    if terms.curved is not None and outputs == slice(6, 12):
        from scipy import sparse

        # one column per interval: its targets' error vectors (sparse: one interval a
        # target or two, and a thousand targets)
        f, error = terms.curved
        assert error.interval is not None
        k = f.shape[2]
        mine = np.flatnonzero(error.interval >= 0)
        groups, column = np.unique(error.interval[mine], return_inverse=True)
        shape = (mine.size, 6, k)  # a target's rows, its interval's k columns
        rows = np.broadcast_to((6 * mine[:, None] + np.arange(6))[:, :, None], shape)
        columns = np.broadcast_to(column[:, None, None] * k + np.arange(k), shape)
        banded = sparse.csr_matrix(
            (f[mine].ravel(), (rows.ravel(), columns.ravel())), shape=(m * 6, groups.size * k)
        )
    return structure.plus(common, banded)
