"""I++ DME client: parser, line buffer, transcripts, recorder, touch plans, and the client
against the simulated server (a session probing balls, every injected fault)."""

from __future__ import annotations

import math
import queue
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexatherm.core.spherefit import fit_sphere
from hexatherm.devices.ipp import (
    TRANSCRIPT_MAGIC,
    Call,
    ClearAndRetry,
    ErrorReport,
    IppClient,
    IppEvent,
    LineBuffer,
    Recorder,
    TranscriptEntry,
    TranscriptFile,
    Word,
    cap_touch_plan,
    fields,
    format_number,
    format_points,
    parse_command,
    parse_data,
    parse_ipp_url,
    parse_response,
    parse_transcript,
    probe_cap,
    replay_transcript,
)
from hexatherm.devices.sim.ipp import Fault, IppSimServer, StaticBalls, segment_hits
from hexatherm.errors import (
    IppCommandError,
    IppConnectionLost,
    IppDmeError,
    IppErrorState,
    IppProtocolError,
    IppTimeout,
)
from tests.waiting import SAFETY_S

BALL_DIAMETER_MM = 25.4
TIP_DIAMETER_MM = 2.0
CENTRES_MM = np.array([[100.0, -50.0, 80.0], [-60.0, 40.0, 95.0]])


# ------------------------------------------------------------------ the parser
@pytest.mark.parametrize(
    ("line", "tag", "kind", "expected"),
    [
        # spec 6.2.3.1 and 6.2.2.2
        ("00005 # X(99.93), Y(17.148)", "00005", "#", {"X": (99.93,), "Y": (17.148,)}),
        # spec 7.5: no spaces, a dotted name
        (
            "00015 # X(199.998),Y(250.123),Z(300.002),Tool.A(45)",
            "00015",
            "#",
            {"X": (199.998,), "Y": (250.123,), "Z": (300.002,), "Tool.A": (45.0,)},
        ),
        # exponents, signs, leading dot, trailing dot, spaces around commas and parentheses
        (
            "00012 # X(1.5), Y(-2.25e-3), Z(3E+2), IJK(0,0,1), ER(1)",
            "00012",
            "#",
            {"X": (1.5,), "Y": (-0.00225,), "Z": (300.0,), "IJK": (0.0, 0.0, 1.0), "ER": (1.0,)},
        ),
        (
            "00013 #  X ( +.197 ) ,Y(-2.6E01 ), Z(4.), IJK( -0.6 , 0 ,+0.8e0)",
            "00013",
            "#",
            {"X": (0.197,), "Y": (-26.0,), "Z": (4.0,), "IJK": (-0.6, 0.0, 0.8)},
        ),
        ("00001 &", "00001", "&", {}),
        ("00001 %", "00001", "%", {}),
        (
            "E0553 # X(50), Y(433), Z(520)",
            "E0553",
            "#",
            {"X": (50.0,), "Y": (433.0,), "Z": (520.0,)},
        ),
    ],
)
def test_parse_response_data(line, tag, kind, expected):
    for text in (line, line + "\r\n", (line + "\r\n").encode("ascii")):
        response = parse_response(text)
        assert (response.tag, response.kind) == (tag, kind)
        assert fields(response.data) == expected
        assert response.is_event == tag.startswith("E")


def test_parse_response_errors_from_the_standard():
    # spec 6.2.4.1: a bare method name and a 3-digit number on an unsolicited event
    r = parse_response('E0000 ! Error(3, 500, HealthCheck, "Emergency Stop")')
    assert (r.tag, r.kind) == ("E0000", "!")
    assert r.error == ErrorReport(3, 500, "HealthCheck", "Emergency Stop")
    # spec 6.3.1.7, no spaces
    r = parse_response('00052 ! Error(2,0006,GoTo,"Transaction aborted")')
    assert r.error == ErrorReport(2, 6, "GoTo", "Transaction aborted")
    # NIST test suite: quoted method holding spaces and parentheses
    r = parse_response('00401 ! Error(2, 0513, "00401 StopDaemon(E1234)", "Daemon does not exist")')
    assert r.error is not None and r.error.method == "00401 StopDaemon(E1234)"
    assert r.error.format() == 'Error(2, 0513, "00401 StopDaemon(E1234)", "Daemon does not exist")'


def test_parse_data_values_of_every_kind():
    values = parse_data('ChangeToolAction(Switch, X(0.00000), Y(0.0), Z(-8.00000)), "Speed", 3')
    assert values[0] == Call(
        "ChangeToolAction",
        (Word("Switch"), Call("X", (0.0,)), Call("Y", (0.0,)), Call("Z", (-8.0,))),
    )
    assert isinstance(values[0].args[0], Word)
    assert values[1] == "Speed" and not isinstance(values[1], Word)
    assert values[2] == 3.0
    # the E0000 examples of the NIST suite: nested, spaces before '(' and before ')'
    r = parse_response(
        "E0000 # GoTo(Tool.A(45),Z(-4.003E-01),Y(-0.129), X(+1.245E01), Tool.B(4.0) )"
    )
    call = r.data[0]
    assert isinstance(call, Call) and call.name == "GoTo"
    assert fields(call.args) == {
        "Tool.A": (45.0,),
        "Z": (-0.4003,),
        "Y": (-0.129,),
        "X": (12.45,),
        "Tool.B": (4.0,),
    }


