"""The I++ DME client: socket, reader thread, tags, timeouts, recovery policy, transcript."""

from __future__ import annotations

import math
import queue
import re
import socket
import threading
from collections.abc import Callable, Mapping

from hexatherm.devices.ipp.protocol import (
    ALLOWED_IN_ERROR,
    DEFAULT_PORT,
    REPORT_ARITY,
    Call,
    ClearAndRetry,
    Direction,
    ErrorReport,
    LineBuffer,
    RecoveryPolicy,
    Value,
    fields,
    format_number,
)
from hexatherm.devices.ipp.transcript import (
    IppEvent,
    ProbedPoint,
    Recorder,
    TransactionResult,
    TranscriptEntry,
    TranscriptSink,
    _method_of,
    now_iso,
)
from hexatherm.errors import (
    IppCommandError,
    IppConnectError,
    IppConnectionLost,
    IppDmeError,
    IppErrorState,
    IppProtocolError,
    IppTimeout,
)


class _Waiter:
    def __init__(self, tag: str, command: str) -> None:
        self.tag = tag
        self.command = command
        self.done = threading.Event()
        self.result: TransactionResult | None = None
        self.error: IppDmeError | None = None


# ------------------------------------------------------------------------ client
class IppClient:
    """A client of an I++ DME server (one TCP connection).

    Parameters
    ----------
    host : str
        Server address.
    port : int
        Server port (1294 by default).
    timeout_s : float
        Default time a transaction may take from sending to its ``%``, s.
    connect_timeout_s : float
        Time to open the connection, s.
    transcript : callable or text file, optional
        Every line sent and received, and the client's notes, in the transcript format of
        the module docstring (the caller writes :data:`TRANSCRIPT_MAGIC` first, or uses a
        :class:`TranscriptFile`).
    on_event : callable, optional
        Called (from the reader thread) with every :class:`IppEvent`; without it the events
        go to the queue :attr:`events`. If it raises, the next command raises instead of
        being sent.
    policy : RecoveryPolicy, optional
        What to do about errors of severity >= 2 (default :class:`ClearAndRetry`).
    clock : callable, optional
        Timestamps (default :func:`now_iso`).
    on_warning : callable, optional
        Called with the transaction and each error of severity 0 or 1 it carried (the
        command succeeded; the lines are in the transcript like every other).

    Notes
    -----
    Commands are sent one at a time: each method sends its command with a fresh tag and waits
    for its ``%``. A reader thread splits the stream into lines, stamps, logs and feeds them to
    the :class:`Recorder` under one lock (so the transcript order is the order acted on), and
    wakes the waiting command. Events never complete or disturb a transaction.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        *,
        timeout_s: float = 60.0,
        connect_timeout_s: float = 10.0,
        transcript: TranscriptSink | None = None,
        on_event: Callable[[IppEvent], object] | None = None,
        policy: RecoveryPolicy | None = None,
        clock: Callable[[], str] = now_iso,
        on_warning: Callable[[TransactionResult, ErrorReport], object] | None = None,
    ) -> None:
        if not (isinstance(port, int) and 0 < port < 65536):
            raise IppDmeError(f"port must be an integer in 1..65535, got {port!r}")
        if not (timeout_s > 0 and connect_timeout_s > 0):
            raise IppDmeError("timeouts must be positive")
        self.host, self.port = host, port
        self.timeout_s = float(timeout_s)
        self.policy: RecoveryPolicy = policy if policy is not None else ClearAndRetry()
        self.events: queue.SimpleQueue[IppEvent] = queue.SimpleQueue()
        self._on_event = on_event
        self._on_warning = on_warning
        self._clock = clock
        self._sink = transcript
        self._lock = threading.Lock()
        self.recorder = Recorder()
        self._waiters: dict[str, _Waiter] = {}
        self._next_tag = 1
        self._next_etag = 1
        self._closing = False
        self.callback_error: Exception | None = None
        try:
            self._sock = socket.create_connection((host, port), timeout=connect_timeout_s)
        except OSError as exc:
            raise IppConnectError(f"cannot connect to the CMM at {host}:{port}: {exc}") from None
        self._sock.settimeout(None)
        self._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        with self._lock:
            self._log("*", f"connect {host}:{port}")
        self._reader = threading.Thread(target=self._read_loop, name="ipp-reader", daemon=True)
        self._reader.start()

    # -- plumbing
    def __enter__(self) -> IppClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def points(self) -> list[ProbedPoint]:
        """Every point probed so far (successful ``PtMeas``), in order."""
        return self.recorder.points

    @property
    def error_state(self) -> ErrorReport | None:
        """The error the server is stuck on (severity >= 2, until ``ClearAllErrors()``)."""
        return self.recorder.error_state

    def _log(self, direction: Direction, text: str) -> str:
        stamp = self._clock()
        if self._sink is not None:
            line = TranscriptEntry(stamp, direction, text).format()
            if callable(self._sink):
                self._sink(line)
            else:
                self._sink.write(line)
                self._sink.flush()
        return stamp

    def close(self) -> None:
        """End the connection (pending transactions fail with :class:`IppConnectionLost`)."""
        with self._lock:
            if self._closing:
                return
            self._closing = True
            if self.recorder.lost is None:
                stamp = self._log("*", "close")
                dropped = self.recorder.note(stamp, "close")
                self._fail(dropped, "the client closed the connection")
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        if threading.current_thread() is not self._reader:
            self._reader.join(timeout=5.0)

    def _fail(self, dropped: list[TransactionResult], reason: str) -> None:
        for result in dropped:
            waiter = self._waiters.pop(result.tag, None)
            if waiter is not None:
                waiter.error = IppConnectionLost(
                    f"connection to the CMM at {self.host}:{self.port} lost ({reason}) while "
                    f"waiting for {waiter.tag} {waiter.command}"
                )
                waiter.done.set()

    def _lose(self, reason: str) -> None:
        with self._lock:
            if self.recorder.lost is not None:
                return
            try:
                stamp = self._log("*", f"lost {reason}")
            except Exception:  # noqa: BLE001 - the transcript itself may be what failed
                stamp = self._clock()
            dropped = self.recorder.note(stamp, f"lost {reason}")
            self._fail(dropped, reason)

    def _read_loop(self) -> None:
        buffer = LineBuffer()
        while True:
            try:
                data = self._sock.recv(65536)
            except OSError as exc:
                if not self._closing:
                    self._lose(f"socket error: {exc}")
                return
            if not data:
                if not self._closing:
                    pending = buffer.pending
                    tail = f" ({len(pending)} bytes of an unfinished line)" if pending else ""
                    self._lose(f"connection closed by the server{tail}")
                return
            try:
                lines = buffer.feed(data)
            except IppProtocolError as exc:
                self._lose(f"protocol error: {exc}")
                return
            for raw in lines:
                try:
                    self._on_line(raw.decode("latin-1"))
                except Exception as exc:  # noqa: BLE001 - e.g. the transcript cannot be written
                    self._lose(f"{type(exc).__name__} while recording a line: {exc}")
                    return

    def _on_line(self, line: str) -> None:
        with self._lock:
            stamp = self._log("<", line)
            result, event = self.recorder.received(stamp, line)
            waiter = self._waiters.pop(result.tag, None) if result is not None else None
            if waiter is not None:
                waiter.result = result
                waiter.done.set()
        if event is not None:
            if self._on_event is None:
                self.events.put(event)
                return
            try:
                self._on_event(event)
            except Exception as exc:  # noqa: BLE001 - handed to the caller, see transact()
                with self._lock:
                    if self.callback_error is None:
                        self.callback_error = exc

    def _new_tag(self, event: bool) -> str:
        for _ in range(100000):
            if event:
                tag = f"E{self._next_etag:04d}"
                self._next_etag = self._next_etag % 9999 + 1
            else:
                tag = f"{self._next_tag:05d}"
                self._next_tag = self._next_tag % 99999 + 1
            if tag not in self.recorder.open and tag not in self.recorder.abandoned:
                return tag
        raise IppDmeError("no free tag")  # pragma: no cover - 99999 open transactions

    # -- transactions
    def transact(
        self, command: str, *, timeout_s: float | None = None, event: bool = False
    ) -> TransactionResult:
        """Send one command with a fresh tag and wait for its ``%`` (no recovery).

        Parameters
        ----------
        command : str
            ``Method(args)``.
        timeout_s : float, optional
            Time from sending to ``%`` (default: the client's).
        event : bool
            Send it on the fast queue with an ``E`` tag.

        Returns
        -------
        TransactionResult
            Errors included (see :attr:`TransactionResult.failure`).

        Raises
        ------
        IppTimeout
            No ``%`` in time: the tag is abandoned (its late lines are logged and ignored).
        IppConnectionLost
            The connection was or got lost; the message names the pending command. A line
            that cannot be recorded (the transcript sink raised) also ends the connection:
            nothing is acted on that is not in the transcript.
        IppDmeError
            The event callback raised since the last command (chained).
        """
        limit = self.timeout_s if timeout_s is None else float(timeout_s)
        if not limit > 0:
            raise IppDmeError(f"timeout_s must be positive, got {timeout_s!r}")
        if "\r" in command or "\n" in command:
            raise IppDmeError("a command cannot contain CR or LF")
        with self._lock:
            if self.recorder.lost is not None or self._closing:
                raise IppConnectionLost(
                    f"connection to the CMM at {self.host}:{self.port} is closed "
                    f"({self.recorder.lost or 'closed'}); cannot send {command}"
                )
            tag = self._new_tag(event)
            line = f"{tag} {command}"
            if self.callback_error is not None:
                exc, self.callback_error = self.callback_error, None
                raise IppDmeError(f"the event callback raised {type(exc).__name__}: {exc}") from exc
            stamp = self._log(">", line)
            waiter = _Waiter(tag, command)
            self._waiters[tag] = waiter
            self.recorder.sent(stamp, line)
            try:
                self._sock.sendall(line.encode("ascii") + b"\r\n")
            except OSError as exc:
                reason = f"socket error while sending: {exc}"
                stamp = self._log("*", f"lost {reason}")
                self._fail(self.recorder.note(stamp, f"lost {reason}"), reason)
        if not waiter.done.wait(limit):
            with self._lock:
                if not waiter.done.is_set():
                    self._waiters.pop(tag, None)
                    stamp = self._log("*", f"abandon {tag} timeout after {limit:g} s")
                    self.recorder.note(stamp, f"abandon {tag} timeout after {limit:g} s")
                    raise IppTimeout(f"the CMM did not complete {tag} {command} within {limit:g} s")
        if waiter.error is not None:
            raise waiter.error
        assert waiter.result is not None
        return waiter.result

    def call(self, command: str, *, timeout_s: float | None = None) -> TransactionResult:
        """Send a command and recover from errors by the policy.

        Errors of severity 0 and 1 are kept in the result's ``warnings``. On an error of
        severity >= 2, or when the server is already in an error state, the policy decides:
        ``ClearAllErrors()`` and the command again with a new tag, or raise.

        Raises
        ------
        IppCommandError
            The command failed and the policy said raise (the error and result attached).
        IppErrorState
            The server is in an error state and the policy does not clear it.
        IppProtocolError
            The answer breaks the protocol.
        IppTimeout, IppConnectionLost
            As for :meth:`transact`.
        """
        attempt = 0
        method = _method_of(command)
        while True:
            state = self.error_state
            if state is not None and method not in ALLOWED_IN_ERROR:
                if self.policy.decide(state, command, attempt) != "retry":
                    raise IppErrorState(
                        f"the CMM is in an error state ({state}); {command} not sent. "
                        "Clear it with ClearAllErrors() once the cause is removed",
                        error=state,
                    )
                self.clear_all_errors()
                attempt += 1
                continue
            result = self.transact(command, timeout_s=timeout_s)
            failure = self._failure_of(result, command)
            if failure is None:
                return result
            if self.policy.decide(failure, command, attempt) != "retry":
                raise IppCommandError(
                    f"the CMM refused {result.tag} {command}: {failure}"
                    + (f" (after {attempt} recovery)" if attempt else ""),
                    error=failure,
                    result=result,
                )
            self.clear_all_errors()
            attempt += 1

    def _failure_of(self, result: TransactionResult, command: str) -> ErrorReport | None:
        """The error that failed ``result`` (None: it succeeded, and its warnings of
        severity 0/1 are said to ``on_warning``); IppProtocolError on a broken answer."""
        if result.protocol_error is not None:
            raise IppProtocolError(f"{result.tag} {command}: {result.protocol_error}")
        failure = result.failure
        if failure is None and self._on_warning is not None:
            for warning in result.warnings:
                self._on_warning(result, warning)
        return failure

    def optional(self, command: str) -> tuple[TransactionResult | None, ErrorReport | None]:
        """Send a command whose refusal is not the end of anything (an optional query).

        Returns
        -------
        (result, None) or (None, error)
            On a refusal the server's error state, if any, is cleared (``ClearAllErrors()``)
            and the error returned.
        """
        result = self.transact(command)
        failure = self._failure_of(result, command)
        if failure is None:
            return result, None
        if self.error_state is not None:
            self.clear_all_errors()
        return None, failure

    # -- commands
    def start_session(self) -> bool:
        """``StartSession()`` (resets the report to ``X(), Y(), Z()`` and clears errors).

        A server that keeps its session across connections refuses a new one while the
        session of a connection gone (a run stopped, a dropped link) is open: that stale
        session is ended (``ClearAllErrors()``, ``EndSession()``) and a new one started.

        Returns
        -------
        bool
            True when a stale session was ended first.
        """
        result = self.transact("StartSession()")
        if result.protocol_error is not None:
            raise IppProtocolError(f"{result.tag} StartSession(): {result.protocol_error}")
        if result.failure is None:
            return False
        self.clear_all_errors()
        self.call("EndSession()")
        self.call("StartSession()")
        return True

    def end_session(self) -> None:
        """``EndSession()``, after ``ClearAllErrors()`` if the server is in an error state
        (6.2.5 allows only ClearAllErrors, GetErrStatusE and GetXtdErrStatus there)."""
        if self.error_state is not None:
            self.clear_all_errors()
        self.call("EndSession()")

    def dme_version(self) -> tuple[str, tuple[int, ...]] | None:
        """``GetDMEVersion()``: ``(text, numbers)``, e.g. ``("1.4.3", (1, 4, 3))``; None when
        the server refuses it (cleared) or answers something that is not a version."""
        result, _ = self.optional("GetDMEVersion()")
        if result is None:
            return None
        for _, values in result.data:
            for item in values:
                if isinstance(item, Call) and item.name == "DMEVersion" and len(item.args) == 1:
                    text = item.args[0]
                    if isinstance(text, str) and re.fullmatch(r"[0-9]+(\.[0-9]+)*", text):
                        return text, tuple(int(x) for x in text.split("."))
        return None

    def enum_tools(self) -> list[str] | None:
        """``EnumTools()``: the tools' names, or None when the server refuses it (cleared)."""
        result, _ = self.optional("EnumTools()")
        if result is None:
            return None
        names = [v for _, values in result.data for v in values if isinstance(v, str)]
        return [str(n) for n in names]

    def clear_all_errors(self) -> None:
        """``ClearAllErrors()``, sent whatever the state; raises if it fails."""
        result = self.transact("ClearAllErrors()")
        if result.failure is not None:
            raise IppCommandError(
                f"ClearAllErrors() failed: {result.failure}", error=result.failure, result=result
            )

    def home(self, *, timeout_s: float | None = 600.0) -> None:
        """``Home()`` (moves the machine to its home position; 10 min by default)."""
        self.call("Home()", timeout_s=timeout_s)

    def is_homed(self) -> bool:
        """``IsHomed()``."""
        value = self._single(self.call("IsHomed()"), "IsHomed")
        return bool(value[0])

    def get_err_status(self) -> bool:
        """``GetErrStatusE()`` on the fast queue: True when the server is in error."""
        result = self.transact("GetErrStatusE()", event=True)
        return bool(self._single(result, "ErrStatus")[0])

    def change_tool(self, name: str, *, timeout_s: float | None = 300.0) -> None:
        """``ChangeTool("name")``."""
        self.call(f'ChangeTool("{_check_string(name)}")', timeout_s=timeout_s)

    def find_tool(self, name: str) -> None:
        """``FindTool("name")`` (makes ``FoundTool`` point at it)."""
        self.call(f'FindTool("{_check_string(name)}")')

    def set_prop(self, values: Mapping[str, float]) -> None:
        """``SetProp(Name(value), ...)``, e.g. ``{"Tool.PtMeasPar.Approach": 2.0}`` (mm, mm/s)."""
        if not values:
            raise IppDmeError("set_prop needs at least one property")
        args = ", ".join(f"{_check_name(k)}({format_number(v)})" for k, v in values.items())
        self.call(f"SetProp({args})")

    def get_prop(self, *names: str) -> dict[str, tuple[Value, ...]]:
        """``GetProp(Name(), ...)``: ``{name: values}`` as the server reported them."""
        if not names:
            raise IppDmeError("get_prop needs at least one property")
        result = self.call(f"GetProp({', '.join(f'{_check_name(n)}()' for n in names)})")
        out: dict[str, tuple[Value, ...]] = {}
        for _, values in result.data:
            for item in values:
                if isinstance(item, Call):
                    out[item.name] = item.args
        missing = [n for n in names if n not in out]
        if missing:
            raise IppProtocolError(f"GetProp answer lacks {', '.join(missing)}")
        return out

    def on_pt_meas_report(self, *names: str) -> None:
        """``OnPtMeasReport(X(), Y(), Z(), IJK(), ER())`` (the default) or the given fields."""
        chosen = names or ("X", "Y", "Z", "IJK", "ER")
        unknown = [n for n in chosen if n not in REPORT_ARITY]
        if unknown or len(set(chosen)) != len(chosen):
            raise IppDmeError(f"report fields must be distinct among {sorted(REPORT_ARITY)}")
        if not {"X", "Y", "Z"} <= set(chosen):
            raise IppDmeError("the report must hold X, Y and Z")
        self.call(f"OnPtMeasReport({', '.join(f'{n}()' for n in chosen)})")

    def goto(self, x: float, y: float, z: float, *, timeout_s: float | None = None) -> None:
        """``GoTo(X(x), Y(y), Z(z))``: move the active tool's centre there (mm)."""
        self.call(f"GoTo({_xyz(x, y, z)})", timeout_s=timeout_s)

    def get_position(self) -> tuple[float, float, float]:
        """``Get(X(), Y(), Z())``: the active tool's centre, mm."""
        result = self.call("Get(X(), Y(), Z())")
        if len(result.data) != 1:
            raise IppProtocolError(f"Get answered {len(result.data)} data lines instead of 1")
        got = fields(result.data[0][1])
        return got["X"][0], got["Y"][0], got["Z"][0]

    def pt_meas(
        self,
        x: float,
        y: float,
        z: float,
        i: float,
        j: float,
        k: float,
        *,
        timeout_s: float | None = None,
    ) -> ProbedPoint:
        """``PtMeas(X(x), Y(y), Z(z), IJK(i, j, k))``: probe one point.

        Parameters
        ----------
        x, y, z : float
            Nominal surface point, mm.
        i, j, k : float
            Approach direction, pointing out of the material (the probe moves along minus it).

        Returns
        -------
        ProbedPoint
            ``point_mm`` and, if reported, ``ijk`` (``normal`` normalized) and ``er_mm``.
        """
        n = math.sqrt(float(i) ** 2 + float(j) ** 2 + float(k) ** 2)
        if not (math.isfinite(n) and n > 0):
            raise IppDmeError(f"IJK must be a finite non-zero vector, got ({i}, {j}, {k})")
        ijk = f"IJK({format_number(i)}, {format_number(j)}, {format_number(k)})"
        result = self.call(f"PtMeas({_xyz(x, y, z)}, {ijk})", timeout_s=timeout_s)
        if result.point is None:  # pragma: no cover - protocol errors raise in call()
            raise IppProtocolError(f"{result.tag} PtMeas gave no point")
        return result.point

    @staticmethod
    def _single(result: TransactionResult, name: str) -> tuple[float, ...]:
        for _, values in result.data:
            for item in values:
                if isinstance(item, Call) and item.name == name:
                    return fields([item])[name]
        raise IppProtocolError(f"{result.tag} {result.command}: no {name}(...) in the answer")


def _xyz(x: float, y: float, z: float) -> str:
    return f"X({format_number(x)}), Y({format_number(y)}), Z({format_number(z)})"


def _check_string(text: str) -> str:
    if '"' in text or any(not 32 <= ord(c) <= 126 for c in text) or not text:
        raise IppDmeError(f"not a valid I++ string: {text!r}")
    return text


def _check_name(name: str) -> str:
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9]*(\.[A-Za-z][A-Za-z0-9]*)*", name):
        raise IppDmeError(f"not a valid I++ property name: {name!r}")
    return name
