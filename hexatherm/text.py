"""How hexatherm writes numbers and poses in messages and plans (floor 0: imports nothing
of hexatherm, so that errors and every floor above can use it)."""

from __future__ import annotations

from collections.abc import Sequence


def format_number(value: float, decimals: int = 6) -> str:
    """A number with at most ``decimals`` decimals, trailing zeros dropped.

    >>> format_number(-0.0000001), format_number(2.50), format_number(1 / 3, 3)
    ('0', '2.5', '0.333')
    """
    text = f"{float(value):.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def format_pose(pose: Sequence[float]) -> str:
    """A pose as ``[Tx, Ty, Tz, Rx, Ry, Rz]`` with up to 6 decimals.

    >>> format_pose([1, -0.5, 40.1234567, 0, 0, 0])
    '[1, -0.5, 40.123457, 0, 0, 0]'
    """
    return "[" + ", ".join(format_number(v) for v in pose) + "]"
