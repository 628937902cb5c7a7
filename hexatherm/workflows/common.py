"""What every command's options need of the floors below the workflows, so that the
command line imports only the workflows (issue 34): how input files may be read, the
run's facts for ``provenance.json``, and a lab's report templates."""

from __future__ import annotations

from pathlib import Path

from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.provenance import run_context

__all__ = ["STRICT", "ReadOptions", "run_context", "template_files", "template_folder"]


def template_folder(template_dir: Path | None, lab: Path | None) -> Path | None:
    """The lab's templates (``--template-dir``, else the lab file's ``templates:``),
    every one of them compiled: a syntax error is refused naming file and line."""
    from hexatherm.io.config.identity import lab_template_dir
    from hexatherm.workflows.report.render import check_template_dir

    if template_dir is None and lab is not None:
        template_dir = lab_template_dir(lab)
    return check_template_dir(template_dir)


def template_files(folder: Path | None, lab: Path | None = None) -> list[Path]:
    """The files of the lab's template folder, and those of its sub-folders that its
    templates name (an included template, an ``asset()``), but the lab file and what
    hexatherm wrote there (a report, its manifest): inputs of the page (its provenance,
    and never an output)."""
    from hexatherm.io.outputs import hexatherms_own
    from hexatherm.workflows.report.render import named_files

    if folder is None:
        return []
    skip = None if lab is None else lab.resolve()
    found = {p for p in folder.iterdir() if p.is_file()} | set(named_files(folder))
    return sorted(p for p in found if p.resolve() != skip and not hexatherms_own(p))