@pytest.mark.parametrize(
    "line",
    [
        "0001 &",  # 4-digit tag
        "00000 &",  # tag 00000
        "A4711 &",  # bad first character
        "00001&",  # no space at 6
        "00001 ?",  # unknown kind
        "00001 & x",  # text after &
        "00001 #",  # no data
        "00001 #X(1)",  # no space after #
        "00001 # X(1.5.3)",  # two points
        "00001 # X(1e0005)",  # 4-digit exponent
        "00001 # X(1.5",  # unbalanced
        "00001 # X(1.5))",  # unbalanced
        "00001 # X(1,,2)",  # empty item
        "00001 # X(1)\tY(2)",  # no comma
        "00001 # X(1\x07)",  # control character
        "00001 ! Error(2, 6, GoTo)",  # 3 fields
        '00001 ! Error(12, 6, GoTo, "x")',  # severity out of range
        '00001 ! Error(2.5, 6, GoTo, "x")',  # fractional severity
        "00001 ! Error(2, 6, GoTo, text)",  # unquoted text
        "00001 ! X(1)",  # not an error
    ],
)
def test_parse_response_rejects_malformed_lines(line):
    with pytest.raises(IppProtocolError):
        parse_response(line)


def test_parse_command_and_numbers_round_trip():
    tag, call = parse_command("00180 PtMeas(X(75.0), Y(50.0), Z(40.0), IJK(-1.0, 0.0, 0.0))")
    assert tag == "00180" and call.name == "PtMeas"
    assert fields(call.args)["IJK"] == (-1.0, 0.0, 0.0)
    assert parse_command("E0553 OnMoveReportE(Time(1),Dis(20),X(), Y(), Z())")[1].args[2] == Call(
        "X"
    )
    for bad in ("E0000 Home()", "00001 Tool.Name()", "00001 Home() Home()", "00001 Home"):
        with pytest.raises(IppProtocolError):
            parse_command(bad)
    rng = np.random.default_rng(3)
    for v in np.concatenate([rng.normal(0, 1e3, 200), 10.0 ** rng.uniform(-12, 12, 200)]):
        text = format_number(v)
        assert sum(c.isdigit() for c in text) <= 16
        assert abs(float(text) - v) <= 1e-11 * abs(v)
        assert fields(parse_data(f"X({text})"))["X"][0] == float(text)
    with pytest.raises(ValueError):
        format_number(math.nan)


def test_parse_ipp_url():
    assert parse_ipp_url("ipp://10.0.0.5:1294") == ("10.0.0.5", 1294)
    assert parse_ipp_url("ipp://[::1]:99") == ("::1", 99)
    for bad in ("http://x:1", "ipp://", "ipp://x:0", "ipp://x:70000"):
        with pytest.raises(IppDmeError):
            parse_ipp_url(bad)


# --------------------------------------------------------------- line buffer
@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 200), max_size=12))
def test_line_buffer_any_split_gives_the_same_lines(cuts):
    lines = [b"00001 &", b"00001 # X(1.5), Y(-2.25e-3)", b'E0000 # KeyPress("F1")', b"00001 %"]
    stream = b"".join(line + b"\r\n" for line in lines) + b"00002 &"
    points = sorted({min(c, len(stream)) for c in cuts})
    pieces = [stream[a:b] for a, b in zip([0, *points], [*points, len(stream)], strict=True)]
    buffer = LineBuffer()
    got = [line for piece in pieces for line in buffer.feed(piece)]
    assert got == lines
    assert buffer.pending == b"00002 &"


def test_line_buffer_refuses_endless_lines():
    buffer = LineBuffer(max_line=10)
    assert buffer.feed(b"0123456789\r\n") == [b"0123456789"]
    with pytest.raises(IppProtocolError):
        buffer.feed(b"0123456789ab")


# ------------------------------------------------- transcripts and the recorder
def _transcript(rows):
    lines = [TRANSCRIPT_MAGIC]
    for k, (direction, text) in enumerate(rows):
        lines.append(
            TranscriptEntry(f"2024-05-01T10:00:{k:02d}.000000+02:00", direction, text).format()[:-1]
        )
    return "\n".join(lines) + "\n"


