"""I++ DME client: drive a CMM over TCP (I++ DME specification 1.4.3).

The protocol in short (spec sections in brackets)
-------------------------------------------------
- TCP, port 1294 by default [6.1]; printable ASCII lines ended by CR LF [6.1.1];
  lengths in mm, angles in degrees [6.1.2].
- A command is ``TAG Method(args)`` [6.2.2.1]; ``TAG`` is ``00001`` .. ``99999`` for the
  normal queue or ``E0001`` .. ``E9999`` for the fast (event) queue [6.2.1].
- Every response line starts with the tag of its command, a space and one of ``&`` (ack),
  ``#`` (data), ``%`` (transaction complete) or ``!`` (error,
  ``Error(severity, number, "method", "text")``) [6.2.2.2, 8.1]. A transaction is complete
  at its ``%`` [6.2.3]. Lines tagged ``E0000`` are unsolicited server events and may come at
  any time, between the data lines of an open transaction too [6.2.4].
- An error of severity >= 2 aborts the pending transactions; the server then only accepts
  ``ClearAllErrors()`` (and the error-status queries) until it gets one [6.2.5].
- ``PtMeas(X(x), Y(y), Z(z), IJK(i, j, k))`` probes one point: the probe goes to the
  approach position ``(x, y, z) + (approach + tip radius) ijk`` and searches along
  ``-ijk`` [6.3.2.13]; the report holds the fields set by ``OnPtMeasReport`` [6.3.2.6].
  hexatherm reads ``X Y Z`` as the probed **surface point** (the tool radius compensated,
  as in the spec's example 7.5: ``PtMeas(X(200), ...)`` answers ``X(199.998), ...``),
  ``IJK`` as the measured surface normal (out of the material) and ``ER`` as the effective
  tool radius, all in the CMM's active coordinate system, mm.

Modules of this package
-----------------------
- :func:`parse_response`, :func:`parse_command`, :func:`parse_data`: pure parsers of one
  line (spaces allowed around commas and parentheses, numbers with exponents and signs).
- :class:`LineBuffer`: bytes in, whole lines out (lines split across reads).
- :class:`Recorder`: the protocol's state machine, without I/O. It is fed the lines sent,
  the lines received and the client's notes, in order, and groups them into per-tag
  transactions, events and probed points. The live client and :func:`replay_transcript`
  feed it the same entries, so a replay gives the same points, bit for bit.
- :class:`IppClient`: socket, reader thread, tags, timeouts, recovery policy, transcript.
- :func:`cap_touch_plan` and :func:`probe_cap`: touch points on a ball's upper cap with
  clearance moves, and their execution.

Transcript format
-----------------
UTF-8 text (in practice ASCII), one entry per line ended by LF::

    # hexatherm ipp transcript 1
    2024-05-01T10:00:00.123456+02:00 > "00001 StartSession()"
    2024-05-01T10:00:00.125002+02:00 < "00001 &"
    2024-05-01T10:00:00.125010+02:00 < "00001 %"
    2024-05-01T10:00:07.000000+02:00 * "abandon 00007 timeout after 5 s"

The first field is the local time with its UTC offset (ISO 8601, microseconds) at which the
line was sent or the received line was complete; the second is the direction: ``>`` a
command line sent, ``<`` a response line received, ``*`` a note of the client (``connect
HOST:PORT``, ``abandon TAG REASON``, ``lost REASON``, ``close``); the third is the line
without its CR LF, in double quotes, with ``\\\\``, ``\\"`` and ``\\xNN`` (bytes outside 32 ..
126) escaped. Entries are written in the order in which the client acted on them;
:func:`replay_transcript` feeds them to a new :class:`Recorder` and gets the same
transactions, events and points.

Examples
--------
>>> r = parse_response("00012 # X(1.5), Y(-2.25e-3), Z(3E+2), IJK(0,0,1), ER(1)")
>>> r.tag, r.kind, fields(r.data)["Z"], fields(r.data)["IJK"]
('00012', '#', (300.0,), (0.0, 0.0, 1.0))
>>> parse_response('00003 ! Error(3, 2500, "GoTo", "Machine limit encountered")').error
ErrorReport(severity=3, number=2500, method='GoTo', text='Machine limit encountered')
"""

from __future__ import annotations

from hexatherm.devices.ipp.client import (
    IppClient,
)
from hexatherm.devices.ipp.protocol import (
    ALLOWED_IN_ERROR,
    DEFAULT_PORT,
    DEFAULT_REPORT,
    MAX_LINE,
    REPORT_ARITY,
    TRANSCRIPT_MAGIC,
    Call,
    ClearAndRetry,
    Decision,
    Direction,
    ErrorReport,
    LineBuffer,
    RecoveryPolicy,
    Response,
    Value,
    Word,
    fields,
    format_number,
    format_value,
    parse_command,
    parse_data,
    parse_ipp_url,
    parse_response,
)
from hexatherm.devices.ipp.touch import (
    CapMeasurement,
    CapTouchPlan,
    cap_touch_plan,
    probe_cap,
)
from hexatherm.devices.ipp.transcript import (
    IppEvent,
    ProbedPoint,
    Recorder,
    Replay,
    TransactionResult,
    TranscriptEntry,
    TranscriptFile,
    TranscriptSink,
    format_points,
    now_iso,
    parse_transcript,
    replay_transcript,
)

__all__ = [
    "ALLOWED_IN_ERROR",
    "Call",
    "CapMeasurement",
    "CapTouchPlan",
    "ClearAndRetry",
    "DEFAULT_PORT",
    "DEFAULT_REPORT",
    "Decision",
    "Direction",
    "ErrorReport",
    "IppClient",
    "IppEvent",
    "LineBuffer",
    "MAX_LINE",
    "ProbedPoint",
    "REPORT_ARITY",
    "Recorder",
    "RecoveryPolicy",
    "Replay",
    "Response",
    "TRANSCRIPT_MAGIC",
    "TransactionResult",
    "TranscriptEntry",
    "TranscriptFile",
    "TranscriptSink",
    "Value",
    "Word",
    "cap_touch_plan",
    "fields",
    "format_number",
    "format_points",
    "format_value",
    "now_iso",
    "parse_command",
    "parse_data",
    "parse_ipp_url",
    "parse_response",
    "parse_transcript",
    "probe_cap",
    "replay_transcript",
]
