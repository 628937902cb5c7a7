"""Diagnosed twin campaigns shared by the diagnosis tests (simulated and diagnosed once).

A campaign is its hidden effects (name and parameter values), its seed and the
options of :func:`~hexatherm.workflows.simulate.campaigns.diagnosis_campaign`: two
tests asking for the same one read the same session folder and the same
:class:`~hexatherm.workflows.diagnose.run.DiagnosisResult`, which none of them changes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import pytest

from hexatherm.core.effects import Effect
from hexatherm.workflows.diagnose.run import DiagnosisResult, read_for_diagnosis, run_diagnosis
from hexatherm.workflows.simulate.campaigns import diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import simulate_session
from tests.replicas import write_session

Diagnosed = Callable[..., DiagnosisResult]


@pytest.fixture(scope="session")
def diagnosed_campaign(tmp_path_factory: pytest.TempPathFactory) -> Diagnosed:
    """``diagnosed_campaign(hidden, seed, **options)``: the campaign written by the twin
    with ``hidden`` applied to the truth (the session's hexapod file does not name
    them), read back as ``hexatherm diagnose`` reads it and diagnosed (the truth is
    ``hidden``: its ``truth/`` is not written)."""
    done: dict[object, DiagnosisResult] = {}
    root = tmp_path_factory.mktemp("campaigns")

    def diagnosed(hidden: Sequence[Effect], seed: int, **options: object) -> DiagnosisResult:
        key = (
            tuple((e.name, tuple(sorted(e.values.items()))) for e in hidden),
            seed,
            tuple(sorted(options.items())),
        )
        if key not in done:
            folder = root / f"c{len(done)}"
            spec = diagnosis_campaign(hidden, seed, **options)  # type: ignore[arg-type]
            write_session(simulate_session(spec, truth_files=False).files, folder)
            done[key] = run_diagnosis(read_for_diagnosis(folder))
        return done[key]

    return diagnosed