STANDARD_SESSION = [
    (">", "00001 StartSession()"),
    ("<", "00001 &"),
    ("<", "00001 %"),
    (">", "00002 OnPtMeasReport(X(), Y(), Z(), IJK(), ER())"),
    ("<", "00002 &"),
    ("<", "00002 %"),
    (">", "00003 PtMeas(X(200), Y(250), Z(300), IJK(0, 0, 1))"),
    ("<", "00003 &"),
    ("<", 'E0000 # KeyPress("F1")'),
    ("<", "00003 # X(199.998),Y(250.123),Z(300.002), IJK(0, 0, 1), ER(1.5)"),
    ("<", "E0000 # GoTo(Tool.A(45),Z(-4.003E-01),Y(-0.129), X(+1.245E01), Tool.B(4.0) )"),
    ("<", "00003 %"),
    (">", "00004 PtMeas(X(-26), Y(-0.129), Z(0.197), IJK(-1, 0, 0))"),
    ("<", "00004 &"),
    ("<", "00004 # X(-2.6002E+01), Y(-1.29e-1), Z( .197 ) , IJK(-1.,0.,0.), ER(1.5)"),
    ("<", "00004 %"),
    (">", "00005 PtMeas(X(100000), Y(0), Z(0), IJK(0, 0, 1))"),
    ("<", "00005 &"),
    ("<", '00005 ! Error(3, 2500, "PtMeas", "Machine limit encountered [Move Out Of Limits]")'),
    ("<", "00005 %"),
    (">", "00006 PtMeas(X(1), Y(1), Z(1), IJK(0, 0, 1))"),
    ("<", "00006 &"),
    ("<", '00006 ! Error(2,0514,PtMeas,"Use ClearAllErrors to continue")'),
    ("<", "00006 %"),
    (">", "00007 ClearAllErrors()"),
    ("<", "00007 &"),
    ("<", "00007 %"),
    (">", "00008 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
    ("<", "00008 &"),
    ("<", '00008 ! Error(1, 0504, "PtMeas", "Argument out of range")'),
    ("<", "00008 # X(1.0e0), Y(2E0), Z(3.000), IJK(0,0,1), ER(1.5)"),
    ("<", "00008 %"),
    (">", "00009 PtMeas(X(5), Y(5), Z(5), IJK(0, 0, 1))"),
    ("<", "00009 &"),
    ("*", "abandon 00009 timeout after 5 s"),
    ("<", "00009 # X(5), Y(5), Z(5), IJK(0,0,1), ER(1.5)"),
    ("<", "00009 %"),
    ("<", "00042 # X(1)"),
]


def test_replay_of_a_transcript_written_from_the_standard():
    replay = replay_transcript(_transcript(STANDARD_SESSION))
    assert [p.point_mm for p in replay.points] == [
        (199.998, 250.123, 300.002),
        (-26.002, -0.129, 0.197),
        (1.0, 2.0, 3.0),
    ]
    assert [p.tag for p in replay.points] == ["00003", "00004", "00008"]
    assert replay.points[1].ijk == (-1.0, 0.0, 0.0) and replay.points[1].er_mm == 1.5
    assert replay.points[1].nominal_mm == (-26.0, -0.129, 0.197)
    assert replay.points[0].time == "2024-05-01T10:00:09.000000+02:00"  # its data line
    # the events, in order, apart from the transactions (and the stray tag 00042)
    assert [e.line[:14] for e in replay.events] == [
        "E0000 # KeyPre",
        "E0000 # GoTo(T",
        "00042 # X(1)",
    ]
    failed = {r.tag: r for r in replay.results}
    assert failed["00005"].failure == ErrorReport(
        3, 2500, "PtMeas", "Machine limit encountered [Move Out Of Limits]"
    )
    assert failed["00006"].failure is not None and failed["00006"].failure.number == 514
    assert failed["00008"].failure is None and failed["00008"].warnings[0].number == 504
    assert "00009" not in failed  # abandoned: its late answer is no point


def test_recorder_follows_the_error_state_and_the_report():
    recorder = Recorder()
    entries = parse_transcript(_transcript(STANDARD_SESSION))
    states = []
    for entry in entries:
        if entry.direction == ">":
            recorder.sent(entry.time, entry.text)
        elif entry.direction == "<":
            recorder.received(entry.time, entry.text)
        else:
            recorder.note(entry.time, entry.text)
        states.append(None if recorder.error_state is None else recorder.error_state.number)
    assert states[18] == 2500 and states[22] == 514 and states[26] is None
    assert recorder.report == ("X", "Y", "Z", "IJK", "ER")


def test_a_report_that_does_not_match_the_request_gives_no_point():
    rows = [
        (">", "00002 OnPtMeasReport(X(), Y(), Z(), IJK())"),
        ("<", "00002 &"),
        ("<", "00002 %"),
        (">", "00003 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00003 &"),
        ("<", "00003 # X(1), Y(2), Z(3)"),  # IJK missing
        ("<", "00003 %"),
        (">", "00004 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00004 &"),
        ("<", "00004 # X(1), Z(3), Y(2), Y(2), IJK(0,0,1)"),  # Y doubled
        ("<", "00004 %"),
        (">", "00005 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00005 &"),
        ("<", "00005 # X(1), Y(2), Z(3), IJK(0,0,1)"),
        ("<", "0005 # garbage"),  # malformed: cannot tell whose it is
        ("<", "00005 %"),
        (">", "00006 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00006 &"),
        ("<", "00006 # X(1), Y(2), Z(3), IJK(0,0,1)"),
        ("<", "00006 # X(1), Y(2), Z(3), IJK(0,0,1)"),  # two data lines
        ("<", "00006 %"),
        (">", "00007 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00007 &"),
        ("<", "00007 # X(1), Y(2), Z(3), IJK(0,0,1)"),
        ("<", "00007 %"),
    ]
    replay = replay_transcript(_transcript(rows))
    assert [p.tag for p in replay.points] == ["00007"]
    bad = {r.tag: r.protocol_error for r in replay.results}
    assert all(bad[t] for t in ("00003", "00004", "00005", "00006"))
    assert replay.events[0].response is None and replay.events[0].problem


def test_a_report_is_read_by_field_name_in_any_order():
    # the NIST I++ DME server answers ER, IJK, X, Y, Z whatever OnPtMeasReport listed
    # (every field is named, spec 6.1.3): the point is read by name
    rows = [
        (">", "00002 OnPtMeasReport(X(), Y(), Z(), IJK(), ER())"),
        ("<", "00002 &"),
        ("<", "00002 %"),
        (">", "00003 PtMeas(X(100), Y(100), Z(50), IJK(0, 0, 1))"),
        ("<", "00003 &"),
        ("<", "00003 # ER(3.00000), IJK(0.00000,0.60000,0.80000), X(100.5), Y(-7.25), Z(53)"),
        ("<", "00003 %"),
        (">", "00004 PtMeas(X(100), Y(100), Z(50), IJK(0, 0, 1))"),
        ("<", "00004 &"),
        ("<", "00004 # Z(1), IJK(0,0,1), ER(3), Y(2)"),  # X missing
        ("<", "00004 %"),
    ]
    replay = replay_transcript(_transcript(rows))
    assert [p.tag for p in replay.points] == ["00003"]
    point = replay.points[0]
    assert point.point_mm == (100.5, -7.25, 53.0)
    assert point.ijk == (0.0, 0.6, 0.8) and point.er_mm == 3.0
    bad = {r.tag: r.protocol_error for r in replay.results}
    assert bad["00004"] is not None and "X" in bad["00004"]


def test_transcript_escapes_and_refuses_garbage(tmp_path):
    entry = TranscriptEntry("2024-05-01T10:00:00.000000+00:00", "<", '00001 # "a\\b", \x07\xe9')
    assert parse_transcript(TRANSCRIPT_MAGIC + "\n" + entry.format()) == [entry]
    # an unfinished last line (a crash while writing) is left out
    assert parse_transcript(TRANSCRIPT_MAGIC + "\n" + entry.format() + entry.format()[:20]) == [
        entry
    ]
    for bad in (
        "not a transcript\n",
        TRANSCRIPT_MAGIC + '\nx > "a"b\n',
        TRANSCRIPT_MAGIC + '\nt > "\\q"\n',
    ):
        with pytest.raises(IppDmeError):
            parse_transcript(bad)
    path = tmp_path / "ipp.log"
    sink = TranscriptFile(path, durable=False)
    sink(entry.format())
    sink.close()
    sink = TranscriptFile(path)  # reopened: no second header
    sink(entry.format())
    sink.close()
    assert parse_transcript(path.read_text()) == [entry, entry]


# ---------------------------------------------------------------- touch plans
def test_cap_touch_plan_geometry_and_clearances():
    centres = np.array([[0.0, 0.0, 100.0], [200.0, 50.0, 90.0]])
    plan = cap_touch_plan(centres, 25.4, 3.0, 25, 70.0, approach_mm=2.0, clearance_mm=6.0)
    assert plan.points_mm.shape == (2, 25, 3) and plan.safe_mm.shape == (2, 3)
    offsets = plan.points_mm - centres[:, None, :]
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=-1), 12.7, rtol=0, atol=1e-12)
    np.testing.assert_allclose(plan.ijk, offsets / 12.7, rtol=0, atol=1e-12)
    polar = np.degrees(np.arccos(plan.ijk[..., 2]))
    assert polar.min() < 10 and 60 < polar.max() <= 70
    np.testing.assert_allclose(
        plan.approach_mm, plan.points_mm + (1.5 + 2.0) * plan.ijk, atol=1e-12
    )
    np.testing.assert_allclose(plan.above_mm[..., :2], plan.approach_mm[..., :2], atol=0)
    safe_z = np.broadcast_to((centres[:, 2] + 12.7 + 1.5 + 6.0)[:, None], (2, 25))
    np.testing.assert_allclose(plan.above_mm[..., 2], safe_z, rtol=0, atol=1e-12)
    np.testing.assert_allclose(plan.safe_mm[:, :2], centres[:, :2])
    # every move of the route keeps the tip (radius 1.5) out of the ball: 1 um margin
    for b in range(2):
        one = plan.ball(b)
        route = [one.safe_mm]
        for k in range(25):
            route += [one.above_mm[k], one.approach_mm[k], one.above_mm[k]]
        route.append(one.safe_mm)
        for p0, p1 in zip(route[:-1], route[1:], strict=True):
            assert not segment_hits(p0, p1, centres[b : b + 1], [12.7 + 1.5 + 0.001]).any()
    # the straight way between two opposite points would cross the ball
    k0, k1 = np.argmax(plan.ijk[0, :, 0]), np.argmin(plan.ijk[0, :, 0])
    assert segment_hits(plan.approach_mm[0, k0], plan.approach_mm[0, k1], centres[:1], [14.2]).all()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"centre_mm": [0.0, 0.0]},
        {"centre_mm": [0.0, np.nan, 0.0]},
        {"ball_diameter_mm": 0.0},
        {"tip_diameter_mm": -1.0},
        {"n_points": 0},
        {"n_points": 2.5},
        {"cap_angle_deg": 95.0},
        {"cap_angle_deg": 0.0},
        {"approach_mm": 0.0},
        {"clearance_mm": 1.0},
    ],
)
def test_cap_touch_plan_preconditions(kwargs):
    args = {
        "centre_mm": [0.0, 0.0, 0.0],
        "ball_diameter_mm": 25.4,
        "tip_diameter_mm": 2.0,
        "n_points": 10,
        "cap_angle_deg": 70.0,
        "approach_mm": 2.0,
        "clearance_mm": 5.0,
    }
    args.update(kwargs)
    with pytest.raises(IppDmeError):
        cap_touch_plan(**args)


