"""``geometry.cross_columns`` (the registration's and the poses' derivatives: a lever
crossed with every column) against :func:`numpy.cross` along axis 1, the code it
replaced: the same products and differences, so the same numbers to the bit, on random,
broadcast and hostile inputs (zeros, huge and tiny magnitudes, inf and NaN)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.geometry import cross_columns
from hexatherm.core.registration import frame_derivatives


def _former(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The former code: ``np.cross(a[..., :, None], b, axis=-2)``."""
    return np.cross(np.asarray(a)[..., :, None], b, axis=-2)


@pytest.mark.parametrize("seed", range(6))
def test_random_levers_and_columns(seed: int) -> None:
    rng = np.random.default_rng(seed)
    s, n = rng.integers(1, 50), rng.integers(1, 12)
    a = rng.normal(size=(s, 3)) * 10.0 ** rng.uniform(-8, 8, size=(s, 1))
    b = rng.normal(size=(s, 3, n)) * 10.0 ** rng.uniform(-8, 8, size=(s, 1, n))
    out = cross_columns(a, b)
    assert out.shape == (s, 3, n) and out.flags.c_contiguous
    assert np.array_equal(out, _former(a, b))
    # the propagation's form: one set of columns (O's) for every lever
    assert np.array_equal(cross_columns(a, b[0]), _former(a, b[0][None]))


def test_hostile_entries() -> None:
    a = np.array([[0.0, 0.0, 0.0], [1e308, -1e308, 1e-308], [np.inf, 1.0, 0.0], [1.0, np.nan, 2.0]])
    b = np.array(
        [
            [[1.0, 0.0, np.inf], [0.0, 1e-320, 1.0], [-0.0, 5.0, 2.0]],
            [[1e308, 2.0, 0.0], [1e308, -3.0, 0.0], [1.0, 4.0, 0.0]],
            [[0.0, 1.0, np.inf], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]],
        ]
    )
    with np.errstate(all="ignore"):
        assert np.array_equal(cross_columns(a, b), _former(a, b), equal_nan=True)


def test_frame_derivatives_translation_is_the_lever_cross_the_rotation() -> None:
    """Where frame_derivatives uses it: ``dt = dc_mean + (R b_mean) x omega``, checked
    with numpy's cross product (ragged weights, one ball weighing nothing)."""
    rng = np.random.default_rng(3)
    balls = np.array([[100.0, 0.0, 10.0], [-50.0, 86.0, -5.0], [-50.0, -86.0, 0.0]])
    centres = balls + rng.normal(scale=1e-3, size=(7, 3, 3)) + [500.0, 200.0, 30.0]
    weights = rng.uniform(0.5, 2.0, size=(7, 3))
    weights[2, 1] = 0.0
    frames, d_rot, d_trans = frame_derivatives(centres, balls, weights)
    w = weights / weights.sum(axis=1, keepdims=True)
    lever = (frames[:, :3, :3] @ (w @ balls)[..., None])[..., 0]
    omega = d_rot.reshape(7, 3, 9)
    mean = (w[:, None, :, None] * np.eye(3)[None, :, None, :]).reshape(7, 3, 9)
    assert np.array_equal(d_trans.reshape(7, 3, 9), _former(lever, omega) + mean)
