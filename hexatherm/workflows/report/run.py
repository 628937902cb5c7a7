"""``hexatherm report``: the page of a results folder that ``process`` wrote.

A report renders ``process``'s results, it never processes with options of its own: the
two deliverables of one job cannot disagree (issue 34). :func:`report`:

1. finds the results: a folder ``process`` wrote (its ``provenance.json``), or a session,
   whose ``SESSION/results`` it takes; a session without results is processed first,
   as ``hexatherm process SESSION`` does with its defaults (recorded as that command, and
   said on the screen), so that ``report SESSION`` works on a session just measured;
2. checks they are current: every input ``process`` recorded still has its SHA-256
   (refused naming the first that changed: "results are stale, run process");
3. reads them back (:mod:`hexatherm.workflows.process.written`): the poses, their u and
   its parts, the legs, the registration residuals and the quality checks of the CSV
   files, ``process``'s options (interpolation, Monte Carlo draws and seed, limits,
   tolerances and decision rule, coverage factor k) and notes (its warnings, where the
   centres' uncertainty came from) of ``provenance.json``, and the session's own files
   (its plan, its thermocouple log): nothing is computed again;
4. renders the page, whose provenance lists the results files it rendered (path and
   SHA-256) and the command line that wrote them.

The conformity statement is ``process``'s (its tolerances and rule, judged on the
numbers it wrote); a lab file's ``tolerances:`` for components ``process`` did not judge
are judged on those same numbers, and the outcome says which (never a silent re-process).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hexatherm.errors import ResultsError
from hexatherm.workflows.process.measured import FileProgress
from hexatherm.workflows.process.run import DrawProgress, ProcessOutcome
from hexatherm.workflows.process.written import WrittenResult
from hexatherm.workflows.report.verdict import Verdict

#: what ``process`` writes beside its result files
PROVENANCE = "provenance.json"


@dataclass(frozen=True)
class ReportRequest:
    """What ``hexatherm report`` was asked."""

    source: Path
    out: Path | None = None
    overwrite: bool = False
    lab: Path | None = None
    template_dir: Path | None = None
    extra_inputs: Sequence[Path] = ()
    report_number: str | None = None
    title: str | None = None


@dataclass(frozen=True)
class Results:
    """A results folder as ``process`` recorded it."""

    folder: Path
    command_line: str
    finished: str
    options: dict[str, Any]
    inputs: list[Path]
    sha256: dict[Path, str]
    notes: dict[str, Any] = field(default_factory=dict)

    @property
    def session_file(self) -> Path:
        """The session file ``process`` read (its first input)."""
        return self.inputs[0]

    def files(self) -> list[Path]:
        """The folder's result files and its provenance (what the page rests on)."""
        return sorted(
            p
            for p in self.folder.iterdir()
            if p.suffix in (".csv", ".json") and not p.name.startswith(".")
        )


@dataclass
class ReportOutcome:
    """What ``report`` rendered and wrote."""

    results: Results
    result: WrittenResult
    out_file: Path
    verdicts: list[Verdict] = field(default_factory=list)
    #: the results files written when the session had none and was processed first
    #: (process's defaults); empty when the results were there
    processed_first: tuple[Path, ...] = ()
    #: the tolerances judged by report, a lab file's, for components process did not judge
    lab_judged: tuple[str, ...] = ()
    #: the lab file's decision rule when process judged with another (not used)
    rule_ignored: str = ""


def results_folder(source: Path) -> Path:
    """The results folder of ``source``: itself when ``process`` wrote it, else a
    session's ``results/`` (refused when there is none)."""
    if source.is_dir() and (source / PROVENANCE).is_file():
        return source
    folder = source if source.is_dir() else source.parent
    results = folder / "results"
    if (results / PROVENANCE).is_file():
        return results
    raise ResultsError(
        f"{source}: no results of process to report (no {results / PROVENANCE}): run "
        f"'hexatherm process {source}' first, then report its results folder"
    )


