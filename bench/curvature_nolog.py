"""``curvature_error`` alone on a no-log session's arrays (a script, not a test).

Run with ``python bench/curvature_nolog.py [--targets 10000] [--dense]``, one run in a
fresh process; it prints the CPU and wall time of the call and the process's peak RSS.
References and targets alternate (R T R T ... R: M targets, M + 1 references, about 60 s
apart), each target on the straight line between the two around it (``--interpolation
linear``), the references' growth an exponential heating (40 um, 600 s) plus 10 nm noise,
each reference's leg covariance a random (6, 6) one. ``--dense`` hands the weights as the
(M, n) matrix ``curvature_excess`` made before: with ``PYTHONPATH`` at a checkout before
the sparse form (f49de77), the former figures (docs/speed.md).
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np

from hexatherm.core.curvature import curvature_error


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--targets", type=int, default=10_000)
    parser.add_argument("--dense", action="store_true")
    args = parser.parse_args()
    m = args.targets
    n = m + 1
    rng = np.random.default_rng(1)
    times = np.cumsum(60.0 + rng.uniform(-5, 5, 2 * m + 1))
    ref_t, tgt_t = times[0::2], times[1::2]
    growth = np.outer(40e-3 * (1 - np.exp(-ref_t / 600.0)), rng.uniform(0.5, 1.5, 6))
    growth += rng.normal(scale=1e-5, size=growth.shape)
    a = rng.normal(size=(n, 6, 6)) * 3e-6
    cov = a @ np.swapaxes(a, 1, 2)
    before = np.arange(m)
    w = (tgt_t - ref_t[before]) / (ref_t[before + 1] - ref_t[before])
    columns = np.stack([before, before + 1], axis=1)
    weights = np.stack([1 - w, w], axis=1)
    cpu, wall = time.process_time(), time.perf_counter()
    if args.dense:
        used = np.zeros((m, n))
        used[np.arange(m), columns[:, 0]] = weights[:, 0]
        used[np.arange(m), columns[:, 1]] += weights[:, 1]
        err = curvature_error(ref_t, growth, cov, tgt_t, used, 0.0)
    else:
        err = curvature_error(ref_t, growth, cov, tgt_t, weights, 0.0, columns)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"{m} targets ({'dense' if args.dense else 'columns'} weights): CPU {cpu:.3f} s, "
        f"wall {wall:.3f} s, peak RSS {peak:.0f} MB; {int(err.evaluated.sum())} evaluated"
    )


if __name__ == "__main__":
    main()
