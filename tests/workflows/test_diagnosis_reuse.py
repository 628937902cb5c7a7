"""The diagnosis reuses what does not change (issue 26): the twin of a CMM-side effect's
parameters, and placements asked for twice. Counted, never timed; the results are
checked against a fit that recomputes everything."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hexatherm.core.diagnosis.fitting as fitting
from hexatherm.core.diagnosis import fit_model, twin_centres
from hexatherm.core.effects import EFFECTS, make_effect
from hexatherm.workflows.diagnose.run import read_for_diagnosis
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session


@pytest.fixture(scope="module")
def drifting(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("reuse") / "drift"
    hidden = (make_effect("cmm_drift", NOMINAL_HIDDEN["cmm_drift"]),)
    write_twin_session(diagnosis_campaign(hidden, 3, n_targets=4), folder)
    return folder


@pytest.mark.parametrize("name", ["cmm_drift", "cmm_scale"])
def test_a_cmm_side_effect_leaves_the_twin_as_it_is(drifting: Path, name: str) -> None:
    data = read_for_diagnosis(drifting)
    cls = EFFECTS[name]
    effect = cls.from_vector((np.ones(len(cls.parameters)) * 7.0).tolist())
    alone = twin_centres(data.hexapod, data.observations, ())
    with_it = twin_centres(data.hexapod, data.observations, (effect,))
    assert np.array_equal(alone, with_it)  # the reuse rests on this, to the bit
    assert fitting._moves_twin(cls) is False
    assert fitting._moves_twin(EFFECTS["leg_thermal_lag"]) is True


def test_fitting_a_drift_runs_the_twin_once_and_finds_the_same_fit(
    drifting: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    data = read_for_diagnosis(drifting)
    calls = []
    real = fitting.twin_centres

    def counted(*args: object) -> np.ndarray:
        calls.append(1)
        return real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(fitting, "twin_centres", counted)
    fit = fit_model(data.hexapod, data.observations, (), [EFFECTS["cmm_drift"]])
    assert len(calls) == 1  # before: one per start value, Jacobian column and iteration
    truth = NOMINAL_HIDDEN["cmm_drift"]
    for p, value in truth.items():
        assert abs(fit.effects[0].values[p] - value) <= 4 * fit.std_errors[0][p]

    # the same fit with nothing memoized: every evaluation recomputed from scratch
    class Fresh(fitting._Problem):
        def centres(self, theta: np.ndarray) -> np.ndarray:
            return real(self.hexapod, self.obs, self.effects(theta))

        def evaluate(self, theta: np.ndarray, mask: np.ndarray):  # type: ignore[no-untyped-def]
            origin2cmm, predicted = fitting.place(
                self.centres(theta), self.obs, self.effects(theta), mask
            )
            return origin2cmm, predicted, self.obs.centres_mm - predicted

        def weighted(self, theta: np.ndarray, mask: np.ndarray) -> np.ndarray:
            return (self.evaluate(theta, mask)[2] * self.sqrt_w)[mask].ravel()

    problem = Fresh(data.hexapod, data.observations, (), [EFFECTS["cmm_drift"]])
    every = np.ones(data.observations.n_steps, dtype=bool)
    theta, seen = problem.solve(problem.start([None], every), every)
    fresh = problem.fit(theta, every, seen)
    assert fresh.effects[0].vector().tolist() == fit.effects[0].vector().tolist()
    assert np.array_equal(fresh.covariance, fit.covariance)
    assert np.array_equal(fresh.residual_mm, fit.residual_mm)
