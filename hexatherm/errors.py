"""The errors hexatherm raises on purpose.

Every error a user can provoke with bad input derives from :class:`HexathermError`;
the command line turns them into a one-line message and a non-zero exit.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import Any

from hexatherm.text import format_pose


class HexathermError(Exception):
    """Base class of every error hexatherm raises deliberately."""


class InputError(HexathermError):
    """Bad content in an input file, located by file, line and field.

    >>> str(InputError("not a number: 'abc'", path="centres.csv", line=12, field="x"))
    "centres.csv:12: field 'x': not a number: 'abc'"
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | os.PathLike[str] | None = None,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else os.fspath(path)
        self.line = line
        self.field = field
        super().__init__(self._format())

    def _format(self) -> str:
        where = ""
        if self.path is not None:
            where = self.path
            if self.line is not None:
                where += f":{self.line}"
            where += ": "
        elif self.line is not None:
            where = f"line {self.line}: "
        what = f"field '{self.field}': " if self.field is not None else ""
        return f"{where}{what}{self.message}"


class PlanError(HexathermError):
    """A plan or session whose steps cannot be processed (names the step)."""


class StepError(PlanError):
    """A plan error attached to one step (``step`` is its label, ``index`` its position)."""

    def __init__(self, message: str, *, step: str | None = None, index: int | None = None):
        self.step = step
        self.index = index
        super().__init__(f"step {step}: {message}" if step is not None else message)


class PoseError(PlanError):
    """A commanded pose the hexapod cannot (or should not) reach, naming its step.

    Attributes
    ----------
    step : str
        Label of the step.
    pose : tuple of float
        The commanded pose.
    source : str or None
        Where the pose came from (``targets.csv:7``, ``grid point 12``, ...).
    """

    def __init__(
        self, message: str, *, step: str, pose: Iterable[float], source: str | None = None
    ) -> None:
        self.step = step
        self.pose = tuple(float(v) for v in pose)
        self.source = source
        where = f" ({source})" if source else ""
        super().__init__(f"step {step}{where}: pose {format_pose(self.pose)}: {message}")


class ResultsError(HexathermError):
    """A results folder ``report`` cannot render: not written by ``process``, missing,
    stale (an input changed since), or no longer what its inputs and options give."""


class OutputExistsError(HexathermError):
    """The output exists and overwriting was not asked for."""


class OutputWriteError(HexathermError):
    """An output that cannot be written (disk full, read-only, dangling link, ...).

    ``path`` is the output, ``errno`` the file system's error number (or ``None``).
    Nothing was left behind.
    """

    def __init__(self, message: str, *, path: str | os.PathLike[str], errno: int | None = None):
        self.path = os.fspath(path)
        self.errno = errno
        super().__init__(message)


class OutputBusyError(HexathermError):
    """Another hexatherm run holds the lock of the output's folder for too long."""


class OutputIsInputError(HexathermError):
    """The output is, contains, or sits inside an input of the run.

    ``output`` and ``input`` are the paths as the caller gave them.
    """

    def __init__(self, message: str, *, output: str, input: str) -> None:
        self.output = output
        self.input = input
        super().__init__(message)


class ForeignFilesError(OutputExistsError):
    """``--overwrite`` would replace something hexatherm did not write (or that was edited).

    ``entries`` lists ``(relative path, reason)`` pairs.
    """

    def __init__(self, message: str, *, entries: list[tuple[str, str]]) -> None:
        self.entries = entries
        super().__init__(message)


class ConvergenceError(HexathermError):
    """An iterative solver did not reach its tolerance."""


class SingularityError(ConvergenceError):
    """A Jacobian is singular or too ill-conditioned to trust the solution."""


class FitError(HexathermError):
    """A geometric fit whose preconditions are not met (too few points, coplanar, ...).

    ``index`` is the group (sphere, circle) the message is about, when known.
    """

    def __init__(self, message: str, *, index: int | None = None) -> None:
        self.index = index
        super().__init__(message)


