"""TargetJacobian.covariance of some parts (the common ones) against the sum over those
parts of J U J^T, one target and part at a time."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.propagation import TargetJacobian


def spd(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    a = rng.normal(size=(*shape, 3, 3))
    return a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(3)


@pytest.mark.parametrize("parts", [(), (0, 1), (1,), (0, 2), (4, 0), (0, 1, 2, 3, 4)])
def test_the_covariance_of_some_parts(parts):
    rng = np.random.default_rng(len(parts) + sum(parts))
    m, n, k = 40, 30, 3
    jac = rng.normal(size=(m, 5, 12, k, 3))
    steps = rng.integers(0, n, size=(m, 5))
    steps[rng.random((m, 5)) < 0.2] = -1  # parts not used (their Jacobian is zero)
    jac[steps < 0] = 0.0
    cov = spd(rng, (n, k))
    got = TargetJacobian(jac, steps).covariance(cov, parts)
    want = np.zeros((m, 12, 12))
    for t in range(m):
        for p in parts or range(5):
            if steps[t, p] < 0:
                continue
            for b in range(k):
                j = jac[t, p, :, b, :]  # (12, 3)
                want[t] += j @ cov[steps[t, p], b] @ j.T
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    if parts:  # the sum of the parts and the rest is the whole
        rest = tuple(p for p in range(5) if p not in parts)
        whole = TargetJacobian(jac, steps).covariance(cov)
        both = got + (TargetJacobian(jac, steps).covariance(cov, rest) if rest else 0.0)
        np.testing.assert_allclose(both, whole, rtol=1e-12, atol=1e-12 * np.abs(whole).max())
