"""The single-axis travel a simulated controller reports: from its hexapod's struts'
stroke, found the way the twins' validation finds a pose out of stroke."""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt

from hexatherm.core.hexapod import Hexapod
from hexatherm.typing import FloatArray


class SimulatedHexapod(Protocol):
    """What the travel needs of a twin's kinematic model: its hexapod."""

    @property
    def hexapod(self) -> Hexapod: ...


def single_axis_travel(model: SimulatedHexapod) -> tuple[FloatArray, FloatArray]:
    """The lower and upper single-axis travel from the zero pose that the struts' stroke
    allows, per axis (mm, deg; a pose with one component is the same in every convention):
    the first pose out of stroke on the way out (steps of 1 mm / 0.5 deg: past it, the
    legs may come back within their stroke through poses no motion reaches), then
    bisection to 1 nm / 1 udeg, written inside.

    Every step of the way out is tried at once, and the twelve bisections (six axes, two
    sides) go in step: the poses and the halvings are those of one pose at a time, a
    batch of inverse kinematics instead of some 600 single ones (0.3 s a twin server)."""
    hexapod = model.hexapod

    def outside(axes: npt.NDArray[np.intp], values: FloatArray) -> npt.NDArray[np.bool_]:
        poses = np.zeros((values.size, 6))
        poses[np.arange(values.size), axes] = values
        return np.asarray(hexapod.check_stroke(hexapod.igm(poses)).any(axis=1))

    axes = np.repeat(np.arange(6), 2)
    signs = np.tile([-1.0, 1.0], 6)
    low, high = np.zeros(12), np.zeros(12)
    for i, (k, sign) in enumerate(zip(axes, signs, strict=True)):
        step, largest = (1.0, 1000.0) if k < 3 else (0.5, 90.0)
        ahead = step * np.arange(1, int(largest // step) + 1)  # low + step <= largest
        first = ahead.size
        for start in range(0, ahead.size, 64):  # 64 steps at a time: the stroke ends early
            block = ahead[start : start + 64]
            out = outside(np.full(block.size, k), sign * block)
            if out.any():
                first = start + int(np.argmax(out))
                break
        low[i] = ahead[first - 1] if first else 0.0
        high[i] = min(low[i] + step, largest)
    going = high - low > 1e-6
    while going.any():
        mid = 0.5 * (low[going] + high[going])
        out = outside(axes[going], signs[going] * mid)
        high[going] = np.where(out, mid, high[going])
        low[going] = np.where(out, low[going], mid)
        going = high - low > 1e-6
    travel = (signs * np.floor(low * 1e6) / 1e6).reshape(6, 2)  # inside, as written
    return travel[:, 0].copy(), travel[:, 1].copy()
