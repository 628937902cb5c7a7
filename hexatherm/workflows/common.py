"""What every command's options need of the floors below the workflows, so that the
command line imports only the workflows (issue 34): how input files may be read, the
run's facts for ``provenance.json``, a tolerance's type, the conformity's decision
rules, and a lab's report templates.

Light at import (the command line imports it at start-up): what needs numpy, scipy or
Jinja2 is imported when called."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from hexatherm.io.files import STRICT, ReadOptions
from hexatherm.io.provenance import run_context

if TYPE_CHECKING:
    # a tolerance's type, for annotations only: hexatherm.session imports numpy, which the
    # command line does not load at start-up
    from hexatherm.session import Tolerance as Tolerance

__all__ = [
    "STRICT",
    "ReadOptions",
    "decision_rules",
    "run_context",
    "template_files",
    "template_folder",
]


def decision_rules() -> tuple[str, ...]:
    """The decision rules a conformity statement may follow (ILAC-G8:09/2019), by name."""
    from hexatherm.core.conformity import RULES  # numpy and scipy: not at start-up

    return tuple(RULES)


def template_folder(template_dir: Path | None, lab: Path | None) -> Path | None:
    """The lab's templates (``--template-dir``, else the lab file's ``templates:``),
    every one of them compiled: a syntax error is refused naming file and line."""
    from hexatherm.io.config.identity import lab_template_dir
    from hexatherm.workflows.report.render import check_template_dir

    if template_dir is None and lab is not None:
        template_dir = lab_template_dir(lab)
    return check_template_dir(template_dir)


def template_files(folder: Path | None, lab: Path | None = None) -> list[Path]:
    """The files of the lab's template folder its pages are made of (its templates, what
    they include, their ``asset()``s: what is read, each of a bounded size), but the lab
    file and what hexatherm wrote there (a report, its manifest): inputs of the page (its
    provenance, and never an output). Other files of the folder are not read (a lab's
    archive, a 100 GiB file nothing uses)."""
    from hexatherm.io.outputs import hexatherms_own
    from hexatherm.workflows.report.render import named_files

    if folder is None:
        return []
    skip = None if lab is None else lab.resolve()
    return sorted(p for p in named_files(folder) if p.resolve() != skip and not hexatherms_own(p))
