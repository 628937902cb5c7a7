"""Where a probe moving along a line first touches a sphere (the simulated CMM's touch physics)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from hexatherm.devices.ipp import (
    Call,
    Value,
)
from hexatherm.errors import (
    IppProtocolError,
)


def _calls(args: tuple[Value, ...], arity: int) -> list[Call]:
    out = []
    for arg in args:
        if not isinstance(arg, Call) or len(arg.args) != arity:
            raise IppProtocolError("bad arguments")
        if arity and not all(isinstance(a, float) for a in arg.args):
            raise IppProtocolError("bad arguments")
        out.append(arg)
    if not out:
        raise IppProtocolError("no arguments")
    return out


def segment_hits(
    start_mm: npt.ArrayLike,
    end_mm: npt.ArrayLike,
    centres_mm: npt.ArrayLike,
    radii_mm: npt.ArrayLike,
) -> npt.NDArray[np.bool_]:
    """Which spheres the straight segment from ``start`` to ``end`` enters (mm).

    A segment that only grazes a sphere (distance = radius, within 1 nm) does not enter it.

    >>> segment_hits([-20, 0, 0], [20, 0, 0], [[0, 0, 0], [0, 30, 0]], [12.7, 12.7]).tolist()
    [True, False]
    """
    p0 = np.asarray(start_mm, dtype=float)
    d = np.asarray(end_mm, dtype=float) - p0
    c = np.asarray(centres_mm, dtype=float)
    length2 = float(d @ d)
    t = np.zeros(len(c)) if length2 == 0 else np.clip((c - p0) @ d / length2, 0.0, 1.0)
    closest = p0 + t[:, None] * d
    return np.linalg.norm(c - closest, axis=1) < np.asarray(radii_mm, dtype=float) - 1e-6


def first_contact(
    start_mm: npt.ArrayLike,
    direction: npt.ArrayLike,
    length_mm: float,
    centres_mm: npt.ArrayLike,
    radii_mm: npt.ArrayLike,
) -> tuple[float, int]:
    """Distance along a unit direction at which a point first reaches one of the spheres.

    Parameters
    ----------
    start_mm : array_like, shape (3,)
        Start (outside every sphere), mm.
    direction : array_like, shape (3,)
        Unit direction of travel.
    length_mm : float
        Length of travel, mm.
    centres_mm, radii_mm : array_like, shapes (k, 3) and (k,)
        Spheres (the balls grown by the tip radius), mm.

    Returns
    -------
    distance_mm : float
        Travel to the first contact (inf if none).
    index : int
        The sphere touched, -1 if none within ``length_mm``.

    Examples
    --------
    >>> s, index = first_contact([0, 0, 20], [0, 0, -1], 10.0, [[0, 0, 0]], [13.7])
    >>> round(s, 9), index
    (6.3, 0)
    """
    p = np.asarray(start_mm, dtype=float)
    u = np.asarray(direction, dtype=float)
    d = p - np.asarray(centres_mm, dtype=float)
    rho = np.asarray(radii_mm, dtype=float)
    b = d @ u
    c = np.einsum("ij,ij->i", d, d) - rho**2
    disc = b**2 - c
    with np.errstate(invalid="ignore"):
        s = -b - np.sqrt(disc)
    ok = (disc >= 0) & (c > 0) & (s >= 0) & (s <= length_mm)
    if not ok.any():
        return math.inf, -1
    s = np.where(ok, s, np.inf)
    index = int(np.argmin(s))
    return float(s[index]), index
