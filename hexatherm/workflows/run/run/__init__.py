"""The unattended campaign: drive the hexapod controller and the CMM through a plan.

For every step of the plan, in order (O, R0, then the targets with their references):

1. the probe goes up to the travel height (above every ball of every step of the plan);
2. the hexapod is commanded to the step's pose (every pose was validated before the first
   move: the stroke by the hexapod model, then the controller's own check) and waited for
   in position (flag, settle, a stable read-back; :class:`InPositionCriteria`); the step's
   record (commanded pose, read-back poses, actuator lengths, the controller's
   temperatures) goes to ``steps.csv``;
3. each ball's upper cap is probed around its **predicted** centre: the placement of frame
   O on the CMM (measured, once O's balls are; before that the nominal ``origin_on_cmm``)
   times the commanded pose, shifted by the mean offset of the balls of the same step
   already measured; each ball is fitted at once (free-radius sphere) and checked (fit,
   radius, form, RMS, distance from the prediction): a bad ball is probed once more,
   around its fitted centre when there is one; the second probing is kept, with a warning
   if it is still bad (``process``'s quality checks see it);
4. before a target, when its reference right before it was measured longer than
   ``max_gap_s`` ago (a late in-position flag, a reconnection, a resume), that reference
   is measured again first; before a reference, when the target right before it (whose
   after-reference it is) was measured longer than ``max_gap_s`` ago (a stop after the
   target, a resume the next morning), that target is measured again first, and with it
   its reference before it by the first rule: the target ends between fresh references.
   New points replace the old ones in ``points.csv`` (the old ones stay in the
   transcript); the rules do not cascade further back (the target before a reference
   measured again gets a later after-reference, which ``process``'s time-gap check
   reports).

A dropped connection to either machine is reopened (``reconnects`` times per ball or
move) and the ball probed, or the move commanded, again from its start. Errors that need
the operator (I++ severity 3, a refused pose, no in-position flag) stop the run; so do
Ctrl-C and a machine that stays away. On every stop that is not the end of the plan the
hexapod gets ``stop()``, and :class:`~hexatherm.errors.IncompleteSession` says how to go
on: ``--resume`` rebuilds the state from the transcript (:mod:`.resume`) and continues
at the first step with a ball not accepted (the hexapod is commanded to that step's pose
again). At the end ``session.yaml`` makes the folder a session for ``hexatherm process``.

Clock and sleep are injectable (POSIX seconds): with the simulators' manual clock a whole
campaign runs without waiting.
"""

from __future__ import annotations

from hexatherm.workflows.run.run.campaign import (
    run_campaign,
)
from hexatherm.workflows.run.run.options import (
    BallChecks,
    BallResult,
    Notify,
    RunOptions,
    RunResult,
)
from hexatherm.workflows.run.run.support import (
    dry_run,
)

__all__ = [
    "BallChecks",
    "BallResult",
    "Notify",
    "RunOptions",
    "RunResult",
    "dry_run",
    "run_campaign",
]
