"""The simulated I++ DME server: its dialect line by line (raw sockets), its touch physics
against independent computations, and each fault it injects."""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest

from hexatherm.devices.ipp import (
    IppClient,
    LineBuffer,
    fields,
    parse_response,
)
from hexatherm.devices.sim.ipp import (
    Fault,
    IppSimServer,
    StaticBalls,
    first_contact,
    segment_hits,
)
from hexatherm.errors import (
    IppDmeError,
)
from tests.waiting import SAFETY_S

R_MM = 12.7
TIP_MM = 1.0  # radius of the 2 mm tip
CENTRE = np.array([10.0, 20.0, 30.0])


class Raw:
    """A bare TCP client: send command lines, read response lines."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=SAFETY_S)
        self.buffer = LineBuffer()
        self.lines: list[str] = []

    def close(self) -> None:
        self.sock.close()

    def send(self, line: str) -> None:
        self.sock.sendall(line.encode("ascii") + b"\r\n")

    def read_line(self) -> str | None:
        while not self.lines:
            data = self.sock.recv(65536)
            if not data:
                return None
            self.lines += [x.decode("ascii") for x in self.buffer.feed(data)]
        return self.lines.pop(0)

    def until_done(self, tag: str) -> list[str]:
        out = []
        while True:
            line = self.read_line()
            if line is None:
                return out
            out.append(line)
            if line == f"{tag} %":
                return out

    def cmd(self, tag: str, command: str) -> list[str]:
        self.send(f"{tag} {command}")
        return self.until_done(tag)


def _server(**kwargs):
    kwargs.setdefault("tools", {"Probe1": 2 * TIP_MM})
    return IppSimServer(StaticBalls([CENTRE], R_MM), **kwargs)


def _ready(raw: Raw) -> None:
    assert raw.cmd("00001", "StartSession()") == ["00001 &", "00001 %"]
    assert raw.cmd("00002", "Home()") == ["00002 &", "00002 %"]
    assert raw.cmd("00003", 'ChangeTool("Probe1")') == ["00003 &", "00003 %"]
    assert raw.cmd("00004", "OnPtMeasReport(X(), Y(), Z(), IJK(), ER())") == [
        "00004 &",
        "00004 %",
    ]


def _data(lines: list[str]) -> dict[str, tuple[float, ...]]:
    data = [parse_response(x) for x in lines if x[6:7] == "#"]
    assert len(data) == 1, lines
    return fields(data[0].data)


# ----------------------------------------------------------------- geometry
def test_first_contact_against_dense_sampling():
    rng = np.random.default_rng(5)
    for _ in range(80):
        centres = rng.uniform(-20, 20, (3, 3))
        radii = rng.uniform(2, 8, 3)
        start = rng.uniform(-40, 40, 3)
        if np.any(np.linalg.norm(start - centres, axis=1) <= radii):
            continue
        target = centres[rng.integers(3)] + rng.normal(0, 3, 3)
        u = (target - start) / np.linalg.norm(target - start)
        length = 80.0
        s, index = first_contact(start, u, length, centres, radii)
        steps = np.linspace(0, length, 40001)  # 2 um apart
        path = start + steps[:, None] * u
        distance = np.linalg.norm(path[:, None, :] - centres, axis=2)
        if np.any(np.abs(distance.min(axis=0) - radii) < 1e-2):
            continue  # grazing: finer than the sampling can tell
        inside = distance <= radii
        hit = np.flatnonzero(inside.any(axis=1))
        if hit.size == 0:
            assert index == -1
            continue
        first = hit[0]
        assert index == int(np.argmax(inside[first]))
        assert steps[first - 1] <= s <= steps[first] + 1e-12
        assert abs(np.linalg.norm(start + s * u - centres[index]) - radii[index]) < 1e-9


def test_segment_hits_against_dense_sampling():
    rng = np.random.default_rng(9)
    centres = rng.uniform(-20, 20, (5, 3))
    radii = rng.uniform(2, 8, 5)
    for _ in range(60):
        a, b = rng.uniform(-40, 40, (2, 3))
        t = np.linspace(0, 1, 20001)[:, None]
        d = np.linalg.norm((a + t * (b - a))[:, None, :] - centres, axis=2)
        expected = (d < radii).any(axis=0)
        margin = np.abs(d.min(axis=0) - radii)
        got = segment_hits(a, b, centres, radii)
        sure = margin > 1e-2  # sampling resolution
        assert np.array_equal(got[sure], expected[sure])
    assert not segment_hits([0, 0, 20], [0, 0, 20], [[0, 0, 0]], [10]).any()


# ----------------------------------------------------------------- touching
def test_pt_meas_reports_the_touched_surface_point():
    with _server() as server:
        raw = Raw(server.port)
        _ready(raw)
        # straight down onto the pole, nominal 0.4 mm above the true surface
        assert raw.cmd("00005", f"GoTo(X(10), Y(20), Z({30 + R_MM + 10}))")[-1] == "00005 %"
        got = _data(raw.cmd("00006", f"PtMeas(X(10), Y(20), Z({30 + R_MM + 0.4}), IJK(0, 0, 1))"))
        assert got == {
            "X": (10.0,),
            "Y": (20.0,),
            "Z": (30 + R_MM,),
            "IJK": (0.0, 0.0, 1.0),
            "ER": (1.0,),
        }
        # off-axis, vertical approach: the tip meets the ball grown by its radius
        xy = np.array([6.0, -4.0])
        rho = R_MM + TIP_MM
        tip_z = 30 + np.sqrt(rho**2 - xy @ xy)
        raw.cmd("00007", f"GoTo(X({10 + xy[0]}), Y({20 + xy[1]}), Z(60))")
        got = _data(
            raw.cmd("00008", f"PtMeas(X({10 + xy[0]}), Y({20 + xy[1]}), Z(40), IJK(0, 0, 2))")
        )
        normal = (np.array([10 + xy[0], 20 + xy[1], tip_z]) - CENTRE) / rho
        np.testing.assert_allclose(
            [got["X"][0], got["Y"][0], got["Z"][0]], CENTRE + R_MM * normal, atol=1e-12
        )
        np.testing.assert_allclose(got["IJK"], normal, atol=1e-12)
        # where the tool is afterwards: retracted 2 mm (the default) along the command's IJK
        pos = _data(raw.cmd("00009", "Get(X(), Y(), Z())"))
        np.testing.assert_allclose(
            [pos["X"][0], pos["Y"][0], pos["Z"][0]], [16, 16, tip_z + 2], atol=1e-12
        )
        raw.close()
    assert server.touches == 2


def test_pt_meas_tip_centres_when_not_compensated_and_nearest_ball_first():
    balls = StaticBalls([[0, 0, 0], [0, 0, 40.0]], [5.0, 5.0])
    with IppSimServer(balls, compensated=False) as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", "GoTo(X(0), Y(0), Z(60))")
        got = _data(raw.cmd("00006", "PtMeas(X(0), Y(0), Z(45.5), IJK(0, 0, 1))"))
        assert got["Z"] == (46.0,)  # the upper ball, its tip centre: 40 + 5 + 1
        raw.cmd("00007", "SetProp(Tool.PtMeasPar.Search(100))")
        raw.cmd("00008", "GoTo(X(0), Y(0), Z(60))")
        got = _data(raw.cmd("00009", "PtMeas(X(0), Y(0), Z(45.5), IJK(0, 0, 1))"))
        assert got["Z"] == (46.0,)  # still the first one on the way, not the lower one
        for tag, xyz in (("00010", "X(20), Y(0), Z(60)"), ("00011", "X(20), Y(0), Z(25)")):
            assert raw.cmd(tag, f"GoTo({xyz})")[-1] == f"{tag} %"
        raw.cmd("00012", "GoTo(X(6.5), Y(0), Z(25))")
        got = _data(raw.cmd("00013", "PtMeas(X(5), Y(0), Z(0), IJK(1, 0, 0))"))
        assert got["X"] == (6.0,) and got["IJK"] == (1.0, 0.0, 0.0)
        raw.close()


def test_pt_meas_without_ijk_approaches_from_the_current_position():
    with _server() as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", f"GoTo(X(10), Y(20), Z({30 + R_MM + 3}))")
        got = _data(raw.cmd("00006", f"PtMeas(X(10), Y(20), Z({30 + R_MM}))"))
        assert got["Z"] == (30 + R_MM,) and got["IJK"] == (0.0, 0.0, 1.0)
        raw.close()


def test_noise_is_seeded_and_has_the_requested_spread():
    def touches(seed, n=300):
        with (
            _server(noise_um=2.0, seed=seed) as server,
            IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm,
        ):
            cmm.start_session()
            cmm.home()
            cmm.change_tool("Probe1")
            top = CENTRE + [0, 0, R_MM]
            cmm.goto(*(top + [0, 0, 5]))
            return np.array([cmm.pt_meas(*top, 0, 0, 1).point_mm for _ in range(n)])

    a, b, c = touches(4), touches(4), touches(5)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(a[:, :2], np.broadcast_to(CENTRE[:2], (300, 2)))
    dz_um = (a[:, 2] - (CENTRE[2] + R_MM)) * 1e3
    assert abs(dz_um.mean()) < 4 * 2.0 / np.sqrt(300)
    assert 0.85 < dz_um.std(ddof=1) / 2.0 < 1.15


def test_time_dependent_backend():
    class Rising:
        def ball_centres_mm(self, t_s):
            return np.array([[0.0, 0.0, 0.001 * t_s]])  # 1 um/s

        def ball_radii_mm(self, t_s):
            return np.array([5.0])

    clock = [0.0]
    with IppSimServer(Rising(), time_s=lambda: clock[0]) as server:
        with IppClient("127.0.0.1", server.port, timeout_s=SAFETY_S) as cmm:
            cmm.start_session()
            cmm.home()
            cmm.change_tool("Probe1")
            cmm.goto(0, 0, 20)
            z0 = cmm.pt_meas(0, 0, 5, 0, 0, 1).point_mm[2]
            clock[0] = 250.0
            z1 = cmm.pt_meas(0, 0, 5, 0, 0, 1).point_mm[2]
    assert z0 == 5.0 and abs(z1 - 5.25) < 1e-12


def test_number_format_with_exponents_reaches_the_client_intact():
    with _server(number_format=lambda v: f"{v:.12E}") as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", "GoTo(X(14), Y(23), Z(60))")
        lines = raw.cmd("00006", "PtMeas(X(14), Y(23), Z(40), IJK(0, 0, 1))")
        assert "E+01" in lines[1] and "E-01" in lines[1]
        got = _data(lines)
        assert (
            abs(np.linalg.norm(np.array([got["X"][0], got["Y"][0], got["Z"][0]]) - CENTRE) - R_MM)
            < 1e-10
        )
        raw.close()


# ------------------------------------------------------------------- errors
def test_surface_not_found_then_error_state_until_cleared():
    with _server() as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", "GoTo(X(100), Y(100), Z(100))")
        assert raw.cmd("00006", "PtMeas(X(100), Y(100), Z(90), IJK(0, 0, 1))") == [
            "00006 &",
            '00006 ! Error(2, 1006, "PtMeas", "Surface not found")',
            "00006 %",
        ]
        assert raw.cmd("00007", "Get(X(), Y(), Z())") == [
            "00007 &",
            '00007 ! Error(2, 0514, "Get", "Use ClearAllErrors to continue")',
            "00007 %",
        ]
        assert raw.cmd("E0001", "GetErrStatusE()") == ["E0001 &", "E0001 # ErrStatus(1)", "E0001 %"]
        assert raw.cmd("00008", "ClearAllErrors()") == ["00008 &", "00008 %"]
        assert raw.cmd("E0002", "GetErrStatusE()")[1] == "E0002 # ErrStatus(0)"
        # the probe went back to the approach position: 2 mm + the tip radius above nominal
        assert raw.cmd("00009", "Get(X(), Y(), Z())")[1] == "00009 # X(100), Y(100), Z(93)"
        raw.close()


def test_collisions_and_limits_are_refused_and_the_probe_stays():
    with _server(limits_mm=((-500, -500, -100), (500, 500, 400)), home_mm=(0, 0, 300)) as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", "GoTo(X(-20), Y(20), Z(30))")
        assert (
            raw.cmd("00006", "GoTo(X(40), Y(20), Z(30))")[1]
            == '00006 ! Error(3, 2504, "GoTo", "Collision")'
        )
        raw.cmd("00007", "ClearAllErrors()")
        assert raw.cmd("00008", "Get(X(), Y(), Z())")[1] == "00008 # X(-20), Y(20), Z(30)"
        # grazing the grown ball is no collision: the tip's surface just meets the ball
        graze = 20 + R_MM + TIP_MM
        assert raw.cmd("00009", f"GoTo(X(-20), Y({graze}), Z(30))")[-2:] == ["00009 &", "00009 %"]
        assert raw.cmd("00010", f"GoTo(X(40), Y({graze}), Z(30))")[-2:] == ["00010 &", "00010 %"]
        lines = raw.cmd("00011", "GoTo(Z(401))")
        assert (
            lines[1]
            == '00011 ! Error(3, 2500, "GoTo", "Machine limit encountered [Move Out Of Limits]")'
        )
        raw.cmd("00012", "ClearAllErrors()")
        # PtMeas from inside the reach of the ball: its approach move collides
        raw.cmd("00013", "GoTo(X(10), Y(20), Z(60))")
        lines = raw.cmd("00014", "PtMeas(X(10), Y(20), Z(30), IJK(0, 0, 1))")
        assert lines[1] == '00014 ! Error(3, 2504, "PtMeas", "Collision")'
        raw.close()


def test_protocol_rules():
    with _server() as server:
        raw = Raw(server.port)
        assert raw.cmd("00001", "Home()")[1] == '00001 ! Error(3, 0008, "Home", "Protocol error")'
        assert raw.cmd("00002", "StartSession()") == ["00002 &", "00002 %"]
        assert (
            raw.cmd("00003", "StartSession()")[1]
            == '00003 ! Error(3, 0008, "StartSession", "Protocol error")'
        )
        raw.cmd("00004", "ClearAllErrors()")
        assert raw.cmd("00005", "GoTo(X(1))")[1] == '00005 ! Error(3, 0508, "GoTo", "Bad context")'
        raw.cmd("00006", "ClearAllErrors()")
        assert raw.cmd("00007", "IsHomed()")[1] == "00007 # IsHomed(0)"
        raw.cmd("00008", "Home()")
        assert raw.cmd("00009", "IsHomed()")[1] == "00009 # IsHomed(1)"
        assert (
            raw.cmd("00010", "Fly()")[1] == '00010 ! Error(3, 0501, "Fly", "Unsupported command")'
        )
        raw.cmd("00011", "ClearAllErrors()")
        raw.send("0012 Home()")
        assert raw.read_line() == 'E0000 ! Error(2, 0001, "Parse", "Illegal tag")'
        raw.send("00012Home()")
        assert raw.read_line() == '00012 ! Error(2, 0002, "Parse", "No space at pos. 6")'
        assert (
            raw.cmd("00013", "GoTo(X(1),)")[1]
            == '00013 ! Error(3, 0502, "Parse", "Incorrect arguments")'
        )
        raw.cmd("00014", "ClearAllErrors()")
        assert (
            raw.cmd("00015", "GoTo(Q(1))")[1]
            == '00015 ! Error(3, 0502, "GoTo", "Incorrect arguments")'
        )
        raw.cmd("00016", "ClearAllErrors()")
        assert (
            raw.cmd("00017", "PtMeas(X(1), Y(2), Z(3))")[1]
            == '00017 ! Error(3, 1503, "PtMeas", "Tool not defined")'
        )
        raw.cmd("00018", "ClearAllErrors()")
        assert (
            raw.cmd("00019", 'ChangeTool("Probe9")')[1]
            == '00019 ! Error(3, 1502, "ChangeTool", "Tool not found")'
        )
        raw.cmd("00020", "ClearAllErrors()")
        assert raw.cmd("00021", "EnumTools()")[1:3] == ['00021 # "NoTool"', '00021 # "Probe1"']
        assert (
            raw.cmd("00022", "OnPtMeasReport(X(), R())")[1]
            == '00022 ! Error(3, 0510, "OnPtMeasReport", "Bad property")'
        )
        raw.cmd("00023", "ClearAllErrors()")
        assert raw.cmd("00024", "GetProp(FoundTool.PtMeasPar.Speed())")[1] == (
            '00024 ! Error(3, 1503, "GetProp", "Tool not defined")'
        )
        raw.cmd("00025", "ClearAllErrors()")
        raw.cmd("00026", 'FindTool("Probe1")')
        raw.cmd("00027", "SetProp(FoundTool.PtMeasPar.Speed(7.5), FoundTool.GoToPar.Speed(50))")
        props = "FoundTool.PtMeasPar.Speed(), FoundTool.Name(), FoundTool.AvrRadius()"
        assert raw.cmd("00028", f"GetProp({props})")[1] == (
            "00028 # FoundTool.PtMeasPar.Speed(7.5), "
            'FoundTool.Name("Probe1"), FoundTool.AvrRadius(1)'
        )
        assert raw.cmd("00029", "SetProp(Tool.PtMeasPar.Search(-1))")[1] == (
            '00029 ! Error(3, 0504, "SetProp", "Argument out of range")'
        )
        raw.cmd("00030", "ClearAllErrors()")
        assert (
            raw.cmd("00031", "GetProp(Tool.Colour())")[1]
            == '00031 ! Error(3, 0510, "GetProp", "Bad property")'
        )
        assert (
            raw.cmd("00032", "GetDMEVersion()")[1]
            == '00032 ! Error(2, 0514, "GetDMEVersion", "Use ClearAllErrors to continue")'
        )
        # 6.2.5: in an error state only ClearAllErrors, GetErrStatusE, GetXtdErrStatus
        assert (
            raw.cmd("00033", "EndSession()")[1]
            == '00033 ! Error(2, 0514, "EndSession", "Use ClearAllErrors to continue")'
        )
        raw.cmd("00036", "ClearAllErrors()")
        assert raw.cmd("00037", "EndSession()") == ["00037 &", "00037 %"]
        assert raw.cmd("00034", "StartSession()") == ["00034 &", "00034 %"]
        assert raw.cmd("00035", "GetDMEVersion()")[1] == '00035 # DMEVersion("1.4.3")'
        raw.close()
    assert server.commands[0] == "00001 Home()" and len(server.commands) == 38


# ------------------------------------------------------------------- faults
def test_fault_events_are_interleaved_with_the_data():
    with _server(
        faults=[Fault("event", nth=2, method="PtMeas", events=("A()", "B(1)", "C(2)"))]
    ) as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", "GoTo(X(10), Y(20), Z(50))")
        plain = raw.cmd("00006", "PtMeas(X(10), Y(20), Z(43), IJK(0, 0, 1))")
        raw.cmd("00007", "GoTo(X(10), Y(20), Z(50))")
        mixed = raw.cmd("00008", "PtMeas(X(10), Y(20), Z(43), IJK(0, 0, 1))")
        raw.close()
    assert len(plain) == 3
    assert mixed == [
        "00008 &",
        "E0000 # A()",
        plain[1].replace("00006", "00008"),
        "E0000 # B(1)",
        "E0000 # C(2)",
        "00008 %",
    ]


def test_fault_split_sends_the_same_bytes_in_pieces():
    def response(faults):
        with _server(faults=faults) as server:
            sock = socket.create_connection(("127.0.0.1", server.port), timeout=SAFETY_S)
            sock.sendall(b"00001 StartSession()\r\n00002 GetDMEVersion()\r\n")
            data = b""
            while not data.endswith(b"00002 %\r\n"):
                chunk = sock.recv(65536)
                assert chunk
                data += chunk
            sock.close()
            return data

    assert response([Fault("split", nth=2, chunk_bytes=1)]) == response([])


def test_a_response_in_one_write_is_the_bytes_written_line_by_line():
    """Without a fault a response goes out in one write; with a fault on every command
    (a split in pieces larger than any line) line by line: the same bytes, errors and
    reports included."""
    commands = [
        "StartSession()",
        "Home()",
        'ChangeTool("Probe1")',
        "GoTo(X(10), Y(20), Z(60))",
        "PtMeas(X(10), Y(20), Z(42.7), IJK(0, 0, 1))",
        "GoTo(X(10), Y(20), Z(30))",  # into the ball: a collision
        "GetErrStatusE()",
        "ClearAllErrors()",
        "OnPtMeasReport(IJK(), X(), Y(), Z(), ER())",
        "GoTo(X(40), Y(20), Z(60))",
        "GoTo(X(40), Y(20), Z(30))",
        "PtMeas(X(22.7), Y(20), Z(30), IJK(1, 0, 0))",
        "Get(X(), Y(), Z())",
        "Nonsense(1)",
        "EndSession()",
    ]
    wire = b"".join(f"{k + 1:05d} {c}\r\n".encode() for k, c in enumerate(commands))
    last = f"{len(commands):05d} %\r\n".encode()

    def response(faults):
        with _server(faults=faults, noise_um=0.5, seed=2) as server:
            sock = socket.create_connection(("127.0.0.1", server.port), timeout=SAFETY_S)
            sock.sendall(wire)
            data = b""
            while not data.endswith(last):
                chunk = sock.recv(65536)
                assert chunk
                data += chunk
            sock.close()
            return data

    line_by_line = [Fault("split", nth=k, chunk_bytes=10**6) for k in range(1, len(commands) + 1)]
    whole = response([])
    assert whole == response(line_by_line)
    assert b"! Error(3, 2504" in whole and b"00012 # IJK(1, 0, 0), X(22.69" in whole
    assert b'00014 ! Error(3, 0501, "Nonsense"' in whole


def test_fault_drop_closes_mid_transaction():
    for after, expected in (
        (0, []),
        (1, ["00002 &"]),
        (2, ["00002 &", '00002 # DMEVersion("1.4.3")']),
    ):
        with _server(faults=[Fault("drop", nth=2, after_lines=after)]) as server:
            raw = Raw(server.port)
            raw.cmd("00001", "StartSession()")
            assert raw.cmd("00002", "GetDMEVersion()") == expected
            assert raw.read_line() is None  # closed
            raw.close()


def test_fault_delay_holds_the_rest_of_the_response():
    with _server(faults=[Fault("delay", nth=1, delay_s=0.3)]) as server:
        raw = Raw(server.port)
        t0 = time.monotonic()
        raw.send("00001 StartSession()")
        assert raw.read_line() == "00001 &"
        assert raw.read_line() == "00001 %"
        assert time.monotonic() - t0 >= 0.3
        raw.close()
    # a long delay does not hold up closing the server: the close ends (an event) long
    # before the delay would (the join's limit is a safety net, not a timing assumption)
    server = _server(faults=[Fault("delay", nth=1, delay_s=100 * SAFETY_S)])
    raw = Raw(server.port)
    raw.send("00001 StartSession()")
    assert raw.read_line() == "00001 &"
    closing = threading.Thread(target=server.close)
    closing.start()
    closing.join(SAFETY_S)
    raw.close()
    assert not closing.is_alive(), "closing the server waited for the delay"


def test_faults_fire_once_on_the_nth_command_counted_as_asked():
    faults = [
        Fault("error", nth=3),  # the 3rd command of any kind
        # the 2nd GetDMEVersion is the 3rd command, taken by the first fault: use the 3rd
        Fault("error", nth=3, method="GetDMEVersion", severity=1, number=9001, text="Hello"),
    ]
    with _server(faults=faults) as server:
        raw = Raw(server.port)
        raw.cmd("00001", "StartSession()")
        assert raw.cmd("00002", "GetDMEVersion()")[1] == '00002 # DMEVersion("1.4.3")'
        assert raw.cmd("00003", "GetDMEVersion()") == [
            "00003 &",
            '00003 ! Error(2, 1011, "GetDMEVersion", "Unable to move")',
            "00003 %",
        ]
        raw.cmd("00004", "ClearAllErrors()")
        assert (
            raw.cmd("00005", "GetDMEVersion()")[1]
            == '00005 ! Error(1, 9001, "GetDMEVersion", "Hello")'
        )
        assert (
            raw.cmd("00006", "GetDMEVersion()")[1] == '00006 # DMEVersion("1.4.3")'
        )  # warning: no state
        raw.close()
    # counting goes on across connections
    with _server(faults=[Fault("error", nth=3, severity=3)]) as server:
        for tag in ("00001", "00002"):
            raw = Raw(server.port)
            lines = raw.cmd(tag, "StartSession()")
            raw.close()
        assert lines == ["00002 &", "00002 %"]
        raw = Raw(server.port)
        assert (
            raw.cmd("00003", "StartSession()")[1]
            == '00003 ! Error(3, 2504, "StartSession", "Collision")'
        )
        raw.close()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"kind": "boom", "nth": 1},
        {"kind": "error", "nth": 0},
        {"kind": "error", "nth": 1, "severity": 10},
        {"kind": "split", "nth": 1, "chunk_bytes": 0},
        {"kind": "delay", "nth": 1, "delay_s": -1.0},
    ],
)
def test_fault_preconditions(kwargs):
    with pytest.raises(IppDmeError):
        Fault(**kwargs)


def test_backend_and_server_preconditions():
    for centres, radii in (
        ([0, 0, 0], 1.0),
        ([[0, 0, 0]], 0.0),
        ([[0, 0, np.inf]], 1.0),
        (np.zeros((0, 3)), 1.0),
    ):
        with pytest.raises(IppDmeError):
            StaticBalls(centres, radii)
    balls = StaticBalls([[0, 0, 0]], 1.0)
    with pytest.raises(IppDmeError):
        IppSimServer(balls, noise_um=-1.0)
    with pytest.raises(IppDmeError):
        IppSimServer(balls, tools={"P": 0.0})
    with IppSimServer(balls) as server:
        assert server.url == f"ipp://127.0.0.1:{server.port}" and server.port > 0


# ------------------------------------------------------------------- dialects
def test_dme_1_4_dialect_speaks_as_the_nist_server():
    """What the NIST I++ DME Test Suite's server (DME 1.4) answered, line for line in kind."""
    with _server(dialect="dme-1.4") as server:
        raw = Raw(server.port)
        _ready(raw)
        assert raw.cmd("00005", "GetDMEVersion()")[1] == '00005 # DMEVersion("1.4")'
        assert raw.cmd("00006", "GetProp(Tool.AvrRadius())")[1] == (
            '00006 ! Error(3, 0502, "GetProp", "Incorrect arguments")'
        )
        raw.cmd("00007", "ClearAllErrors()")
        raw.cmd("00008", "GoTo(X(10), Y(20), Z(60))")
        lines = raw.cmd("00009", "PtMeas(X(10), Y(20), Z(43), IJK(0, 0, 1))")
        body = lines[1].split(" # ")[1]
        assert [x.split("(")[0] for x in body.split("), ")] == ["ER", "IJK", "X", "Y", "Z"]
        assert _data(lines)["Z"][0] == pytest.approx(CENTRE[2] + R_MM)
        # FindTool is lax: no error, FoundTool as it was
        assert raw.cmd("00010", 'FindTool("Probe1")') == ["00010 &", "00010 %"]
        assert raw.cmd("00011", 'FindTool("Probe9")') == ["00011 &", "00011 %"]
        assert (
            raw.cmd("00012", "GetProp(FoundTool.Name())")[1] == '00012 # FoundTool.Name("Probe1")'
        )
        raw.close()
        # the session outlives the connection: a new StartSession is refused
        raw = Raw(server.port)
        assert raw.cmd("00001", "StartSession()")[1] == (
            '00001 ! Error(3, 0507, "StartSession", "Illegal command")'
        )
        assert raw.cmd("00002", "EndSession()")[1].startswith("00002 ! Error(2, 0514")
        raw.cmd("00003", "ClearAllErrors()")
        assert raw.cmd("00004", "EndSession()") == ["00004 &", "00004 %"]
        assert raw.cmd("00005", "StartSession()") == ["00005 &", "00005 %"]
        raw.close()
    with _server() as server:  # the default: one session per connection
        for _ in range(2):
            raw = Raw(server.port)
            assert raw.cmd("00001", "StartSession()") == ["00001 &", "00001 %"]
            raw.close()
    with pytest.raises(IppDmeError, match="dialect"):
        _server(dialect="dme-2")


def test_a_warning_fault_comes_with_the_answer():
    fault = Fault("error", nth=1, method="PtMeas", severity=1, number=1005)
    with _server(faults=[fault]) as server:
        raw = Raw(server.port)
        _ready(raw)
        raw.cmd("00005", "GoTo(X(10), Y(20), Z(60))")
        lines = raw.cmd("00006", "PtMeas(X(10), Y(20), Z(43), IJK(0, 0, 1))")
        assert lines[1].startswith('00006 ! Error(1, 1005, "PtMeas"')
        assert _data(lines)["Z"][0] == pytest.approx(CENTRE[2] + R_MM)
        raw.close()
