"""O and R0 measured 4 times while the legs heat (issue 35, item 3), against the twin's truth.

``plan --origin-repeats 4 --reference0-repeats 4`` then heating from the start: each
measurement of O and R0 is carried to the thermal state of R0's last one by the leg model
and the thermocouple log before they are averaged, and the first target interpolates from
R0 at that last measurement's time. Before, the average of repeats taken in different
thermal states biased the corrected Tx by -0.46 um (t = -10 over 30 seeds), Tz by -0.31
um, no u covered it (claimed/observed Tx 0.76), and ``process --strict`` exited 3 on the
first target's time gap.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.correction import correct
from hexatherm.core.registration import register
from hexatherm.io.config import read_session
from hexatherm.workflows.process.carryerror import _response_term
from hexatherm.workflows.process.carrying import carry_and_average, line_at_end
from hexatherm.workflows.process.measured import read_measured, registration_weights
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from hexatherm.workflows.process.uncertainty import centre_covariance, pose_uncertainty
from hexatherm.workflows.simulate.twinsession import simulate_session, write_files
from tests.replicas import write_session
from tests.workflows.test_repeats import CMM, spec

SEEDS = 20
SCALE = np.array([1e3] * 3 + [np.pi / 180 * 1e6] * 3)  # um, urad


def write(
    folder: Path, seed: int, log: bool = True, repeats: int = 4, n_targets: int = 6
) -> tuple[Path, np.ndarray]:
    """The session folder (O and R0 x4 unless ``repeats``, 6 targets unless
    ``n_targets``; without its thermocouple log unless ``log``) and the twin's corrected
    truth of its targets."""
    s = spec(folder, seed, repeats=repeats, n_targets=n_targets)
    simulated = simulate_session(s, truth_files=False)
    write_session(simulated.files, folder)
    text = (folder / "session.yaml").read_text() + CMM
    if not log:
        text = "".join(line for line in text.splitlines(True) if "temperatures" not in line)
    (folder / "session.yaml").write_text(text)
    targets = [i for i, label in enumerate(s.plan.labels) if label.startswith("S")]
    return folder, simulated.truth.corrected_pose[targets]


def errors_and_claims(
    root: Path, seeds: Iterable[int], log: bool = True, repeats: int = 4
) -> tuple[np.ndarray, np.ndarray]:
    """Errors of the corrected poses against the twin's truth, and their claimed u,
    (seeds, targets, 6) in um and urad (``bench/carry_seeds.py`` runs more seeds)."""
    errors, claimed = [], []
    for seed in seeds:
        folder, truth = write(root / f"r{seed}", seed, log, repeats)
        result = process_session(folder)
        if not log:
            assert result.carry is not None and result.carry.source == "references"
        errors.append((result.correction.corrected - truth) * SCALE)
        claimed.append(pose_uncertainty(result).corrected_u * SCALE)
    return np.array(errors), np.array(claimed)


@pytest.fixture(scope="module")
def replicas(tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, np.ndarray]:
    """Errors of the corrected poses against the twin's truth, and their claimed u,
    (seeds, targets, 6) in um and urad."""
    return errors_and_claims(tmp_path_factory.mktemp("heating"), range(SEEDS))


def test_repeats_during_heating_are_unbiased_and_their_u_covers_the_error(
    replicas: tuple[np.ndarray, np.ndarray],
) -> None:
    """Measured (30 seeds): claimed/observed 0.95-1.10 per component, 95.6 % within 2u,
    every mean error within 1.7 standard errors (before: Tx t = -10, Tz -4.6)."""
    errors, claimed = replicas
    bias = errors.mean(axis=(0, 1))
    se = errors.std(axis=(0, 1), ddof=1) / np.sqrt(errors.shape[0] * errors.shape[1])
    assert np.all(np.abs(bias / se)[:3] < 4.0), (bias / se).round(1)
    ratio = np.sqrt((claimed**2).mean(axis=(0, 1)) / (errors**2).mean(axis=(0, 1)))
    assert np.all((ratio > 0.82) & (ratio < 1.25)), ratio.round(2)
    coverage = float((np.abs(errors) <= 2 * claimed).mean())
    assert 0.92 <= coverage <= 0.99, coverage


def test_strict_process_passes_a_good_repeated_session(tmp_path: Path) -> None:
    """The first target interpolates from R0's last measurement (200 s before it), not
    from the repeats' mean time (800 s: the time-gap check failed, exit 3)."""
    folder, _ = write(tmp_path / "s", 0)
    result = CliRunner().invoke(
        main, ["process", str(folder), "--strict", "-o", str(tmp_path / "o")]
    )
    assert result.exit_code == 0, result.output
    assert "O carried to R0's thermal state" in result.output


