"""When a named effect may stand in for a cause outside the registry.

The diagnosis names effects of its registry; a cause the registry does not hold
(a ball on a heated stem, a base joint that moves with the heat) is then named as
the registry effect whose shape comes nearest, and the model may even be
adequate. The data can say so only in part: when the named effect's parameters
are not stable across the session, are far from what physics gives, or trade off
against another added effect. These functions say which, in words.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hexatherm.core.diagnosis.model import Addition, Fit
from hexatherm.core.effects import Effect

#: a named effect's parameter moving by more than this many standard errors when the
#: round's runner-up is fitted with it is not pinned down by the data (a caution)
RUNNER_UP_SHIFT_SE = 2.0

#: an added effect's parameters moving by more than this many of their standard errors
#: (those of the round that added it) when a later effect joins the joint fit: the two
#: trade off, and neither size is to be trusted
TRADE_OFF_SE = 5.0


def stand_in_reasons(
    addition: Addition, final_effect: Effect, unseen: Sequence[str] = ()
) -> list[str]:
    """Why ``addition`` may be a stand-in (empty: no sign of it), each ending a sentence
    that starts "its parameters".

    Two signs: the parameters of the final joint fit refitted on the two held-out
    folds differ by more than :data:`~hexatherm.core.diagnosis.model.FOLD_SIGMAS`
    combined standard errors (unstable), or one of them is far from physical
    (:meth:`~hexatherm.core.effects.Effect.implausible` of ``final_effect``, the
    effect as the final joint fit has it).
    ``unseen`` parameters (not identifiable from these data) are left out.
    """
    why = []
    if addition.folds is not None:
        unstable = {p: z for p, z in addition.folds.unstable().items() if p not in unseen}
        if unstable:
            p = max(unstable, key=lambda q: abs(unstable[q]))
            (a, b) = (addition.folds.values[0][p], addition.folds.values[1][p])
            why.append(
                f"differ between the two halves of the session (even and odd blocks of "
                f"time) by up to {abs(unstable[p]):.1f} combined standard errors "
                f"({p} {a:.4g} vs {b:.4g})"
            )
    far = {p: text for p, text in final_effect.implausible().items() if p not in unseen}
    if far:
        shown = list(far.values())
        more = f" (and {len(shown) - 2} more)" if len(shown) > 2 else ""
        why.append("are far from physical: " + "; ".join(shown[:2]) + more)
    return why


def trade_offs(added: Sequence[Addition], chosen: Sequence[Fit]) -> list[tuple[int, int, float]]:
    """Pairs of added effects that trade off: ``(earlier, later, shift)`` (indices in
    ``added``).

    ``chosen[r]`` is the joint fit of round ``r`` (every effect added up to it). When
    effect ``later`` joins, the parameters of an ``earlier`` one move from their values
    of the round before by ``shift`` standard errors (the largest, in the standard
    errors of that round) above :data:`TRADE_OFF_SE`: the two sizes depend on each
    other (e.g. a leg CTE error taking the place of a screw overheat it cancels).
    """
    out = []
    for later in range(1, min(len(added), len(chosen))):
        before, after = chosen[later - 1], chosen[later]
        for earlier in range(later):
            errors = before.std_errors[earlier]
            shifts = [
                abs(after.effects[earlier].values[p] - v) / errors[p]
                for p, v in before.effects[earlier].values.items()
                if np.isfinite(errors.get(p, np.nan)) and errors[p] > 0
            ]
            if shifts and max(shifts) > TRADE_OFF_SE:
                out.append((earlier, later, float(max(shifts))))
    return out


def runner_up_caution(addition: Addition) -> str | None:
    """The sentence saying that an added effect's parameters move by more than
    :data:`RUNNER_UP_SHIFT_SE` when its round's runner-up is fitted with it, or None."""
    runner = addition.runner_up
    if runner is None:
        return None
    shifts = [abs(v) for v in runner.shift_in_se().values() if np.isfinite(v)]
    if not shifts or max(shifts) <= RUNNER_UP_SHIFT_SE:
        return None
    return (
        f"{addition.effect.name}'s parameters move by up to {max(shifts):.1f} SE when "
        f"{runner.name} is fitted with it: the data do not pin them down"
    )


def cautions(added: Sequence[Addition], final: Fit, chosen: Sequence[Fit]) -> list[str]:
    """Every caution of a diagnosis, the one list that the story, its verdict line,
    ``report.md``/``report.html`` and ``diagnosis.json``'s ``cautions`` print: an added
    effect that may stand in for another cause (a parameter at a bound of its range or
    far from its physical prior, :meth:`~hexatherm.core.effects.Effect.implausible`, or
    unstable between folds), one whose parameters the runner-up moves, and two added
    effects that trade off (empty: none)."""
    out = []
    for k, addition in enumerate(added):
        why = stand_in_reasons(addition, final.effects[k], final.unseen_of(k))
        if why:
            name = addition.effect.name
            out.append(
                f"{name} may be a stand-in: the cause may lie outside the registry (its "
                f"parameters {' and '.join(why)}); read it as the shape of the "
                "disagreement, not its physical cause"
            )
        moved = runner_up_caution(addition)
        if moved is not None:
            out.append(moved)
    for earlier, later, shift in trade_offs(added, chosen):
        a, b = added[earlier].effect.name, added[later].effect.name
        out.append(
            f"{a} and {b} trade off: {a}'s parameters moved by {shift:.1f} standard errors "
            f"when {b} joined the fit; neither size is trustworthy (they may cancel each "
            "other, or stand in for a cause outside the registry)"
        )
    return out
