"""Uncertainty of the poses: linear propagation, Monte Carlo, spread of repeated sessions."""

from __future__ import annotations

import re

import numpy as np
import pytest

from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.propagation import (
    cap_centre_covariance,
    linear_covariance,
    monte_carlo_covariance,
    output_difference,
)
from hexatherm.core.smoothbias import own_leg_covariance
from hexatherm.core.spherefit import fit_spheres
from hexatherm.core.twin import probe_points
from hexatherm.errors import InputError
from hexatherm.io.config import read_session
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import (
    centre_covariance,
    point_sampler,
    pose_chain,
    pose_uncertainty,
)
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    TwinSessionSpec,
    simulate_session,
    write_files,
)
from tests.sessions import BALLS, LEG_GAIN_C, ROOT, make_session, small_plan

HEXAPOD_TEXT = (ROOT / "configs" / "symetrie-like.yaml").read_text()
GAIN = LEG_GAIN_C


def points_session(folder, seed=0, n_targets=3, noise_mm=1e-3, **kw):
    spec = TwinSessionSpec(
        name=folder.name,
        hexapod_text=HEXAPOD_TEXT,
        balls=BALLS,
        plan=small_plan(n_targets, 1),
        heating=Heating(on_s=0.0, tau_s=2400.0, gain_C=GAIN),
        seed=seed,
        output="points",
        point_noise_mm=noise_mm,
        **kw,
    )
    write_files(simulate_session(spec).files, folder)
    return folder


@pytest.fixture(scope="module")
def noisy(tmp_path_factory):
    return process_session(points_session(tmp_path_factory.mktemp("u") / "s"))


def test_chain_reproduces_the_method(noisy):
    out = pose_chain(noisy)(noisy.centres.centres_mm)
    expected = np.concatenate([noisy.correction.conventional, noisy.correction.corrected], 1)
    assert np.abs(output_difference(out, expected)).max() < 1e-12


def test_pose_derivatives_equal_central_differences(noisy):
    """The poses' analytic derivatives by each step's own centres and by O's (what the
    chain rule starts from) against central differences of the registrations, as they
    were computed before (every step's coordinate moved at once, O's alone): within 1e-6
    of the largest derivative (the differences' own error is about 1e-9 of it); and of
    some steps alone (O's frame registered with them) the same rows."""
    chain = pose_chain(noisy)
    c = noisy.centres.centres_mm
    n, k = c.shape[:2]
    origin, convention = chain.plan.origin_index, chain.hexapod.convention
    pose, own, by_origin = chain.pose_derivatives(c)
    frames = chain.frames(c)
    o_inv = invert_transform(frames[origin])
    np.testing.assert_array_equal(pose, pose_from_transform(o_inv @ frames, convention))
    h = 1e-3
    num_own, num_origin = np.zeros_like(own), np.zeros_like(by_origin)
    for ball in range(k):
        for axis in range(3):
            col = 3 * ball + axis
            moved = [c.copy(), c.copy()]
            moved[0][:, ball, axis] += h
            moved[1][:, ball, axis] -= h
            at = [chain.frames(m) for m in moved]
            own_pm = [pose_from_transform(o_inv @ f, convention) for f in at]
            origin_pm = [
                pose_from_transform(invert_transform(f[origin]) @ frames, convention) for f in at
            ]
            num_own[:, :, col] = output_difference(*own_pm)[:, :6] / (2 * h)
            num_origin[:, :, col] = output_difference(*origin_pm)[:, :6] / (2 * h)
    for analytic, numeric in ((own, num_own), (by_origin, num_origin)):
        assert np.abs(numeric).max() > 0.1
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())
    some = np.array([n - 1, 2, origin])
    for whole, part in zip((pose, own, by_origin), chain.pose_derivatives(c, some), strict=True):
        np.testing.assert_allclose(part, whole[some], rtol=1e-12, atol=1e-12)


def test_own_leg_covariance_equals_central_differences(noisy):
    """The references' leg covariance from their own centres (the smooth fit's and the
    carry's error) by the analytic pose derivatives, against central differences of the
    leg lengths of registrations with O held (as it was computed before)."""
    chain = pose_chain(noisy)
    c = noisy.centres.centres_mm
    cov = centre_covariance(noisy).cov_mm2
    refs = chain.plan.reference_indices
    k, h = c.shape[1], 1e-4
    convention = chain.hexapod.convention
    o_inv = invert_transform(chain.frames(c)[chain.plan.origin_index])
    dq = np.zeros((refs.size, k, 3, 6))
    for ball in range(k):
        for axis in range(3):
            moved = [c.copy(), c.copy()]
            moved[0][:, ball, axis] += h
            moved[1][:, ball, axis] -= h
            q = [
                chain.hexapod.igm(pose_from_transform(o_inv @ chain.frames(m), convention))
                for m in moved
            ]
            dq[:, ball, axis] = ((q[0] - q[1]) / (2 * h))[refs]
    numeric = np.einsum("rbil,rbij,rbjm->rlm", dq, cov[refs], dq)
    analytic = own_leg_covariance(chain, c, cov, refs)
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())


