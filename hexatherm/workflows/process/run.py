"""``hexatherm process`` from a request to its outcome: the command's steps, start to end.

:func:`compute` runs the pipeline (read, register, correct; the twin with ``--method
twin``; the uncertainty; the quality checks; the conformity with tolerances) and returns
everything it found, writing nothing; :func:`process` checks the output folder first,
computes, and writes the results. The command line (``hexatherm.cli.process``) turns its
options into a :class:`ProcessRequest` and prints the :class:`ProcessOutcome`; ``report``
computes again from the request ``process`` recorded in ``provenance.json``
(:func:`request_from_options`).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.limits import DISTANCE_REFUSAL_UM, QualityLimits
from hexatherm.workflows.process.conformity import Conformity
from hexatherm.workflows.process.measured import FileProgress
from hexatherm.workflows.process.pipeline import Checks, ProcessResult
from hexatherm.workflows.process.quality import QualityReport
from hexatherm.workflows.process.uncertainty import PoseUncertainty

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
    tolerances: Mapping[str, float] = field(default_factory=dict)
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
    def tolerances(self) -> dict[str, float]:
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
    from hexatherm.workflows.process.conformity import conformity
    from hexatherm.workflows.process.pipeline import process_session
    from hexatherm.workflows.process.quality import (
        parse_threshold,
        quality_checks,
        session_thresholds,
    )
    from hexatherm.workflows.process.twin import twin_poses
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
        path = request.hexapod_path
        model = result.session.hexapod if path is None else read_hexapod(path)
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
    judged = (
        conformity(result, uncertainty, tolerances, request.coverage_factor) if tolerances else None
    )
    return ProcessOutcome(request, result, uncertainty, quality, twin, twin_note, judged)


def result_texts(outcome: ProcessOutcome) -> dict[str, str]:
    """The result files' texts (name -> CSV text) of ``outcome``, as :func:`process`
    writes them."""
    from hexatherm.workflows.process.outputs import result_tables

    return result_tables(
        outcome.result,
        outcome.uncertainty,
        outcome.quality,
        outcome.twin,
        outcome.conformity,
    )


def process(
    request: ProcessRequest,
    reading_progress: FileProgress | None = None,
    draws_progress: DrawProgress | None = None,
) -> ProcessOutcome:
    """``hexatherm process``: check the output, compute, write the results folder."""
    import dataclasses

    from hexatherm.workflows.process.outputs import write_results

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
    )
    return dataclasses.replace(outcome, written=tuple(written))


def _recorded_path(text: str, inputs: Sequence[Path], base: Path) -> Path:
    """A path ``process`` recorded as given (relative to where it ran): the input file it
    names (inputs are recorded absolute), else the path relative to ``base``."""
    given = os.path.normpath(text)
    for path in inputs:
        if str(path) == given or str(path).endswith(os.sep + given):
            return path
    return base / given


def request_from_options(
    options: Mapping[str, Any], session_file: Path, inputs: Sequence[Path]
) -> ProcessRequest:
    """The :class:`ProcessRequest` of a ``provenance.json``'s ``options`` (what the command
    line recorded), with the session file found among the recorded inputs."""

    def get(name: str, default: Any) -> Any:
        value = options.get(name, default)
        return default if value is None and default is not None else value

    def number(value: Any) -> float:
        return float(value)  # "inf" as JSON writes it

    pose = options.get("pose_tolerance")
    hexapod = options.get("hexapod_path")
    return ProcessRequest(
        session=session_file,
        interpolation=str(get("interpolation", "linear")),
        fixed_diameter=bool(get("fixed_diameter", False)),
        distance_tolerance_um=number(get("distance_tolerance_um", DISTANCE_REFUSAL_UM)),
        registration_tolerance_um=number(
            get("registration_tolerance_um", QualityLimits.registration_rms_um)
        ),
        strict_registration=bool(get("strict_registration", False)),
        pose_tolerance=None if pose is None else (number(pose[0]), number(pose[1])),
        mc=int(get("mc", 0)),
        seed=int(get("seed", 0)),
        quality_thresholds=tuple(get("quality_thresholds", ())),
        methods=tuple(get("methods", ("references",))),
        hexapod_path=None
        if hexapod is None
        else _recorded_path(str(hexapod), inputs, session_file.parent),
        between=options.get("between"),
        tolerances={k: number(v) for k, v in dict(get("tolerances", {})).items()},
        coverage_factor=number(get("coverage_factor", 2.0)),
        reading=ReadOptions(bool(get("allow_truncated", False)), bool(get("keep_later", False))),
    )
