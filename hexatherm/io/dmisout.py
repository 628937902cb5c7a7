"""Write DMIS output (``.dmo``) as a CMM would report probed points and spheres.

Used by the twin to produce DMIS sessions; the result reads back through
:mod:`hexatherm.io.dmis`. Each feature is preceded by ``DATE=`` and ``TIME=``
statements when its time differs from the previous one (DMIS times carry whole
seconds).
"""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np
import numpy.typing as npt


def _stamp(seconds: float) -> tuple[str, str]:
    moment = datetime.fromtimestamp(round(float(seconds)), tz=UTC)
    return moment.strftime("%Y/%m/%d"), moment.strftime("%H:%M:%S")


def dmis_output(
    labels: npt.ArrayLike,
    xyz_mm: npt.ArrayLike,
    times_s: npt.ArrayLike,
    kind: str,
    ijk: npt.ArrayLike | None = None,
    diameters_mm: npt.ArrayLike | None = None,
    name: str = "hexatherm",
) -> str:
    """DMIS output text with one actual feature per row.

    Parameters
    ----------
    labels : array_like of str
        Feature labels (``<step>_<ball>`` for spheres, ``<step>_<ball>_<n>`` for points).
    xyz_mm : array_like, shape (n, 3)
    times_s : array_like, shape (n,)
        POSIX seconds (rounded to whole seconds in the file).
    kind : {"POINT", "SPHERE"}
    ijk : array_like, shape (n, 3), optional
        Directions of the points.
    diameters_mm : array_like, shape (n,), optional
        Diameters of the spheres.
    """
    xyz = np.asarray(xyz_mm, dtype=float)
    directions = None if ijk is None else np.asarray(ijk, dtype=float)
    diameters = None if diameters_mm is None else np.asarray(diameters_mm, dtype=float)
    times = np.asarray(times_s, dtype=float)
    lines = ["DMISMN/'hexatherm twin output',04.0", "UNITS/MM,ANGDEC", f"FILNAM/'{name}'"]
    last = None
    for i, label in enumerate(np.asarray(labels, dtype=str)):
        stamp = _stamp(times[i])
        if stamp != last:
            lines += [f"DATE={stamp[0]}", f"TIME={stamp[1]}"]
            last = stamp
        coords = ",".join(repr(float(v)) for v in xyz[i])
        if kind == "POINT":
            tail = (
                "" if directions is None else "," + ",".join(repr(float(v)) for v in directions[i])
            )
            lines.append(f"FA({label})=FEAT/POINT,CART,{coords}{tail}")
        elif kind == "SPHERE":
            diameter = "" if diameters is None else f",{float(diameters[i])!r}"
            lines.append(f"FA({label})=FEAT/SPHERE,OUTER,CART,{coords}{diameter}")
        else:
            raise ValueError(f"kind must be POINT or SPHERE, got {kind!r}")
        lines.append(f"OUTPUT/FA({label})")
    lines.append("ENDFIL")
    return "\r\n".join(lines) + "\r\n"
