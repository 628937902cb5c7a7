"""``--help`` as a lab reads it (issue 34, item 6): every option of every command described,
the exit-status table complete at the top, the commands in a lab's order, no option's
help naming an option its command lacks."""

from __future__ import annotations

import re

import click
import pytest
from click.testing import CliRunner

from hexatherm.cli import COMMANDS, EXIT_CODES, main

#: numeric options whose values carry no unit (a count, a factor, a seed, a port)
UNITLESS = re.compile(
    r"coverage|seed|port|cycles|random|grid|mc$|draws|readings|reconnects|repeats|"
    r"points|min_points|calibration|level|jobs|candidates|workers|every|max_targets|n_"
)
#: what names a unit in a help text (or the option's name carries it)
UNIT = re.compile(
    r"\b(um|mm|deg|s|K|C|urad|baud|bits|Hz|h|%|ppm|degC|seconds)\b|\(s\)|_um$|_mm$|_s$|_deg$|_c$"
)


def commands() -> list[click.Command]:
    ctx = click.Context(main)
    found = [main.get_command(ctx, name) for name in COMMANDS]
    assert all(c is not None for c in found)
    return found  # type: ignore[return-value]


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_option_of_every_command_has_help(name: str) -> None:
    command = main.get_command(click.Context(main), name)
    assert command is not None and (command.help or "").strip(), name
    bare = [
        p.opts[0]
        for p in command.params
        if isinstance(p, click.Option) and not p.hidden and not (p.help or "").strip()
    ]
    assert bare == [], f"{name}: options without help: {bare}"


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_number_option_names_its_unit(name: str) -> None:
    command = main.get_command(click.Context(main), name)
    assert command is not None
    missing = []
    for p in command.params:
        if not isinstance(p, click.Option) or p.is_flag or p.name is None:
            continue
        numeric = isinstance(p.type, click.types.FloatParamType | click.types.IntParamType) or type(
            p.type
        ).__name__ in ("CheckedFloat", "PoseTolerance")
        if numeric and not UNITLESS.search(p.name):
            if not (UNIT.search(p.help or "") or UNIT.search(p.name)):
                missing.append(p.opts[0])
    assert missing == [], f"{name}: number options without a unit: {missing}"


@pytest.mark.parametrize("name", list(COMMANDS))
def test_no_help_names_an_option_its_command_lacks(name: str) -> None:
    result = CliRunner().invoke(main, [name, "--help"], terminal_width=4000)
    assert result.exit_code == 0, result.output
    command = main.get_command(click.Context(main), name)
    assert command is not None
    own = {o for p in command.params for o in [*p.opts, *getattr(p, "secondary_opts", [])]} | {
        "--help"
    }
    # an option of another command named as such ("plan --max-gap") is that command's
    others = "|".join(re.escape(n) for n in COMMANDS)
    text = re.sub(rf"\b({others}) (--[a-z-]+)", "", result.output)
    named = set(re.findall(r"(?<![\w-])(--[a-z][a-z-]+)", text))
    assert named <= own, f"{name} --help names {sorted(named - own)}"


def test_the_top_help_lists_the_commands_in_a_labs_order_and_every_exit_status() -> None:
    result = CliRunner().invoke(main, ["--help"], terminal_width=200)
    assert result.exit_code == 0
    listed = re.findall(r"^  ([a-z-]+)  ", result.output.split("Commands:")[1], re.M)
    assert listed[:8] == [
        "plan",
        "acquire",
        "run",
        "simulate",
        "process",
        "report",
        "calibrate",
        "diagnose",
    ]
    assert sorted(listed) == sorted(COMMANDS)
    flat = " ".join(result.output.split())
    for code in EXIT_CODES:
        assert re.search(rf"\b{code} ", flat.split("Exit status")[1]), code
    # exit 3 of each command that has it
    for words in ("process --strict", "calibrate --strict", "run"):
        assert words in flat.split("Exit status")[1], words