# ----------------------------------------------- the client against the server
def _server(**kwargs):
    balls = StaticBalls(CENTRES_MM, 0.5 * BALL_DIAMETER_MM)
    kwargs.setdefault("tools", {"Probe1": TIP_DIAMETER_MM})
    return IppSimServer(balls, **kwargs)


def _prepare(cmm):
    cmm.start_session()
    cmm.home()
    cmm.change_tool("Probe1")
    cmm.on_pt_meas_report()


def _probe(cmm, centre_mm, n_points=12):
    plan = cap_touch_plan(centre_mm, BALL_DIAMETER_MM, TIP_DIAMETER_MM, n_points, 70.0)
    return probe_cap(cmm, plan)


def test_session_probes_balls_and_the_fit_recovers_the_centres():
    lines: list[str] = []
    with _server(noise_um=0.5, seed=7) as server:
        with IppClient(
            "127.0.0.1", server.port, timeout_s=SAFETY_S, transcript=lines.append
        ) as cmm:
            cmm.start_session()
            assert not cmm.is_homed()
            cmm.home()
            assert cmm.is_homed()
            cmm.find_tool("Probe1")
            cmm.change_tool("Probe1")
            cmm.set_prop({"Tool.PtMeasPar.Approach": 2.0, "Tool.PtMeasPar.Search": 4.0})
            props = cmm.get_prop("Tool.PtMeasPar.Search", "Tool.AvrRadius", "Tool.Name")
            assert props == {
                "Tool.PtMeasPar.Search": (4.0,),
                "Tool.AvrRadius": (1.0,),
                "Tool.Name": ("Probe1",),
            }
            cmm.on_pt_meas_report("X", "Y", "Z", "IJK", "ER")
            # the predicted centres are 0.3 mm off the true ones (within approach + search)
            predicted = CENTRES_MM + np.array([0.2, -0.1, 0.2])
            measured = [_probe(cmm, c, n_points=25) for c in predicted]
            position = cmm.get_position()
            cmm.end_session()
    np.testing.assert_allclose(position, predicted[1] + [0, 0, 12.7 + 1.0 + 5.0], atol=1e-9)
    assert server.touches == 50
    for truth, m in zip(CENTRES_MM, measured, strict=True):
        fit = fit_sphere(m.points_mm)
        u_mm = np.sqrt(np.diag(fit.cov_centre_mm2[0]))
        assert np.all(np.abs(fit.centre_mm[0] - truth) < 5 * u_mm), (fit.centre_mm[0] - truth, u_mm)
        assert np.all(u_mm < 1e-3)  # 0.5 um noise, 25 points: sub-micrometre
        assert abs(fit.radius_mm[0] - 12.7) < 2e-3
        assert 0.25 < fit.rms_um[0] < 0.75  # the server's 0.5 um noise, seen by the fit
        np.testing.assert_array_equal(m.er_mm, 1.0)
        np.testing.assert_allclose(np.linalg.norm(m.ijk, axis=1), 1.0, atol=1e-12)
    # the transcript replays into the same points, byte for byte
    replay = replay_transcript(TRANSCRIPT_MAGIC + "\n" + "".join(lines))
    assert format_points(replay.points) == format_points(cmm.points)
    assert len(replay.points) == 50
    assert [e.direction for e in replay.entries[:3]] == ["*", ">", "<"]