@pytest.fixture(scope="module")
def replicas_without_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, ...]:
    """As :func:`replicas`, the sessions without their thermocouple log (10 seeds)."""
    return errors_and_claims(tmp_path_factory.mktemp("heating-nolog"), range(10), log=False)


def test_without_a_log_o_and_r0_are_carried_by_the_references(
    replicas_without_log: tuple[np.ndarray, ...],
) -> None:
    """No thermocouple log: O read from the references' growth series (R0's four
    measurements, then R1...), R0 its straight line at the last one's time, the carry's
    noise in the propagation with R0's. Measured (20 seeds): RMS error 0.60/0.58/0.99 um
    (with the log 0.56/0.56/0.93), claimed/observed 0.99 1.01 0.91 1.02 0.91 1.04, 94 %
    within 2u; these 10 seeds 0.92-1.05. The bounds: 60 errors, correlated through the
    common part (about half their variance), some 20 independent: the RMS ratio
    scatters by about 1/sqrt(40) = 0.16, so 0.72-1.35 (2 of it). Before: claimed/observed
    Tx/Ty/Rz 1.7 (the carry's noise added as independent of R0's in the correction; R0's
    line counted as a mean, 1/4 of a measurement's variance, not sum l^2 = 0.7); before
    the carry (nothing carried, R0 at the repeats' mean time): Tx 2.5 um RMS, t = 44,
    claimed/observed 0.23, 71 % within 2u."""
    errors, claimed = replicas_without_log
    bias = errors.mean(axis=(0, 1))
    se = errors.std(axis=(0, 1), ddof=1) / np.sqrt(errors.shape[0] * errors.shape[1])
    assert np.all(np.abs(bias / se)[:3] < 5.0), (bias / se).round(1)
    rms = np.sqrt((errors**2).mean(axis=(0, 1)))
    assert np.all(rms[:3] < [0.8, 0.8, 1.3]), rms.round(2)
    ratio = np.sqrt((claimed**2).mean(axis=(0, 1)) / (errors**2).mean(axis=(0, 1)))
    assert np.all((ratio > 0.72) & (ratio < 1.35)), ratio.round(2)
    assert float((np.abs(errors) <= 2 * claimed).mean()) >= 0.92


def test_the_screen_says_o_was_carried_by_the_references(tmp_path: Path) -> None:
    """Without a log, ``process --strict`` passes the x4 session (R0 at its last time) and
    one line says how O was carried and what its error in u rests on."""
    folder, _ = write(tmp_path / "s", 0, log=False)
    result = CliRunner().invoke(
        main, ["process", str(folder), "--strict", "-o", str(tmp_path / "o")]
    )
    assert result.exit_code == 0, result.output
    line = next(x for x in result.output.splitlines() if x.startswith("O carried"))
    assert "by the references' growth (no thermocouple log" in line
    assert "R0's 4 measurements fitted by a straight line in time" in line
    assert "its error in u (common): the references' noise" in line


