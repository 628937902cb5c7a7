"""Options and error handling shared by every command."""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

from hexatherm.errors import HexathermError

F = TypeVar("F", bound=Callable[..., Any])

overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace the output if it exists (never by default)."
)
output_dir_option = click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(file_okay=False),
    default=None,
    help="Output folder [default: SESSION/results].",
)
interpolation_option = click.option(
    "--interpolation",
    type=click.Choice(["linear", "before", "after", "nearest"]),
    default="linear",
    show_default=True,
    help="With references on both sides of a target: interpolate their growth linearly in "
    "time, or use one neighbour as in the paper.",
)
quality_threshold_option = click.option(
    "--quality-threshold",
    "quality_thresholds",
    multiple=True,
    metavar="NAME=VALUE",
    help="Change a quality check's limit (repeatable; over the session file's quality: "
    "mapping): form_um, radius_dev_um, distance_dev_um, registration_rms_um, time_gap_s, "
    "temperature_change_C, min_rcond; inf (0 for min_rcond) disables a check.",
)
max_gap_option = click.option(
    "--max-gap",
    type=click.FloatRange(min=0),
    default=600.0,
    show_default=True,
    help="Warn when a target and its reference are further apart (s).",
)


def clean_errors(func: F) -> F:
    """Turn hexatherm's own errors into a one-line message on stderr and exit status 1.

    Anything else is a bug and keeps its traceback.
    """

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except HexathermError as exc:
            raise click.ClickException(str(exc)) from None

    return wrapper  # type: ignore[return-value]


def echo_err(message: str) -> None:
    """A log line on standard error (data goes to standard output)."""
    click.echo(message, err=True)


class ProgressBars:
    """Click progress bars on standard error, one per task, fed by ``update(label, done, total)``.

    A bar opens when a task first reports that it is under way (``done < total``), so
    that work that finishes at once (a fast file read) shows none; a new label closes
    the previous bar. Use as a context manager so that the last bar is closed.
    """

    def __init__(self) -> None:
        self.label: str | None = None
        self.bar: Any = None

    def update(self, label: str, done: int, total: int) -> None:
        """Task ``label`` has done ``done`` of ``total`` units."""
        if label != self.label:
            self.close()
            self.label = label
            if done >= total:
                return
            self.bar = click.progressbar(length=total, label=label, file=sys.stderr)
            self.bar.__enter__()
        if self.bar is not None:
            self.bar.update(max(0, min(done, total) - self.bar.pos))

    def reading(self, path: str, done: int, total: int) -> None:
        """Progress of reading a measurement file (lines), as
        :func:`hexatherm.workflows.process.pipeline.read_measured` reports it."""
        self.update(f"reading {os.path.basename(path)}", done, total)

    def draws(self, done: int, total: int) -> None:
        """Progress of Monte Carlo draws, as the process workflow reports them."""
        self.update("Monte Carlo draws", done, total)

    def close(self) -> None:
        """Close the open bar, if any."""
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
        self.bar = None
        self.label = None

    def __enter__(self) -> ProgressBars:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