def test_session_without_noise_is_exact():
    with _server() as server, IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
        _prepare(cmm)
        m = _probe(cmm, CENTRES_MM[0] + [0.5, 0.0, -0.4], n_points=8)
    distance = np.linalg.norm(m.points_mm - CENTRES_MM[0], axis=1)
    np.testing.assert_allclose(distance, 12.7, rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.ijk, (m.points_mm - CENTRES_MM[0]) / 12.7, atol=1e-12)


def test_fault_severity_2_is_cleared_and_retried_once():
    lines: list[str] = []
    fault = Fault("error", nth=3, method="PtMeas", severity=2)
    with _server(faults=[fault], noise_um=0.5, seed=1) as server:
        with IppClient(
            "127.0.0.1", server.port, timeout_s=SAFETY_S, transcript=lines.append
        ) as cmm:
            _prepare(cmm)
            m = _probe(cmm, CENTRES_MM[0], n_points=6)
    assert len(m.probed) == 6 and server.touches == 6
    measures = [c[6:] for c in server.commands if c[6:].startswith(("PtMeas", "ClearAllErrors"))]
    assert measures[2].startswith("PtMeas") and measures[3] == "ClearAllErrors()"
    assert measures[4] == measures[2]  # the same command again, with a new tag
    failed = [r for r in cmm.recorder.results if r.failure is not None]
    assert len(failed) == 1 and failed[0].failure == ErrorReport(
        2, 1011, "PtMeas", "Unable to move"
    )
    assert cmm.error_state is None
    np.testing.assert_allclose(np.linalg.norm(m.points_mm - CENTRES_MM[0], axis=1), 12.7, atol=5e-3)
    replay = replay_transcript(TRANSCRIPT_MAGIC + "\n" + "".join(lines))
    assert format_points(replay.points) == format_points(cmm.points)


