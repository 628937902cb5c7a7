"""The twin's truth for poses a simulated session did not measure: what a calibration
from the session should predict for new poses.

A calibration from corrected poses models the hexapod in the thermal state of the
session's first reference R0, relative to the measured frame O. The true pose of a
new commanded pose is then the twin's *true corrected* pose of that command
(:attr:`hexatherm.core.twin.TwinSteps.corrected_pose`): the true geometry, the legs
at R0's segment temperatures (effects included), relative to the true platform at
the origin step as it was measured.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hexatherm.core.effects import ThermocoupleLog
from hexatherm.core.geometry import check_poses, transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.core.twin import predict
from hexatherm.io.config import read_hexapod_text
from hexatherm.typing import FloatArray
from hexatherm.workflows.simulate.twinsession import TwinSessionSpec, step_timing


def heldout_truth(spec: TwinSessionSpec, commanded_poses: npt.ArrayLike) -> FloatArray:
    """True poses (M, 6) relative to the measured O, in R0's thermal state, of commanded
    poses (M, 6) the session ``spec`` did not measure (mm, deg; no positioning error:
    the hexapod's repeatability is not the model's).

    The session's thermocouple history, effects and true geometry are those of
    :func:`~hexatherm.workflows.simulate.twinsession.simulate_session`; the new poses
    are solved at R0's time, with the origin step at its own time.
    """
    poses = np.atleast_2d(check_poses(commanded_poses, "commanded pose"))
    hexapod = read_hexapod_text(spec.hexapod_text, "hexapod.yaml")
    plan = spec.plan
    n, k = len(plan.labels), len(spec.balls.names)
    ball_t, step_t = step_timing(n, k, spec.seconds_per_ball, spec.seconds_per_move, spec.pauses_s)
    end = ball_t.max() + spec.seconds_per_ball
    sample_t = np.arange(0.0, end + spec.sample_period_s, spec.sample_period_s)
    truth_t = np.union1d(sample_t, step_t)
    log = ThermocoupleLog(truth_t, spec.heating.legs(truth_t), spec.heating.air(truth_t))
    origin = plan.origin_index
    refs = plan.reference_indices
    r0 = int(refs[0]) if refs.size else origin
    m = poses.shape[0]
    steps = Plan(
        ("O", "R0", *(f"H{i + 1}" for i in range(m))),
        ("origin", "reference", *(("target",) * m)),
        np.concatenate([plan.poses[[origin, r0]], poses]),
        plan.reference_pose,
        plan.points_per_ball,
    )
    times = np.concatenate([step_t[[origin, r0]], np.full(m, step_t[r0])])
    truth = predict(
        hexapod,
        steps,
        times,
        log,
        spec.balls.centres_mm,
        transform_from_pose(spec.origin_on_cmm, hexapod.convention),
        spec.effects,
        true_parameters=spec.true_parameters,
    )
    return np.asarray(truth.corrected_pose[2:], float)
