"""``hexatherm serve-twin --dialect symetrie-pmac``: the gpascii controller over telnet."""

from __future__ import annotations

import signal

import numpy as np

from hexatherm.devices.symetriepmac import SymetriePmacController
from hexatherm.devices.urls import controller_from_url
from hexatherm.io.config import read_hexapod
from tests.cli.test_serve_twin import HEXAPOD, serving


def test_serve_twin_serves_the_gpascii_dialect() -> None:
    with serving("--dialect", "symetrie-pmac") as proc:
        assert proc.stdout is not None
        proc.stdout.readline()
        controller_line = proc.stdout.readline()
        assert controller_line.startswith("controller: symetrie-pmac://127.0.0.1:")
        hexapod = read_hexapod(HEXAPOD)
        with controller_from_url(
            controller_line.split()[1], hexapod=hexapod, reply_timeout_s=30
        ) as controller:
            assert isinstance(controller, SymetriePmacController)
            state = controller.state()
            assert state.ready and state.in_position and not state.error
            assert np.abs(controller.read_pose()).max() < 1e-3
            np.testing.assert_allclose(
                controller.read_actuators(), hexapod.igm(np.zeros(6))[0], atol=1e-6
            )
            controller.stop()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 0, err
        assert "--controller symetrie-pmac://127.0.0.1:" in err
