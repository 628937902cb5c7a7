"""The ``hexatherm`` command line: one module per command, loaded lazily.

Each command lives in ``hexatherm.cli.<name>`` as a click command called
``command``; the group imports it only when that command runs (or its help is
asked for), so ``hexatherm --help`` stays fast.

Exit status, the same for every command (:data:`EXIT_CODES`):

====  ==========================================================================
code  meaning
====  ==========================================================================
0     done
1     refused: bad input, an output that would touch an input, a failed
      computation (one line on stderr naming file, line and field, or the step)
2     usage error: a bad option or argument (click's message)
3     ``--strict``: results written, but a check failed (``process``: a quality
      check; ``calibrate``: the model does not explain the poses); ``run``: the
      session recorded, but balls fail their checks after the re-probe
130   interrupted (Ctrl-C); outputs are whole or absent, a hexapod is stopped
====  ==========================================================================
"""

from __future__ import annotations

import importlib
import os
import sys
import textwrap
from typing import Any

from hexatherm.cli import allocator, collector
from hexatherm.cli.signals import exit_on_signals


def _command_of(argv: list[str]) -> str | None:
    """The command named on a command line (its first word that is not an option)."""
    return next((word for word in argv if not word.startswith("-")), None)


# ``run`` drives machines: a signal from its first moments on exits 130 like any other
# interruption (click and numpy take a quarter of a second to import, during which the
# default action would kill the process: exit -15 or -1)
if _command_of(sys.argv[1:]) == "run":
    exit_on_signals()

import click  # noqa: E402

from hexatherm import __version__  # noqa: E402

#: BLAS threads, one unless the user's environment says otherwise (set here, before
#: numpy is imported: nothing above imports it). The matrices are small (6x6 per pose,
#: a few hundred columns at most): a threaded BLAS gains little on them, and on a
#: shared machine its threads spin waiting for each other (calibrate --level auto, 100
#: targets: 6.5 s of CPU with the default threads on 2 loaded cores, 0.6 s with one;
#: issue 26). The outputs are the same bytes either way (checked on the commands'
#: outputs, see docs/speed.md).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
for _name in BLAS_THREAD_VARIABLES:
    os.environ.setdefault(_name, "1")

#: exit status -> meaning, for every command
EXIT_CODES = {
    0: "done",
    1: "refused: bad input, an output that would touch an input, a failed computation (one "
    "line on stderr naming file, line and field, or the step)",
    2: "usage error: a bad option or argument",
    3: "results written, but a check failed: process --strict (a quality check), calibrate "
    "--strict (the model does not explain the poses, chi-square), run (always: balls that "
    "fail their checks after the re-probe)",
    130: "interrupted (Ctrl-C; for run also SIGTERM, SIGHUP, SIGQUIT): outputs are whole or "
    "absent, a hexapod driven by run is stopped",
}
#: the exit status of an interrupted command (128 + SIGINT, as shells report it)
INTERRUPTED = 130

#: where the group keeps its arguments as given, in ``click.Context.meta``
ARGV_KEY = "hexatherm.argv"

#: command name -> (module, one-line help shown by ``hexatherm --help``), in a lab's order:
#: plan, measure (acquire, run, simulate), process, report, calibrate, diagnose, then the
#: tools (``hexatherm --help`` lists them in this order)
COMMANDS: dict[str, tuple[str, str]] = {
    "plan": ("hexatherm.cli.plan", "Write a measuring plan (and its DMIS program, checklist)."),
    "acquire": ("hexatherm.cli.acquire", "Record a session from a serial probe stream."),
    "run": ("hexatherm.cli.run", "Measure a plan unattended: CMM (I++ DME) and controller."),
    "simulate": ("hexatherm.cli.simulate", "Simulate a session (and its truth) from a scenario."),
    "process": ("hexatherm.cli.process", "Process a session: conventional and corrected poses."),
    "report": ("hexatherm.cli.report", "Write the HTML report of a processed session's results."),
    "calibrate": ("hexatherm.cli.calibrate", "Calibrate the hexapod's geometry from sessions."),
    "diagnose": ("hexatherm.cli.diagnose", "Find where the twin and a session disagree, and why."),
    "fit-spheres": ("hexatherm.cli.fit_spheres", "Fit ball centres to probed points (CSV, DMIS)."),
    "inspect": ("hexatherm.cli.inspect", "List the features of a measurement file."),
    "register": ("hexatherm.cli.register", "Balls file from a measurement of the platform datums."),
    "replay": ("hexatherm.cli.replay", "Re-process recorded sessions against their expected/."),
    "serve-twin": ("hexatherm.cli.serve_twin", "Serve a simulated CMM and controller (the twin)."),
}


def exit_status_help() -> str:
    """The exit-status table of :data:`EXIT_CODES`, as ``hexatherm --help`` prints it (kept
    as written: click does not rewrap a paragraph that starts with ``\\b``)."""
    rows = [
        textwrap.fill(text, 72, initial_indent=f"{code:>3}  ", subsequent_indent=" " * 5)
        for code, text in EXIT_CODES.items()
    ]
    return "\b\nExit status, the same for every command:\n" + "\n".join(rows)


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)  # a lab's order, not the alphabet's

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        module = importlib.import_module(COMMANDS[cmd_name][0])
        command: click.Command = module.command
        return command

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """Run the command line with the garbage collector paused until the command has
        imported its modules (:mod:`hexatherm.cli.collector`: each command resumes it in
        :func:`~hexatherm.cli.collector.imports_done`; restored at the end whatever
        happens)."""
        with collector.paused():
            return super().main(*args, **kwargs)

    def make_context(
        self,
        info_name: str | None,
        args: list[str],
        parent: click.Context | None = None,
        **extra: Any,
    ) -> click.Context:
        """The group's context, keeping the arguments as given (for ``provenance.json``)."""
        given = list(args)
        ctx = super().make_context(info_name, args, parent=parent, **extra)
        ctx.meta[ARGV_KEY] = given
        return ctx

    def invoke(self, ctx: click.Context) -> object:
        """Run the command; Ctrl-C exits with :data:`INTERRUPTED` (click would say 1). A
        command that computes keeps the memory it frees for its next arrays
        (:mod:`hexatherm.cli.allocator`)."""
        allocator.keep_freed_memory(_command_of(ctx.meta.get(ARGV_KEY, [])))
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            click.echo("interrupted", err=True)
            raise click.exceptions.Exit(INTERRUPTED) from None

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][1]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(
    cls=LazyGroup,
    context_settings={"help_option_names": ["-h", "--help"]},
    epilog=exit_status_help(),
)
@click.version_option(__version__, prog_name="hexatherm")
def main() -> None:
    """Thermal deflection decoupled 6-DOF pose measurement of hexapods.

    A lab's day, in the order the commands are listed: plan the steps, measure them
    (acquire, run or simulate), process the session, report its results, calibrate the
    hexapod, diagnose a disagreement. Data goes to standard output, messages and logs to
    standard error; `hexatherm COMMAND --help` lists a command's options.
    """
