"""Options and error handling shared by every command."""

from __future__ import annotations

import functools
import math
import os
import re
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from hexatherm.cli.collector import imports_done as imports_done
from hexatherm.errors import HexathermError, InputWarning
from hexatherm.workflows.common import ReadOptions, run_context

# the lab's report templates, for the commands that write pages (report, calibrate, diagnose)
from hexatherm.workflows.common import template_files as template_files
from hexatherm.workflows.common import template_folder as template_folder
from hexatherm.workflows.limits import limits_text

F = TypeVar("F", bound=Callable[..., Any])

overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace the output if it exists (never by default)."
)


def folder_name(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    """``-o`` of an output folder as given: not empty (an unset shell variable would
    otherwise be read as ``.``, and refused naming a folder never given)."""
    if value is not None and not value:
        raise click.BadParameter("empty; give the output folder", ctx, param)
    return value


output_dir_option = click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(file_okay=False),
    default=None,
    callback=folder_name,
    help="Output folder [default: SESSION/results].",
)
interpolation_option = click.option(
    "--interpolation",
    type=click.Choice(["linear", "before", "after", "nearest", "smooth"]),
    default="linear",
    show_default=True,
    help="With references on both sides of a target: interpolate their growth linearly in "
    "time, or use one neighbour as in the paper; smooth: a smoothing spline of the growth "
    "over all references (per leg, chosen by cross-validation, which falls back to linear "
    "when the heating is not smooth).",
)


def _thresholds(
    ctx: click.Context, param: click.Parameter, values: tuple[str, ...]
) -> tuple[str, ...]:
    """Each ``NAME=VALUE`` checked before any work: a bad one is a usage error (status 2)."""
    from hexatherm.workflows.process.quality import parse_threshold

    seen: set[str] = set()
    for value in values:
        try:
            name, _ = parse_threshold(value)
        except HexathermError as exc:
            text = str(exc).removeprefix("--quality-threshold ")
            raise click.BadParameter(text, ctx=ctx, param=param) from None
        if name in seen:
            raise click.BadParameter(f"{value!r}: {name} is given twice", ctx=ctx, param=param)
        seen.add(name)
    return values


quality_threshold_option = click.option(
    "--quality-threshold",
    "quality_thresholds",
    multiple=True,
    callback=_thresholds,
    metavar="NAME=VALUE",
    help="Change a quality check's limit (repeatable; over the session file's quality: "
    f"mapping). The table of limits, units in the names: {limits_text()}; inf (0 for "
    "min_rcond) disables a check (docs/uncertainty.md, 'One table of limits').",
)
#: exit status of ``--strict`` when a check fails (the outputs are still written)
CHECK_FAILED_EXIT = 3
#: the largest number of Monte Carlo draws (the draws of every centre are held at once)
MAX_DRAWS = 100_000
#: seeds accepted (numpy's SeedSequence takes any integer >= 0; 64 bits are plenty)
MAX_SEED = 2**64 - 1
#: the fastest serial line accepted, baud (USB adapters reach a few Mbaud)
MAX_BAUD = 100_000_000


#: how infinity is written on purpose
_INF = ("inf", "infinity")


class CheckedFloat(click.ParamType):
    """A float option that refuses NaN (and infinity unless ``allow_inf``), within bounds.

    ``click.FloatRange`` lets ``nan`` through (every comparison with it is false), and a
    NaN tolerance turns its check off unseen.

    >>> CheckedFloat(min=0).convert("2.5", None, None)
    2.5
    >>> CheckedFloat(min=0).convert("nan", None, None)
    Traceback (most recent call last):
    ...
    click.exceptions.BadParameter: 'nan' is not a number
    """

    name = "float"

    def __init__(
        self,
        min: float | None = None,
        max: float | None = None,
        *,
        min_open: bool = False,
        allow_inf: bool = False,
    ) -> None:
        self.min, self.max, self.min_open, self.allow_inf = min, max, min_open, allow_inf

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> float:
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if math.isnan(number):
            self.fail(f"{value!r} is not a number", param, ctx)
        if math.isinf(number) and not self.allow_inf:
            self.fail(f"{value!r}: must be finite", param, ctx)
        if math.isinf(number) and str(value).strip().lower().lstrip("+-") not in _INF:
            # 1e400: a number past a float's range, not the word that turns a check off
            self.fail(f"{value!r}: beyond a float's range (inf is written inf)", param, ctx)
        if self.min is not None and (number < self.min or (self.min_open and number == self.min)):
            sign = ">" if self.min_open else ">="
            self.fail(f"{value!r}: must be {sign} {self.min:g}", param, ctx)
        if self.max is not None and number > self.max:
            self.fail(f"{value!r}: must be <= {self.max:g}", param, ctx)
        return number


