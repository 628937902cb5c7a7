"""Odd option values are usage errors, never tracebacks or silent NaN (issue 12, item 13).

Structural: every number option of every command either refuses NaN and infinity
(:class:`~hexatherm.cli.options.CheckedFloat`, or an integer type) and every integer
count or seed has an upper bound. Then the cases the audit found, end to end.
"""

from __future__ import annotations

from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.cli.options import CheckedFloat
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
SESSION = SHIPPED / "paper-zero-pose"
#: commands left out of the structural check (none)
ELSEWHERE: set[str] = set()


def commands() -> list[str]:
    with click.Context(main) as ctx:
        return [name for name in main.list_commands(ctx) if name not in ELSEWHERE]


def number_options(name: str) -> list[click.Option]:
    with click.Context(main) as ctx:
        command = main.get_command(ctx, name)
    assert command is not None
    return [
        p
        for p in command.params
        if isinstance(p, click.Option)
        and not p.is_flag
        and isinstance(p.type, click.types.FloatParamType | click.types.IntParamType | CheckedFloat)
    ]


@pytest.mark.parametrize("name", commands())
def test_float_options_refuse_nan_and_counts_are_bounded(name: str) -> None:
    for option in number_options(name):
        if isinstance(option.type, click.types.FloatParamType):
            pytest.fail(f"{name} {option.opts[-1]}: a click float lets nan through")
        if isinstance(option.type, click.types.IntParamType):
            assert isinstance(option.type, click.IntRange) and option.type.max is not None, (
                f"{name} {option.opts[-1]}: an unbounded integer"
            )


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


PLAN = [
    "plan",
    "--hexapod",
    ROOT / "configs" / "symetrie-like.yaml",
    "--balls",
    ROOT / "configs" / "balls-3.yaml",
]


@pytest.mark.parametrize(
    "args",
    [
        [*PLAN, "--random", "3", "--box", "Tx=-1:1", "--seed", "-1"],
        [*PLAN, "--random", "3", "--box", "Tx=-1:1", "--max-gap", "nan"],
        [*PLAN, "--random", "3", "--box", "Tx=-1:1", "--seconds-per-point", "inf"],
        [*PLAN, "--random", "3", "--box", "Tx=-1:1", "--cycles", "10" + "0" * 20],
        [*PLAN, "--random", "10" + "0" * 20, "--box", "Tx=-1:1"],
        [*PLAN, "--grid", "200", "--box", "Tx=-1:1", "--box", "Ty=-1:1", "--box", "Tz=-1:1"],
        [*PLAN, "--grid", "2", "--box", "Tx=-1:1", "--clearance", "nan"],
        [
            "fit-spheres",
            SHIPPED / "paper-zero-pose-dmis" / "points.dmo",
            "--diameter-mm",
            "nan",
        ],
        ["process", SESSION, "--mc", "1"],
        ["process", SESSION, "--mc", "-5"],
        ["process", SESSION, "--seed", "-1"],
        ["process", SESSION, "--distance-tolerance-um", "nan"],
        [
            "simulate",
            SHIPPED / "calibration-campaign" / "truth" / "scenario.yaml",
            "-o",
            "x",
            "--seed",
            "-1",
        ],
    ],
    ids=lambda args: " ".join(str(a) for a in args[-2:]) if isinstance(args, list) else None,
)
def test_odd_values_are_usage_errors(args: list[object], tmp_path: Path) -> None:
    result = run(*args)
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines()[-1].startswith("Error: Invalid value"), result.output
