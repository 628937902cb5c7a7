"""``hexatherm diagnose`` from its options to its outcome: the command's steps, start to end.

:func:`diagnose` checks the output folder before any work (never into, around or onto
the session's files), reads the session (said through ``on_read``: its name, steps and
warnings, before the search), runs the search for missing effects, and writes
``diagnosis.json``, the diagnosed ``hexapod.yaml`` and the report's pages; the command
line prints the :class:`Diagnosed` outcome.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from hexatherm.io.files import ReadOptions
from hexatherm.workflows.diagnose.run import DiagnosisResult, SessionData


@dataclass(frozen=True)
class Diagnosed:
    """What ``diagnose`` found and the files it wrote."""

    result: DiagnosisResult
    written: tuple[Path, ...]


def diagnose(
    session: Path,
    out: Path | None,
    overwrite: bool,
    hexapod_path: Path | None,
    templates: Path | None,
    template_inputs: list[Path],
    reading: ReadOptions,
    on_read: Callable[[SessionData], None] | None = None,
    progress: Callable[[int, int, int], None] | None = None,
) -> Diagnosed:
    """``hexatherm diagnose SESSION`` (see the module); ``progress(round, done, total)``
    over the candidates of every round."""
    from hexatherm.io.config import read_session
    from hexatherm.io.files import digests_kept
    from hexatherm.io.outputs import check_output_settled, output_dir
    from hexatherm.workflows.diagnose.outputs import diagnosed_hexapod_yaml, diagnosis_json
    from hexatherm.workflows.diagnose.report import write_report_files
    from hexatherm.workflows.diagnose.run import read_for_diagnosis, run_diagnosis

    folder = session if session.is_dir() else session.parent
    out_dir = out if out is not None else folder / "diagnosis"
    spec = read_session(session)  # read once: read_for_diagnosis is given it
    inputs = spec.input_files()
    extra_inputs = ([hexapod_path] if hexapod_path is not None else []) + template_inputs
    inputs += extra_inputs
    # before any work: never into, around or onto the session's files (checked again
    # under the output's lock when the results are written)
    check_output_settled(out_dir, kind="folder", inputs=inputs, overwrite=overwrite)
    written: list[Path] = []
    # provenance.json's and the report's digests of the bytes read, not a second and a
    # third read of the measurements (a scanning session's 150 MB)
    with digests_kept():
        data = read_for_diagnosis(session, hexapod_path, reading, spec)
        if on_read is not None:
            on_read(data)
        result = run_diagnosis(data, progress)
        files = {
            "diagnosis.json": diagnosis_json(result),
            "hexapod.yaml": diagnosed_hexapod_yaml(result),
        }
        with output_dir(out_dir, inputs=inputs, overwrite=overwrite) as tmp:
            for name, text in files.items():
                (tmp / name).write_text(text, encoding="utf-8")
                written.append(out_dir / name)
            pages = write_report_files(
                result, tmp, template_dir=templates, extra_inputs=extra_inputs
            )
            written += [out_dir / p.relative_to(tmp) for p in pages]
    return Diagnosed(result, tuple(written))
