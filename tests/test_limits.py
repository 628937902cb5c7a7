"""One table of limits (issue 34, item 3): every command that checks a ball, a distance or
a registration reads its default from :class:`hexatherm.limits.QualityLimits`, so that a
ball accepted while measuring is not flagged when processing, and the reverse; each
command's ``--help`` shows the limit it uses."""

from __future__ import annotations

import click
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.limits import DISTANCE_REFUSAL_UM, QualityLimits, limits_text
from hexatherm.workflows.acquire.recorder import FitChecks
from hexatherm.workflows.process.pipeline import Checks
from hexatherm.workflows.run.options import BallChecks

TABLE = QualityLimits()


def defaults(command: str) -> dict[str, object]:
    """Every option's default of ``hexatherm COMMAND``, by parameter name."""
    cmd = main.get_command(click.Context(main), command)
    assert cmd is not None
    return {p.name: p.default for p in cmd.params if p.name}


def test_measuring_checks_are_the_processing_limits() -> None:
    # a radius is half a diameter: 20 um on the diameter is 10 um on the radius
    assert FitChecks().radius_tol_mm * 1e3 == pytest.approx(TABLE.diameter_dev_um / 2)
    assert FitChecks().form_tol_um == TABLE.form_um
    assert FitChecks().centre_distance_tol_mm * 1e3 == pytest.approx(TABLE.distance_dev_um)
    assert BallChecks().radius_tol_um == TABLE.diameter_dev_um / 2
    assert BallChecks().form_um == TABLE.form_um
    for command in ("acquire", "run"):
        given = defaults(command)
        assert given["radius_tol_um"] == TABLE.diameter_dev_um / 2, command
        assert given["form_tol_um"] == TABLE.form_um, command


def test_process_warns_at_the_quality_limit_and_refuses_beyond_the_gross_one() -> None:
    assert Checks().registration_tolerance_um == TABLE.registration_rms_um
    assert Checks().distance_tolerance_um == DISTANCE_REFUSAL_UM > TABLE.distance_dev_um
    given = defaults("process")
    assert given["registration_tolerance_um"] == TABLE.registration_rms_um
    assert given["distance_tolerance_um"] == DISTANCE_REFUSAL_UM


@pytest.mark.parametrize("command", ["process", "acquire", "run"])
def test_every_checking_command_shows_its_limits_in_its_help(command: str) -> None:
    result = CliRunner().invoke(main, [command, "--help"], terminal_width=2000)
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.split())
    if command == "process":
        assert limits_text() in text
    if command in ("acquire", "run"):
        assert "half the quality limit diameter_dev_um" in text
        assert f"[default: {TABLE.diameter_dev_um / 2:g}" in text.replace(".0]", "]")