class AssemblyModeError(ConvergenceError):
    """The FGM cannot vouch for a pose: it may belong to another assembly mode.

    Raised for leg lengths out of the stroke and for a path from the start pose that
    cannot be followed with certainty. ``index`` is the pose's index.
    """

    def __init__(self, message: str, *, index: int | None = None) -> None:
        self.index = index
        super().__init__(message)


class RegistrationError(HexathermError):
    """Ball centres that cannot be registered to the balls file."""


class AcquisitionError(HexathermError):
    """The acquisition cannot go on (a port that does not open, a session in the way, ...)."""


class IncompleteSession(AcquisitionError):
    """The acquisition stopped before the end of the plan; ``--resume`` continues it."""


class ControllerError(HexathermError):
    """A hexapod controller could not do what was asked (base of the errors below)."""


class ControllerConnectionError(ControllerError):
    """The controller cannot be reached, or the connection dropped."""


class ControllerTimeoutError(ControllerError):
    """The controller did not answer, or the hexapod did not get in position, in time."""


class PoseRefusedError(ControllerError):
    """A pose failed validation (stroke, workspace, controller check): nothing moved."""


class ControllerReplyError(ControllerError):
    """The controller answered a command with an error code.

    ``code`` is the controller's number, ``command`` the command it answered.
    """

    def __init__(self, message: str, *, code: int, command: str) -> None:
        self.code = code
        self.command = command
        super().__init__(message)


# I++ DME (hexatherm.devices.ipp)
class IppDmeError(HexathermError):
    """Base of the errors of the I++ DME client."""


class IppProtocolError(IppDmeError):
    """A line that breaks the protocol (syntax, tag, data that do not match the request)."""


class IppCommandError(IppDmeError):
    """The server answered a command with an error of severity >= 2 (after recovery).

    ``error`` is the :class:`hexatherm.devices.ipp.ErrorReport`, ``result`` the
    :class:`hexatherm.devices.ipp.TransactionResult` of the command.
    """

    def __init__(self, message: str, *, error: Any, result: Any) -> None:
        self.error = error
        self.result = result
        super().__init__(message)


class IppErrorState(IppDmeError):
    """The server is in an error state and the recovery policy does not clear it."""

    def __init__(self, message: str, *, error: Any) -> None:
        self.error = error
        super().__init__(message)


class IppTimeout(IppDmeError):
    """A transaction was not complete within its timeout."""


class IppConnectionLost(IppDmeError):
    """The connection to the server is closed or broken."""


class IppConnectError(IppConnectionLost):
    """The connection to the server could not be opened (refused, unreachable)."""


# calibration (hexatherm.core.calibration)
class CalibrationError(HexathermError):
    """A calibration that cannot be done as asked (bad input, too few poses)."""


class RankDeficientError(CalibrationError):
    """The poses do not identify the level's parameters (the message says why and what to add).

    Attributes
    ----------
    rank : int
        Rank counted over the level's parameters, the gauge's fixed freedoms included.
    n_parameters : int
        The level's number of parameters (6, 42 or 48).
    directions : ndarray, shape (k, 48)
        Unit parameter directions the poses cannot see (gauge excluded).
    """

    def __init__(self, message: str, *, rank: int, n_parameters: int, directions: Any):
        self.rank = rank
        self.n_parameters = n_parameters
        self.directions = directions
        super().__init__(message)


class InputWarning(UserWarning):
    """Input that a reader read past or dropped because it was asked to (``allow_truncated``,
    ``keep_later``); the message names the file and the line."""


class Terminated(KeyboardInterrupt):
    """A terminating signal other than Ctrl-C (SIGTERM, SIGHUP, SIGQUIT, ...) caught by a
    command that drives a machine: a :class:`KeyboardInterrupt`, so that it takes the path
    of Ctrl-C exactly (the hexapod is stopped, the session left resumable).

    >>> str(Terminated(15)), Terminated(15).name
    ('SIGTERM', 'SIGTERM')
    """

    def __init__(self, signum: int) -> None:
        import signal

        self.signum = int(signum)
        try:
            self.name = signal.Signals(self.signum).name
        except ValueError:
            self.name = f"signal {self.signum}"
        super().__init__(self.name)