def test_fault_severity_2_twice_raises_after_one_retry():
    faults = [Fault("error", nth=2, method="PtMeas"), Fault("error", nth=3, method="PtMeas")]
    with (
        _server(faults=faults) as server,
        IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm,
    ):
        _prepare(cmm)
        cmm.goto(*(CENTRES_MM[0] + [0, 0, 20]))
        top = CENTRES_MM[0] + [0, 0, 12.7]
        cmm.pt_meas(*top, 0, 0, 1)
        with pytest.raises(IppCommandError, match="after 1 recovery") as info:
            cmm.pt_meas(*top, 0, 0, 1)
        assert info.value.error.severity == 2 and info.value.result.method == "PtMeas"
        assert sum(c.endswith("ClearAllErrors()") for c in server.commands) == 1
        # a third try works once cleared
        cmm.clear_all_errors()
        assert cmm.pt_meas(*top, 0, 0, 1).point_mm == tuple(top)


def test_fault_severity_3_raises_and_blocks_until_cleared():
    fault = Fault("error", nth=2, method="PtMeas", severity=3)
    with (
        _server(faults=[fault]) as server,
        IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm,
    ):
        _prepare(cmm)
        cmm.goto(*(CENTRES_MM[0] + [0, 0, 20]))
        top = CENTRES_MM[0] + [0, 0, 12.7]
        cmm.pt_meas(*top, 0, 0, 1)
        with pytest.raises(IppCommandError, match="Collision") as info:
            cmm.pt_meas(*top, 0, 0, 1)
        assert info.value.error == ErrorReport(3, 2504, "PtMeas", "Collision")
        assert not any(c.endswith("ClearAllErrors()") for c in server.commands)
        sent = len(server.commands)
        with pytest.raises(IppErrorState, match="Collision"):
            cmm.goto(*(CENTRES_MM[0] + [0, 0, 20]))
        assert len(server.commands) == sent  # refused without sending
        assert cmm.get_err_status() is True  # the fast queue still answers
        cmm.clear_all_errors()
        assert cmm.get_err_status() is False
        assert cmm.pt_meas(*top, 0, 0, 1).point_mm == tuple(top)


def test_unsolicited_error_event_puts_the_client_in_error_state():
    rows = list(STANDARD_SESSION[:3]) + [
        ("<", 'E0000 ! Error(3, 500, HealthCheck, "Emergency Stop")')
    ]
    replay = replay_transcript(_transcript(rows))
    assert replay.events[0].response is not None and replay.events[0].response.error is not None
    recorder = Recorder()
    for direction, text in rows:
        (recorder.sent if direction == ">" else recorder.received)("t", text)
    assert recorder.error_state == ErrorReport(3, 500, "HealthCheck", "Emergency Stop")


def test_fault_events_are_routed_apart_from_the_transactions():
    fault = Fault("event", nth=2, method="PtMeas")
    with (
        _server(faults=[fault]) as server,
        IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm,
    ):
        _prepare(cmm)
        m = _probe(cmm, CENTRES_MM[1], n_points=4)
    events = []
    while True:
        try:
            events.append(cmm.events.get_nowait())
        except queue.Empty:
            break
    assert [e.line for e in events] == [
        'E0000 # KeyPress("F1")',
        "E0000 # GoTo(X(10), Y(-11.5), Z(3.25E+02))",
    ]
    assert fields(events[1].response.data[0].args) == {"X": (10.0,), "Y": (-11.5,), "Z": (325.0,)}
    assert len(m.probed) == 4 and cmm.error_state is None
    np.testing.assert_allclose(
        np.linalg.norm(m.points_mm - CENTRES_MM[1], axis=1), 12.7, atol=1e-12
    )
    # with a callback instead of the queue
    got: list[IppEvent] = []
    with _server(faults=[Fault("event", nth=5)]) as server:
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S, on_event=got.append) as cmm:
            _prepare(cmm)
            cmm.goto(0, 0, 300)
    assert len(got) == 2 and cmm.events.empty()


def test_fault_dropped_connection_names_the_pending_command():
    lines: list[str] = []
    fault = Fault("drop", nth=3, method="PtMeas", after_lines=1)
    with _server(faults=[fault]) as server:
        with IppClient(
            "127.0.0.1", server.port, timeout_s=SAFETY_S, transcript=lines.append
        ) as cmm:
            _prepare(cmm)
            with pytest.raises(IppConnectionLost, match=r"lost .*while waiting for \d{5} PtMeas\("):
                _probe(cmm, CENTRES_MM[0], n_points=6)
            with pytest.raises(IppConnectionLost, match="cannot send GoTo"):
                cmm.goto(0, 0, 300)
            assert len(cmm.points) == 2
        # the server is still there for a new connection
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as again:
            _prepare(again)
            assert again.is_homed()
    assert any(' * "lost connection closed by the server' in line for line in lines)
    replay = replay_transcript(TRANSCRIPT_MAGIC + "\n" + "".join(lines))
    assert format_points(replay.points) == format_points(cmm.points)


