"""What ``process`` says on the screen of its uncertainty (lines the command line prints)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hexatherm.core.curvature import LEGS_DIFFER
from hexatherm.workflows.process.carryerror import carry_line, carry_warning

if TYPE_CHECKING:
    from hexatherm.workflows.process.run import ProcessOutcome
    from hexatherm.workflows.process.uncertainty import PoseUncertainty

#: the largest relative standard uncertainty of a Monte Carlo u said without a warning
#: (1/sqrt(2 (M - 1)): 10 % at 51 draws)
MC_RELATIVE_LIMIT = 0.1


#: references farther apart than this many times their median spacing, without a log,
#: leave the smooth fit's error inside the gap unclaimed (a warning)
WIDE_GAP = 2.0


def past_warning(uncertainty: PoseUncertainty) -> str:
    """A warning for targets past the last reference without a thermocouple log: their u
    holds the growth's continuation past it, which no reference shows (a limit of the
    method, over-claimed where the heating settles there, under where it starts)."""
    curved, excess = uncertainty.curvature, uncertainty.smooth_excess
    count = 0
    if curved is not None and curved.source == "curvature" and curved.past is not None:
        count = int(np.count_nonzero(curved.past))
    if excess is not None and excess.shape_um is None and excess.past_um is not None:
        count = max(count, int(np.count_nonzero(excess.past_um > 0)))
    if not count:
        return ""
    return (
        f"warning: {count} target(s) after the last reference and no thermocouple log: their "
        "u holds the growth's straight continuation beyond it, which no reference shows "
        "(a heating switched on 300-600 s before the last reference, 200 s before such a "
        "target: linear claimed 1.2-11x of its corrected Tx error, smooth 0.3-1.1x); "
        "measure a reference after the last target, or give the session its log"
    )


def differ_warning(uncertainty: PoseUncertainty) -> str:
    """A warning when the references' growth follows two or more shapes over the legs
    beyond its noise without a thermocouple log (:func:`~hexatherm.core.curvature.second_shape`):
    the legs' histories differ, and O's carry, extrapolated back from the references
    along one history in time, does not hold how each leg grew before R0 (a limit,
    docs/uncertainty.md)."""
    curved = uncertainty.curvature
    if curved is None or curved.source != "curvature" or not curved.second_shape > LEGS_DIFFER:
        return ""
    return (
        f"warning: the references' growth follows a second shape over the legs "
        f"{curved.second_shape:.2g}x its noise and there is no thermocouple log: the legs' "
        "histories differ (lagging one another, heated unevenly), and O's carry to R0's "
        "state, extrapolated back from the references, does not hold how each leg grew "
        "before R0 (the air drifting with the legs lagging 0-400 s: the corrected Ty "
        "claimed 0.65x of its error; a leg heated from between R0 and R1: Rz 0.84x); "
        "measure O and R0 with the legs settled, or give the session its log"
    )


def uncertainty_summary(uncertainty: PoseUncertainty) -> list[str]:
    """Screen lines: where the centre uncertainties came from, and the largest pose ones."""
    lines = [f"uncertainty: centres from {uncertainty.centres.description}"]
    for name, u in (
        ("conventional", uncertainty.conventional_u),
        ("corrected", uncertainty.corrected_u),
    ):
        if u.size == 0:
            continue
        t_um, r_urad = u[:, :3].max() * 1e3, np.deg2rad(u[:, 3:]).max() * 1e6
        lines.append(
            f"  u ({uncertainty.method}, k=1) of the {name} poses: up to "
            f"{t_um:.3f} um, {r_urad:.2f} urad"
        )
    lines.extend(shared_summary(uncertainty))
    excess = uncertainty.smooth_excess
    if excess is not None:
        residuals = (
            f"the references' standardized residuals from the smooth fit {excess.observed_um:.3g}"
            f" um RMS, {excess.noise_um:.3g} um from their noise alone"
        )
        lines.append(
            f"  smooth fit's own error (bias, smoothing chosen from the data): growth at R "
            f"{excess.excess_um:.3g} um RMS over the legs added to each corrected pose's own u "
            f"({residuals})"
            if excess.excess_um > 0
            else f"  smooth fit's own error: nothing added ({residuals})"
        )
        lines.append(
            "  smooth fit's own error on a growth shaped as the thermocouple log: "
            f"{np.sqrt(np.mean(excess.shape_um**2)):.3g} um RMS over the targets and legs, "
            f"up to {excess.shape_um.max():.3g} um, added to each target's own u"
            if excess.shape_um is not None and excess.shape_um.size
            else "  no thermocouple log: the smooth fit's error between references far apart "
            "or across a heating switched on or off rests on the references' residuals alone"
        )
        if excess.past_um is not None and np.any(excess.past_um > 0):
            lines.append(
                "  smooth fit's own error past the last reference (its straight continuation):"
                f" up to {excess.past_um.max():.3g} um RMS over the legs, at "
                f"{np.count_nonzero(excess.past_um)} target(s), added to their own u"
            )
        if excess.shape_um is None and excess.widest_gap > WIDE_GAP:
            lines.append(
                f"warning: references up to {excess.widest_gap:.2g}x their median spacing "
                "apart and no thermocouple log: the smooth fit's u does not hold its error "
                "inside the widest gaps (a 30 min pause in a heating session claimed 0.56x "
                "and 0.72x of the corrected Tx and Tz errors); give the session its log"
            )
    curved = uncertainty.curvature
    if curved is not None and curved.evaluated.any():
        what = (
            "on a growth shaped as the thermocouple log"
            if curved.source == "log"
            else "from the curvature of the references' growth (second differences)"
        )
        lines.append(
            f"  straight line's own error between references {what}: "
            f"{np.sqrt(np.mean(curved.error_um[curved.evaluated] ** 2)):.3g} um RMS over the "
            f"targets and legs, up to {curved.error_um.max():.3g} um, added to each target's "
            "own u"
        )
        if curved.source == "curvature" and curved.widest_gap > WIDE_GAP and excess is None:
            lines.append(
                f"warning: references up to {curved.widest_gap:.2g}x their median spacing "
                "apart and no thermocouple log: the curvature the references show does not "
                "hold a heating that starts or settles inside the gap (a 30 min pause "
                "after mats switched on 90 s before a reference claimed 0.55x of the "
                "corrected Tx error; a step inside one interval 0.42x); give the session "
                "its log"
            )
    differ = differ_warning(uncertainty)
    if differ:
        lines.append(differ)
    past = past_warning(uncertainty)
    if past:
        lines.append(past)
    for check in uncertainty.repeats:
        line = (
            f"  {check.label} measured {check.n} times, averaged: their scatter is "
            f"{check.ratio:.2f}x the claimed u (chi2 {check.chi2:.1f} over {check.dof} dof"
            + (", after a straight-line drift" if check.n >= 3 else "")
            + ")"
        )
        lines.append(line)
        if not check.ok:
            lines.append(
                f"warning: the {check.n} measurements of {check.label} scatter more than "
                f"their u allows (p = {check.p_value:.1g}): the platform moved or drifted "
                "between them, or a ball was probed badly; the average is used, and u "
                "does not include that scatter"
            )
    if uncertainty.method == "monte-carlo":
        ratio = uncertainty.ratio_to_linear()
        if np.isfinite(ratio).any():
            drawn = (
                "probed points drawn, spheres refitted"
                if uncertainty.drawn == "points"
                else "centres drawn from their covariance"
            )
            lines.append(
                f"  Monte Carlo ({uncertainty.draws} draws, seed {uncertainty.seed}) "
                f"over linear propagation: {np.nanmin(ratio):.3f} to "
                f"{np.nanmax(ratio):.3f} ({drawn})"
            )
        # a standard deviation of M draws is itself uncertain by 1/sqrt(2 (M - 1)) (k=1)
        relative = 1 / np.sqrt(2 * (uncertainty.draws - 1))
        if relative > MC_RELATIVE_LIMIT:
            lines.append(
                f"warning: {uncertainty.draws} Monte Carlo draws: every u written is the "
                f"standard deviation of {uncertainty.draws} values, itself uncertain by "
                f"about {relative * 100:.0f} % (k=1); --mc 1000 or more for a u to rely on"
            )
    return lines


def shared_summary(uncertainty: PoseUncertainty) -> list[str]:
    """Screen lines: the parts of u common to all targets (O and R0) and of their own."""
    common, own = uncertainty.common_u, uncertainty.own_u
    if common is None or own is None or common.size == 0:
        return []
    from hexatherm.core.geometry import to_um_urad

    def rms(values: np.ndarray) -> str:
        v = np.sqrt(np.mean(to_um_urad(values) ** 2, axis=0))
        return (
            " ".join(f"{n} {x:.3g}" for n, x in zip(("Tx", "Ty", "Tz"), v[:3], strict=True))
            + " um, "
            + " ".join(f"{n} {x:.3g}" for n, x in zip(("Rx", "Ry", "Rz"), v[3:], strict=True))
            + " urad"
        )

    scaled = " (linear shares of the Monte Carlo u)" if uncertainty.method == "monte-carlo" else ""
    lines = [
        "  parts of u, RMS over the targets" + scaled + ": common to all targets (the one "
        "measurement of O and R0 every pose carries; it shifts all targets together and "
        "cancels in their differences) and own (the target's step and its references):"
    ]
    for name, cols in (("conventional", slice(0, 6)), ("corrected", slice(6, 12))):
        lines.append(f"    {name:12} common {rms(common[:, cols])}")
        lines.append(f"    {'':12} own    {rms(own[:, cols])}")
    if uncertainty.between_covariance is not None:
        lines.append("  covariance between targets: covariance.csv")
    else:
        m = len(common)
        lines.append(
            f"  covariance between targets: not written for {m} targets "
            f"({m * (m + 1) // 2:,} pairs); --covariance writes covariance.csv"
        )
    return lines


def session_lines(outcome: ProcessOutcome) -> list[str]:
    """The lines that say what was processed: steps, targets, the interpolation (and the
    smooth fit's choice), the repeats averaged, O carried to R0's thermal state."""
    result = outcome.result
    n = len(result.correction.target_index)
    averaged = "".join(
        f", {g.label} averaged over {len(g.labels)} measurements" for g in result.repeats
    )
    lines = [
        f"session {result.session.name}: {len(result.session.plan.labels)} steps, "
        f"{n} targets, interpolation {outcome.request.interpolation}{averaged}"
    ]
    carried = carry_line(result, outcome.uncertainty.carry)
    if carried:
        lines.append(carried)
    warning = carry_warning(outcome.uncertainty.carry)
    if warning:
        lines.append(warning)
    smooth = result.correction.smooth
    if smooth is not None:
        lams = ", ".join(sorted({f"{v:.2g}" for v in smooth.lam})) if smooth.used else ""
        lines.append(
            f"interpolation smooth: {smooth.reason}"
            + (f" (smoothing {lams}, times scaled to [0, 1])" if lams else "")
        )
    return lines


def failure_text(outcome: ProcessOutcome) -> str | None:
    """What failed the quality checks, naming up to five steps; None when nothing did."""
    quality = outcome.quality
    if not quality.any_failed:
        return None
    steps = quality.failed_steps
    return (
        f"quality checks failed at {len(steps)} step(s) ({', '.join(steps[:5])}"
        + (" ..." if len(steps) > 5 else "")
        + ")"
    )
