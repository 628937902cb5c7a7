"""``simulate_session(..., truth_files=False)``: the same session without ``truth/``.

The noise-replica tests never read the twin's ``truth/`` files, whose formatting was a
third to a half of a replica's simulation; without them every other file is the same,
byte for byte, and so is the truth returned (the random draws do not depend on it).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hexatherm.io.scenario import read_scenario
from hexatherm.workflows.simulate.run import simulate
from tests.sessions import ROOT


@pytest.mark.parametrize(
    "scenario",
    ["with-hidden-effect", "calibration-geometry", "paper-zero-pose-dmis", "serial-capture"],
)
def test_without_truth_files_the_rest_is_the_same(scenario: str) -> None:
    read = read_scenario(ROOT / "configs" / "scenarios" / f"{scenario}.yaml")
    whole, bare = simulate(read), simulate(read, truth_files=False)
    truth = [rel for rel in whole.files if rel.startswith("truth/")]
    assert "truth/steps.csv" in truth and "truth/scenario.yaml" in truth
    assert bare.files == {rel: t for rel, t in whole.files.items() if rel not in truth}
    for field in dataclasses.fields(whole.truth):
        np.testing.assert_array_equal(
            getattr(bare.truth, field.name), getattr(whole.truth, field.name)
        )
    np.testing.assert_array_equal(bare.step_times_s, whole.step_times_s)