def test_fault_split_lines_give_the_same_points():
    results = []
    chunks = [1, 2, 3, 5, 7, 4, 6, 9]
    split = [Fault("split", nth=n, method="PtMeas", chunk_bytes=c) for n, c in enumerate(chunks, 1)]
    for faults in ([], split):
        with _server(faults=faults, noise_um=1.0, seed=11) as server:
            with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
                _prepare(cmm)
                results.append(_probe(cmm, CENTRES_MM[0], n_points=8))
    np.testing.assert_array_equal(results[0].points_mm, results[1].points_mm)
    np.testing.assert_array_equal(results[0].ijk, results[1].ijk)


def test_fault_delay_times_out_and_a_short_delay_does_not():
    lines: list[str] = []
    with _server(faults=[Fault("delay", nth=5, delay_s=60.0)]) as server:
        with IppClient(
            "127.0.0.1", server.port, timeout_s=SAFETY_S, transcript=lines.append
        ) as cmm:
            _prepare(cmm)
            with pytest.raises(
                IppTimeout,
                match=r"did not complete 00005 GoTo\(X\(0\), Y\(0\), Z\(300\)\) within 0.2 s",
            ):
                cmm.transact("GoTo(X(0), Y(0), Z(300))", timeout_s=0.2)
    assert lines[-2].endswith('* "abandon 00005 timeout after 0.2 s"\n')
    with _server(faults=[Fault("delay", nth=5, delay_s=0.05)]) as server:
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
            _prepare(cmm)
            cmm.goto(0, 0, 300)
            assert cmm.get_position() == (0.0, 0.0, 300.0)


def test_policy_can_refuse_every_retry_and_errors_name_the_command():
    with _server(faults=[Fault("error", nth=1, method="GoTo")]) as server:
        with IppClient(
            "127.0.0.1", server.port, timeout_s=SAFETY_S, policy=ClearAndRetry(retries=0)
        ) as cmm:
            _prepare(cmm)
            with pytest.raises(
                IppCommandError, match=r"refused \d{5} GoTo\(X\(1\), Y\(2\), Z\(300\)\)"
            ):
                cmm.goto(1, 2, 300)
            with pytest.raises(IppErrorState):
                cmm.goto(1, 2, 300)


def test_client_preconditions():
    with _server() as server, IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
        for bad in (
            lambda: cmm.pt_meas(0, 0, 0, 0, 0, 0),
            lambda: cmm.change_tool('a"b'),
            lambda: cmm.set_prop({}),
            lambda: cmm.set_prop({"Tool.PtMeas Par": 1.0}),
            lambda: cmm.on_pt_meas_report("X", "Y"),
            lambda: cmm.on_pt_meas_report("X", "Y", "Z", "W"),
            lambda: cmm.transact("Home()\r\nHome()"),
            lambda: probe_cap(cmm, cap_touch_plan(CENTRES_MM, 25.4, 2.0, 4, 60.0)),
        ):
            with pytest.raises(IppDmeError):
                bad()
        assert server.commands == []
    with pytest.raises(IppDmeError, match="cannot connect"):
        IppClient("127.0.0.1", server.port, connect_timeout_s=5)


def test_concurrent_events_do_not_disturb_a_waiting_command():
    """A server event arriving from another thread's point of view: the callback runs on the
    reader thread while the caller waits; the caller still gets its own answer."""
    seen = threading.Event()
    with _server(faults=[Fault("event", nth=4, events=('KeyPress("F2")',))]) as server:
        with IppClient(
            "127.0.0.1", server.port, timeout_s=SAFETY_S, on_event=lambda e: seen.set()
        ) as cmm:
            _prepare(cmm)
            assert cmm.is_homed()
    assert seen.is_set()


def test_a_raising_callback_or_transcript_is_not_swallowed():
    def callback(event):
        raise RuntimeError("operator display down")

    with _server(faults=[Fault("event", nth=2)]) as server:
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S, on_event=callback) as cmm:
            cmm.start_session()
            cmm.home()  # its answer carries the events: the callback raises on the reader
            sent = len(server.commands)
            with pytest.raises(IppDmeError, match="callback raised RuntimeError") as info:
                cmm.is_homed()
            assert isinstance(info.value.__cause__, RuntimeError)
            assert len(server.commands) == sent
            assert cmm.is_homed()  # reported once, then the client goes on

    lines: list[str] = []

    def sink(line):
        if len(lines) == 6:
            raise OSError("disk full")
        lines.append(line)

    with _server() as server:
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S, transcript=sink) as cmm:
            cmm.start_session()  # connect, >, <, < : 4 lines
            with pytest.raises(
                IppConnectionLost, match=r"OSError while recording a line: disk full"
            ):
                cmm.home()  # >, < (the ack), then the '%' cannot be recorded
    assert len(lines) == 6 and lines[-1].endswith('< "00002 &"\n')


