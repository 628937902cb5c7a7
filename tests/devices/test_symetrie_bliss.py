"""Symétrie API v2 as ESRF's BLISS client speaks it, against the twin and the driver.

BLISS (``bliss.controllers.motors.hexapode.symetrie``, LGPL, read to learn the dialect,
nothing copied) is a public client of the controllers' port 61559. The small client here
is written from its documented behaviour, to pin the dialect the twin must speak:

* the greeting is 4 lines, the 2nd ``API version: X``, the 3rd ``Project: Y``;
* a command is ``NAME`` + the arguments joined by commas + CR LF (``CFG#CS?3``);
* replies are ``NAME:CODE[,DATA]``, ``NAME`` the command up to its ``?``; a command
  "with acknowledge" (every one but ``STA#HEXAPOD?`` / ``STA#AXES?``) is answered ``1``
  then ``2``; the other queries only ``2``; DATA loses its first comma;
* the status word is read with ``int()`` (so ``858.0`` is refused);
* ``CFG#CS?3`` answers ``3,`` then the user frame and the object frame (6 + 6);
* ``STA#AXES?``: ``N``, ``N`` status words (``int()``), ``N`` lengths in m.

Runs on a ManualClock shared with the twin: no test waits for wall-clock time. The truth
is the twin's model (its true pose, its IGM), not the driver.
"""

from __future__ import annotations

import re
import socket
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.controller import LineBuffer
from hexatherm.devices.controllersim import ManualClock, SimulatedHexapod, SymetrieSimulator

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "symetrie-like.yaml"
REPLY = re.compile(r"(?P<cmd>[^:]+):(?P<code>[+\-0-9]+)(?P<data>.*)$")


def make_hexapod() -> Hexapod:
    data = yaml.safe_load(CONFIG.read_text())
    return Hexapod(
        name=data["name"],
        convention="symetrie",
        base_joints_mm=np.array(data["base_joints"], dtype=float),
        platform_joints_mm=np.array(data["platform_joints"], dtype=float),
        stroke_mm=np.array(data["stroke"], dtype=float),
    )


class BlissLikeClient:
    """What BLISS sends and how it parses the answers (see the module docstring)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.buffer = LineBuffer()
        self.lines: list[str] = []
        greeting = [self.readline() for _ in range(4)]
        self.api_version = greeting[1].split(":", 1)[1].strip()
        self.project = greeting[2].split(":", 1)[1].strip()

    def readline(self) -> str:
        while not self.lines:
            data = self.sock.recv(4096)
            assert data, "the twin closed the connection"
            self.lines.extend(self.buffer.feed(data))
        return self.lines.pop(0)

    def reply(self, cmd_id: str, expected: int) -> str:
        match = REPLY.match(self.readline())
        assert match is not None
        assert match["cmd"] == cmd_id, f"a reply to {match['cmd']!r}, none pending"
        assert int(match["code"]) == expected, f"code {match['code']} to {cmd_id}"
        return match["data"]

    def __call__(self, cmd: str, *args: object, ack: bool = True) -> str:
        cmd_id = cmd.split("?", 1)[0]
        self.sock.sendall(f"{cmd}{','.join(map(str, args))}\r\n".encode())
        if ack:
            self.reply(cmd_id, 1)
        data = self.reply(cmd_id, 2)
        return data[1:] if "?" in cmd and data else data

    def status(self) -> tuple[int, np.ndarray]:
        data = self("STA#HEXAPOD?", ack=False).split(",")
        pose = np.array([float(v) for v in data[1:7]])
        pose[:3] *= 1e3
        pose[3:] = np.rad2deg(pose[3:])
        return int(data[0]), pose

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def twin() -> Iterator[tuple[SimulatedHexapod, ManualClock, BlissLikeClient]]:
    clock = ManualClock(100.0)
    model = SimulatedHexapod(make_hexapod(), clock=clock)
    sim = SymetrieSimulator(model)
    client = BlissLikeClient(sim.port)
    yield model, clock, client
    client.close()
    sim.close()


def test_bliss_like_client_moves_the_twin(
    twin: tuple[SimulatedHexapod, ManualClock, BlissLikeClient],
) -> None:
    model, clock, client = twin
    assert client.api_version.startswith("2.")
    cs = client("CFG#CS?", 3).split(",")
    assert cs[0] == "3" and len(cs) == 13  # the leading field: the coordinate system asked
    np.testing.assert_array_equal([float(v) for v in cs[1:]], np.zeros(12))
    status, pose = client.status()  # int(): an integer status word
    assert status >> 1 & 1 and status >> 4 & 1  # ready, in position
    target = np.array([1.5, -0.75, 2.0, 0.2, -0.1, 0.5])
    wire = np.concatenate([target[:3] * 1e-3, np.deg2rad(target[3:])])
    client("MOVE#ABS", ",".join(map(str, wire)))
    for _ in range(1000):
        status, pose = client.status()
        if not status >> 5 & 1 and status >> 4 & 1:  # not moving, in position
            break
        clock.sleep(0.25)
    else:
        pytest.fail("the twin never reported in position")
    np.testing.assert_allclose(pose, target, atol=1e-9)
    np.testing.assert_allclose(model.true_pose(), target, atol=1e-12)
    axes = client("STA#AXES?", ack=False).split(",")
    n = int(axes[0])
    assert n == 6 and [int(v) for v in axes[1 : 1 + n]] == [0] * 6
    lengths_mm = np.array([float(v) for v in axes[1 + n :]]) * 1e3
    np.testing.assert_allclose(lengths_mm, model.hexapod.igm(target)[0], atol=1e-9)
    client("STOP")
    assert not model.moving()
