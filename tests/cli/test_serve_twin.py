"""``hexatherm serve-twin``: two servers on 127.0.0.1 that answer like the real machines."""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.devices.ipp import IppClient, parse_ipp_url
from hexatherm.devices.probestream import parse_numbers
from hexatherm.devices.serialport import PortSettings
from hexatherm.devices.urls import controller_from_url
from hexatherm.io.config import read_hexapod
from tests.sessions import ROOT
from tests.waiting import SAFETY_S

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


@contextmanager
def serving(*options: str) -> Iterator[subprocess.Popen[str]]:
    """``hexatherm serve-twin`` of the symetrie-like hexapod and its three balls with
    ``options``, its standard output and error piped; killed if still running at the end."""
    command = [sys.executable, "-m", "hexatherm", "serve-twin", "--hexapod", str(HEXAPOD),
               "--balls", str(BALLS), *options]  # fmt: skip
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_serve_twin_prints_its_urls_serves_and_stops_on_ctrl_c() -> None:
    with serving(
        "--dialect",
        "pi",
        "--time-scale",
        "100",
        "--fault",
        "ipp-error:severity=2,method=IsHomed,nth=1",
    ) as proc:
        assert proc.stdout is not None
        cmm_line, controller_line = proc.stdout.readline(), proc.stdout.readline()
        thermo_line = proc.stdout.readline()
        assert cmm_line.startswith("cmm: ipp://127.0.0.1:"), cmm_line
        assert controller_line.startswith("controller: pi://127.0.0.1:"), controller_line
        assert thermo_line.startswith("thermocouples: socket://127.0.0.1:"), thermo_line
        # the logger, opened as run --temperature-port opens it (pyserial), sends lines that
        # acquire's parser reads as six legs and the air, the mats' heating on the legs
        port = PortSettings(thermo_line.split()[1], timeout_s=SAFETY_S).open()
        try:
            port.readline()  # the first line may be cut by pyserial's flush at open
            samples = [parse_numbers(port.readline()) for _ in range(2)]
        finally:
            port.close()
        for sample in samples:
            assert sample is not None and len(sample) == 7
            assert all(15.0 < v < 40.0 for v in sample) and sample[6] == 20.0
        host, port = parse_ipp_url(cmm_line.split()[1])
        with IppClient(host, port, timeout_s=SAFETY_S) as cmm:
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
        _, err = proc.communicate(timeout=SAFETY_S)
        assert proc.returncode == 0, err
        assert "stopped" in err and "hexatherm run PLAN --cmm ipp://127.0.0.1:" in err
        # what the accelerated time does to the rehearsal's heating, said before serving
        assert err.count("warning: --time-scale 100: the twin's legs heat 100 times faster") == 1
        assert "the heating's 2400 s time constant lasts 24 s of the session's times" in err


def test_serve_twin_cmm_dialect_dme_1_4() -> None:
    with serving("--cmm-dialect", "dme-1.4", "--time-scale", "100") as proc:
        assert proc.stdout is not None
        cmm_line = proc.stdout.readline()
        host, port = parse_ipp_url(cmm_line.split()[1])
        with IppClient(host, port, timeout_s=30) as cmm:
            assert cmm.start_session() is False
            assert cmm.dme_version() == ("1.4", (1, 4))
        with IppClient(host, port, timeout_s=30) as cmm:  # the session was kept
            assert cmm.start_session() is True
            cmm.end_session()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err


def test_ctrl_c_as_soon_as_the_urls_are_out_stops_it() -> None:
    """Ctrl-C right after the first URL is printed (while the others and the rehearsal
    line are still being written) stops the serving as any Ctrl-C does: exit 0,
    "stopped". It exited 130 ("interrupted") when the signal came before the wait for it
    began: a whole-suite run under load saw it after two I++ sessions."""
    with serving("--time-scale", "100") as proc:
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("cmm: ipp://127.0.0.1:")
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert err.rstrip().endswith("stopped")


def test_a_bad_fault_is_refused() -> None:
    result = CliRunner().invoke(
        main, ["serve-twin", "--hexapod", str(HEXAPOD), "--balls", str(BALLS),
               "--fault", "ipp-error:colour=red"]
    )  # fmt: skip
    assert result.exit_code == 2 and "bad setting 'colour=red'" in result.output
    result = CliRunner().invoke(main, ["serve-twin", "--hexapod", str(HEXAPOD)])
    assert result.exit_code == 2 and "--balls" in result.output


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["--time-scale", "nan"], 2, "'nan' is not a number"),
        (["--time-scale", "0"], 2, "must be >= 0.001"),
        (["--time-scale", "inf"], 2, "must be finite"),
        (["--speed-mm-s", "nan"], 2, "'nan' is not a number"),
        (["--settle", "-1"], 2, "must be >= 0"),
        (["--cmm-move-s", "inf"], 2, "must be finite"),
        (["--point-noise-um", "nan"], 2, "'nan' is not a number"),
        (["--thermocouple-period", "0"], 2, "must be >= 0.01"),
        (["--thermocouple-period", "nan"], 2, "'nan' is not a number"),
        (["--seed", "-1"], 2, "not in the range"),
        (["--origin-on-cmm", "0,0,0,0,0,inf"], 2, "expected 6 finite numbers"),
        (["--fault", "late-in-position:seconds=nan"], 2, "must be a finite number"),
        (["--fault", "late-in-position:seconds=-3"], 2, "seconds must be >= 0"),
        (["--fault", "refuse:axis=Tz,max=nan"], 2, "must be a finite number"),
        (["--fault", "ipp-error:severity=2,nth=inf"], 2, "must be a finite number"),
        (["--fault", "ipp-error:severity=12"], 2, "severity must be 0..9"),
        # issue 22, "Also": an empty interval refused every pose and was accepted
        (["--fault", "refuse:axis=Tz,min=5,max=-5"], 2, "min=5 is above max=-5"),
    ],
)
def test_hostile_values_are_one_line_errors(args: list[str], code: int, message: str) -> None:
    """Refused before any server starts: one line, no traceback."""
    result = CliRunner().invoke(
        main, ["serve-twin", "--hexapod", str(HEXAPOD), "--balls", str(BALLS), *args]
    )
    assert result.exit_code == code, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert message in result.output
    assert "Traceback" not in result.output and "serving" not in result.output


def test_an_empty_refuse_interval_is_refused_and_a_point_interval_kept() -> None:
    """Issue 22, "Also": min above max refused every pose, silently."""
    from hexatherm.errors import InputError
    from hexatherm.workflows.serve import parse_fault

    with pytest.raises(InputError, match=r"min=5 is above max=-5: an empty interval"):
        parse_fault("refuse:axis=Tz,min=5,max=-5")
    refuse = parse_fault("refuse:axis=Tz,min=5,max=5").controller.refuse
    assert refuse is not None
    assert not refuse([0, 0, 5.0, 0, 0, 0]) and refuse([0, 0, 4.999, 0, 0, 0])