def brute_force_covariance(chain, centres, cov, step_mm=1e-3):
    """Full Jacobian of all outputs by all N*k*3 coordinates, one at a time."""
    n, k = centres.shape[:2]
    pert = np.broadcast_to(centres, (n, k, 3, 2, n, k, 3)).copy()
    for s in range(n):
        for b in range(k):
            for a in range(3):
                pert[s, b, a, 0, s, b, a] += step_mm
                pert[s, b, a, 1, s, b, a] -= step_mm
    out = chain(pert)
    jac = output_difference(out[:, :, :, 0], out[:, :, :, 1]) / (2 * step_mm)  # (n,k,3,M,12)
    jac = jac.reshape(n * k * 3, -1).T  # (M*12, n*k*3)
    big = np.zeros((n * k * 3, n * k * 3))
    for i in range(n * k):
        big[3 * i : 3 * i + 3, 3 * i : 3 * i + 3] = cov.reshape(-1, 3, 3)[i]
    full = jac @ big @ jac.T
    m = full.shape[0] // 12
    return np.array([full[12 * i : 12 * i + 12, 12 * i : 12 * i + 12] for i in range(m)])


@pytest.mark.parametrize("interpolation", ["linear", "before", "after", "nearest"])
def test_chain_rule_jacobian_equals_the_brute_force_one(tmp_path, interpolation):
    # one-sided references too: R S S R S S R
    session = points_session(tmp_path / "s", n_targets=4)
    plan_text = (session / "plan.yaml").read_text()
    (session / "plan.yaml").write_text(re.sub(r"  - \{label: R[13],.*\n", "", plan_text))
    (session / "points.csv").write_text(
        "".join(
            ln
            for ln in (session / "points.csv").read_text().splitlines(keepends=True)
            if not ln.startswith(("R1,", "R3,"))
        )
    )
    result = process_session(session, interpolation=interpolation)
    chain = pose_chain(result)
    cov = centre_covariance(result).cov_mm2
    fast = linear_covariance(chain, result.centres.centres_mm, cov)
    slow = brute_force_covariance(chain, result.centres.centres_mm, cov)
    scale = np.sqrt(np.einsum("mii->mi", slow))
    assert np.abs(fast - slow).max() <= 1e-6 * scale.max() ** 2
    np.testing.assert_allclose(np.sqrt(np.einsum("mii->mi", fast)), scale, rtol=1e-6)


def test_monte_carlo_agrees_with_linear_propagation_within_10_percent(noisy):
    u = pose_uncertainty(noisy, mc=2000, seed=7)
    assert u.method == "monte-carlo" and u.draws == 2000 and u.drawn == "points"
    ratio = u.ratio_to_linear()
    assert np.all(np.abs(ratio - 1) < 0.10), ratio
    first, again = (pose_uncertainty(noisy, mc=50, seed=7) for _ in range(2))
    np.testing.assert_array_equal(again.corrected_u, first.corrected_u)  # seeded


def test_monte_carlo_mean_is_the_measured_value(noisy):
    chain = pose_chain(noisy)
    cov = centre_covariance(noisy).cov_mm2
    _, mean = monte_carlo_covariance(
        chain, noisy.centres.centres_mm, cov, 500, np.random.default_rng(1)
    )
    u = pose_uncertainty(noisy)
    measured = np.concatenate([noisy.correction.conventional, noisy.correction.corrected], 1)
    both_u = np.concatenate([u.conventional_u, u.corrected_u], 1)
    assert np.all(np.abs(output_difference(mean, measured)) < 4 * both_u / np.sqrt(500))


# the spread of noise replicas against the claimed u: tests/workflows/test_uncertainty_replicas.py


def test_cap_covariance_matches_the_scatter_of_sphere_fits():
    rng = np.random.default_rng(3)
    centres = np.zeros((4000, 3))
    points, _ = probe_points(centres, 12.7, 25, 70.0, 1e-3, rng)
    fits = fit_spheres(points.reshape(-1, 3), np.repeat(np.arange(4000), 25))
    empirical = np.cov(fits.centre_mm.T)
    formula = cap_centre_covariance(25, 70.0, 1e-3)
    np.testing.assert_allclose(np.sqrt(np.diag(empirical)), np.sqrt(np.diag(formula)), rtol=0.05)