class PoseTolerance(click.ParamType):
    """``MM,DEG``: the largest deviation of a measured pose from its commanded one;
    ``inf`` (or ``inf,inf``) turns the check off.

    >>> PoseTolerance().convert("2,1", None, None)
    (2.0, 1.0)
    >>> PoseTolerance().convert("inf", None, None)
    (inf, inf)
    """

    name = "MM,DEG"

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> tuple[float, float]:
        if isinstance(value, tuple):
            return value
        parts = str(value).split(",")
        if len(parts) == 1 and parts[0].strip().lower() in ("inf", "+inf"):
            parts = parts * 2
        if len(parts) != 2:
            self.fail(f"{value!r}: expected MM,DEG (e.g. 2,1) or inf", param, ctx)
        check = CheckedFloat(min=0, min_open=True, allow_inf=True)
        mm, deg = (check.convert(p.strip(), param, ctx) for p in parts)
        return mm, deg


pose_tolerance_option = click.option(
    "--pose-tolerance",
    type=PoseTolerance(),
    default=None,
    help="Refuse a step whose measured pose relative to O deviates more from its commanded "
    "pose relative to O (translation mm, rotation deg; inf: no check) [default: the session "
    "file's pose_check:, else 2 % of the leg stroke, at least 2 mm, and in rotation 0.05 "
    "deg + 1 % of the step's largest commanded angle, at most the angle that moves the "
    "platform's joints as much; a given DEG holds for every step; a mirror image is "
    "refused too].",
)
mc_option = click.option(
    "--mc",
    "mc",
    type=click.IntRange(min=0, max=MAX_DRAWS),
    default=0,
    show_default=True,
    metavar="N",
    help="Monte Carlo uncertainty with N draws (GUM Supplement 1; 2 to "
    f"{MAX_DRAWS:,}), checked against the linear propagation; 0: linear propagation only.",
)
seed_option = click.option(
    "--seed",
    type=click.IntRange(min=0, max=MAX_SEED),
    default=0,
    show_default=True,
    help="Seed of the Monte Carlo draws (an integer >= 0).",
)


def reading_options(func: F) -> F:
    """``--allow-truncated`` and ``--keep-later``, given to the command as one
    ``reading`` argument (:class:`~hexatherm.io.files.ReadOptions`)."""

    @functools.wraps(func)
    def wrapper(*args: Any, allow_truncated: bool, keep_later: bool, **kwargs: Any) -> Any:
        return func(*args, reading=ReadOptions(allow_truncated, keep_later), **kwargs)

    wrapper = click.option(
        "--keep-later",
        is_flag=True,
        help="A ball probed twice in one step, or a DMIS point label seen twice: keep the "
        "later one, with a warning naming both (default: refused).",
    )(wrapper)
    wrapper = click.option(
        "--allow-truncated",
        is_flag=True,
        help="Read a measurement or temperature file cut short (no line break at its end, a "
        "DMIS output without ENDFIL): its last record is dropped, with a warning (default: "
        "refused).",
    )(wrapper)
    return wrapper  # type: ignore[return-value]


def check_draws(mc: int) -> None:
    """A usage error for ``--mc 1`` (a standard deviation needs two draws), and for
    ``--seed`` given without ``--mc`` (the linear propagation draws nothing: the seed
    would be ignored without a word)."""
    if mc == 1:
        raise click.BadParameter("Monte Carlo needs at least 2 draws", param_hint="'--mc'")
    source = click.get_current_context().get_parameter_source("seed")
    if mc == 0 and source is click.core.ParameterSource.COMMANDLINE:
        raise click.BadParameter(
            "--seed is the Monte Carlo draws': use it with --mc N (without, the linear "
            "propagation draws nothing)",
            param_hint="'--seed'",
        )


max_gap_option = click.option(
    "--max-gap",
    type=CheckedFloat(min=0),
    default=600.0,
    show_default=True,
    help="Warn when a target and its reference are further apart (s).",
)


