"""Geometric calibration of a hexapod from poses measured relative to frame O.

**The measurement model.** The true hexapod differs from the nominal one (the
hexapod file) by its parameters ``theta`` (48, :data:`PARAMETER_NAMES`): base joints
``b_i`` (6 x 3, mm, in a base frame B fixed to the base), platform joints ``p_i``
(6 x 3, mm, in the platform frame, the frame the balls define), leg offsets ``dq_i``
(mm) and leg gains ``g_i`` (mm/mm: 1e-6 is 1 ppm). For a commanded pose ``X_cmd``
(relative to O, mm and deg):

1. the controller drives the actuators to ``q_cmd = IGM_nominal(X_cmd)``;
2. they produce the joint-to-joint lengths
   ``q_true_i = q_cmd_i + dq_i + g_i (q_cmd_i - q_home_i)``, ``q_home =
   IGM_nominal(0)``: the offset is the error at the home (zero-pose) length, the
   gain scales the travel from it (a screw-pitch error; written about ``q_home``
   and not about 0 so that offset and gain are not 99.99 % correlated);
3. the platform stands at ``Y = FGM_theta(q_true)`` in B, the FGM started from
   ``X_cmd`` (the assembly mode of the commanded pose; during a fit, from the last
   solution for nearby parameters), and at ``Y_O = FGM_theta(q_true(0))`` for the
   zero command;
4. the CMM measures the platform frame, and poses are taken relative to the
   measured frame O: ``X_meas = inv(T(O)) T(S)``, predicted as
   ``X_pred(theta) = inv(T(Y_O)) T(Y)``.

Frame O carries no information (its relative pose is 0 by definition): leave it
out of the poses fitted. Every prediction is computed this way (FGM to 1e-11 mm).

**The gauge.** Moving every base joint by one rigid motion ``G`` moves ``Y`` and
``Y_O`` to ``G Y`` and ``G Y_O`` and changes no relative pose: B is unknown, and
six freedoms (three translations, three rotations of the base joints as one body)
are not identifiable (:func:`gauge_directions`). They are fixed by six linear
conditions on the base joints' change ``db_i = b_i - b0_i`` from the nominal
``b0_i``: ``sum_i db_i = 0`` and ``sum_i b0_i x db_i = 0``, exactly the
conditions that the fitted base is the least-squares (Kabsch) best fit of itself
onto the nominal base (:func:`gauge_fixed` moves any geometry there). The fit
works in free coordinates ``z``, ``theta = theta0 + B z``, ``B`` an orthonormal
basis of the level's parameters less the gauge directions at the nominal base, so
every update lies in the gauge's orthogonal complement and the solution is unique.
The ``offsets`` level keeps the joints nominal and has no gauge. The calibrated
hexapod (:meth:`CalibrationFit.hexapod`) is gauge-free: its base joints are moved
into frame O (the platform frame at the zero command), where ``process`` needs
them; :meth:`CalibrationFit.origin_parameters` gives those with their covariance.

**Levels** (:data:`LEVELS`): ``offsets`` (6 parameters, 6 free coordinates),
``joints`` (base, platform, offsets: 42 parameters, 36 free + 6 gauge),
``joints+gains`` (48: 42 free + 6 gauge).

**Identification** (:func:`fit_calibration`): weighted least squares,
Levenberg-Marquardt (MINPACK through ``scipy.optimize.least_squares``) with the
analytic Jacobian, from the nominal parameters. Residuals are whitened by the
poses' covariance: ``L^-1 r`` with ``L`` the Cholesky factor of each pose's 6 x 6
covariance, or of the whole (6N x 6N) covariance when the between-target terms are
known (a common frame O, say).

- ``pose`` residuals (the default): ``r_k = X_meas_k - X_pred_k(theta)`` (mm, deg).
  The covariance is given in this space (no reweighting), the residuals are what a
  user reads (um, urad), and the held-out checks compare predicted poses.
- ``leg`` residuals: ``r_k = IGM_theta(T(Y_O) X_meas_k) - q_true(X_cmd_k)`` (mm), the
  measured pose put into B through the model's frame O; no FGM per pose, but the
  covariance ``A C A^T`` (``A = dr/dX_meas``) depends on ``theta`` and is
  re-evaluated at each estimate until the step is below 1e-3 sigma. To first order
  ``r_leg = A r_pose``, so the whitened leg residuals are the whitened pose residuals
  and both estimate the same parameters (a test: their difference is a small
  fraction of the uncertainty).

The Jacobian is analytic: by the implicit function theorem on ``IGM_theta(Y) =
q_true``, ``dY/dtheta = J(Y)^-1 (dq_true/dtheta - dIGM/dtheta)`` with ``d|l_i|/db_i =
-u_i`` and ``d|l_i|/dp_i = R^T u_i`` (``u_i`` the unit leg vector), then the
derivatives of the relative pose (:func:`relative_pose`); checked against central
differences.

**Outputs** (:class:`CalibrationFit`): parameters in the gauge and their covariance
``B (J_w^T J_w)^-1 B^T`` (not scaled by ``chi^2/dof``: the covariance given is taken
as honest, and ``chi^2/dof`` says whether it is), standard uncertainties, the
correlation matrix with pairs ``|rho| > 0.9`` flagged, ``chi^2`` and ``dof = 6N -
n_free``, the predicted poses' covariance at any commanded poses (``G C_z G^T``, ``G``
the prediction's Jacobian), and :class:`Observability`: the singular values ``s_1 >=
... >= s_L`` of the whitened Jacobian in the free coordinates (``L = n_free``; per mm,
per unit gain), the condition number ``s_1 / s_L`` and Sun and Hollerbach's
observability indices over ``m`` poses:

- ``O1 = (s_1 s_2 ... s_L)^(1/L) / sqrt(m)`` (Borm and Menq; D-optimality),
- ``O2 = s_L / s_1`` (the inverse condition number; Driels and Pathre),
- ``O3 = s_L`` (the smallest singular value; E-optimality, Nahvi et al.),
- ``O4 = s_L^2 / s_1`` (the noise amplification index; Nahvi and Hollerbach),
- ``O5 = 1 / (1/s_1 + ... + 1/s_L)`` (Sun and Hollerbach; A-optimality-like).

The rank counts singular values above 1e-8 of the largest, plus the gauge's six
fixed freedoms, over the level's parameters; it is checked at the start (the
nominal, where a structural deficiency is exact) and a deficient set is refused
(:class:`RankDeficientError`) naming why and what to add. Poses without rotation
leave rank 24 of 42: each leg's base and platform joints then enter only through
their difference (18 directions).

**Level selection** (:func:`select_level`): as ``diagnose`` chooses effects: from the
smallest level that can be fitted, a larger level is taken when its BIC (``n ln(RSS_w
/ n) + p ln n``, n whitened residuals, p free coordinates) drops by more than 10 and
its whitened held-out RMS (interleaved folds of poses, each predicted by the level
refitted to the others) is lower.

**Pose selection** (:func:`select_poses`): from candidate commanded poses inside the
stroke, the user's box and away from singularities (``min_rcond``), N poses chosen
greedily by D-optimality (the log-determinant of the information, O1), or for the
worst predicted standard uncertainty of Tx, Ty, Tz (the D-optimal choice improved by
exchange passes); a candidate set or a choice that does not identify the level is
refused with the reason.

**Applying a calibration.** The calibrated hexapod's IGM gives the true
joint-to-joint lengths of a pose relative to O (what the thermal correction
needs); to command a pose ``X`` the controller must be given
``q_cmd = commanded_leg_lengths(IGM_cal(X))`` (:func:`commanded_leg_lengths`), and a
commanded ``q_cmd`` stands at ``FGM_cal(true_leg_lengths(q_cmd))``.

>>> import numpy as np
>>> from hexatherm.core.hexapod import Hexapod
>>> nominal = Hexapod.symmetric(base_radius_mm=180, platform_radius_mm=110,
...     base_half_angle_deg=20, platform_half_angle_deg=10, height_mm=240)
>>> truth = nominal_parameters(nominal) + np.r_[np.full(36, 0.02), np.full(6, 0.01), np.zeros(6)]
>>> model = CalibrationModel(nominal, "joints")
>>> commanded = np.random.default_rng(0).uniform(-1, 1, (20, 6)) * [20, 20, 15, 4, 4, 8]
>>> measured, _ = model.predict(truth, commanded)
>>> fit = fit_calibration(nominal, commanded, measured,
...     pose_covariance_from_sigma(20, 1.0, 5.0), level="joints")
>>> fit.observability.rank, fit.dof
(42, 84)
>>> bool(np.abs(fit.predict(commanded) - measured).max() < 1e-9)
True
"""

