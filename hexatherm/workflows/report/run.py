"""``hexatherm report``: the page of a results folder that ``process`` wrote.

A report renders ``process``'s results, it never processes with options of its own: the
two deliverables of one job cannot disagree (issue 34). :func:`report`:

1. finds the results: a folder ``process`` wrote (its ``provenance.json``), or a session,
   whose ``SESSION/results`` it takes; a session without results is processed first,
   as ``hexatherm process SESSION`` does with its defaults (recorded as that command, and
   said on the screen), so that ``report SESSION`` works on a session just measured;
2. checks they are current: every input ``process`` recorded still has its SHA-256
   (refused naming the first that changed: "results are stale, run process");
3. takes ``process``'s options from ``provenance.json`` (interpolation, Monte Carlo
   draws and seed, limits, tolerances, coverage factor, ...), derives from the session
   what the page draws with them (the figures' steps, temperatures and growth), and
   refuses unless that derivation writes every result file of the folder to the byte
   (a file edited by hand, another version of hexatherm): so every number on the page is
   the results folder's;
4. renders the page, whose provenance lists the results files it rendered (path and
   SHA-256) and the command line that wrote them.
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
from hexatherm.workflows.process.run import (
    DrawProgress,
    ProcessOutcome,
    compute,
    request_from_options,
    result_texts,
)
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


@dataclass(frozen=True)
class Results:
    """A results folder as ``process`` recorded it."""

    folder: Path
    command_line: str
    finished: str
    options: dict[str, Any]
    inputs: list[Path]
    sha256: dict[Path, str]

    @property
    def session_file(self) -> Path:
        """The session file ``process`` read (its first input)."""
        return self.inputs[0]

    def files(self) -> list[Path]:
        """The folder's result files and its provenance (what the page rests on)."""
        return sorted(p for p in self.folder.iterdir() if p.suffix in (".csv", ".json"))


@dataclass
class ReportOutcome:
    """What ``report`` rendered and wrote."""

    results: Results
    outcome: ProcessOutcome
    out_file: Path
    verdicts: list[Verdict] = field(default_factory=list)
    #: the results files written when the session had none and was processed first
    #: (process's defaults); empty when the results were there
    processed_first: tuple[Path, ...] = ()


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


def derive(
    results: Results,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
) -> ProcessOutcome:
    """What the page draws, derived with ``process``'s recorded options, held to the
    results folder's files byte for byte."""
    request = request_from_options(results.options, results.session_file, results.inputs)
    outcome = compute(request, reading_progress, draws_progress)
    for name, text in result_texts(outcome).items():
        path = results.folder / name
        if not path.is_file():
            raise ResultsError(
                f"{path} is missing from the results folder: run process again (--overwrite)"
            )
        if path.read_bytes() != text.encode("utf-8"):
            raise ResultsError(
                f"{path} is not what process writes from these inputs and options (edited, "
                "or written by another version of hexatherm): run process again (--overwrite)"
            )
    return outcome


def report(
    request: ReportRequest,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
    on_verdict: Callable[[Verdict], None] | None = None,
) -> ReportOutcome:
    """``hexatherm report``: the page of ``request.source``'s results, written."""
    from hexatherm.io.config import read_session
    from hexatherm.io.config.identity import identification, read_lab
    from hexatherm.io.outputs import check_output_settled, write_output_file
    from hexatherm.workflows.report.html import report_html

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
        processed = process_first(request.source, reading_progress, draws_progress)
        results = read_results(processed.request.out_dir)
        inputs = [*results.inputs, *results.files(), *request.extra_inputs]
    try:
        check_current(results)
        outcome = derive(results, reading_progress, draws_progress)
        verdicts: list[Verdict] = []

        def said(summary: Verdict) -> None:
            verdicts.append(summary)
            if on_verdict is not None:
                on_verdict(summary)

        page = report_html(
            outcome.result,
            uncertainty=outcome.uncertainty,
            quality=outcome.quality,
            coverage_factor=outcome.request.coverage_factor,
            on_verdict=said,
            identification=identification(outcome.result.session.identification, lab_fields),
            tolerances={**lab_tolerances, **outcome.tolerances},
            extra_inputs=[*results.files(), *request.extra_inputs],
            template_dir=request.template_dir,
        )
        write_output_file(out_file, page, inputs=inputs, overwrite=request.overwrite)
    except BaseException:
        if processed is not None:  # nothing half-written: the results this run made go too
            shutil.rmtree(processed.request.out_dir, ignore_errors=True)
        raise
    return ReportOutcome(
        results, outcome, out_file, verdicts, () if processed is None else processed.written
    )


def process_first(
    session: Path,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
) -> ProcessOutcome:
    """A session without results: ``hexatherm process SESSION`` with process's defaults,
    recorded as that command (its ``provenance.json`` says ``process``), before the page.
    A session that is no session is refused by process, naming the file."""
    import dataclasses

    from hexatherm.io.provenance import json_ready, run_context
    from hexatherm.workflows.process.run import ProcessRequest, process

    request = ProcessRequest(session=session)
    options = {k: v for k, v in json_ready(dataclasses.asdict(request)).items() if k != "reading"}
    options.update(json_ready(dataclasses.asdict(request.reading)))
    with run_context("process", [str(session)], options):
        return process(request, reading_progress, draws_progress)