def clean_errors(func: F) -> F:
    """Turn hexatherm's own errors into a one-line message on stderr and exit status 1,
    and each :class:`~hexatherm.errors.InputWarning` (input read past because an option
    asked for it) into a ``warning:`` line on stderr as it happens.

    Anything else is a bug and keeps its traceback.
    """

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with warnings.catch_warnings():
            warnings.simplefilter("always", InputWarning)
            shown = warnings.showwarning

            def show(message: Any, category: Any, *rest: Any, **options: Any) -> None:
                if issubclass(category, InputWarning):
                    echo_err(f"warning: {message}")
                else:
                    shown(message, category, *rest, **options)

            warnings.showwarning = show
            ctx = click.get_current_context()
            given = ctx.meta.get("hexatherm.argv", [])  # the group's arguments as given
            argv = given[1:] if given[:1] == [ctx.info_name] else given
            try:
                with run_context(ctx.info_name or "", argv, ctx.params):
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
        :func:`hexatherm.workflows.process.measured.read_measured` reports it."""
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


lab_option = click.option(
    "--lab",
    "lab",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="A lab file (format: hexatherm-lab/1): lab, customer, operator, report number, "
    "CMM, hexapod, ambient conditions, signatories, tolerances, printed in the header of "
    "every page; a session file's identification: and tolerances: win key by key.",
)


class _LabAwareOption(click.Option):
    """An option shared by commands with and without ``--lab``, whose help names the lab
    file only where the command has one: the help's sentences that name ``--lab`` (or its
    parenthesis) are left out elsewhere."""

    def get_help_record(self, ctx: click.Context) -> tuple[str, str] | None:
        record = super().get_help_record(ctx)
        if record is None or any(p.name == "lab" for p in ctx.command.params):
            return record
        text = re.sub(r" ?(\([^()]*--lab[^()]*\)|[^.()]*--lab[^.()]*\.)", "", record[1])
        return record[0], text


template_dir_option = click.option(
    "--template-dir",
    "template_dir",
    cls=_LabAwareOption,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="A folder of the lab's report templates (Jinja2: letterhead.html.j2, closing.html.j2 "
    "or any other of hexatherm's), used before hexatherm's own: logo, address, wording. "
    "Over a --lab file's templates: entry.",
)


def _tolerances(ctx: click.Context, param: click.Parameter, values: tuple[str, ...]) -> dict:
    found: dict[str, object] = {}
    if values:  # the conformity's module, only for a run that judges tolerances
        from hexatherm.workflows.process.conformity import parse_tolerances
    for value in values:
        try:
            given = parse_tolerances(value)
        except ValueError as exc:
            raise click.BadParameter(str(exc), ctx=ctx, param=param) from None
        twice = next((key for key in given if key in found), None)
        if twice is not None:  # which one holds? neither: say so
            name = twice.split("_")[0]
            raise click.BadParameter(
                f"{value!r}: {name} is given twice (in two --tolerance options)",
                ctx=ctx,
                param=param,
            )
        found.update(given)
    return found


tolerance_option = click.option(
    "--tolerance",
    "tolerances",
    cls=_LabAwareOption,
    multiple=True,
    metavar="Tx=2um,Rx=10urad,...",
    callback=_tolerances,
    help="Tolerance zone |corrected - commanded| <= T of a pose component (Tx..Tz in um, "
    "mm or nm; Rx..Rz in urad, mrad or deg; repeatable): each target is judged conforms / "
    "does not conform / not decidable under ISO 14253-1 (U = k u as a guard band). Over "
    "the session's tolerances: mapping (and a --lab file's).",
)


def decision_rule_options(func: F) -> F:
    """``--decision-rule`` and ``--guard-factor``: the conformity statement's rule
    (ILAC-G8:09/2019), over a lab file's ``decision_rule:``."""

    def rule(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
        if value is None:  # the rules' module (12 kB of source): only to check a name
            return value
        from hexatherm.workflows.common import decision_rules  # numpy: not at start-up

        rules = decision_rules()
        if value not in rules:
            raise click.BadParameter(f"{value!r}: one of {', '.join(rules)}", ctx, param)
        return value

    func = click.option(
        "--guard-factor",
        "guard_factor",
        type=CheckedFloat(min=0),
        default=None,
        help="r of the guard band w = r U of the decision rule (>= 0) [default: the lab "
        "file's decision_rule: guard_factor, else 1].",
    )(func)
    return click.option(
        "--decision-rule",
        "decision_rule",
        callback=rule,
        metavar="RULE",
        default=None,
        help="How a deviation is judged against its tolerance, as agreed with the customer: "
        "iso14253 (ISO 14253-1: conforms inside the zone shrunk by w, does not conform "
        "outside it widened by w, else not decidable), simple (w = 0), guarded-acceptance, "
        "guarded-rejection (ILAC-G8) [default: the lab file's decision_rule:, else iso14253]; "
        "the report states the rule and its risk of false acceptance.",
    )(func)


def document_options(func: F) -> F:
    """``--report-number`` and ``--title``: the document's own number and title."""
    func = click.option(
        "--title",
        "title",
        default=None,
        help="The document's title (e.g. 'Calibration certificate') [default: the lab "
        "file's titles:, else hexatherm's].",
    )(func)
    return click.option(
        "--report-number",
        "report_number",
        default=None,
        help="This document's own number, printed on every page and in its provenance "
        "[default: the lab file's numbering: pattern, e.g. '{session}-{doc}-{date}'; else "
        "the session's report_number for report, and that number with -C for calibrate].",
    )(func)


#: the largest --coverage-factor: beyond any coverage (Student's t of one degree of
#: freedom at 99.73 % is 236), and U = k u overflowed to inf at 1e308
MAX_COVERAGE_FACTOR = 1000.0


def coverage_factor_option(what: str) -> Callable[[F], F]:
    """``--coverage-factor k`` (default 2, > 0, at most :data:`MAX_COVERAGE_FACTOR`) of
    the expanded uncertainties U = k u ``what`` (the command's own words: where its U
    appear)."""
    return click.option(
        "--coverage-factor",
        "coverage_factor",
        type=CheckedFloat(min=0, max=MAX_COVERAGE_FACTOR, min_open=True),
        default=2.0,
        show_default=True,
        help=f"Coverage factor k of the expanded uncertainties U = k u {what} "
        f"(> 0, <= {MAX_COVERAGE_FACTOR:g}).",
    )