from hexatherm.core.calibration.design import (
    CRITERIA,
    DEFAULT_MIN_RCOND,
    DELTA_BIC_THRESHOLD,
    LevelChoice,
    LevelScore,
    PoseSelection,
    feasible_candidates,
    predicted_sigma,
    select_level,
    select_poses,
)
from hexatherm.core.calibration.fit import (
    HIGH_CORRELATION,
    RANK_RTOL,
    RESIDUAL_KINDS,
    CalibrationFit,
    Observability,
    fit_calibration,
    fold_of_poses,
    observability,
)
from hexatherm.core.calibration.model import (
    LEVELS,
    N_PARAMETERS,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    CalibrationModel,
    commanded_leg_lengths,
    compose_pose,
    gauge_directions,
    gauge_fixed,
    join_parameters,
    level_mask,
    nominal_parameters,
    relative_pose,
    split_parameters,
    true_leg_lengths,
)
from hexatherm.core.calibration.weights import (
    BandedCovariance,
    PoseWeights,
    pose_covariance_from_sigma,
)
from hexatherm.errors import CalibrationError, RankDeficientError

__all__ = [
    "CRITERIA",
    "DEFAULT_MIN_RCOND",
    "DELTA_BIC_THRESHOLD",
    "HIGH_CORRELATION",
    "LEVELS",
    "N_PARAMETERS",
    "PARAMETER_NAMES",
    "PARAMETER_UNITS",
    "RANK_RTOL",
    "RESIDUAL_KINDS",
    "CalibrationError",
    "CalibrationFit",
    "CalibrationModel",
    "LevelChoice",
    "LevelScore",
    "Observability",
    "PoseSelection",
    "BandedCovariance",
    "PoseWeights",
    "RankDeficientError",
    "commanded_leg_lengths",
    "compose_pose",
    "feasible_candidates",
    "fit_calibration",
    "fold_of_poses",
    "gauge_directions",
    "gauge_fixed",
    "join_parameters",
    "level_mask",
    "nominal_parameters",
    "observability",
    "pose_covariance_from_sigma",
    "predicted_sigma",
    "relative_pose",
    "select_level",
    "select_poses",
    "split_parameters",
    "true_leg_lengths",
]
