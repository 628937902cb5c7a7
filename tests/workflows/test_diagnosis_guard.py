"""diagnose never writes a model that corrects worse than the session's own (issue 35,
item 7).

A CMM whose readings drift periodically (3 um over a 1 h period: the air conditioning's
cycle; outside the registry) gets a linear ``cmm_drift`` added: it lowers the held-out
RMS of the centres, yet on some campaigns the written model makes the twin correction
(``process --method twin``) worse against the truth. The truth is the twin's true
corrected poses (``truth/steps.csv``); the check diagnose makes is truth-free (held-out
targets, :mod:`hexatherm.core.diagnosis.guard`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hexatherm.core.effects import Effect, ThermocoupleLog, make_effect
from hexatherm.io.config import read_hexapod_text
from hexatherm.typing import FloatArray
from hexatherm.workflows.diagnose.outputs import diagnosed_hexapod_yaml, diagnosis_json, story
from hexatherm.workflows.diagnose.report import report_markdown
from hexatherm.workflows.diagnose.run import DiagnosisResult, read_for_diagnosis, run_diagnosis
from hexatherm.workflows.process.twin import model_effects
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session
from tests.workflows.test_twin_correction import errors_um


class PeriodicDrift(Effect):
    """Every measured coordinate moves by ``a sin(2 pi (t - t0) / T)`` along (1, -0.7, 0.5)."""

    parameters = ("amp_um", "period_s")
    units = ("um", "s")
    ranges = ((0.0, 100.0), (60.0, 1e6))

    def cmm_coordinates_mm(
        self, xyz_mm: FloatArray, times_s: FloatArray, log: ThermocoupleLog
    ) -> FloatArray:
        dt = np.asarray(times_s, dtype=float) - log.t0_s
        phase = np.sin(2 * np.pi * dt / self.values["period_s"])
        drift = self.values["amp_um"] * 1e-3 * phase
        return np.asarray(xyz_mm, dtype=float) + drift[..., None] * np.array([1.0, -0.7, 0.5])


PeriodicDrift.name = "test_periodic_drift"  # after the class statement: not registered

PERIODIC = PeriodicDrift(amp_um=3.0, period_s=3600.0)
LAG = make_effect("leg_thermal_lag", NOMINAL_HIDDEN["leg_thermal_lag"])


def rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2)))


def diagnosed(root: Path, hidden: Effect, seed: int) -> tuple[DiagnosisResult, dict[str, float]]:
    """A campaign of 8 targets diagnosed, and the twin correction's RMS error against the
    truth (um) with the session's own model, the diagnosed one and the one written."""
    folder = root / f"{hidden.name}-{seed}"
    write_twin_session(diagnosis_campaign((hidden,), seed, n_targets=8), folder)
    data = read_for_diagnosis(folder)
    result = run_diagnosis(data)
    written = read_hexapod_text(diagnosed_hexapod_yaml(result), "hexapod.yaml")
    models = {
        "own": data.current,
        "diagnosed": (*data.current, *result.diagnosis.final.effects),
        "written": model_effects(written, "hexapod.yaml"),
    }
    return result, {name: rms(errors_um(folder, model)[0]) for name, model in models.items()}


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple]:
    root = tmp_path_factory.mktemp("guard")
    return {
        "periodic-1": diagnosed(root, PERIODIC, 1),
        "periodic-3": diagnosed(root, PERIODIC, 3),
        "lag-1": diagnosed(root, LAG, 1),
    }


@pytest.mark.parametrize("which", ["periodic-1", "periodic-3", "lag-1"])
def test_the_written_model_never_corrects_worse_than_the_sessions_own(
    campaigns: dict[str, tuple], which: str
) -> None:
    _, error = campaigns[which]
    assert error["written"] <= error["own"] * 1.0001, error


def test_a_linear_drift_for_a_periodic_one_that_corrects_worse_is_not_written(
    campaigns: dict[str, tuple],
) -> None:
    result, error = campaigns["periodic-3"]
    d = result.diagnosis
    assert [a.effect.name for a in d.added] == ["cmm_drift"]
    assert error["diagnosed"] > 1.05 * error["own"], error  # the truth: 9 % worse
    assert not d.writes_diagnosed
    assert d.twin_check is not None and d.twin_check.worse
    written = read_hexapod_text(diagnosed_hexapod_yaml(result), "hexapod.yaml")
    assert written.effects == result.data.hexapod.effects  # the session's own model
    doc = json.loads(diagnosis_json(result))
    assert doc["written_model"] == "session"
    sentence = "the model with cmm_drift is not written: on held-out targets"
    assert any(sentence in c for c in doc["cautions"])
    text = story(result)
    for where in (text, text.splitlines()[0], report_markdown(result, {})):
        assert sentence in where
        assert "hexapod.yaml holds the session's own model" in where


@pytest.mark.parametrize("which", ["periodic-1", "lag-1"])
def test_a_model_that_corrects_better_is_written(campaigns: dict[str, tuple], which: str) -> None:
    result, error = campaigns[which]
    assert result.diagnosis.writes_diagnosed
    assert error["written"] == pytest.approx(error["diagnosed"])
    assert json.loads(diagnosis_json(result))["written_model"] == "diagnosed"
