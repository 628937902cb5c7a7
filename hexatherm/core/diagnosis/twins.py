"""The twin's ball centres of one session for many sets of effects: the fits' twin runs.

A fit runs the twin (:func:`hexatherm.core.twin.predict`) hundreds of times on the
same steps with other effects' parameters: a Jacobian's columns, start values, chord
iterations. :class:`TwinRuns` computes once what does not depend on the effects (the
thermocouple log at the steps' times, the commanded leg lengths, the FGM's first
iteration at the commanded poses) and runs the FGM of several sets of effects as one
stack of poses. The centres are those of ``predict`` (nominal frame O, no reference
state), bit for bit: the same operations on the same numbers
(``tests/core/test_diagnosis_twins.py`` compares them).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexatherm.core.effects import Effect, ThermocoupleLog, check_distinct
from hexatherm.core.geometry import apply_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.twin import _leg_model, _TrueGeometry
from hexatherm.errors import ConvergenceError
from hexatherm.typing import FloatArray

#: most poses (steps times sets) one stacked FGM solves: beyond, the call overhead a
#: stack saves is small and its arrays (a few kB a pose) only take memory
MAX_STACKED_POSES = 8192


class TwinRuns:
    """The twin's centres (N, k, 3) in frame O of a plan's steps, for sets of effects.

    The arguments are those of :func:`~hexatherm.core.twin.predict` (``times_s`` (N,)
    of the steps, the log, the balls (k, 3) in the platform frame).
    """

    def __init__(
        self,
        hexapod: Hexapod,
        plan: Plan,
        times_s: FloatArray,
        log: ThermocoupleLog,
        balls_mm: FloatArray,
    ) -> None:
        self.hexapod, self.plan, self.log = hexapod, plan, log
        self.legs = _leg_model(hexapod)
        self.step_times_s = t = np.asarray(times_s, dtype=float).reshape(-1)
        self.balls_mm = np.asarray(balls_mm, dtype=float)
        self.times_s = np.concatenate([[log.t0_s], t])
        self.log_legs_C = log.legs_at(self.times_s)
        self.q_cmd = hexapod.igm(plan.poses)
        self.actuated = _TrueGeometry.of(hexapod, None).actuated_mm(self.q_cmd)
        self.order = np.argsort(t, kind="stable")
        self.ball_times_s = np.broadcast_to(t[:, None], (t.size, self.balls_mm.shape[0]))
        self.start = hexapod.fgm_start(plan.poses)

    def _legs_of(
        self, effects: tuple[Effect, ...]
    ) -> tuple[FloatArray, FloatArray | None, FloatArray]:
        """Leg lengths (N, 6), base joints of each step (None: the nominal ones) and the
        balls, (k, 3) or (N, k, 3), under ``effects`` (as :func:`~hexatherm.core.twin.predict`)."""
        check_distinct(effects)
        log, t, variable = self.log, self.step_times_s, self.legs.variable
        leg = self.log_legs_C
        for effect in effects:
            leg = effect.leg_temperature_C(leg, self.times_s, log)
        leg0, leg = leg[0], leg[1:]
        segments = np.broadcast_to(leg[..., None], leg.shape + (variable.shape[1],))
        for effect in effects:
            segments = effect.segment_temperature_C(segments, leg, leg0, variable)
        nominal = self.hexapod.base_joints_mm
        base = nominal
        for effect in effects:
            base = effect.base_joints_mm(base, t, log)
        step_base = None if base is nominal else np.broadcast_to(base, (t.size, 6, 3))
        balls = self.balls_mm
        for effect in effects:
            balls = effect.ball_positions_mm(balls, self.ball_times_s, log)
        growth = self.legs.growth_mm(self.q_cmd, segments, per_segment=True)
        for effect in effects:
            growth = effect.leg_growth_mm(growth, leg, self.legs.reference_temperature_C)
        q = self.actuated + growth
        for effect in effects:
            q = effect.commanded_leg_length_mm(q, self.q_cmd, self.order)
        return q, step_base, balls

    def centres(self, effect_sets: Sequence[Sequence[Effect]]) -> list[FloatArray]:
        """The centres (N, k, 3) of every set of effects, in order.

        The sets that keep the nominal base joints share one FGM (their legs stacked,
        from the FGM's first iteration kept; at most :data:`MAX_STACKED_POSES` poses a
        stack); a set that moves them has its own.
        """
        runs = [self._legs_of(tuple(effects)) for effects in effect_sets]
        n = self.q_cmd.shape[0]
        poses = np.empty((len(runs) * n, 6))
        shared = [i for i, (_, base, _) in enumerate(runs) if base is None]
        per_stack = max(1, MAX_STACKED_POSES // n)
        for chunk in (shared[k : k + per_stack] for k in range(0, len(shared), per_stack)):
            try:
                stacked = self.hexapod.fgm(
                    np.concatenate([runs[i][0] for i in chunk]), start=self.start
                )
            except ConvergenceError:
                # the pose named is one of the stack: name the step, as predict would
                for i in chunk:
                    self.hexapod.fgm(runs[i][0], start=self.start)
                raise
            for j, i in enumerate(chunk):
                poses[i * n : (i + 1) * n] = stacked[j * n : (j + 1) * n]
        for i, (q, base, _) in enumerate(runs):
            if base is not None:
                poses[i * n : (i + 1) * n] = self.hexapod.fgm(
                    q, initial_poses=self.plan.poses, base_joints_mm=base
                )
        # (predict's origin2cmm, the identity, left out: the same numbers)
        frames = transform_from_pose(poses, self.hexapod.convention).reshape(len(runs), n, 4, 4)
        if all(balls.ndim == 2 for _, _, balls in runs):
            balls = np.stack([balls for _, _, balls in runs])[:, None]  # (M, 1, k, 3)
            return list(apply_transform(frames, balls))
        return [
            apply_transform(frame, balls) for frame, (_, _, balls) in zip(frames, runs, strict=True)
        ]
