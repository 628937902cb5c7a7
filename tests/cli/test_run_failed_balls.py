"""A run whose balls still fail their checks after the re-probe does not exit 0 (issue 22,
item 8).

The run is given a balls file whose diameters are 6 mm larger than the twin's balls: every
ball fits 3000 um below the nominal radius on both probings and is kept (nothing is lost),
and the run must say so: exit status 3, naming every ball.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.spherefit import fit_spheres
from hexatherm.devices.sim.ipp import Fault
from hexatherm.workflows.serve import TwinMachines
from tests.cli.test_run import BALLS, base, machines, write_plan  # noqa: F401  (the fixture)

TARGET = [[5.0, -3.0, 4.0, 1.0, -2.0, 3.0]]


def test_every_ball_off_exits_3_naming_the_balls_also_after_a_resume(
    tmp_path: Path,
    machines: TwinMachines,  # noqa: F811
) -> None:
    wrong = tmp_path / "balls-wrong.yaml"
    wrong.write_text(BALLS.read_text().replace("diameter: 25.4", "diameter: 31.4"))
    session = tmp_path / "s"
    args = [str(a) for a in base(write_plan(tmp_path, TARGET), machines, session)]
    args[args.index(str(BALLS))] = str(wrong)
    # stopped inside R0 (the CMM drops the link), then resumed: O's balls, accepted before
    # the resume, are checked again and named with the others
    machines.cmm._faults.append(Fault("drop", 3 * 6 * 2 + 4, "PtMeas", after_lines=1))
    stopped = CliRunner().invoke(main, [*args, "--reconnects", "0"])
    assert stopped.exit_code == 1 and "ball B1" in stopped.output, stopped.output
    result = CliRunner().invoke(main, [*args, "--resume"])
    assert result.exit_code == 3, result.output
    names = [f"{s} {b}" for s in ("O", "R0", "S1", "R1") for b in ("B1", "B2", "B3")]
    line = result.stderr.strip().splitlines()[-1]
    assert line.startswith(
        f"error: 12 of 12 balls still fail their checks after probing them again: "
        f"{', '.join(names)} (first: O B1: radius -"
    ), line
    # the truth: the points fit the twin's 25.4 mm balls, 3000 um below the nominal 31.4
    # (within 20 um: this twin heats while it probes, on a clock 100 times real time, so a
    # stalled test process moves the platform during a ball by a few um; 3000 um is the
    # point)
    points = pd.read_csv(session / "points.csv")
    groups = points.groupby(["label", "ball"], sort=False).ngroup().to_numpy()
    fits = fit_spheres(points[["x", "y", "z"]].to_numpy(), groups)
    np.testing.assert_allclose(fits.radius_mm, 12.7, atol=0.02)
    said = float(re.search(r"radius (-\d+\.\d) um off", line).group(1))  # type: ignore[union-attr]
    assert abs(said - 1e3 * (fits.radius_mm[0] - 15.7)) < 0.1
    # the session is recorded all the same (nothing lost), every ball once
    assert (session / "session.yaml").is_file() and len(points) == 12 * 6
    assert (points.groupby(["label", "ball"]).size() == 6).all()


def test_a_good_run_still_exits_0(tmp_path: Path, machines: TwinMachines) -> None:  # noqa: F811
    result = CliRunner().invoke(
        main, [str(a) for a in base(write_plan(tmp_path, TARGET), machines, tmp_path / "s")]
    )
    assert result.exit_code == 0, result.output
    assert "fail their checks" not in result.output
