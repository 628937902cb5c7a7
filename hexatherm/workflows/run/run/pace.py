"""The campaign's clock on screen: each step's time and the estimated end (ETA).

The estimate starts from the plan's timing model (:func:`hexatherm.core.planning.
estimate_timing`: a move of ``seconds_per_move``, then ``points_per_ball`` points per
ball at ``seconds_per_point``, ``plan``'s defaults) and is corrected by the pace measured
so far in this run: the work left, in the model's seconds, times the ratio of the time
this run has taken to the model's seconds of the work it has done (moves in position,
balls accepted). A ball measured again (a re-probe, a reference measured again after a
delay) is not foreseen: it shows as a slower pace in the next estimate.
"""

from __future__ import annotations

from datetime import datetime

#: the plan's timing model (``hexatherm plan --seconds-per-point/--seconds-per-move``
#: defaults): only their ratio matters once the run has a measured pace
SECONDS_PER_POINT = 3.0
SECONDS_PER_MOVE = 30.0


def clock_text(seconds: float) -> str:
    """POSIX seconds as local time, ISO 8601 to the second with its UTC offset.

    >>> datetime.fromisoformat(clock_text(1700000000.7)).timestamp()
    1700000000.0
    """
    return datetime.fromtimestamp(int(seconds // 1)).astimezone().isoformat(timespec="seconds")


def duration_text(seconds: float) -> str:
    """A duration as ``2 h 05 min``, ``7 min 30 s`` or ``40 s`` (rounded to the second).

    >>> duration_text(7530.4), duration_text(450.0), duration_text(39.6)
    ('2 h 05 min', '7 min 30 s', '40 s')
    """
    s = round(max(seconds, 0.0))
    if s >= 3600:
        return f"{s // 3600} h {s % 3600 // 60:02d} min"
    if s >= 60:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s} s"


class Pace:
    """The estimated end of a campaign, corrected by its measured pace.

    Parameters
    ----------
    start_s : float
        When this run (or resume) started, POSIX seconds.
    points_per_ball : int
    seconds_per_point, seconds_per_move : float
        The timing model (> 0).

    Examples
    --------
    A run started at t = 1000 s whose first move (30 s in the model) was in position
    at 1045 s goes 1.5 times slower than the model: 3 balls of 6 points left on this
    step (54 s) and 3 more steps (3 x 84 s) take 306 x 1.5 = 459 s, the end at 1504 s.

    >>> pace = Pace(1000.0, 6)
    >>> pace.moved()
    >>> pace.eta_s(1045.0, moves_left=3, balls_left=12)
    1504.0
    """

    def __init__(
        self,
        start_s: float,
        points_per_ball: int,
        seconds_per_point: float = SECONDS_PER_POINT,
        seconds_per_move: float = SECONDS_PER_MOVE,
    ) -> None:
        self.start_s = float(start_s)
        self.ball_s = points_per_ball * float(seconds_per_point)
        self.move_s = float(seconds_per_move)
        #: the model's seconds of the work this run has done
        self.done_s = 0.0

    def moved(self) -> None:
        """A step's move is in position."""
        self.done_s += self.move_s

    def probed(self) -> None:
        """A ball is accepted."""
        self.done_s += self.ball_s

    def eta_s(self, now_s: float, *, moves_left: int, balls_left: int) -> float:
        """The estimated end, POSIX seconds, with ``moves_left`` moves and ``balls_left``
        balls still to do."""
        left_s = moves_left * self.move_s + balls_left * self.ball_s
        ratio = (now_s - self.start_s) / self.done_s if self.done_s > 0 else 1.0
        return now_s + left_s * max(ratio, 0.0)