def test_centre_covariance_sources(tmp_path, noisy):
    assert set(centre_covariance(noisy).source.ravel()) == {"fit"}
    make_session(tmp_path / "c", noise_mm=1e-3)
    result = process_session(tmp_path / "c")
    cc = centre_covariance(result)
    assert set(cc.source.ravel()) == {"registration"}
    assert "registration residuals" in cc.description
    assert 0.5 < cc.u_um.mean() < 1.5  # the twin's 1 um per coordinate
    with (tmp_path / "c" / "session.yaml").open("a") as f:
        f.write("cmm: {mpe_um: 2.0, points_per_ball: 16, cap_angle_deg: 60}\n")
    session = read_session(tmp_path / "c")
    assert session.cmm is not None and session.cmm.point_noise_um == 1.0
    cc = centre_covariance(process_session(tmp_path / "c"))
    assert set(cc.source.ravel()) == {"cmm"}
    np.testing.assert_allclose(cc.cov_mm2[3, 1], cap_centre_covariance(16, 60.0, 1e-3))


BAD_CMM = {
    "both": (
        "cmm: {mpe_um: 2.0, point_noise_um: 1.0}",
        r":9: field 'cmm.mpe_um': give point_noise_um or mpe_um",
    ),
    "none": ("cmm: {cap_angle_deg: 60}", r":9: field 'cmm': give point_noise_um or mpe_um"),
    "negative": ("cmm: {mpe_um: -1}", r":9: field 'cmm.mpe_um': must be positive"),
    "unknown": ("cmm: {sigma: 1}", r":9: field 'cmm.sigma': unknown key"),
    "points": ("cmm: {mpe_um: 1, points_per_ball: 2}", r":9: field 'cmm.points_per_ball'"),
    "text": ("cmm:\n  point_noise_um: abc", r":10: field 'cmm.point_noise_um': expected a number"),
}


@pytest.mark.parametrize("case", sorted(BAD_CMM))
def test_bad_cmm_mapping_names_file_line_and_field(tmp_path, case):
    make_session(tmp_path / "s")
    text, pattern = BAD_CMM[case]
    with (tmp_path / "s" / "session.yaml").open("a") as f:
        f.write(text + "\n")
    with pytest.raises(InputError, match=r"session\.yaml" + pattern):
        read_session(tmp_path / "s")


def test_point_draws_scatter_the_centres_as_the_fit_covariance_says(noisy):
    # GUM S1 on the points: refits of drawn points vs the fits' s^2 (J^T J)^-1
    cov = centre_covariance(noisy).cov_mm2
    draws = point_sampler(noisy, cov)(np.random.default_rng(5), 2000)
    dev = draws - noisy.centres.centres_mm
    assert np.abs(dev.mean(axis=0)).max() < 5 * np.sqrt(cov.diagonal(0, 2, 3).max() / 2000)
    empirical = np.einsum("dnki,dnkj->nkij", dev, dev) / 2000
    ratio = np.sqrt(np.einsum("nkii->nki", empirical) / np.einsum("nkii->nki", cov))
    assert np.abs(ratio - 1).max() < 0.10 and abs(ratio.mean() - 1) < 0.02, ratio
    # the off-diagonal terms (the cap's tilt couples x, y with z) too
    corr = empirical / np.sqrt(
        np.einsum("nkii->nki", empirical)[..., :, None]
        * np.einsum("nkii->nki", empirical)[..., None, :]
    )
    expected = cov / np.sqrt(
        np.einsum("nkii->nki", cov)[..., :, None] * np.einsum("nkii->nki", cov)[..., None, :]
    )
    assert np.abs(corr - expected).max() < 0.1


def test_centres_sessions_draw_the_centres(tmp_path):
    make_session(tmp_path / "s", noise_mm=1e-3)
    result = process_session(tmp_path / "s")
    assert point_sampler(result, centre_covariance(result).cov_mm2) is None
    u = pose_uncertainty(result, mc=50, seed=1)
    assert u.drawn == "centres" and np.isfinite(u.corrected_u).all()


def test_point_draws_do_not_depend_on_how_the_refits_are_chunked(noisy, monkeypatch):
    # issue 26: the refits run in chunks small enough for the caches; the draws come
    # from the generator in the same order and each sphere's arithmetic is its own, so
    # the drawn centres are the same whatever the chunk, to rounding: numpy picks its
    # kernels (and the order of a sum) by the arrays' shapes and the CPU's SIMD, so a
    # chunk of 7 and one of 64 may differ in the last bits on some CPUs; 1e-10 mm keeps
    # a factor of 1000 over the spacing of coordinates of a few hundred mm
    import hexatherm.workflows.process.uncertainty as uncertainty

    cov = centre_covariance(noisy).cov_mm2
    whole = point_sampler(noisy, cov)(np.random.default_rng(8), 300)
    n_points = sum(len(p.xyz_mm) for p in noisy.points if p is not None)
    for per_chunk in (7, 64):  # draws per chunk: 300 = 42 x 7 + 6; 4 x 64 + 44
        monkeypatch.setattr(uncertainty, "POINTS_PER_REFIT", per_chunk * n_points)
        chunked = point_sampler(noisy, cov)(np.random.default_rng(8), 300)
        np.testing.assert_allclose(chunked, whole, rtol=0, atol=1e-10)