def brute_force_covariance(folder: Path, result: ProcessResult, cov: np.ndarray) -> np.ndarray:
    """Covariance (M, 6, 6) of the corrected poses by a second method: differences
    of the whole of ``process`` (O and R0's repeats carried and averaged, O's carry read
    from the references, registration, correction) by every coordinate of every
    measurement's centres, each measurement independent; R0's measurements each of the
    covariance whose line at the last time is R0's (``cov``, the reduced steps'), O's each
    n times O's mean's."""
    session = read_session(folder)
    _, _, centres, _ = read_measured(session)
    labels = session.plan.labels
    kept = result.session.plan.labels
    repeat_of = result.repeat_of
    counts = {g.label: g for g in result.repeats}
    full = []
    for label in labels:
        first = repeat_of.get(label, label)
        one = cov[kept.index(first)]
        group = counts.get(first)
        if group is not None and first == kept[result.session.plan.origin_index]:
            one = one * len(group.labels)
        elif group is not None:
            one = one / float(np.sum(line_at_end(group.times_s) ** 2))
        full.append(one)
    full_cov = np.array(full)

    def corrected(c: np.ndarray) -> np.ndarray:
        s, averaged, _, carry = carry_and_average(
            session, dataclasses.replace(centres, centres_mm=c), None
        )
        frames = register(
            averaged.centres_mm, s.balls.centres_mm, registration_weights(averaged.u_um)
        ).platform2cmm
        assert carry is not None
        _, corr = correct(
            s.hexapod,
            s.plan,
            averaged.times_s,
            frames,
            "linear",
            averaged.measurements,
            carry.shift,
        )
        return np.asarray(corr.corrected)

    c0, h = centres.centres_mm, 1e-3
    at = corrected(c0)
    jac = np.zeros((len(result.correction.target_index), 6) + c0.shape)
    for index in np.ndindex(c0.shape):  # forward differences: the chain is smooth
        plus = c0.copy()
        plus[index] += h
        jac[(..., *index)] = (corrected(plus) - at) / h
    flat = jac.reshape(jac.shape[:2] + (len(labels), -1))  # (M, 6, N, 3k)
    blocks = np.zeros((len(labels),) + (flat.shape[-1],) * 2)
    for ball in range(c0.shape[1]):
        blocks[:, 3 * ball : 3 * ball + 3, 3 * ball : 3 * ball + 3] = full_cov[:, ball]
    return np.einsum("myni,nij,mznj->myz", flat, blocks, flat)


@pytest.mark.parametrize("repeats", [4, 1])
def test_without_a_log_the_carrys_noise_is_propagated_with_its_correlations(
    tmp_path: Path, repeats: int
) -> None:
    """O's carry without a log reads R0's state and the later references, which the
    targets' correction reads too: the corrected poses' noise u (the carry's model error
    aside) equals a brute-force propagation through all of ``process`` by every
    measurement's centres within 1 % (0.01 % measured), with O and R0 measured 4 times or
    once (2 targets, so that the brute force is quick; the carry reads R0 and the first
    references as with 6). Before, the carry's noise was added as independent of R0's in
    the correction: u over the brute force's 1.8-1.9 on Tx, Ty, Rz (x4), 0.82-0.87 on Tz,
    Rx, Ry (once), as the twin's truth saw it (claimed/observed over 20 seeds 1.67 1.74
    0.92 1.02 0.91 1.69; once 1.46 1.62 0.76 0.81 0.89 1.31)."""
    folder, _ = write(tmp_path / "s", 0, log=False, repeats=repeats, n_targets=2)
    result = process_session(folder)
    claimed = pose_uncertainty(result)
    assert claimed.carry is not None and claimed.carry.source == "references"
    model = claimed.carry.factor[:, 6:, 6]
    noise = claimed.linear_covariance[:, 6:, 6:] - model[:, :, None] * model[:, None, :]
    second = brute_force_covariance(folder, result, claimed.centres.cov_mm2)
    ratio = np.sqrt(np.diagonal(noise, axis1=1, axis2=2) / np.diagonal(second, axis1=1, axis2=2))
    assert np.all(np.abs(ratio - 1.0) < 0.01), ratio.round(3)


