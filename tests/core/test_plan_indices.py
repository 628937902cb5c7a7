"""Plan's step indices by kind, found once: against the steps read one by one, and each
caller's array its own."""

from __future__ import annotations

import numpy as np

from hexatherm.core.plan import Plan


def test_indices_of_each_kind_as_the_steps_say():
    rng = np.random.default_rng(3)
    for n in (1, 2, 7, 300):
        kinds = ("origin", *rng.choice(["reference", "target"], n - 1).tolist())
        plan = Plan(tuple(f"S{i}" for i in range(n)), kinds, np.zeros((n, 6)), np.zeros(6))
        for kind, got in (("reference", plan.reference_indices), ("target", plan.target_indices)):
            want = np.array([i for i, k in enumerate(kinds) if k == kind], dtype=np.intp)
            np.testing.assert_array_equal(got, want)
            assert got.dtype == np.intp
        # an array handed out is the caller's: changing it changes no later answer
        refs = plan.reference_indices
        refs[:] = -7
        np.testing.assert_array_equal(
            plan.reference_indices, [i for i, k in enumerate(kinds) if k == "reference"]
        )
