"""Benchmark of hexatherm.core.spherefit (a plain script, not a test).

Run with ``.venv/bin/python bench/spherefit.py``.  It prints:

1. accuracy on null-space reference data (the exact least-squares solution is
   known) for caps of 30-90 deg: a plain algebraic (Kasa) fit vs ours;
2. the time to fit 10,000 spheres of 25 points (free and fixed radius);
3. the time of the straightforward way, one ``scipy.optimize.least_squares``
   per sphere, measured on a subset and extrapolated, and the speed ratio.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import least_squares

from hexatherm.core.spherefit import fit_spheres

N_POINTS = 25
N_SPHERES = 10_000
N_SCIPY = 300
RESIDUAL_RMS_MM = 2e-3


def cap_directions(n: int, half_angle_deg: float, rng: np.random.Generator) -> np.ndarray:
    z = rng.uniform(np.cos(np.radians(half_angle_deg)), 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    u = np.c_[s * np.cos(phi), s * np.sin(phi), z]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))  # random orientation of the cap
    return u @ q.T


def nullspace_sphere(
    half_angle_deg: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, float]:
    """Points whose geometric least-squares sphere is exactly (centre, radius)."""
    u = cap_directions(N_POINTS, half_angle_deg, rng)
    m = np.vstack([np.ones(N_POINTS), u.T])
    v = rng.normal(size=N_POINTS)
    e = v - m.T @ np.linalg.lstsq(m.T, v, rcond=None)[0]
    e *= RESIDUAL_RMS_MM / np.sqrt(np.mean(e**2))
    centre = rng.uniform(-500.0, 500.0, 3)
    radius = float(rng.uniform(5.0, 20.0))
    return centre + (radius + e)[:, None] * u, centre, radius


def kasa(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Plain algebraic fit: |p|^2 = 2 c.p + (r^2 - |c|^2), linear least squares."""
    mean = points.mean(axis=0)
    q = points - mean
    a = np.c_[2.0 * q, np.ones(len(q))]
    sol = np.linalg.lstsq(a, np.einsum("ij,ij->i", q, q), rcond=None)[0]
    c = sol[:3]
    return mean + c, float(np.sqrt(sol[3] + c @ c))


def scipy_fit(points: np.ndarray) -> tuple[np.ndarray, float]:
    c0, r0 = kasa(points)

    def fun(x: np.ndarray) -> np.ndarray:
        return np.linalg.norm(points - x[:3], axis=1) - x[3]

    def jac(x: np.ndarray) -> np.ndarray:
        d = points - x[:3]
        u = d / np.linalg.norm(d, axis=1)[:, None]
        return np.c_[-u, -np.ones(len(points))]

    res = least_squares(fun, np.r_[c0, r0], jac=jac, method="lm", xtol=1e-15, ftol=1e-15)
    return res.x[:3], float(res.x[3])


def accuracy_table(rng: np.random.Generator, per_cap: int = 500) -> None:
    print(f"1. Accuracy on null-space data: {per_cap} spheres per cap, {N_POINTS} points,")
    print(f"   residual RMS {1e3 * RESIDUAL_RMS_MM:g} um, radius 5-20 mm (max abs errors)")
    print(
        f"   {'cap':>7} | {'Kasa centre':>12} {'Kasa radius':>12} | "
        f"{'ours centre':>12} {'ours radius':>12}"
    )
    for cap in (30.0, 45.0, 60.0, 90.0):
        data = [nullspace_sphere(cap, rng) for _ in range(per_cap)]
        pts = np.vstack([d[0] for d in data])
        centres = np.array([d[1] for d in data])
        radii = np.array([d[2] for d in data])
        fits = fit_spheres(pts, np.repeat(np.arange(per_cap), N_POINTS))
        kasa_fits = [kasa(d[0]) for d in data]
        kc = np.array([k[0] for k in kasa_fits])
        kr = np.array([k[1] for k in kasa_fits])
        errors = (
            np.abs(kc - centres).max(),
            np.abs(kr - radii).max(),
            np.abs(fits.centre_mm - centres).max(),
            np.abs(fits.radius_mm - radii).max(),
        )
        cells = [f"{x:9.2e} mm" for x in errors]
        print(f"   {cap:3.0f} deg | {cells[0]} {cells[1]} | {cells[2]} {cells[3]}")


def best_of(fn, repeats: int = 3) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def timing_table(rng: np.random.Generator) -> None:
    caps = rng.uniform(30.0, 90.0, N_SPHERES)
    u = np.vstack([cap_directions(N_POINTS, c, rng) for c in caps])
    centres = rng.uniform(-500.0, 500.0, (N_SPHERES, 3))
    radii = rng.uniform(5.0, 20.0, N_SPHERES)
    groups = np.repeat(np.arange(N_SPHERES), N_POINTS)
    noise = rng.normal(0.0, RESIDUAL_RMS_MM, N_SPHERES * N_POINTS)
    pts = centres[groups] + (radii[groups] + noise)[:, None] * u

    t_free = best_of(lambda: fit_spheres(pts, groups))
    t_fixed = best_of(lambda: fit_spheres(pts, groups, radius_mm=radii))
    fits = fit_spheres(pts, groups)
    iters = np.bincount(fits.iterations)

    sub = rng.choice(N_SPHERES, N_SCIPY, replace=False)
    t0 = time.perf_counter()
    ref = [scipy_fit(pts[groups == k]) for k in sub]
    t_scipy = (time.perf_counter() - t0) * N_SPHERES / N_SCIPY
    agree = max(
        max(np.abs(ref[i][0] - fits.centre_mm[k]).max(), abs(ref[i][1] - fits.radius_mm[k]))
        for i, k in enumerate(sub)
    )

    print(f"\n2./3. Time to fit {N_SPHERES:,} spheres of {N_POINTS} points (caps 30-90 deg,")
    print(f"   noise {1e3 * RESIDUAL_RMS_MM:g} um; best of 3)")
    print(f"   {'method':<44} {'time':>9} {'ratio':>8}")
    print(f"   {'fit_spheres, free radius':<44} {t_free:8.3f}s {1.0:8.1f}")
    print(f"   {'fit_spheres, fixed radius':<44} {t_fixed:8.3f}s {t_fixed / t_free:8.1f}")
    label = f"scipy least_squares per sphere (x{N_SPHERES // N_SCIPY} of {N_SCIPY})"
    print(f"   {label:<44} {t_scipy:8.3f}s {t_scipy / t_free:8.1f}")
    print(
        "   iterations per sphere (free radius): "
        + ", ".join(f"{k}: {c}" for k, c in enumerate(iters) if c)
    )
    print(f"   max |ours - scipy| on the subset: {agree:.2g} mm")


def main() -> None:
    rng = np.random.default_rng(20240607)
    accuracy_table(rng)
    timing_table(rng)


if __name__ == "__main__":
    main()
