"""What a calibration claims for a NEW pose: the parameters' uncertainty propagated to
the pose, plus the level's model floor (what the level cannot model).

**The claim.** The calibrated model predicts a pose it was not fitted to with the
covariance ``G C_z G^T`` of its parameters (``G`` the prediction's Jacobian at that
pose), and with an error its level cannot represent at all. The claimed standard
uncertainty of component ``c`` of a new pose is

    ``u_c = sqrt( (G C_z G^T)_cc + f_c^2 )``

``f_c`` the floor of component ``c`` (one variance component per component, the same
for every pose), :func:`model_floor`.

**The floor: the legs' growth in the states the poses refer to.** Corrected poses
stand in the thermal state of their session's first reference R0, relative to frame O
as measured (in the thermal state of the origin step), not at the leg model's
reference temperature ``T_ref``. At R0 every leg is longer by ``sum_s cte_s L_s
(T_R0 - T_ref)``, linear in the commanded length: an offset ``a_i`` (the growth at
the home length) and a gain ``b_i`` (the variable segment's ``cte (T_R0 - T_ref)``: 15
ppm for 1.3 K of steel) about the home length (:func:`growth_as_parameters`); and
between O and R0 the legs grew by the same law with ``T_R0 - T_O``, which moves frame O
under every pose (a common shift the model, whose pose at the zero command is zero
by definition, cannot make). The ``joints+gains`` level absorbs the R0 growth; the
``joints`` and ``offsets`` levels absorb its offsets and what the joints can mimic
of its gains; none absorbs O's move entirely. The floor is what is left: the pose
change the growth makes (``J dtheta_R0 + J_O (dtheta_O - dtheta_R0)``, ``J`` the
prediction's Jacobian by the 48 parameters, ``J_O`` its part through frame O,
``dtheta`` the growth's offsets and gains of each session) minus the level's
weighted least-squares fit of it at the campaign's poses (the same weights as the
calibration), evaluated at the new poses ``X_m``, RMS over them and over the
sessions:

    ``f_c^2 = mean_{s, m} (shift_s(X_m) - G(X_m) dz)_c^2``

It is a model of one known cause, computed from the thermocouples at R0 and the leg
model (no noise of its own): causes outside it (an effect the thermal model lacks,
errors a level other than ``joints+gains`` leaves in the joints) are not in it, and
show as a chi-square per degree of freedom above its limit.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from hexatherm.core.calibration.fit import CalibrationFit
from hexatherm.core.calibration.model import (
    GAINS,
    N_PARAMETERS,
    OFFSETS,
    compose_pose,
    relative_pose,
)
from hexatherm.core.calibration.weights import BandedCovariance, PoseWeights
from hexatherm.core.geometry import to_um_urad
from hexatherm.core.thermal import LegThermalModel
from hexatherm.typing import FloatArray, IntArray

#: how the floor is estimated, in words (the outputs and the report say it)
FLOOR_METHOD = (
    "the legs' growth at R0 (the thermocouple temperatures of each session's R0 above "
    "the leg model's reference temperature: an offset and a gain of every leg) and "
    "between O and R0 (which moves frame O under every pose); the floor is the RMS, "
    "over new poses in the campaign's span, of the pose change this makes that the "
    "level's fit at the campaign's poses does not absorb"
)


@dataclass(frozen=True)
class ModelFloor:
    """The level's model floor (see the module text).

    Attributes
    ----------
    sigma_um_urad : ndarray, shape (6,)
        ``f_c`` of Tx .. Rz, um and urad: the RMS over the new poses.
    at_poses_um_urad : ndarray, shape (M, 6)
        ``f_c(X_m)`` at each new pose (RMS over the sessions): what the growth leaves at
        that pose, larger towards the stroke's ends (empty without a floor).
    growth_um_urad : ndarray, shape (6,)
        RMS of the pose change the growth makes at the new poses (what the floor would
        be if the level absorbed none of it), um and urad.
    leg_temperature_C : ndarray, shape (S, 6)
        Each session's leg temperatures at R0.
    origin_temperature_C : ndarray, shape (S, 6)
        And at its origin step O.
    reference_temperature_C : float
        The leg model's.
    method : str
        How the floor was estimated, in words.
    note : str
        Why there is none ("" when there is one).
    """

    sigma_um_urad: FloatArray
    growth_um_urad: FloatArray
    leg_temperature_C: FloatArray
    origin_temperature_C: FloatArray
    reference_temperature_C: float
    method: str = FLOOR_METHOD
    note: str = ""
    at_poses_um_urad: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 6)))

    @classmethod
    def none(cls, note: str) -> ModelFloor:
        """No floor (``note`` says why): zero in every component."""
        none = np.zeros((0, 6))
        return cls(np.zeros(6), np.zeros(6), none, none, float("nan"), note=note)

    def at(self, n_poses: int) -> FloatArray:
        """The floor (n_poses, 6) at each of the ``n_poses`` new poses it was evaluated at
        (its RMS at every pose when it was evaluated elsewhere, or there is none)."""
        if self.at_poses_um_urad.shape == (n_poses, 6):
            return self.at_poses_um_urad
        return np.broadcast_to(self.sigma_um_urad, (n_poses, 6))


def growth_as_parameters(
    legs: LegThermalModel, home_leg_mm: npt.ArrayLike, leg_temperature_C: npt.ArrayLike
) -> FloatArray:
    """The legs' growth at ``leg_temperature_C`` (6,) as parameter changes (48,): leg
    offsets (the growth at the home lengths ``home_leg_mm``, mm) and gains (its change
    per mm of travel, mm/mm); exact, the growth being linear in the leg length."""
    home = np.asarray(home_leg_mm, dtype=float)
    temps = np.asarray(leg_temperature_C, dtype=float)
    at_home = legs.growth_mm(home, temps)
    out = np.zeros(N_PARAMETERS)
    out[OFFSETS:GAINS] = at_home
    out[GAINS:] = legs.growth_mm(home + 1.0, temps) - at_home
    return out


def model_floor(
    fit: CalibrationFit,
    commanded_poses: npt.ArrayLike,
    covariance: npt.ArrayLike | BandedCovariance,
    legs: LegThermalModel,
    leg_temperature_C: npt.ArrayLike,
    origin_temperature_C: npt.ArrayLike,
    session_of_pose: npt.ArrayLike,
    new_poses: npt.ArrayLike,
) -> ModelFloor:
    """The level's floor from R0's leg growth (see the module text).

    Parameters
    ----------
    fit : CalibrationFit
        The level fitted to the campaign.
    commanded_poses : array_like, shape (N, 6)
        The campaign's commanded poses (mm, deg).
    covariance : array_like, shape (N, 6, 6) or (6N, 6N), or BandedCovariance
        Their measured poses' covariance, as fitted with.
    legs : LegThermalModel
        The hexapod file's leg model.
    leg_temperature_C : array_like, shape (S, 6)
        Every session's leg temperatures at its R0.
    origin_temperature_C : array_like, shape (S, 6)
        And at its origin step O.
    session_of_pose : array_like of int, shape (N,)
        The session (row of ``leg_temperature_C``) of every pose.
    new_poses : array_like, shape (M, 6)
        Where the floor is evaluated: new poses over the stroke (mm, deg).

    Returns
    -------
    ModelFloor
    """
    model = fit.model
    x_cmd = np.atleast_2d(np.asarray(commanded_poses, dtype=float))
    temps = np.atleast_2d(np.asarray(leg_temperature_C, dtype=float))
    at_origin = np.atleast_2d(np.asarray(origin_temperature_C, dtype=float))
    session: IntArray = np.asarray(session_of_pose, dtype=np.int64)
    growth = np.stack([growth_as_parameters(legs, model.home_leg_mm, t) for t in temps])
    origin_move = (
        np.stack([growth_as_parameters(legs, model.home_leg_mm, t) for t in at_origin]) - growth
    )
    jac, jac_origin = _jacobians(fit, x_cmd)
    shift = np.einsum("kcp,kp->kc", jac, growth[session]) + np.einsum(
        "kcp,kp->kc", jac_origin, origin_move[session]
    )
    weights = PoseWeights(covariance, x_cmd.shape[0])
    absorbed = np.linalg.lstsq(
        weights.whiten(jac @ model.basis), weights.whiten(shift), rcond=None
    )[0]
    jac_new, origin_new = _jacobians(fit, np.atleast_2d(np.asarray(new_poses, dtype=float)))
    made = np.einsum("mcp,sp->smc", jac_new, growth) + np.einsum(
        "mcp,sp->smc", origin_new, origin_move
    )
    left = made - (jac_new @ model.basis @ absorbed)[None]
    return ModelFloor(
        np.sqrt(np.mean(to_um_urad(left) ** 2, axis=(0, 1))),
        np.sqrt(np.mean(to_um_urad(made) ** 2, axis=(0, 1))),
        temps,
        at_origin,
        float(legs.reference_temperature_C),
        at_poses_um_urad=np.sqrt(np.mean(to_um_urad(left) ** 2, axis=0)),
    )


def _jacobians(fit: CalibrationFit, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The prediction's Jacobian (M, 6, 48) by the parameters at ``poses``, and its part
    through frame O alone (the relative pose's derivative by O times O's by the
    parameters)."""
    model = fit.model
    pred, jac = model.predict(fit.parameters, poses)
    origin, d_origin = model.origin(fit.parameters)
    stand, _, _ = compose_pose(origin, pred, model.nominal.convention)
    _, d_a, _ = relative_pose(origin, stand, model.nominal.convention)
    return jac, np.asarray(d_a @ d_origin, float)


def combined_sigma(parameters_um_urad: npt.ArrayLike, floor: ModelFloor) -> FloatArray:
    """The claimed standard uncertainty ``sqrt(sigma^2 + f^2)`` per component, ``sigma``
    (M, 6) the parameters' part (um and urad) at the M poses the floor was evaluated at
    (``f`` the floor at each, :meth:`ModelFloor.at`), or (6,) or (M', 6) elsewhere (``f``
    its RMS)."""
    sigma = np.asarray(parameters_um_urad, dtype=float)
    f = floor.at(sigma.shape[0]) if sigma.ndim == 2 else floor.sigma_um_urad
    return np.asarray(np.sqrt(sigma**2 + f**2), float)
