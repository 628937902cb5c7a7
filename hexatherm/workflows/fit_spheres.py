"""``hexatherm fit-spheres``: the centres of the balls probed in points files.

:func:`fit_spheres` reads every file (its probed points; a file without any is said
through ``on_skipped``), refuses a step's ball probed in two files, fits a sphere to
every (label, ball) group and returns the centres file's text, written to ``out``
when one is given (checked before any work: never onto an input).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexatherm.errors import InputError
from hexatherm.io.files import ReadOptions
from hexatherm.io.records import Records


@dataclass(frozen=True)
class FittedSpheres:
    """The centres file's text, and per file its spheres and their largest form error."""

    text: str
    files: tuple[tuple[str, int, float], ...]


def fit_spheres(
    points: Sequence[Path],
    out: Path | None,
    fixed_diameter: float | None,
    overwrite: bool,
    reading: ReadOptions,
    progress: Callable[[str, int, int], None] | None = None,
    on_skipped: Callable[[Path], None] | None = None,
) -> FittedSpheres:
    """``hexatherm fit-spheres`` (see the module); ``progress(file, done, total)`` while
    reading."""
    import functools

    from hexatherm.io.csvfile import centres_to_csv
    from hexatherm.io.measurements import read_measurements
    from hexatherm.io.outputs import check_output_settled, write_output_file
    from hexatherm.io.records import concat_records, refuse_groups_in_two_files
    from hexatherm.workflows.process.measured import fit_points

    if out is not None:
        check_output_settled(out, kind="file", inputs=points, overwrite=overwrite)
    probed: list[Records] = []
    for path in points:
        records = read_measurements(
            path,
            progress=None if progress is None else functools.partial(progress, str(path)),
            allow_truncated=reading.allow_truncated,
            keep_later=reading.keep_later,
        )
        found = [r for r in records if r.kind == "points"]
        if not found and on_skipped is not None:
            on_skipped(path)
        probed.extend(found)
    # a step's ball in two files would be two centres that process refuses: say so here
    refuse_groups_in_two_files(probed)
    fitted = [fit_points(r, fixed_diameter_mm=fixed_diameter) for r in probed]
    if not fitted:
        raise InputError("no probed points in the given files")
    if len({r.time_kind for r in fitted}) > 1:
        raise InputError("the files mix ISO 8601 times and seconds")
    text = centres_to_csv(concat_records(fitted))
    if out is not None:
        write_output_file(out, text, inputs=points, overwrite=overwrite)
    files = tuple(
        (
            os.fspath(rec.path),
            len(rec),
            float(np.max(np.asarray(rec.extra["form_um"], dtype=float))),
        )
        for rec in fitted
    )
    return FittedSpheres(text, files)
