"""Issue 37's faster steps of the uncertainty against the ones they replaced: the targets'
Jacobian evaluated at the corrected poses found by Newton from the correction's own
(``Hexapod.fgm_near``) against the certified FGM from the chain's start as before; the
IGM's Newton against the FGM; the registration Hessians' inverses by their adjugates
against LAPACK's; the legs' sensitivity in closed form against the segments' sum."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.geometry import inverse3
from hexatherm.core.hexapod import NEAR_MM, Hexapod
from hexatherm.core.propagation import target_jacobian
from hexatherm.core.thermal import LegThermalModel
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.uncertainty import pose_chain
from tests.conftest import make_hexapod

from .test_uncertainty import points_session


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    return process_session(points_session(tmp_path_factory.mktemp("fast") / "s", n_targets=6))


def test_jacobian_at_newtons_poses_equals_the_certified_fgms(processed, monkeypatch):
    chain = pose_chain(processed)
    assert chain.origin_shift is not None  # O carried to R0's state: the start brought back
    centres = processed.centres.centres_mm
    fast = target_jacobian(chain, centres)

    def former(self, q, start):  # as before: the FGM from the chain's (shifted) poses
        x = self.fgm(q, initial_poses=chain.initial_poses)
        return x, self.jacobian(x)

    monkeypatch.setattr(Hexapod, "fgm_near", former)
    slow = target_jacobian(chain, centres)
    np.testing.assert_array_equal(fast.steps, slow.steps)
    scale = np.abs(slow.jac).max()
    assert np.abs(fast.jac - slow.jac).max() <= 1e-9 * scale


@pytest.mark.parametrize("convention", ["symetrie", "pi"])
def test_fgm_near_equals_the_fgm(convention):
    hexapod = make_hexapod(convention)
    rng = np.random.default_rng(11)
    poses = np.column_stack([rng.uniform(-20, 20, (200, 3)), rng.uniform(-5, 5, (200, 3))])
    q = hexapod.igm(poses)
    # starts micrometres off (a thermal correction), one exactly at the answer
    start = poses + rng.normal(0.0, 2e-3, poses.shape)
    start[0] = poses[0]
    x, jac = hexapod.fgm_near(q, start)
    ref = hexapod.fgm(q, initial_poses=start)
    np.testing.assert_allclose(x, ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(jac, hexapod.jacobian(x), rtol=0, atol=1e-12)
    assert np.abs(hexapod.igm(x) - q).max() <= 1e-10
    # a start whose legs are beyond NEAR_MM: the certified FGM's own answer
    far = poses + np.array([5.0, 0, 0, 1.0, 0, 0])
    assert np.abs(hexapod.igm(far) - q).max() > NEAR_MM
    x_far, _ = hexapod.fgm_near(q, far)
    np.testing.assert_array_equal(x_far, hexapod.fgm(q, initial_poses=far))


def test_adjugate_inverses_equal_lapacks():
    rng = np.random.default_rng(12)
    m = rng.normal(size=(500, 3, 3))
    m = m @ np.swapaxes(m, 1, 2) + np.eye(3) * rng.uniform(0.01, 10, (500, 1, 1))
    m[:10] = -m[:10]  # not positive definite: the adjugate does not care
    ref = np.linalg.inv(m)
    cond = np.linalg.cond(m)[:, None, None]
    assert np.all(np.abs(inverse3(m) - ref) <= 1e-14 * cond * np.abs(ref).max())
    singular = np.array([[[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]])
    with pytest.raises(np.linalg.LinAlgError):  # LAPACK's own verdict
        inverse3(singular)


def test_sensitivity_in_closed_form_equals_the_segments_sum():
    rng = np.random.default_rng(13)
    legs = LegThermalModel.from_segments(
        [
            [
                ("strut", "steel", 11.5e-6, 120.0 + rng.uniform(0, 20)),
                ("actuator", "aluminium", 23.1e-6, None),
                ("joint", "invar", 1.2e-6, 15.0),
            ]
        ]
        * 6
    )
    q = rng.uniform(250.0, 350.0, (40, 6))

    def before(q_mm):  # the segments' lengths, their CTEs, summed
        return (legs.cte_per_K * legs.segment_lengths_mm(q_mm)).sum(axis=-1)

    np.testing.assert_allclose(legs.sensitivity_mm_per_K(q), before(q), rtol=1e-14, atol=0)
    np.testing.assert_allclose(legs.sensitivity_mm_per_K(q[0]), before(q[0]), rtol=1e-14)
