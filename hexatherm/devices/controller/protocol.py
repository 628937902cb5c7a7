"""The controller protocol (HexapodController), its data types, pose conversions, line buffer."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from hexatherm.core.geometry import (
    Convention,
    check_convention,
    check_poses,
    pose_from_transform,
    transform_from_pose,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.typing import FloatArray

#: micrometres per millimetre and microradians per degree
UM_PER_MM = 1e3


URAD_PER_DEG = np.pi / 180.0 * 1e6


#: longest reply line kept, bytes (a stream without line ends is cut there)
MAX_LINE = 65536


# ------------------------------------------------------------------------- errors
# ------------------------------------------------------------------- data types
@dataclass(frozen=True)
class ControllerState:
    """What the controller says about itself.

    Attributes
    ----------
    in_position : bool
        The controller's in-position flag (every axis on target).
    moving : bool
        A motion is under way (where the dialect has no such flag: not in position).
    error : bool
        The controller reports an error.
    ready : bool
        The controller accepts motion commands (powered, homed, under control).
    message : str
        The flags set, or the error, in words.
    """

    in_position: bool
    moving: bool
    error: bool
    ready: bool
    message: str = ""


@dataclass(frozen=True)
class InPositionCriteria:
    """When :meth:`HexapodController.wait_in_position` calls the hexapod there.

    Attributes
    ----------
    settle_s : float
        Wait after the in-position flag before reading back, s.
    tolerance_um, tolerance_urad : float
        Largest peak-to-peak spread of the ``n_readings`` last read-back poses, per
        translation component (um) and per angle (urad).
    n_readings : int
        Consecutive read-backs that must agree (>= 1).
    target_tolerance_um, target_tolerance_urad : float
        Largest deviation of their mean from the commanded pose, per component.
    poll_s : float
        Interval between status queries and read-backs, s.
    timeout_s : float
        Longest wait for the flag and a stable read-back (the settle time excluded), s.
    """

    settle_s: float = 2.0
    tolerance_um: float = 0.5
    tolerance_urad: float = 2.5
    n_readings: int = 3
    target_tolerance_um: float = 5.0
    target_tolerance_urad: float = 25.0
    poll_s: float = 0.2
    timeout_s: float = 120.0

    def __post_init__(self) -> None:
        for name in ("settle_s", "tolerance_um", "tolerance_urad", "target_tolerance_um"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if not (np.isfinite(self.target_tolerance_urad) and self.target_tolerance_urad >= 0):
            raise ValueError(
                f"target_tolerance_urad must be a finite number >= 0, "
                f"got {self.target_tolerance_urad!r}"
            )
        if not (np.isfinite(self.poll_s) and self.poll_s > 0):
            raise ValueError(f"poll_s must be a finite number > 0, got {self.poll_s!r}")
        if not (self.timeout_s > 0):
            raise ValueError(f"timeout_s must be > 0, got {self.timeout_s!r}")
        if int(self.n_readings) != self.n_readings or self.n_readings < 1:
            raise ValueError(f"n_readings must be an integer >= 1, got {self.n_readings!r}")


@dataclass(frozen=True)
class StepRecord:
    """One step as the controller saw it, recorded once the hexapod is in position.

    Attributes
    ----------
    commanded_pose_mm_deg : ndarray, shape (6,)
        The pose commanded by :meth:`HexapodController.move_absolute`.
    readings_pose_mm_deg : ndarray, shape (n, 6)
        The consecutive read-back poses found stable.
    pose_mm_deg : ndarray, shape (6,)
        Their mean.
    deviation_um_urad : ndarray, shape (6,)
        ``pose - commanded``: translations in um, angles in urad.
    spread_um_urad : ndarray, shape (6,)
        Peak-to-peak spread of the readings per component, um and urad.
    actuators_mm : ndarray, shape (6,)
        Actuator (leg) lengths reported by the controller, mm; NaN when the controller
        reports none.
    temperatures_C : ndarray, shape (k,)
        The controller's temperature channels, deg C; empty when it has none.
    flag_after_s : float
        Time from the start of the wait to the in-position flag, s.
    time_s : float
        Clock time when the read-back was found stable (the injected clock), s.
    convention : {"symetrie", "pi"}
        Convention of the angles of the poses.
    """

    commanded_pose_mm_deg: FloatArray
    readings_pose_mm_deg: FloatArray
    pose_mm_deg: FloatArray
    deviation_um_urad: FloatArray
    spread_um_urad: FloatArray
    actuators_mm: FloatArray
    temperatures_C: FloatArray
    flag_after_s: float
    time_s: float
    convention: Convention


@runtime_checkable
class HexapodController(Protocol):
    """What hexatherm needs from a hexapod controller, whatever its dialect.

    Poses are ``[Tx, Ty, Tz, Rx, Ry, Rz]`` in mm and deg in :attr:`convention`.
    """

    url: str
    convention: Convention

    def connect(self) -> None:
        """Open the connection (again, after a drop)."""

    def state(self) -> ControllerState:
        """The controller's flags."""

    def validate(self, pose_mm_deg: npt.ArrayLike) -> None:
        """Raise :class:`PoseRefusedError` unless the pose can be reached; never moves."""

    def move_absolute(self, pose_mm_deg: npt.ArrayLike) -> None:
        """Validate the pose, then start the move to it (returns once accepted)."""

    def wait_in_position(self, criteria: InPositionCriteria | None = None) -> StepRecord:
        """Wait until the hexapod is at the last commanded pose; the step's record."""

    def read_pose(self) -> FloatArray:
        """The controller's current pose (6,), mm and deg."""

    def read_actuators(self) -> FloatArray:
        """Actuator lengths (6,), mm (NaN if the controller reports none)."""

    def read_temperatures(self) -> FloatArray:
        """Temperature channels (k,), deg C (empty if the controller has none)."""

    def stop(self) -> None:
        """Stop any motion; safe to call at any time."""

    def close(self) -> None:
        """Close the connection (no motion command is sent)."""


