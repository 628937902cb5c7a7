"""The one table of limits every command that checks reads (issue 34, item 3).

:class:`QualityLimits` holds the limits of the quality checks (``process``'s
``quality.csv``, the session's ``quality:`` mapping, ``--quality-threshold``); ``acquire``
warns and ``run`` probes a ball again at its form and diameter limits, ``process`` warns
at its registration limit and refuses only beyond :data:`DISTANCE_REFUSAL_UM`. Pure
Python (no numpy), so that every command's ``--help`` shows the limits without loading
the maths. Why each limit is what it is: docs/uncertainty.md, "One table of limits".

>>> limits_text()  # doctest: +ELLIPSIS
'form_um 10, diameter_dev_um 20, distance_dev_um 10, registration_rms_um 5, ...'
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

#: the smallest reciprocal condition number of the Jacobian at a target (``plan``
#: chooses poses above it, ``process`` flags a target below it)
DEFAULT_MIN_RCOND = 1e-2

#: quality limit names of earlier versions -> (the name now, the factor to it): a radius
#: deviation limit is half the diameter deviation limit
QUALITY_ALIASES: dict[str, tuple[str, float]] = {"radius_dev_um": ("diameter_dev_um", 2.0)}


@dataclass(frozen=True)
class QualityLimits:
    """Limits of the quality checks (``--quality-threshold NAME=VALUE`` overrides one):
    the one table of limits every command that checks reads (issue 34; docs/uncertainty.md,
    "One table of limits"). ``acquire`` warns and ``run`` probes a ball again at the same
    form and diameter limits (a radius: half the diameter's), so that a ball accepted
    while measuring is not flagged when processing; ``process`` warns (or with
    ``--strict-registration`` refuses) at ``registration_rms_um``, and refuses a step only
    beyond :data:`DISTANCE_REFUSAL_UM`, a gross error rather than a flag.

    Attributes
    ----------
    form_um : float
        Largest sphere form error (max - min residual) of a ball: about 4 sigma of
        the probing noise for 25 points, so 10 um holds CMMs of up to 2.5 um noise.
    diameter_dev_um : float
        Largest deviation of a fitted diameter from the nominal one (a wrong ball,
        a missed probe compensation, a bad fit), as ``fits.csv``'s ``diameter_dev_um``.
        The name ``radius_dev_um`` of earlier versions is read as half of it
        (:data:`QUALITY_ALIASES`); ``acquire`` and ``run`` compare a radius with half.
    distance_dev_um : float
        Largest deviation of an inter-ball distance from the balls file (``process``
        refuses a step beyond :data:`DISTANCE_REFUSAL_UM`; this flags less).
    registration_rms_um : float
        Largest registration RMS residual of a step (``process`` warns beyond it too).
    time_gap_s : float
        Largest time between a target and a reference it uses (the plan's ``--max-gap``).
    temperature_change_C : float
        Largest leg temperature change between a target and a reference it uses
        (1 K is about 4.5 um of growth per leg for the Symetrie-like legs, left to
        the correction's model and interpolation to carry over).
    min_rcond : float
        Smallest reciprocal condition number of the Jacobian at a target (as ``plan``).
    growth_margin_C : float
        With a thermocouple log: how much more a leg's growth since R0 at a reference may
        need (as the smallest temperature change that explains it) than the span of the
        leg's logged temperatures up to that reference. It covers the thermocouple's
        error, gradients along the leg and the leg length's noise (about 1 um, 0.2 K on
        the Symetrie-like legs); the shipped sessions need at most 0.7 K.
    max_warming_C : float
        Without a log: the largest temperature change since R0 that a leg's growth at a
        reference may need. Twice the largest leg warming of the shipped and simulated
        campaigns (10.7 K, heating mats on the legs): motors and a CMM room at 20 +- 1 K
        do not warm a hexapod's legs by more; 20 K is 91 um on the Symetrie-like legs.
    """

    form_um: float = 10.0
    diameter_dev_um: float = 20.0
    distance_dev_um: float = 10.0
    registration_rms_um: float = 5.0
    time_gap_s: float = 600.0
    temperature_change_C: float = 1.0
    min_rcond: float = DEFAULT_MIN_RCOND
    growth_margin_C: float = 2.0
    max_warming_C: float = 20.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and value >= 0 and not math.isnan(value)):
                raise ValueError(f"quality threshold {f.name} must be a number >= 0, got {value!r}")


#: an inter-ball distance off by more than this (um) is no quality matter but a gross
#: error (swapped balls or labels, a wrong ball, inch read as mm): ``process`` refuses the
#: step before any work, with a diagnosis (``--distance-tolerance-um``). Five times the
#: flag ``distance_dev_um``: a step between the two is processed and flagged
DISTANCE_REFUSAL_UM = 50.0


def limits_text(limits: QualityLimits | None = None) -> str:
    """Every limit of the table as ``name value`` (for the commands' ``--help``)."""
    limits = limits or QualityLimits()
    return ", ".join(f"{f.name} {getattr(limits, f.name):g}" for f in dataclasses.fields(limits))
