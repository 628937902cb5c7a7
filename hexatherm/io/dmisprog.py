"""DMIS measurement program of a plan, for the CMM (``hexatherm plan --dmis``).

For every step of the plan, the program shows the operator the pose to command
(``TEXT/OPER`` and ``PAUSE``), then for every ball declares the nominal sphere
``F(<label>_<ball>)=FEAT/SPHERE,OUTER,CART,x,y,z,d`` at the ball's nominal
position on the CMM, measures it with a ``MEAS/SPHERE`` block of
``PTMEAS/CART,x,y,z,i,j,k`` touch points spread over the ball's upper cap and
``ENDMES``, and asks for the actual with ``OUTPUT/FA(<label>_<ball>)``. The
labels are the spec's, so the CMM's output file (``FA(S1_B2)=FEAT/SPHERE,...``)
reads straight back with :func:`hexatherm.io.dmis.read_dmis`. A DMIS label holds
letters, digits and ``_`` only (a ``-`` would read as a minus sign, and CMM software
refuses it): a ``-`` of a step or ball name is written ``__`` (``O-2_B1`` is
``O__2_B1``, :func:`dmis_label`), which the reader turns back.

``i,j,k`` of a ``PTMEAS`` is the nominal outward surface normal at the point;
the probe approaches along its opposite. Between balls the probe is taken up
to a clearance height above the step's highest ball (``GOTO/CART``).

>>> import numpy as np
>>> from hexatherm.core.planning import build_plan
>>> from hexatherm.core.touch import touch_points
>>> from hexatherm.session import Balls
>>> balls = Balls(("B1", "B2", "B3"), np.array([[10.0, 0, 30], [0, 10, 30], [-10, 0, 30]]),
...               np.full(3, 20.0))
>>> plan = build_plan([[0, 0, 5, 0, 0, 0]], points_per_ball=4)
>>> tp = touch_points(plan, balls.centres_mm, balls.diameters_mm, [100, 200, 50, 0, 0, 0])
>>> text = dmis_program(plan, balls, tp, origin_on_cmm=[100, 200, 50, 0, 0, 0])
>>> lines = text.splitlines()
>>> first = next(i for i, line in enumerate(lines) if line.startswith("F(O_B1)"))
>>> print("\\n".join(lines[first:first + 8]))
F(O_B1)=FEAT/SPHERE,OUTER,CART,110.00000,200.00000,80.00000,20.00000
GOTO/CART,110.00000,200.00000,120.00000
MEAS/SPHERE,F(O_B1),4
PTMEAS/CART,114.20371,200.00000,89.07352,0.420371,0.000000,0.907352
PTMEAS/CART,104.89864,204.67327,87.22057,-0.510136,0.467327,0.722057
PTMEAS/CART,110.73764,191.59497,85.36762,0.073764,-0.840503,0.536762
PTMEAS/CART,115.69621,207.42969,83.51467,0.569621,0.742969,0.351467
ENDMES
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexatherm.core.plan import Plan
from hexatherm.core.planning import StepTiming
from hexatherm.core.touch import TouchPoints
from hexatherm.errors import PlanError
from hexatherm.session import Balls
from hexatherm.text import format_pose

#: DMIS version written in the ``DMISMN`` statement
DMIS_VERSION = "05.2"


def _xyz(values: Sequence[float]) -> str:
    return ",".join(f"{float(v):.5f}" for v in values)


def _ijk(values: Sequence[float]) -> str:
    return ",".join(f"{float(v) + 0.0:.6f}" for v in values)


def _text(value: str) -> str:
    """A DMIS string literal (single quotes doubled)."""
    return "'" + value.replace("'", "''") + "'"


def dmis_label(*names: str) -> str:
    """A DMIS label of hexatherm names joined by ``_``, each ``-`` written ``__``.

    >>> dmis_label("O-2", "B1")
    'O__2_B1'
    >>> try:
    ...     dmis_label("O-", "B1")
    ... except PlanError as error:
    ...     print(error)
    'O-' begins or ends with '-': its DMIS label (where '-' is written '__') would be ambiguous
    """
    for name in names:
        if name.startswith("-") or name.endswith("-"):
            raise PlanError(
                f"{name!r} begins or ends with '-': its DMIS label (where '-' is written "
                "'__') would be ambiguous"
            )
    return "_".join(name.replace("-", "__") for name in names)


def dmis_program(
    plan: Plan,
    balls: Balls,
    touch: TouchPoints,
    *,
    origin_on_cmm: Sequence[float],
    name: str = "hexatherm plan",
    clearance_mm: float = 30.0,
    timing: StepTiming | None = None,
) -> str:
    """The DMIS program text (CRLF line ends, as CMM software expects).

    Parameters
    ----------
    plan : Plan
    balls : Balls
    touch : TouchPoints
        From :func:`hexatherm.core.planning.touch_points`, same plan and balls.
    origin_on_cmm : sequence of 6 floats
        The nominal placement of frame O on the CMM the points were computed
        for (written in a comment).
    name : str
        Program name (``DMISMN``).
    clearance_mm : float
        Height of the probe's moves between balls above the highest ball top.
    timing : StepTiming, optional
        Estimated step durations, shown to the operator.

    Returns
    -------
    str
    """
    n_steps, n_balls = touch.centres_mm.shape[:2]
    if n_steps != len(plan.labels) or n_balls != len(balls.names):
        raise ValueError("touch points do not match the plan and the balls")
    radii = balls.diameters_mm / 2.0
    lines = [
        f"$$ {name}: hexatherm measuring program, {n_steps} steps x {n_balls} balls x "
        f"{plan.points_per_ball} points",
        f"$$ nominal placement of frame O on the CMM: {format_pose(origin_on_cmm)} "
        "(Tx, Ty, Tz mm; Rx, Ry, Rz deg)",
        "$$ touch points spread over the upper cap of each ball; i,j,k = outward normal",
        "$$ measure the steps in this order; a reference R right before/after its target S",
        f"DMISMN/{_text(name)},{DMIS_VERSION}",
        "UNITS/MM,ANGDEC",
    ]
    for i, (label, kind, pose) in enumerate(zip(plan.labels, plan.kinds, plan.poses, strict=True)):
        centres = touch.centres_mm[i]
        safe_z = float(np.max(centres[:, 2] + radii)) + clearance_mm
        eta = ""
        if timing is not None:
            eta = f", about {timing.duration_s[i] / 60.0:.0f} min"
        message = (
            f"Step {label} ({kind}): command the hexapod to pose {format_pose(pose)}"
            f"{eta}, then continue"
        )
        lines += [
            f"$$ ---- step {i + 1}/{n_steps}: {label} ({kind})",
            f"TEXT/OPER,{_text(message)}",
            "PAUSE",
        ]
        for j, ball in enumerate(balls.names):
            feature = dmis_label(label, ball)
            lines.append(
                f"F({feature})=FEAT/SPHERE,OUTER,CART,{_xyz(centres[j])},"
                f"{balls.diameters_mm[j]:.5f}"
            )
            lines.append(f"GOTO/CART,{_xyz([centres[j, 0], centres[j, 1], safe_z])}")
            lines.append(f"MEAS/SPHERE,F({feature}),{plan.points_per_ball}")
            for point, normal in zip(touch.points_mm[i, j], touch.normals[i, j], strict=True):
                lines.append(f"PTMEAS/CART,{_xyz(point)},{_ijk(normal)}")
            lines.append("ENDMES")
            lines.append(f"GOTO/CART,{_xyz([centres[j, 0], centres[j, 1], safe_z])}")
            lines.append(f"OUTPUT/FA({feature})")
    lines.append("ENDFIL")
    return "\r\n".join(lines) + "\r\n"