# ---------------------------------------------------------------- conversions
def convert_pose(
    pose_mm_deg: npt.ArrayLike, from_convention: str, to_convention: str
) -> FloatArray:
    """The same pose (one (6,) or a stack (N, 6)) written in another rotation convention.

    Translations are unchanged; the angles are those of the same rotation matrix.

    >>> convert_pose([0, 0, 0, 0, 0, 30.0], "symetrie", "pi") + 0.0
    array([ 0.,  0.,  0.,  0.,  0., 30.])
    """
    src, dst = check_convention(from_convention), check_convention(to_convention)
    pose = check_poses(pose_mm_deg)
    if src == dst:
        return np.array(pose, dtype=float)
    return pose_from_transform(transform_from_pose(pose, src), dst)


def wrap_deg(angles_deg: npt.ArrayLike) -> FloatArray:
    """Angles wrapped to [-180, 180) deg.

    >>> wrap_deg([190.0, -180.0, 359.0])
    array([-170., -180.,   -1.])
    """
    a = np.asarray(angles_deg, dtype=float)
    return np.mod(a + 180.0, 360.0) - 180.0


def pose_deviation_um_urad(
    pose_mm_deg: npt.ArrayLike, reference_mm_deg: npt.ArrayLike
) -> FloatArray:
    """``pose - reference`` per component, translations in um, angles in urad (wrapped).

    >>> pose_deviation_um_urad([0.001, 0, 0, 0, 0, 180.0], [0, 0, 0, 0, 0, -180.0]) + 0.0
    array([1., 0., 0., 0., 0., 0.])
    """
    diff = np.asarray(pose_mm_deg, dtype=float) - np.asarray(reference_mm_deg, dtype=float)
    out = np.empty(diff.shape)
    out[..., :3] = diff[..., :3] * UM_PER_MM
    out[..., 3:] = wrap_deg(diff[..., 3:]) * URAD_PER_DEG
    return out


def format_pose(pose_mm_deg: npt.ArrayLike) -> str:
    """A pose for messages: ``[Tx, Ty, Tz] mm, [Rx, Ry, Rz] deg``.

    >>> format_pose([1, 2, 3, 0.5, 0, -1])
    '[1.0000, 2.0000, 3.0000] mm, [0.50000, 0.00000, -1.00000] deg'
    """
    p = np.asarray(pose_mm_deg, dtype=float)
    t = ", ".join(f"{v:.4f}" for v in p[:3])
    r = ", ".join(f"{v:.5f}" for v in p[3:])
    return f"[{t}] mm, [{r}] deg"


def stroke_violations(hexapod: Hexapod, pose_mm_deg: npt.ArrayLike) -> list[str]:
    """The legs of ``hexapod`` out of its stroke at a pose (in the hexapod's convention).

    Returns one message per leg out of stroke (empty when the pose is within stroke or
    the hexapod has no stroke).
    """
    if hexapod.stroke_mm is None:
        return []
    q = hexapod.igm(check_poses(pose_mm_deg))[0]
    out = hexapod.check_stroke(q)[0]
    low, high = hexapod.stroke_mm
    return [
        f"leg {i + 1} would be {q[i]:.4f} mm, outside the stroke [{low:g}, {high:g}] mm"
        for i in np.flatnonzero(out)
    ]


# --------------------------------------------------------------------- lines
class LineBuffer:
    """Cut a received byte stream into lines at LF (a CR before it is dropped).

    Blanks at the end of a line are kept (PI GCS marks a continued answer with a
    blank before the line end). Whatever the chunks the bytes arrive in, the lines are
    the same.

    >>> buffer = LineBuffer()
    >>> buffer.feed(b"MOVE#A"), buffer.feed(b"BS:1\\r\\nX=1 \\nY"), buffer.pending
    ([], ['MOVE#ABS:1', 'X=1 '], b'Y')
    """

    def __init__(self) -> None:
        self.pending = b""

    def feed(self, data: bytes) -> list[str]:
        """Add received bytes; return the complete lines they finish."""
        self.pending += data
        *lines, self.pending = self.pending.split(b"\n")
        if len(self.pending) > MAX_LINE:
            lines.append(self.pending)
            self.pending = b""
        return [line.removesuffix(b"\r").decode("latin-1") for line in lines]

    def reset(self) -> None:
        """Forget a partial line (after a reconnection)."""
        self.pending = b""