def test_r0s_line_weighs_its_measurements_in_u(tmp_path: Path) -> None:
    """Without a log R0's centres are its measurements' line at the last time: their
    covariance is ``sum l^2`` (0.7 for four evenly spaced) of one measurement's, not the
    mean's 1/4 (before: R0's u 0.6 of its scatter over 80 seeds); Monte Carlo (the
    centres drawn, O's carry's part linear) agrees with the linear u within its draws'
    scatter."""
    folder, _ = write(tmp_path / "s", 0, log=False)
    result = process_session(folder)
    cov = centre_covariance(result).cov_mm2
    plan = result.session.plan
    group = next(g for g in result.repeats if g.label == "R0")
    spread = float(np.sum(line_at_end(group.times_s) ** 2))
    assert spread == pytest.approx(0.7)
    one = cov[plan.target_indices[0]]  # one measurement, the same cap fit
    np.testing.assert_allclose(cov[plan.reference_indices[0]], spread * one, rtol=1e-12)
    drawn = pose_uncertainty(result, mc=1500, seed=3)
    ratio = np.sqrt(np.diagonal(drawn.covariance / drawn.linear_covariance, axis1=1, axis2=2))
    # 1500 draws: a standard deviation within 2 * sqrt(1 / 3000) = 3.7 % (1 sigma 1.8 %)
    assert np.all(np.abs(ratio[:, 6:] - 1.0) < 0.06), ratio[:, 6:].round(3)


def test_monte_carlo_refits_weigh_r0s_measurements_as_its_line(tmp_path: Path) -> None:
    """Probed points, no log: Monte Carlo refits every measurement of R0 and combines
    them with its line's weights, as ``process`` does (before: their mean, 1/4 of a
    measurement's variance where the line has 0.7: Monte Carlo's corrected Tz u 0.8 of
    the linear one); its u agrees with the linear one within its draws' scatter."""
    s = dataclasses.replace(spec(tmp_path / "s", 0, repeats=4, n_targets=2), output="points")
    write_files(simulate_session(s).files, tmp_path / "s")
    text = (tmp_path / "s" / "session.yaml").read_text()
    (tmp_path / "s" / "session.yaml").write_text(
        "".join(line for line in text.splitlines(True) if "temperatures" not in line)
    )
    result = process_session(tmp_path / "s")
    drawn = pose_uncertainty(result, mc=1500, seed=5)
    assert drawn.drawn == "points"
    ratio = np.sqrt(np.diagonal(drawn.covariance / drawn.linear_covariance, axis1=1, axis2=2))
    # 1500 draws: a standard deviation within 2 * sqrt(1 / 3000) = 3.7 % (1 sigma 1.8 %)
    assert np.all(np.abs(ratio[:, 6:] - 1.0) < 0.06), ratio[:, 6:].round(3)


def test_the_model_error_follows_the_growths_shape() -> None:
    """The term the line misses at O's time, read from the series along the growth's
    shape (every leg the same history, its own gain), points where the heating's
    curvature there does and has its size: over 50 noise draws of 0.05 um, the cosine
    with the exact half curvature at the first interval's middle is above 0.99 and the
    size's RMS within 0.8-1.25 of it. Before (issue 35's round 3), leg by leg, a leg's
    noise read as curvature: cosine 0.41-0.99 (median 0.88), so the error went into
    pose components the heating did not move (with O and R0 once, Ty claimed 1.2x its
    observed error)."""
    t = np.arange(7) * 400.0
    gains_mm = np.array([3, 7, 2, 3, 9, 3.5]) * 1e-3
    truth = np.outer(1 - np.exp(-t / 2400), gains_mm)
    var = np.full(truth.shape, 0.05e-3**2)
    curvature = -gains_mm * np.exp(-200.0 / 2400) / 2400**2 / 2  # g'' / 2 at 200 s
    cosines, sizes = [], []
    for seed in range(50):
        noisy = truth + np.random.default_rng(seed).normal(0, 0.05e-3, truth.shape)
        missed = _response_term(t, noisy, var, 2, -200.0)
        cosines.append(missed @ curvature / np.linalg.norm(missed) / np.linalg.norm(curvature))
        sizes.append(np.linalg.norm(missed) / np.linalg.norm(curvature))
    assert min(cosines) > 0.99, np.round(cosines, 3)
    assert 0.8 < np.sqrt(np.mean(np.square(sizes))) < 1.25, np.round(sizes, 2)
