"""Every catchable terminating signal stops the hexapod like Ctrl-C (issue 22, item 7).

``hexatherm run`` runs as a separate process against the twin's machines (in this
process, on accelerated time). Once it says its first step is in position (the twin
has moved), it gets the signal; it must send STOP to the controller, exit with status
130 naming the signal, and leave a session that ``--resume`` completes. Nothing here
waits on the wall clock: the test reads the run's lines and waits for its end (the
timeouts are a safety net of 600 s that no passing run comes near).

There are two paths, and each is run end to end, killed and resumed: SIGINT, Python's
own KeyboardInterrupt, and SIGTERM, which :func:`~hexatherm.cli.signals.signals_interrupt`
turns into :class:`~hexatherm.errors.Terminated`. Every other terminating signal takes
SIGTERM's path exactly: the same handler raises the same class, which differs only by the
signal it carries, and the command line's message names ``Terminated.name``. What is left
to prove for each of them, that the handler is installed for it, raises ``Terminated``
naming it and gives the signal back afterwards, is asserted directly, in this process
(a whole killed and resumed run is 4-5 s a signal).
"""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.cli.signals import TERMINATING, signals_interrupt
from hexatherm.errors import Terminated
from hexatherm.workflows.serve import TwinMachines
from tests.cli.test_run import base, machines, write_plan  # noqa: F401  (the fixture)

#: a safety net against a hung process, never what decides a pass
SAFETY_S = 600.0

#: the two paths, run end to end: KeyboardInterrupt itself, and Terminated
END_TO_END = ["SIGINT", "SIGTERM"]
#: the signals that take SIGTERM's path, their mapping asserted in this process
LIKE_SIGTERM = ["SIGHUP", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGXCPU"]


def test_every_terminating_signal_is_handled() -> None:
    for name in ("SIGTERM", "SIGHUP", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGXCPU"):
        assert getattr(signal, name) in TERMINATING


@pytest.mark.parametrize("name", END_TO_END)
def test_a_signal_stops_the_hexapod_and_resume_completes(
    tmp_path: Path,
    machines: TwinMachines,  # noqa: F811
    name: str,
) -> None:
    plan = write_plan(tmp_path, [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]])
    session = tmp_path / "s"
    args = [str(a) for a in base(plan, machines, session)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "hexatherm", *args],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        seen = []
        for line in proc.stderr:  # until the first step is in position: the hexapod moved
            seen.append(line)
            if line.startswith("step 1/"):
                break
        assert seen and seen[-1].startswith("step 1/"), "".join(seen)
        before = machines.controller.received.count("STOP")
        proc.send_signal(getattr(signal, name))
        _, err = proc.communicate(timeout=SAFETY_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    err = "".join(seen) + err
    assert proc.returncode == 130, err
    assert machines.controller.received.count("STOP") == before + 1, err
    how = "Ctrl-C" if name == "SIGINT" else name
    # said once: what became of the hexapod, where the measurements are
    assert err.count("STOP") == 1, err
    assert (
        f"interrupted ({how}): the hexapod was sent STOP; everything measured is in {session}; "
        "continue with --resume\n"
    ) in err
    assert "Traceback" not in err
    transcript = (session / "ipp.transcript").read_text()
    assert f"run stopped interrupted ({how})" in transcript
    assert not (session / "session.yaml").exists()
    # resumable: --resume completes the campaign, every ball of every step once
    result = CliRunner().invoke(main, [*args, "--resume"])
    assert result.exit_code == 0, result.output
    points = pd.read_csv(session / "points.csv")
    counts = points.groupby(["label", "ball"]).size()
    assert len(counts) == 4 * 3 and (counts == 6).all()
    assert (session / "session.yaml").is_file()


@pytest.mark.parametrize("name", LIKE_SIGTERM)
def test_every_other_terminating_signal_takes_sigterms_path(name: str) -> None:
    """Inside ``signals_interrupt`` (as ``hexatherm run`` drives the machines) the signal
    raises :class:`Terminated` naming it, a KeyboardInterrupt as SIGTERM's is; a second one
    while its stop runs is noted, not raised; the previous handler is back afterwards."""
    sig = getattr(signal, name)
    previous = signal.getsignal(sig)
    with pytest.raises(Terminated) as caught, signals_interrupt() as received:
        # checked first: a signal left to its default action would end the test process
        assert signal.getsignal(sig) is not previous, f"{name} is not caught"
        try:
            signal.raise_signal(sig)  # the handler runs before the next line
        finally:
            signal.raise_signal(sig)  # the stop under way: noted and ignored
    assert isinstance(caught.value, KeyboardInterrupt)
    assert (caught.value.signum, caught.value.name) == (sig, name)
    assert received == [sig, sig]
    assert signal.getsignal(sig) is previous


@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP", "SIGINT"])
def test_a_signal_in_the_first_moments_exits_130(tmp_path: Path, name: str) -> None:
    """The signal arrives right after the command line module is imported (before the
    options are read, click and numpy loaded): exit status 130, said in one line."""
    code = (
        "import os, signal, sys; sys.argv = ['hexatherm', 'run', '--help']; "
        "import hexatherm.cli; "
        f"os.kill(os.getpid(), signal.{name}); "
        "print('not interrupted')"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=SAFETY_S,
    )
    how = "Ctrl-C" if name == "SIGINT" else name
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr == f"interrupted ({how})\n" and "not interrupted" not in proc.stdout
