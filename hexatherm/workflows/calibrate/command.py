"""``hexatherm calibrate`` from its options to its outcome: the command's steps, start to end.

:func:`run_calibrate` reads the lab file, checks the output folder before any work
(never into, around or onto an input: the sessions' files, the lab's, the twin's
model), reads and calibrates the campaign (iterated with ``iterate``), and writes the
calibration's files; the command line prints the :class:`Calibrated` outcome.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from hexatherm.io.files import ReadOptions
from hexatherm.workflows.calibrate.run import Calibration


@dataclass(frozen=True)
class Calibrated:
    """The calibration, the files written (name -> text) into ``out``, and how far the
    parameters moved in every further round of ``--iterate`` (mm)."""

    run: Calibration
    out: Path
    files: dict[str, str]
    moves: tuple[float, ...] = ()


def run_calibrate(
    sessions: Sequence[Path],
    out: Path | None,
    poses: str,
    twin_model: Path | None,
    level: str,
    residuals: str,
    iterate: bool,
    interpolation: str,
    overwrite: bool,
    lab: Path | None,
    templates: Path | None,
    template_inputs: Sequence[Path],
    coverage_factor: float,
    report_number: str | None,
    title: str | None,
    reading: ReadOptions,
) -> Calibrated:
    """``hexatherm calibrate SESSIONS`` (see the module)."""
    from hexatherm.io.config import read_session
    from hexatherm.io.config.identity import read_lab
    from hexatherm.io.files import digests_kept
    from hexatherm.io.outputs import check_output_settled, output_dir
    from hexatherm.workflows.calibrate.outputs import output_files
    from hexatherm.workflows.calibrate.run import (
        TwinModel,
        calibrate,
        calibrate_iterated,
        read_campaign,
    )

    lab_fields, lab_tolerances = read_lab(lab) if lab is not None else ({}, {})
    if out is None:
        first = sessions[0] if sessions[0].is_dir() else sessions[0].parent
        out = first / "calibration"
    specs = [read_session(s) for s in sessions]  # read once: the campaign reads them too
    inputs = [f for spec in specs for f in spec.input_files()]
    if lab is not None:
        inputs.append(lab)
    inputs += template_inputs
    if twin_model is not None:
        inputs.append(twin_model)
    twin = None if twin_model is None else TwinModel.read(twin_model)
    check_output_settled(out, kind="folder", inputs=inputs, overwrite=overwrite)
    # provenance.json's and the report's digests of the bytes read, not a second and a
    # third read of the measurements (a scanning session's 150 MB)
    with digests_kept():
        moves: list[float] = []
        if iterate:
            run, moves = calibrate_iterated(
                sessions,
                poses,  # type: ignore[arg-type]
                reading,
                interpolation,  # type: ignore[arg-type]
                level,
                residuals,
                twin,
                specs,
            )
        else:
            campaign = read_campaign(
                sessions,
                poses,  # type: ignore[arg-type]
                reading,
                interpolation,  # type: ignore[arg-type]
                twin=twin,
                specs=specs,
            )
            run = calibrate(campaign, level, residuals)
        files = output_files(
            run,
            inputs,
            out,
            lab_fields,
            coverage_factor,
            templates,
            report_number,
            title,
            lab_tolerances,
        )
        with output_dir(out, inputs=inputs, overwrite=overwrite) as tmp:
            for name, text in files.items():
                (tmp / name).write_text(text, encoding="utf-8")
    return Calibrated(run, out, files, tuple(moves))