def _located(path: str, folder: Path) -> Path:
    """An input's path as recorded (absolute, or relative to the session), found again:
    as recorded, else beside the results folder's session (a folder moved whole)."""
    recorded = Path(path)
    if recorded.is_absolute() and recorded.exists():
        return recorded
    session = folder.parent
    for candidate in (session / recorded, session / recorded.name):
        if candidate.exists():
            return candidate
    return recorded


def read_results(folder: Path) -> Results:
    """The results folder's ``provenance.json``: written by ``process``, with its inputs."""
    path = folder / PROVENANCE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ResultsError(f"{path}: not a provenance file process wrote ({exc})") from None
    if not isinstance(doc, dict) or doc.get("command") != "process":
        raise ResultsError(
            f"{path}: written by {doc.get('command') if isinstance(doc, dict) else '?'!r}, "
            "not by process: report renders the results folder of process"
        )
    entries = [e for e in doc.get("inputs", []) if isinstance(e, dict) and "sha256" in e]
    if not entries:
        raise ResultsError(f"{path}: no input files recorded")
    inputs = [_located(str(e["path"]), folder) for e in entries]
    return Results(
        folder,
        str(doc.get("command_line", "")),
        str(doc.get("finished", "")),
        dict(doc.get("options", {})),
        inputs,
        {p: str(e["sha256"]) for p, e in zip(inputs, entries, strict=True)},
        dict(doc.get("process") or {}),
    )


def check_current(results: Results) -> None:
    """Refuse results whose inputs changed (or went) since ``process`` wrote them."""
    from hexatherm.io.provenance import input_entries

    for path, digest in results.sha256.items():
        if not path.is_file():
            raise ResultsError(
                f"results {results.folder} are stale: their input {path} is gone; run process again"
            )
        (entry,) = input_entries([path])
        if entry.get("sha256") != digest:
            raise ResultsError(
                f"results {results.folder} are stale: {path} changed since process wrote "
                f"them ({results.finished}); run process again (--overwrite)"
            )


def check_written(results: Results) -> None:
    """Refuse a results folder whose files are not what ``process`` wrote there (its
    manifest's SHA-256): a result edited by hand is not ``process``'s result."""
    from hexatherm.io.manifest import foreign_entries

    for name, reason in foreign_entries(results.folder):
        if name.endswith(".csv") or name == PROVENANCE:
            raise ResultsError(
                f"{results.folder / name} is not what process wrote ({reason}): run process "
                "again (--overwrite replaces only what it wrote: move the edited file away)"
            )


def report(
    request: ReportRequest,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
    on_verdict: Callable[[Verdict], None] | None = None,
) -> ReportOutcome:
    """``hexatherm report``: the page of ``request.source``'s results, written."""
    from hexatherm.io.config import read_session
    from hexatherm.io.config.identity import read_lab
    from hexatherm.io.outputs import check_output_settled, write_output_file

    processed: ProcessOutcome | None = None
    results: Results | None = None
    try:
        results = read_results(results_folder(request.source))
        known = [*results.inputs, *results.files()]
        home = results.folder.parent
    except ResultsError:
        if request.source.is_dir() and (request.source / PROVENANCE).exists():
            raise
        # no results: process first (below), once the report's own output is checked
        session = read_session(request.source)
        known, home = session.input_files(), session.path.parent
    out_file = request.out if request.out is not None else home / "report.html"
    lab_fields, lab_tolerances = read_lab(request.lab) if request.lab is not None else ({}, {})
    inputs = [*known, *request.extra_inputs]
    check_output_settled(out_file, kind="file", inputs=inputs, overwrite=request.overwrite)
    if results is None:
        processed = process_first(request.source, reading_progress, draws_progress, lab_fields)
        results = read_results(processed.request.out_dir)
        inputs = [*results.inputs, *results.files(), *request.extra_inputs]
    try:
        check_current(results)
        check_written(results)
        outcome = render(results, request, lab_fields, lab_tolerances, on_verdict)
        write_output_file(out_file, outcome.page, inputs=inputs, overwrite=request.overwrite)
    except BaseException:
        if processed is not None:  # nothing half-written: the results this run made go too
            shutil.rmtree(processed.request.out_dir, ignore_errors=True)
        raise
    return ReportOutcome(
        results,
        outcome.result,
        out_file,
        outcome.verdicts,
        () if processed is None else processed.written,
        outcome.lab_judged,
        outcome.rule_ignored,
    )


