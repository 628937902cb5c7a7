"""``hexatherm serve-twin``: two servers on 127.0.0.1 that answer like the real machines."""

from __future__ import annotations

import signal
import subprocess
import sys

from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.devices.ipp import IppClient, parse_ipp_url
from hexatherm.devices.urls import controller_from_url
from hexatherm.io.config import read_hexapod
from tests.sessions import ROOT

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


def test_serve_twin_prints_its_urls_serves_and_stops_on_ctrl_c() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "hexatherm", "serve-twin", "--hexapod", str(HEXAPOD),
         "--balls", str(BALLS), "--dialect", "pi", "--time-scale", "100",
         "--fault", "ipp-error:severity=2,method=IsHomed,nth=1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        cmm_line, controller_line = proc.stdout.readline(), proc.stdout.readline()
        assert cmm_line.startswith("cmm: ipp://127.0.0.1:"), cmm_line
        assert controller_line.startswith("controller: pi://127.0.0.1:"), controller_line
        host, port = parse_ipp_url(cmm_line.split()[1])
        with IppClient(host, port, timeout_s=30) as cmm:
            cmm.start_session()
            assert cmm.is_homed() is False  # after the injected error, cleared and retried
            cmm.home()
            cmm.change_tool("Probe1")
            assert "ClearAllErrors" in "".join(r.command for r in cmm.recorder.results)
        hexapod = read_hexapod(HEXAPOD)
        with controller_from_url(controller_line.split()[1], hexapod=hexapod) as controller:
            temperatures = controller.read_temperatures()
            assert temperatures.shape == (6,) and (temperatures > 15).all()
            assert abs(controller.read_pose()).max() < 1e-3
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "stopped" in err and "hexatherm run PLAN --cmm ipp://127.0.0.1:" in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_a_bad_fault_is_refused() -> None:
    result = CliRunner().invoke(
        main, ["serve-twin", "--hexapod", str(HEXAPOD), "--balls", str(BALLS),
               "--fault", "ipp-error:colour=red"]
    )  # fmt: skip
    assert result.exit_code == 1 and "bad setting 'colour=red'" in result.output
    result = CliRunner().invoke(main, ["serve-twin", "--hexapod", str(HEXAPOD)])
    assert result.exit_code == 2 and "--balls" in result.output
