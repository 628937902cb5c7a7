"""Hexapod controllers: one protocol for every dialect, and what the dialects share.

A driver moves the hexapod and reports what its controller says: the pose, the actuator
(leg) lengths, the controller's temperatures. hexatherm drives two dialects over plain
TCP sockets (no vendor library): Symétrie API v2 (:mod:`hexatherm.devices.symetrie`)
and PI GCS (:mod:`hexatherm.devices.pi`); :func:`controller_from_url` picks one.

Poses at this interface are hexatherm's ``[Tx, Ty, Tz, Rx, Ry, Rz]`` in mm and deg,
in the convention of the hexapod (``symetrie``: fixed axes, ``R = Rz Ry Rx``; ``pi``:
mobile axes, ``R = Rx Ry Rz``; :mod:`hexatherm.core.geometry`). Each driver speaks its
controller's units and convention on the wire (Symétrie: m and rad, ``symetrie``
convention; PI: mm and deg, ``pi`` convention) and converts both ways; a driver given
another interface convention converts the angles through the rotation matrix.

"Not moving" is not "there". :meth:`HexapodController.wait_in_position` waits for the
controller's in-position flag, then a settle time, then requires ``n_readings``
consecutive read-back poses to agree within a tolerance (um, urad, peak to peak per
component), and their mean to lie within a tolerance of the commanded pose. It returns a
:class:`StepRecord` of the step. Clock and sleep are injectable, so the waiting can run
on simulated time.

Errors a user can meet derive from :class:`ControllerError` (a
:class:`~hexatherm.errors.HexathermError`): :class:`ControllerConnectionError` (refused,
dropped, silent connection), :class:`ControllerTimeoutError` (no in-position flag, an
unstable read-back), :class:`PoseRefusedError` (the pose fails validation: nothing was
moved) and :class:`ControllerReplyError` (the controller answered with an error code,
decoded into words).

>>> pose = [1.0, -2.0, 3.0, 0.5, -0.25, 10.0]
>>> back = convert_pose(convert_pose(pose, "symetrie", "pi"), "pi", "symetrie")
>>> bool(np.allclose(back, pose, atol=1e-12))
True
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
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
from hexatherm.errors import (
    ControllerConnectionError,
    ControllerError,
    ControllerTimeoutError,
    PoseRefusedError,
)
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


# ------------------------------------------------------------------ the base
LogCallback = Callable[[str, str], None]
"""``log(direction, line)``: ``direction`` is ``"tx"`` (sent) or ``"rx"`` (received)."""


@dataclass
class _Connection:
    sock: socket.socket
    buffer: LineBuffer = field(default_factory=LineBuffer)
    lines: list[str] = field(default_factory=list)


class SocketController:
    """What the socket drivers share: connection, line I/O, conversions and waiting.

    Subclasses implement the dialect: ``_handshake``, ``_validate_wire``,
    ``_move_wire``, ``_state``, ``_read_pose_wire``, ``_read_actuators_mm``,
    ``_read_temperatures_C`` and ``_stop_wire``; ``_wire_from_pose`` and
    ``_pose_from_wire`` convert units.

    Parameters
    ----------
    host, port : str, int
        The controller's address.
    hexapod : Hexapod, optional
        Geometry of the hexapod: when given, :meth:`validate` also checks the stroke of
        every leg (the inverse geometric model), before asking the controller.
    convention : {"symetrie", "pi"}, optional
        Convention of the poses at this interface; default the hexapod's, else the
        dialect's own.
    reply_timeout_s : float
        Longest wait for one reply, s (wall clock: it is the socket's timeout).
    clock, sleep : callable
        Time source (s) and sleep (s) of the waiting; inject them to run on simulated
        time.
    log : callable, optional
        Called with every line sent and received (see :data:`LogCallback`).
    """

    dialect = ""
    scheme = ""
    default_port = 0
    native_convention: Convention = "symetrie"

    def __init__(
        self,
        host: str,
        port: int | None = None,
        *,
        hexapod: Hexapod | None = None,
        convention: str | None = None,
        reply_timeout_s: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        log: LogCallback | None = None,
    ) -> None:
        if not host:
            raise ValueError("controller host is empty")
        port = self.default_port if port is None else int(port)
        if not 0 < port < 65536:
            raise ValueError(f"controller port must be in 1..65535, got {port}")
        if not (reply_timeout_s > 0):
            raise ValueError(f"reply_timeout_s must be > 0, got {reply_timeout_s!r}")
        if convention is None:
            convention = hexapod.convention if hexapod is not None else self.native_convention
        self.convention: Convention = check_convention(convention)
        if hexapod is not None and hexapod.convention != self.convention:
            raise ValueError(
                f"the hexapod's convention is {hexapod.convention!r}, the controller "
                f"interface's {self.convention!r}: they must agree"
            )
        self.host, self.port = host, port
        self.hexapod = hexapod
        self.reply_timeout_s = float(reply_timeout_s)
        self.clock, self.sleep, self.log = clock, sleep, log
        self.url = f"{self.scheme}://{host}:{port}"
        self.commanded_pose_mm_deg: FloatArray | None = None
        self.info: dict[str, str] = {}
        self._conn: _Connection | None = None
        self._lock = threading.RLock()

    # ------------------------------------------------------------ connection
    def connect(self) -> None:
        """Open the connection (closing a previous one) and greet the controller."""
        with self._lock:
            self._drop()
            try:
                sock = socket.create_connection(
                    (self.host, self.port), timeout=self.reply_timeout_s
                )
            except OSError as exc:
                raise ControllerConnectionError(
                    f"cannot connect to the {self.dialect} controller at {self.url}: {exc}"
                ) from exc
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conn = _Connection(sock)
            try:
                self._handshake()
            except BaseException:
                self._drop()
                raise

    @property
    def connected(self) -> bool:
        """Whether a connection is open (it may still have dropped unnoticed)."""
        return self._conn is not None

    def close(self) -> None:
        """Close the connection; no motion command is sent (see :meth:`stop`)."""
        with self._lock:
            self._drop()

    def __enter__(self) -> SocketController:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _drop(self) -> None:
        if self._conn is not None:
            try:
                self._conn.sock.close()
            except OSError:  # pragma: no cover - closing a dead socket
                pass
            self._conn = None

    def _require(self) -> _Connection:
        if self._conn is None:
            raise ControllerConnectionError(
                f"not connected to the {self.dialect} controller at {self.url} "
                "(connect() first, or again after a dropped connection)"
            )
        return self._conn

    def _send(self, text: str) -> None:
        """Send one line (the terminator is added)."""
        conn = self._require()
        if self.log is not None:
            self.log("tx", text)
        try:
            conn.sock.sendall(text.encode("ascii") + self.terminator)
        except OSError as exc:
            self._drop()
            raise ControllerConnectionError(
                f"connection to the {self.dialect} controller at {self.url} lost while "
                f"sending {text!r}: {exc}"
            ) from exc

    terminator = b"\n"

    def _readline(self, waiting_for: str) -> str:
        """The next received line; raises on a dropped or silent connection."""
        conn = self._require()
        while not conn.lines:
            try:
                conn.sock.settimeout(self.reply_timeout_s)
                data = conn.sock.recv(4096)
            except TimeoutError as exc:
                self._drop()
                raise ControllerTimeoutError(
                    f"no reply from the {self.dialect} controller at {self.url} to "
                    f"{waiting_for!r} within {self.reply_timeout_s:g} s"
                ) from exc
            except OSError as exc:
                self._drop()
                raise ControllerConnectionError(
                    f"connection to the {self.dialect} controller at {self.url} lost "
                    f"waiting for the reply to {waiting_for!r}: {exc}"
                ) from exc
            if not data:
                self._drop()
                raise ControllerConnectionError(
                    f"the {self.dialect} controller at {self.url} closed the connection "
                    f"while hexatherm waited for the reply to {waiting_for!r}"
                )
            conn.lines.extend(conn.buffer.feed(data))
        line = conn.lines.pop(0)
        if self.log is not None:
            self.log("rx", line)
        return line

    def _discard_pending(self) -> None:
        """Drop whatever has been received and not read (before a stop)."""
        conn = self._conn
        if conn is None:
            return
        conn.lines.clear()
        conn.buffer.reset()
        try:
            conn.sock.setblocking(False)
            while conn.sock.recv(4096):
                pass
        except (BlockingIOError, InterruptedError):
            pass
        except OSError:
            self._drop()
            return
        finally:
            if self._conn is not None:
                conn.sock.setblocking(True)

    # ------------------------------------------------------------- conversion
    def _to_native(self, pose_mm_deg: npt.ArrayLike) -> FloatArray:
        return convert_pose(pose_mm_deg, self.convention, self.native_convention)

    def _from_native(self, pose_mm_deg: npt.ArrayLike) -> FloatArray:
        return convert_pose(pose_mm_deg, self.native_convention, self.convention)

    def _check_pose(self, pose_mm_deg: npt.ArrayLike) -> FloatArray:
        pose = check_poses(pose_mm_deg)
        if pose.shape != (6,):
            raise ValueError(f"one pose of shape (6,) expected, got {pose.shape}")
        return pose

    # -------------------------------------------------------------- protocol
    def validate(self, pose_mm_deg: npt.ArrayLike) -> None:
        """Raise :class:`PoseRefusedError` unless the pose can be reached; never moves.

        With a hexapod model, every leg's length (its inverse geometric model) must lie
        within the stroke; then the controller checks the pose itself.
        """
        pose = self._check_pose(pose_mm_deg)
        if self.hexapod is not None:
            legs = stroke_violations(self.hexapod, pose)
            if legs:
                raise PoseRefusedError(
                    f"pose {format_pose(pose)} refused before asking the controller: "
                    + "; ".join(legs)
                )
        with self._lock:
            self._validate_wire(self._to_native(pose), pose)

    def move_absolute(self, pose_mm_deg: npt.ArrayLike) -> None:
        """Validate the pose, then command the move to it (returns once accepted)."""
        pose = self._check_pose(pose_mm_deg)
        self.validate(pose)
        with self._lock:
            self.commanded_pose_mm_deg = None
            self._move_wire(self._to_native(pose), pose)
            self.commanded_pose_mm_deg = pose

    def state(self) -> ControllerState:
        """The controller's flags."""
        with self._lock:
            return self._state()

    def read_pose(self) -> FloatArray:
        """The controller's current pose (6,), mm and deg in :attr:`convention`."""
        with self._lock:
            return self._from_native(self._read_pose_wire())

    def read_actuators(self) -> FloatArray:
        """Actuator lengths (6,), mm; NaN when the controller reports none."""
        with self._lock:
            return self._read_actuators_mm()

    def read_temperatures(self) -> FloatArray:
        """The controller's temperature channels (k,), deg C; empty when it has none."""
        with self._lock:
            return self._read_temperatures_C()

    def stop(self) -> None:
        """Stop any motion. Safe at any time: after Ctrl-C, an error, a dropped link.

        Unread replies are discarded first; with no usable connection (never opened,
        dropped, or held by a transaction of another thread for longer than the reply
        timeout), one fresh connection is opened for the stop. Raises
        :class:`ControllerConnectionError` only when the stop could not be delivered
        (the hexapod may then still be moving).
        """
        locked = self._lock.acquire(timeout=self.reply_timeout_s)
        try:
            if not locked:  # another thread is stuck in a transaction: a new link
                self._stop_on_fresh_connection()
                return
            self.commanded_pose_mm_deg = None
            if self._conn is not None:
                self._discard_pending()
            if self._conn is not None:
                try:
                    self._stop_wire()
                    return
                except ControllerConnectionError:
                    pass
                except ControllerTimeoutError:
                    pass
            self.connect()
            self._stop_wire()
        except (ControllerConnectionError, ControllerTimeoutError) as exc:
            raise ControllerConnectionError(
                f"could not deliver STOP to the {self.dialect} controller at {self.url}: "
                f"{exc}; THE HEXAPOD MAY STILL BE MOVING"
            ) from exc
        finally:
            if locked:
                self._lock.release()

    def _stop_on_fresh_connection(self) -> None:
        other = type(self)(
            self.host,
            self.port,
            convention=self.convention,
            reply_timeout_s=self.reply_timeout_s,
            clock=self.clock,
            sleep=self.sleep,
            log=self.log,
        )
        try:
            other.connect()
            other._stop_wire()
        finally:
            other.close()

    def wait_in_position(self, criteria: InPositionCriteria | None = None) -> StepRecord:
        """Wait until the hexapod is at the last commanded pose; the step's record.

        In order: the controller's in-position flag (an error flag raises at once),
        ``criteria.settle_s``, then read-backs every ``poll_s`` until the last
        ``n_readings`` agree within ``tolerance_um`` / ``tolerance_urad``; their mean must
        lie within ``target_tolerance_um`` / ``target_tolerance_urad`` of the command.
        Then the actuator lengths and temperatures are read.

        Raises
        ------
        ControllerTimeoutError
            No flag, or no stable read-back, within ``timeout_s`` (settle excluded).
        ControllerError
            No move commanded, an error flag, a read-back away from the command.
        ControllerConnectionError
            The connection dropped: the hexapod may still be moving.
        """
        c = InPositionCriteria() if criteria is None else criteria
        commanded = self.commanded_pose_mm_deg
        if commanded is None:
            raise ControllerError("wait_in_position without a move_absolute before it")
        start = self.clock()
        deadline = start + c.timeout_s
        while True:
            st = self.state()
            if st.error:
                raise ControllerError(
                    f"the {self.dialect} controller reports an error while moving to "
                    f"{format_pose(commanded)}: {st.message}"
                )
            if st.in_position and not st.moving:
                break
            if self.clock() >= deadline:
                raise ControllerTimeoutError(
                    f"no in-position flag within {c.timeout_s:g} s after the move to "
                    f"{format_pose(commanded)} (last state: {st.message or 'none'})"
                )
            self.sleep(c.poll_s)
        flag_after_s = self.clock() - start
        if c.settle_s > 0:
            self.sleep(c.settle_s)
        deadline += c.settle_s
        readings: list[FloatArray] = []
        while True:
            readings.append(self.read_pose())
            readings = readings[-c.n_readings :]
            if len(readings) == c.n_readings:
                stack = np.array(readings)
                spread = _spread_um_urad(stack)
                if (spread[:3] <= c.tolerance_um).all() and (spread[3:] <= c.tolerance_urad).all():
                    break
            if self.clock() >= deadline:
                detail = "fewer readings than n_readings"
                if len(readings) == c.n_readings:
                    detail = (
                        f"spread {spread[:3].max():.3f} um / {spread[3:].max():.3f} urad "
                        f"over {c.n_readings} readings, tolerance {c.tolerance_um:g} um / "
                        f"{c.tolerance_urad:g} urad"
                    )
                raise ControllerTimeoutError(
                    f"the read-back pose did not settle within {c.timeout_s:g} s after the "
                    f"move to {format_pose(commanded)}: {detail}"
                )
            self.sleep(c.poll_s)
        time_s = self.clock()
        st = self.state()
        if st.error or not st.in_position:
            raise ControllerError(
                f"the {self.dialect} controller left the in-position state while the "
                f"read-back was checked at {format_pose(commanded)}: {st.message}"
            )
        mean = _mean_pose(stack)
        deviation = pose_deviation_um_urad(mean, commanded)
        if (np.abs(deviation[:3]) > c.target_tolerance_um).any() or (
            np.abs(deviation[3:]) > c.target_tolerance_urad
        ).any():
            raise ControllerError(
                f"the hexapod settled at {format_pose(mean)}, not at the commanded "
                f"{format_pose(commanded)}: deviation "
                + ", ".join(f"{v:.2f}" for v in deviation)
                + f" (um, urad), tolerance {c.target_tolerance_um:g} um / "
                f"{c.target_tolerance_urad:g} urad"
            )
        return StepRecord(
            commanded_pose_mm_deg=np.array(commanded),
            readings_pose_mm_deg=stack,
            pose_mm_deg=mean,
            deviation_um_urad=deviation,
            spread_um_urad=spread,
            actuators_mm=self.read_actuators(),
            temperatures_C=self.read_temperatures(),
            flag_after_s=float(flag_after_s),
            time_s=float(time_s),
            convention=self.convention,
        )

    # ------------------------------------------------------ dialect (abstract)
    def _handshake(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _validate_wire(self, native: FloatArray, pose: FloatArray) -> None:  # pragma: no cover
        raise NotImplementedError

    def _move_wire(self, native: FloatArray, pose: FloatArray) -> None:  # pragma: no cover
        raise NotImplementedError

    def _state(self) -> ControllerState:  # pragma: no cover
        raise NotImplementedError

    def _read_pose_wire(self) -> FloatArray:  # pragma: no cover
        raise NotImplementedError

    def _read_actuators_mm(self) -> FloatArray:  # pragma: no cover
        raise NotImplementedError

    def _read_temperatures_C(self) -> FloatArray:  # pragma: no cover
        raise NotImplementedError

    def _stop_wire(self) -> None:  # pragma: no cover
        raise NotImplementedError


def _spread_um_urad(stack: FloatArray) -> FloatArray:
    """Peak-to-peak spread (6,) of poses (n, 6): um and urad (angles unwrapped)."""
    rel = pose_deviation_um_urad(stack, stack[0])
    return np.ptp(rel, axis=0)


def _mean_pose(stack: FloatArray) -> FloatArray:
    """Mean of poses (n, 6) (angles averaged relative to the first, so +-180 is safe)."""
    mean = stack.mean(axis=0)
    mean[3:] = stack[0, 3:] + wrap_deg(stack[:, 3:] - stack[0, 3:]).mean(axis=0)
    return mean


def parse_numbers(text: str, what: str, count: int | None = None) -> FloatArray:
    """Comma-separated numbers of a reply, checked finite (and counted when asked).

    >>> parse_numbers("1,-2.5e-3, 4", "STA#AXES?").tolist()
    [1.0, -0.0025, 4.0]
    """
    try:
        values = np.array([float(v) for v in text.split(",")], dtype=float)
    except ValueError as exc:
        raise ControllerError(f"malformed reply to {what}: {text!r} ({exc})") from exc
    if count is not None and values.size != count:
        raise ControllerError(
            f"malformed reply to {what}: {values.size} numbers, expected {count}: {text!r}"
        )
    if not np.all(np.isfinite(values)):
        raise ControllerError(f"malformed reply to {what}: a non-finite number in {text!r}")
    return values


# ------------------------------------------------------------------------ URL