@dataclass
class Rendered:
    """A results folder's page and what it said."""

    page: str
    result: WrittenResult
    verdicts: list[Verdict]
    lab_judged: tuple[str, ...]
    rule_ignored: str


def render(
    results: Results,
    request: ReportRequest,
    lab_fields: dict[str, object],
    lab_tolerances: dict[str, Any],
    on_verdict: Callable[[Verdict], None] | None = None,
) -> Rendered:
    """The page of ``results`` (read back, nothing computed again), with the lab's
    identification and templates; the conformity statement is process's, and a lab
    file's tolerances for components it did not judge are judged on the same numbers."""
    from hexatherm.io.config import read_session
    from hexatherm.io.config.identity import identification
    from hexatherm.io.files import ReadOptions
    from hexatherm.workflows.process.conformity import decision_rule, parse_recorded
    from hexatherm.workflows.process.written import read_written
    from hexatherm.workflows.report.html import report_html

    options = results.options
    reading = ReadOptions(bool(options.get("allow_truncated")), bool(options.get("keep_later")))
    session = read_session(results.session_file)
    result, uncertainty, quality = read_written(
        results.folder, session, options, results.notes, reading
    )
    judged = {**session.tolerances, **parse_recorded(options.get("tolerances") or {})}
    recorded_rule = options.get("decision_rule")
    recorded_guard = options.get("guard_factor")
    if judged:  # process judged: its rule
        rule = decision_rule({}, recorded_rule, recorded_guard)
        lab_rule = decision_rule(lab_fields)
        ignored = "" if not lab_fields.get("decision_rule") or lab_rule == rule else lab_rule.rule
    else:  # the lab's tolerances alone: the lab's rule
        rule, ignored = decision_rule(lab_fields), ""
    lab_judged = tuple(k for k in lab_tolerances if k not in judged)
    verdicts: list[Verdict] = []

    def said(summary: Verdict) -> None:
        verdicts.append(summary)
        if on_verdict is not None:
            on_verdict(summary)

    page = report_html(
        result,
        uncertainty=uncertainty,
        quality=quality,
        coverage_factor=float(options.get("coverage_factor") or 2.0),
        on_verdict=said,
        identification=identification(session.identification, lab_fields),
        tolerances={**lab_tolerances, **judged},
        extra_inputs=[*results.files(), *request.extra_inputs],
        template_dir=request.template_dir,
        rule=rule,
        report_number=request.report_number,
        title=request.title,
    )
    return Rendered(page, result, verdicts, lab_judged, ignored)


def process_first(
    session: Path,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
    lab_fields: dict[str, object] | None = None,
) -> ProcessOutcome:
    """A session without results: ``hexatherm process SESSION`` with process's defaults
    and the lab file's decision rule (its ``--decision-rule``/``--guard-factor``, so that
    process judges the session's tolerances as the lab agreed), recorded as that command
    (its ``provenance.json`` says ``process``), before the page. A session that is no
    session is refused by process, naming the file."""
    import dataclasses

    from hexatherm.io.provenance import json_ready, run_context
    from hexatherm.workflows.process.run import ProcessRequest, process

    fields = lab_fields or {}
    rule, r = fields.get("decision_rule"), fields.get("guard_factor")
    request = ProcessRequest(
        session=session,
        decision_rule=rule if isinstance(rule, str) else None,
        guard_factor=float(r) if isinstance(r, int | float) else None,
    )
    options = {k: v for k, v in json_ready(dataclasses.asdict(request)).items() if k != "reading"}
    options.update(json_ready(dataclasses.asdict(request.reading)))
    with run_context("process", [str(session)], options):
        return process(request, reading_progress, draws_progress)
