"""The decision rules of ILAC-G8:09/2019 and their risk (JCGM 106:2012), issue 33 item 6:
hand-computed cases exactly at, 1 nm inside and 1 nm outside every limit of every rule,
asymmetric tolerance zones, and the probability of false acceptance at the acceptance
limit against values of the normal distribution written out here (tables of Phi)."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.conformity import (
    CONFORMS,
    DOES_NOT_CONFORM,
    GUARDED_ACCEPTANCE,
    GUARDED_REJECTION,
    ISO14253,
    NOT_DECIDABLE,
    SIMPLE,
    DecisionRule,
    acceptance_limits,
    conformance_probability,
    decide,
    false_acceptance_at_limit,
)

C, F, N = CONFORMS, DOES_NOT_CONFORM, NOT_DECIDABLE
NM = 1e-3  # one nanometre, in um
#: Phi(2), Phi(1) (normal distribution tables)
PHI_2 = 0.9772498680518208
PHI_1 = 0.8413447460685429

#: an asymmetric tolerance zone [TL, TU] = [-3, 8] um, U = 1.5 um
TL, TU, U = -3.0, 8.0, 1.5


def around(limit: float) -> np.ndarray:
    """1 nm below, at, and 1 nm above ``limit``."""
    return np.array([limit - NM, limit, limit + NM])


@pytest.mark.parametrize(
    ("rule", "cases"),
    [
        # simple acceptance, w = 0: the tolerance limits themselves, inclusive
        (DecisionRule(SIMPLE), {TL: [F, C, C], TU: [C, C, F]}),
        # guarded acceptance, w = U: acceptance limits -1.5 and 6.5, binary
        (DecisionRule(GUARDED_ACCEPTANCE), {TL + U: [F, C, C], TU - U: [C, C, F]}),
        # guarded acceptance, w = 0.5 U: -2.25 and 7.25
        (DecisionRule(GUARDED_ACCEPTANCE, 0.5), {-2.25: [F, C, C], 7.25: [C, C, F]}),
        # guarded rejection, w = U: the zone widened, -4.5 and 9.5
        (DecisionRule(GUARDED_REJECTION), {TL - U: [F, C, C], TU + U: [C, C, F]}),
        # ISO 14253-1, w = U: conforms inside [-1.5, 6.5], does not outside [-4.5, 9.5]
        (
            DecisionRule(ISO14253),
            {TL + U: [N, C, C], TU - U: [C, C, N], TL - U: [F, N, N], TU + U: [N, N, F]},
        ),
    ],
)
def test_every_rule_at_and_one_nanometre_around_each_of_its_limits(rule, cases):
    for limit, expected in cases.items():
        got = decide(around(limit), U, TU, TL, rule)
        assert got.tolist() == expected, (rule, limit)


def test_acceptance_limits_and_the_symmetric_default():
    lo, hi = acceptance_limits(TL, TU, U, DecisionRule(GUARDED_ACCEPTANCE, 2.0))
    assert (lo, hi) == (0.0, 5.0)
    lo, hi = acceptance_limits(TL, TU, U, DecisionRule(SIMPLE, 2.0))  # r ignored
    assert (lo, hi) == (TL, TU)
    # lower None: [-T, T]; a guard band that closes the zone leaves nothing conforming
    assert decide([0.0, 0.0], [1.0, 2.5], 2.0).tolist() == [C, N]
    assert decide(0.0, 2.5, 2.0, rule=DecisionRule(GUARDED_ACCEPTANCE)).tolist() == F
    # an unknown U: only simple acceptance decides
    assert decide(1.0, np.nan, 2.0, rule=DecisionRule(SIMPLE)).tolist() == C
    assert decide(1.0, np.nan, 2.0, rule=DecisionRule(GUARDED_ACCEPTANCE)).tolist() == N
    with pytest.raises(ValueError):
        DecisionRule("lenient")
    with pytest.raises(ValueError):
        DecisionRule(GUARDED_ACCEPTANCE, -1.0)


def test_conformance_probability_against_the_normal_tables():
    # y = 0, u = 1, [-1, 1]: Phi(1) - Phi(-1)
    assert conformance_probability(0.0, 1.0, 1.0) == pytest.approx(2 * PHI_1 - 1, abs=1e-15)
    # at the upper limit of a wide zone: one half
    assert conformance_probability(TU, 0.75, TU, TL) == pytest.approx(0.5, abs=1e-12)
    # u = 0: inside (limits included) or outside; NaN u: unknown
    assert conformance_probability([TU, TU + NM], 0.0, TU, TL).tolist() == [1.0, 0.0]
    assert np.isnan(conformance_probability(0.0, np.nan, 1.0))


def test_probability_of_false_acceptance_at_the_acceptance_limit():
    k = 2.0  # u = U / k = 0.75 um
    rules = {
        DecisionRule(SIMPLE): 0.5,  # a value at the limit: inside or outside alike
        DecisionRule(GUARDED_ACCEPTANCE): 1 - PHI_2,  # w/u = r k = 2
        DecisionRule(ISO14253): 1 - PHI_2,
        DecisionRule(GUARDED_REJECTION): PHI_2,  # at TU + w: outside unless 2 u low
        DecisionRule(GUARDED_ACCEPTANCE, 0.5): 1 - PHI_1,  # w/u = 1
    }
    for rule, expected in rules.items():
        got = false_acceptance_at_limit(U, k, TU, TL, rule)
        assert got == pytest.approx(expected, abs=1e-12), rule
        assert f"{100 * expected:.3g} %" in rule.risk_text(k)
    # a narrow zone: the far limit counts too. [-1, 1], U = 1 (u = 0.5), w = U: the
    # acceptance zone is the one point 0, outside either limit with 1 - Phi(2) each
    got = false_acceptance_at_limit(1.0, 2.0, 1.0, rule=DecisionRule(GUARDED_ACCEPTANCE))
    assert got == pytest.approx(2 * (1 - PHI_2), abs=1e-12)
    # no acceptance zone: no limit to be at
    assert np.isnan(false_acceptance_at_limit(2.5, 2.0, 1.0))
    # vectorized over targets and components
    many = false_acceptance_at_limit(np.full((4, 3), U), k, TU, TL, DecisionRule(SIMPLE))
    assert many.shape == (4, 3) and np.allclose(many, 0.5)
