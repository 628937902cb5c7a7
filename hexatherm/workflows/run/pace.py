"""The campaign's clock on screen: each step's time and the estimated end (ETA).

The estimate starts from the plan's timing model (:func:`hexatherm.core.planning.
estimate_timing`: a move of ``seconds_per_move``, then ``points_per_ball`` points per
ball at ``seconds_per_point``, ``plan``'s defaults) and is corrected by the pace measured
so far in this run: the work left, in the model's seconds, times the ratio of the time
taken since the first move was commanded to the model's seconds of the work done (moves
in position, balls accepted). Until a ball is accepted the model's pace is kept (one
move says little about probing). The time before the first move (connecting, homing,
the plan's checks) happens once and is not counted. A ball measured again (a re-probe, a
reference measured again after a delay) is not foreseen: it shows as a slower pace in
the next estimate.
"""

from __future__ import annotations

from datetime import datetime

from hexatherm.core.planning import DEFAULT_SECONDS_PER_MOVE, DEFAULT_SECONDS_PER_POINT

#: the plan's timing model (``hexatherm plan --seconds-per-point/--seconds-per-move``
#: defaults, the same as ``simulate``'s): only their ratio matters once the run has a
#: measured pace
SECONDS_PER_POINT = DEFAULT_SECONDS_PER_POINT
SECONDS_PER_MOVE = DEFAULT_SECONDS_PER_MOVE


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
    points_per_ball : int
    seconds_per_point, seconds_per_move : float
        The timing model (> 0).

    Examples
    --------
    6 points a ball at 3 s a point (18 s in the model), 30 s a move (given here; the
    defaults are ``plan``'s). The first move, commanded at
    t = 1000 s, is in position at 1015 s: 3 balls on this step and 3 more steps left
    (3 x 30 + 12 x 18 = 306 model seconds) end at 1321 s, the model's pace (no ball yet).
    Its 3 balls accepted at 1141 s (141 s for 30 + 54 = 84 model seconds, 1.68 times
    slower), the next step in position at 1183 s (113 model seconds done), the rest (2
    moves, 9 balls: 222 model seconds) ends at 1183 + 222 x 183 / 114 = 1539.4 s.

    >>> pace = Pace(6, seconds_per_point=3.0, seconds_per_move=30.0)
    >>> pace.move_started(1000.0)
    >>> pace.moved()
    >>> pace.eta_s(1015.0, moves_left=3, balls_left=12)
    1321.0
    >>> for _ in range(3):
    ...     pace.probed()
    >>> pace.move_started(1141.0)
    >>> pace.moved()
    >>> round(pace.eta_s(1183.0, moves_left=2, balls_left=9), 1)
    1539.4
    """

    def __init__(
        self,
        points_per_ball: int,
        seconds_per_point: float = SECONDS_PER_POINT,
        seconds_per_move: float = SECONDS_PER_MOVE,
    ) -> None:
        self.ball_s = points_per_ball * float(seconds_per_point)
        self.move_s = float(seconds_per_move)
        #: when the first move was commanded (None: not yet)
        self.start_s: float | None = None
        self.moves = self.balls = 0

    def move_started(self, now_s: float) -> None:
        """A step's move is commanded."""
        if self.start_s is None:
            self.start_s = float(now_s)

    def moved(self) -> None:
        """The step's move is in position."""
        self.moves += 1

    def probed(self) -> None:
        """A ball is accepted."""
        self.balls += 1

    def eta_s(self, now_s: float, *, moves_left: int, balls_left: int) -> float:
        """The estimated end, POSIX seconds, with ``moves_left`` moves and ``balls_left``
        balls still to do."""
        left_s = moves_left * self.move_s + balls_left * self.ball_s
        done_s = self.moves * self.move_s + self.balls * self.ball_s
        if self.balls == 0 or self.start_s is None or done_s <= 0:
            return now_s + left_s
        return now_s + left_s * max(now_s - self.start_s, 0.0) / done_s
