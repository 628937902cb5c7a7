"""O's carry without a log: the noise its model error is read beyond (issue 35).

The term the line or parabola through the references misses at O's time is read from
the series' divided differences along the growth's shape, less what the references'
noise gives them. A reference's six legs come from one pose: their errors are
correlated (legs 1 and 6 at +0.94 at the twin's reference pose), and the noise along
the shape is ``s^T S s``, 1.27x ``sum s_l^2 S_ll`` there. Read from the legs'
variances alone (before), a fifth of the noise passed for curvature: on the series
below the model error's square came out 1.25x the truth's (2000 draws), now 1.03x.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hexatherm.workflows.process.carryerror as carryerror
from hexatherm.core.smoothbias import own_leg_covariance
from hexatherm.workflows.process.carryerror import _beyond_noise, _divided
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import centre_covariance, pose_chain
from hexatherm.workflows.simulate.twinsession import simulate_session
from tests.replicas import write_session
from tests.sessions import LEG_GAIN_C
from tests.workflows.test_repeats import CMM, spec


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A twin session without its log (O, R0 and 3 targets between references, heating
    from the start, 1 um point noise, ``cmm:`` stated)."""
    folder = tmp_path_factory.mktemp("carry") / "s"
    write_session(simulate_session(spec(folder, 0, repeats=1), truth_files=False).files, folder)
    text = (folder / "session.yaml").read_text() + CMM
    (folder / "session.yaml").write_text(
        "".join(line for line in text.splitlines(True) if "temperatures" not in line)
    )
    return folder


def references_legs_covariance(folder: Path) -> np.ndarray:
    """The references' leg lengths' covariance from their own centres (R, 6, 6)."""
    result = process_session(folder)
    refs = result.session.plan.reference_indices
    centres = result.centres.centres_mm
    return own_leg_covariance(pose_chain(result), centres, centre_covariance(result).cov_mm2, refs)


def test_the_model_error_is_read_beyond_the_legs_correlated_noise(session: Path) -> None:
    """Seven references 400 s apart, a growth of the twin's leg gains bending with tau
    1200 s, each reference's noise drawn from the twin's own leg covariance: the model
    error's square (the divided differences' RMS along the shape beyond their noise,
    squared) against the noise-free series' over 1000 draws. Measured 1.03 (the
    positive part: 14 % of the draws read nothing); with the variances alone 1.25."""
    cov = references_legs_covariance(session)[1]
    t = np.arange(7) * 400.0
    truth = np.outer(1 - np.exp(-t / 1200), np.array(LEG_GAIN_C) * 4e-3)
    shape = np.linalg.svd(truth)[2][0]
    true2 = float(np.mean((_divided(t, truth, 2) @ shape) ** 2))
    root = np.linalg.cholesky(cov)
    rng = np.random.default_rng(1)
    series_cov = np.broadcast_to(cov, (t.size, 6, 6))
    draws = [truth + rng.normal(size=truth.shape) @ root.T for _ in range(1000)]
    read = [float(np.sum(_beyond_noise(t, g, series_cov, 2) ** 2)) for g in draws]
    ratio = np.mean(read) / true2
    assert 0.93 < ratio < 1.12, ratio  # standard error about 0.035
    # the variances alone (the legs taken as independent): noise read as curvature
    variances = np.diagonal(series_cov, axis1=1, axis2=2)
    alone = np.mean([float(np.sum(_beyond_noise(t, g, variances, 2) ** 2)) for g in draws])
    assert alone / true2 > ratio + 0.12, (alone / true2, ratio)


def test_the_carry_reads_the_references_full_leg_covariance(
    session: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``process`` hands the model error each member's 6x6 leg covariance (before: the
    diagonal), R0's and the later references' as ``own_leg_covariance`` makes them."""
    handed = []

    def spy(times: np.ndarray, values: np.ndarray, var: np.ndarray, order: int) -> np.ndarray:
        handed.append(np.asarray(var))
        return np.asarray(_beyond_noise(times, values, var, order))

    monkeypatch.setattr(carryerror, "_beyond_noise", spy)
    from hexatherm.workflows.process.uncertainty import pose_uncertainty

    pose_uncertainty(process_session(session))
    assert handed, "the carry's model error was not read from the series"
    expected = references_legs_covariance(session)
    for var in handed:
        assert var.shape == expected.shape
        np.testing.assert_allclose(var, expected, rtol=1e-9, atol=0.0)
