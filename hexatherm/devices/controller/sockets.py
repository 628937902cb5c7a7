"""SocketController: socket, line protocol and in-position logic of the Symetrie and PI drivers."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from hexatherm.core.frames import platform_in_machine
from hexatherm.core.geometry import (
    Convention,
    check_convention,
    check_poses,
)
from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller.protocol import (
    ControllerState,
    InPositionCriteria,
    LineBuffer,
    StepRecord,
    convert_pose,
    format_pose,
    pose_deviation_um_urad,
    stroke_violations,
    wrap_deg,
)
from hexatherm.errors import (
    ControllerConnectionError,
    ControllerError,
    ControllerTimeoutError,
    PoseRefusedError,
)
from hexatherm.typing import FloatArray

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
        #: the user frame in the machine frame then the object frame in the platform frame
        #: (12 values, mm and deg, Symétrie convention) the controller reported when it
        #: connected; None: it reports none (PI: moved only in its ZERO system)
        self.frames_mm_deg: FloatArray | None = None
        #: what :meth:`check_ready` found (name -> state in words), for the run's record
        self.readiness: dict[str, str] = {}
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

    def _received(self, data: bytes) -> bytes:
        """What a dialect keeps of received bytes before they are cut into lines (all)."""
        return data

    def _readline(self, waiting_for: str) -> str:
        """The next received line; raises on a dropped or silent connection."""
        conn = self._require()
        while not conn.lines:
            conn.lines.extend(conn.buffer.feed(self._received(self._recv(waiting_for))))
        line = conn.lines.pop(0)
        if self.log is not None:
            self.log("rx", line)
        return line

    def _recv(self, waiting_for: str) -> bytes:
        """The next bytes received; raises on a dropped or silent connection."""
        conn = self._require()
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
        return data

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
    def check_ready(self) -> None:
        """Check that the controller will move as commanded; never moves.

        What was checked goes in :attr:`readiness`; raises :class:`ControllerError`
        naming every problem found. The base class has nothing to check (a dialect
        overrides it).
        """
        self.readiness = {}

    def platform_pose(self, pose_mm_deg: npt.ArrayLike) -> FloatArray:
        """The platform's pose in the machine frame (6,) that commanding ``pose_mm_deg``
        makes the controller drive, through the frames it reported
        (:attr:`frames_mm_deg`, ``U0 X O0^-1``); the pose itself without frames."""
        pose = self._check_pose(pose_mm_deg)
        if self.frames_mm_deg is None:
            return pose
        return platform_in_machine(self.frames_mm_deg, pose, self.convention)

    def validate(self, pose_mm_deg: npt.ArrayLike) -> None:
        """Raise :class:`PoseRefusedError` unless the pose can be reached; never moves.

        With a hexapod model, every leg's length (the inverse geometric model of the
        platform's pose the controller's frames make of it, :meth:`platform_pose`) must
        lie within the stroke; then the controller checks the pose itself.
        """
        pose = self._check_pose(pose_mm_deg)
        if self.hexapod is not None:
            platform = self.platform_pose(pose)
            legs = stroke_violations(self.hexapod, platform)
            if legs:
                framed = ""
                if self.frames_mm_deg is not None and self.frames_mm_deg.any():
                    framed = (
                        f" (the platform at {format_pose(platform)} in the machine frame, "
                        "through the controller's user and object frames)"
                    )
                raise PoseRefusedError(
                    f"pose {format_pose(pose)} refused before asking the controller: "
                    + "; ".join(legs)
                    + framed
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