# ------------------------------------------------- servers of other dialects (issue 23)
def test_client_against_a_plain_dme_1_4_server():
    """Version first, optional queries cleared, points read by name, a stale session ended."""
    with _server(dialect="dme-1.4") as server:
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
            _prepare(cmm)
            assert cmm.dme_version() == ("1.4", (1, 4))
            result, error = cmm.optional("GetProp(Tool.AvrRadius())")
            assert result is None and error is not None and error.number == 502
            assert cmm.error_state is None and server.commands[-1].endswith("ClearAllErrors()")
            assert cmm.enum_tools() == ["NoTool", "Probe1"]
            top = CENTRES_MM[0] + [0, 0, 12.7]
            cmm.goto(*(top + [0, 0, 8]))
            point = cmm.pt_meas(*top, 0, 0, 1)  # answered ER, IJK, X, Y, Z
            np.testing.assert_allclose(point.point_mm, top, atol=1e-9)
            assert point.er_mm == 0.5 * TIP_DIAMETER_MM
        # the session outlived that connection: the next client ends it and starts anew
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
            assert cmm.start_session() is True
            assert cmm.error_state is None
            tail = [c[6:] for c in server.commands[-4:]]
            assert tail == ["StartSession()", "ClearAllErrors()", "EndSession()", "StartSession()"]
            assert cmm.dme_version() == ("1.4", (1, 4))
    with _server() as server, IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
        assert cmm.start_session() is False
        assert cmm.dme_version() == ("1.4.3", (1, 4, 3))


def test_end_session_is_not_sent_in_an_error_state():
    faults = [Fault("error", nth=1, method="GoTo", severity=3)]
    with (
        _server(faults=faults) as server,
        IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm,
    ):
        _prepare(cmm)
        with pytest.raises(IppCommandError):
            cmm.goto(*(CENTRES_MM[0] + [0, 0, 20]))
        assert cmm.error_state is not None
        cmm.end_session()  # clears first: 6.2.5 allows no EndSession in an error state
        assert [c[6:] for c in server.commands[-2:]] == ["ClearAllErrors()", "EndSession()"]
        assert cmm.error_state is None
        assert all(r.failure is None for r in cmm.recorder.results[-2:])


def test_warnings_are_said_not_dropped():
    faults = [
        Fault("error", nth=1, method=m, severity=s, number=n)
        for m, s, n in (("SetProp", 0, 1), ("GoTo", 1, 1005), ("PtMeas", 1, 1005))
    ]
    said = []
    lines = []
    with (
        _server(faults=faults) as server,
        IppClient(
            "127.0.0.1",
            server.port,
            timeout_s=SAFETY_S,
            transcript=lines.append,
            on_warning=lambda r, w: said.append((r.method, w.severity, w.number)),
        ) as cmm,
    ):
        _prepare(cmm)
        cmm.set_prop({"Tool.PtMeasPar.Approach": 2.0})
        cmm.goto(*(CENTRES_MM[0] + [0, 0, 20]))
        top = CENTRES_MM[0] + [0, 0, 12.7]
        point = cmm.pt_meas(*top, 0, 0, 1)
        np.testing.assert_allclose(point.point_mm, top, atol=1e-9)
    assert said == [("SetProp", 0, 1), ("GoTo", 1, 1005), ("PtMeas", 1, 1005)]
    assert sum(" ! Error(1, 1005" in line for line in lines) == 2


#: event lines a CMM may send that cannot be parsed: a truncated call, and an informational
#: error whose text has one Latin-1 character (a European CMM's software)
BAD_EVENTS = ("E0000 # Blah(", 'E0000 ! Error(1, 0, "Info", "Temp\xe9rature stable")')


def test_an_unparsable_event_line_is_an_event_and_fails_no_open_transaction():
    rows = [
        (">", "00003 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00003 &"),
        ("<", BAD_EVENTS[0]),
        ("<", "00003 # X(1), Y(2), Z(3)"),
        ("<", BAD_EVENTS[1]),
        ("<", "00003 %"),
        (">", "00004 PtMeas(X(1), Y(2), Z(3), IJK(0, 0, 1))"),
        ("<", "00004 &"),
        ("<", "00004 # X(1), Y(2), Z(3\xe9)"),  # the transaction's own line: strict
        ("<", "00004 %"),
    ]
    replay = replay_transcript(_transcript(rows))
    assert [p.tag for p in replay.points] == ["00003"]
    assert replay.results[0].protocol_error is None and replay.results[1].protocol_error
    assert [e.line for e in replay.events[:2]] == list(BAD_EVENTS)
    assert all(e.response is None and e.problem for e in replay.events)


def test_bad_event_lines_from_the_server_leave_the_command_and_the_transcript_whole():
    lines: list[str] = []
    got: list[IppEvent] = []
    fault = Fault("event", nth=2, method="PtMeas", events=("Blah(", BAD_EVENTS[1][6:]))
    with _server(faults=[fault]) as server:
        with IppClient(
            "127.0.0.1",
            server.port,
            timeout_s=SAFETY_S,
            transcript=lines.append,
            on_event=got.append,
        ) as cmm:
            _prepare(cmm)
            m = _probe(cmm, CENTRES_MM[0], n_points=4)
    assert len(m.probed) == 4
    assert [e.line for e in got] == list(BAD_EVENTS)
    # the Latin-1 character is kept in the transcript (escaped), which replays to the same
    text = TRANSCRIPT_MAGIC + "\n" + "".join(lines)
    assert "Temp\\xe9rature" in text
    replay = replay_transcript(text)
    assert [p.point_mm for p in replay.points] == [p.point_mm for p in m.probed]
