"""The ``hexatherm`` command line: one module per command, loaded lazily.

Each command lives in ``hexatherm.cli.<name>`` as a click command called
``command``; the group imports it only when that command runs (or its help is
asked for), so ``hexatherm --help`` stays fast.
"""

from __future__ import annotations

import importlib

import click

from hexatherm import __version__

#: command name -> (module, one-line help shown by ``hexatherm --help``)
COMMANDS: dict[str, tuple[str, str]] = {
    "process": ("hexatherm.cli.process", "Process a session: conventional and corrected poses."),
    "plan": ("hexatherm.cli.plan", "Write a measuring plan (and its DMIS program, checklist)."),
    "acquire": ("hexatherm.cli.acquire", "Record a session from a serial probe stream."),
    "fit-spheres": ("hexatherm.cli.fit_spheres", "Fit ball centres to probed points (CSV, DMIS)."),
    "inspect": ("hexatherm.cli.inspect", "List the features of a measurement file."),
    "register": ("hexatherm.cli.register", "Balls file from a measurement of the platform datums."),
    "replay": ("hexatherm.cli.replay", "Re-process recorded sessions against their expected/."),
    "diagnose": ("hexatherm.cli.diagnose", "Find where the twin and a session disagree, and why."),
    "simulate": ("hexatherm.cli.simulate", "Simulate a session (and its truth) from a scenario."),
    "report": ("hexatherm.cli.report", "Write an HTML report of a session with figures."),
    "run": ("hexatherm.cli.run", "Measure a plan unattended: CMM (I++ DME) and controller."),
    "serve-twin": ("hexatherm.cli.serve_twin", "Serve a simulated CMM and controller (the twin)."),
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        module = importlib.import_module(COMMANDS[cmd_name][0])
        command: click.Command = module.command
        return command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="hexatherm")
def main() -> None:
    """Thermal deflection decoupled 6-DOF pose measurement of hexapods.

    Data goes to standard output, messages and logs to standard error.
    """
