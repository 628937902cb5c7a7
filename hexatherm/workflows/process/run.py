"""``hexatherm process`` from a request to its outcome: the command's steps, start to end.

:func:`compute` runs the pipeline (read, register, correct; the twin with ``--method
twin``; the uncertainty; the quality checks; the conformity with tolerances) and returns
everything it found, writing nothing; :func:`process` checks the output folder first,
computes, and writes the results. The command line (``hexatherm.cli.process``) turns its
options into a :class:`ProcessRequest` and prints the :class:`ProcessOutcome`; ``report``
renders the folder written (:mod:`hexatherm.workflows.report.run`), computing nothing again:
what its page needs beyond the CSV files (the warnings, where the centres' uncertainty
came from) goes into ``provenance.json``'s ``process`` entry (:func:`page_notes`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.limits import DISTANCE_REFUSAL_UM, QualityLimits
from hexatherm.workflows.process.measured import FileProgress
from hexatherm.workflows.process.pipeline import Checks, ProcessResult
from hexatherm.workflows.process.quality import QualityReport
from hexatherm.workflows.process.uncertainty import PoseUncertainty

if TYPE_CHECKING:
    from hexatherm.session import Tolerance

    # a plain run judges no tolerances: the conformity's module is read when it does
    from hexatherm.workflows.process.conformity import Conformity

#: ``progress(done, total)`` of the Monte Carlo draws
DrawProgress = Callable[[int, int], None]


@dataclass(frozen=True)
class ProcessRequest:
    """What ``hexatherm process`` was asked (its options, in the workflow's types)."""

    session: Path
    out: Path | None = None
    overwrite: bool = False
    interpolation: str = "linear"
    fixed_diameter: bool = False
    distance_tolerance_um: float = DISTANCE_REFUSAL_UM
    registration_tolerance_um: float = QualityLimits.registration_rms_um
    strict_registration: bool = False
    pose_tolerance: tuple[float, float] | None = None
    mc: int = 0
    seed: int = 0
    quality_thresholds: tuple[str, ...] = ()
    methods: tuple[str, ...] = ("references",)
    hexapod_path: Path | None = None
    between: bool | None = None
    tolerances: Mapping[str, Tolerance] = field(default_factory=dict)
    decision_rule: str | None = None
    guard_factor: float | None = None
    coverage_factor: float = 2.0
    reading: ReadOptions = STRICT

    @property
    def folder(self) -> Path:
        """The session's folder."""
        return self.session if self.session.is_dir() else self.session.parent

    @property
    def out_dir(self) -> Path:
        """The results folder (``-o``, default ``SESSION/results``)."""
        return self.out if self.out is not None else self.folder / "results"

    @property
    def extra_inputs(self) -> list[Path]:
        """Files read besides the session's: the twin's model of ``--hexapod``."""
        return [] if self.hexapod_path is None else [self.hexapod_path]


@dataclass(frozen=True)
class ProcessOutcome:
    """Everything ``process`` computed (and, from :func:`process`, wrote)."""

    request: ProcessRequest
    result: ProcessResult
    uncertainty: PoseUncertainty
    quality: QualityReport
    twin: np.ndarray | None = None
    twin_note: str = ""
    conformity: Conformity | None = None
    written: tuple[Path, ...] = ()

    @property
    def poses_csv(self) -> Path | None:
        """The ``poses.csv`` written (every target's deviations), None before writing."""
        return next((p for p in self.written if p.name == "poses.csv"), None)

    @property
    def tolerances(self) -> dict[str, Tolerance]:
        """The tolerances judged: the session file's, then the request's."""
        return {**self.result.session.tolerances, **self.request.tolerances}


def compute(
    request: ProcessRequest,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
    check_output: bool = False,
) -> ProcessOutcome:
    """Run ``process``'s steps on ``request``, writing nothing.

    With ``check_output``, the results folder is checked against the session's inputs
    before any work (never into, around or onto them; :func:`process` does).
    """
    from hexatherm.io.config import read_hexapod, read_session
    from hexatherm.io.outputs import check_output_settled
    from hexatherm.workflows.process.pipeline import process_session
    from hexatherm.workflows.process.quality import (
        parse_threshold,
        quality_checks,
        session_thresholds,
    )
    from hexatherm.workflows.process.uncertainty import pose_uncertainty

    overrides = dict(parse_threshold(t) for t in request.quality_thresholds)
    session_file = read_session(request.session)
    if check_output:
        check_output_settled(
            request.out_dir,
            kind="folder",
            inputs=[*session_file.input_files(), *request.extra_inputs],
            overwrite=request.overwrite,
        )
    if "twin" in request.methods and session_file.temperatures is None:
        raise InputError(
            "the twin corrects from the thermocouple log: add 'temperatures: "
            "temperatures.csv' to the session",
            path=str(session_file.path),
            field="temperatures",
        )
    checks = Checks(
        request.distance_tolerance_um,
        request.registration_tolerance_um,
        request.strict_registration,
        request.pose_tolerance,
    )
    result = process_session(
        request.session,
        request.interpolation,  # type: ignore[arg-type]
        0.0 if request.fixed_diameter else None,
        checks,
        reading_progress,
        request.reading,
        session=session_file,
    )
    twin, twin_note = None, ""
    if "twin" in request.methods:
        from hexatherm.workflows.process.twin import twin_poses

        path = request.hexapod_path
        # the file's model (the machine frame): twin_poses moves it into frame O
        model = session_file.hexapod if path is None else read_hexapod(path)
        twin = twin_poses(result, model, str(path or ""))
        gap = (twin - result.correction.corrected)[:, :3] * 1e3
        effects = ", ".join(e["name"] for e in model.effects) or "none"
        twin_note = (
            f"twin ({path or 'the session hexapod'}; effects: {effects}): "
            f"twin-corrected minus corrected by the references, RMS "
            f"{np.sqrt(np.mean(gap**2)):.3f} um over the targets' translations"
        )
    uncertainty = pose_uncertainty(
        result,
        mc=request.mc,
        seed=request.seed,
        progress=draws_progress,
        between=request.between,
    )
    quality = quality_checks(result, session_thresholds(result.session, overrides))
    tolerances = {**result.session.tolerances, **request.tolerances}
    judged = None
    if tolerances:
        from hexatherm.workflows.process.conformity import conformity, decision_rule

        rule = decision_rule({}, request.decision_rule, request.guard_factor)
        judged = conformity(result, uncertainty, tolerances, request.coverage_factor, rule)
    return ProcessOutcome(request, result, uncertainty, quality, twin, twin_note, judged)


def process(
    request: ProcessRequest,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
) -> ProcessOutcome:
    """``hexatherm process``: check the output, compute, write the results folder."""
    import dataclasses

    from hexatherm.io.files import digests_kept
    from hexatherm.workflows.process.outputs import write_results

    with digests_kept():  # provenance.json's digests of the bytes read, not a second read
        outcome = compute(request, reading_progress, draws_progress, check_output=True)
        written = write_results(
            outcome.result,
            request.out_dir,
            overwrite=request.overwrite,
            uncertainty=outcome.uncertainty,
            quality=outcome.quality,
            twin=outcome.twin,
            conformity=outcome.conformity,
            extra_inputs=request.extra_inputs,
            notes=page_notes(outcome),
        )
    return dataclasses.replace(outcome, written=tuple(written))


def page_notes(outcome: ProcessOutcome) -> dict[str, Any]:
    """What ``report``'s page says of a results folder beyond its CSV files, recorded in
    its ``provenance.json`` (``process``): the warnings of processing and where the ball
    centres' uncertainty came from (one line each, as the screen said them); the
    controller's frames the commanded poses went through, when not zero."""
    notes: dict[str, Any] = {
        "warnings": list(outcome.result.warnings),
        "centres_uncertainty": outcome.uncertainty.centres.description,
    }
    frames = outcome.result.frames
    if frames is not None:  # what the commanded poses (Tx_cmd_mm ...) went through
        notes["controller_frames"] = (
            "user, object frames "
            + " ".join(f"{v:.15g}" for v in frames)
            + " (mm, deg; run.yaml): the commanded poses relative to frame O are O0 X O0^-1"
        )
    return notes
