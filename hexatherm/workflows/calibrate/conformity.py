"""The calibration report's conformity: every target's calibrated pose error judged against
the lab's tolerances on it (issue 33, item 7), with the decision rule the lab agreed."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from hexatherm.workflows.calibrate.run import Calibration
from hexatherm.workflows.process.conformity import Conformity, judge

if TYPE_CHECKING:
    from hexatherm.core.conformity import DecisionRule
    from hexatherm.session import Tolerance

#: k of the expanded uncertainties, as the calibration report prints them
COVERAGE_FACTOR = 2.0


def pose_error_conformity(
    run: Calibration,
    tolerances: dict[str, Tolerance],
    coverage_factor: float = COVERAGE_FACTOR,
    rule: DecisionRule | None = None,
) -> Conformity:
    """Every target's calibrated pose error (measured minus the calibrated model's
    prediction, held out when the level was chosen) judged against ``tolerances``, with
    ``U = k sqrt(u_measured^2 + u_predicted^2)`` per component (the measured pose's
    linear uncertainty and the prediction's from the parameters' covariance)."""
    from hexatherm.core.geometry import to_um_urad

    campaign = run.campaign
    n = len(campaign.labels)
    u_measured = to_um_urad(np.sqrt(np.diag(campaign.covariance)).reshape(n, 6))
    u_predicted = run.fit.predicted_sigma_um_urad(campaign.commanded)
    expanded = coverage_factor * np.hypot(u_measured, u_predicted)
    return judge(
        list(campaign.labels),
        run.residuals_after_um_urad,
        expanded,
        tolerances,
        coverage_factor,
        rule,
    )


def conformity_part(
    run: Calibration, tolerances: dict[str, Tolerance], k: float, rule: DecisionRule
) -> dict[str, object]:
    """The report's conformity part: its item and its table."""
    from hexatherm.workflows.report.conformity import conformity_item, conformity_table

    judged = pose_error_conformity(run, tolerances, k, rule)
    what = "the calibrated pose error d (measured \u2212 the calibrated model's prediction"
    what += ", held out)" if run.heldout else ", in sample)"
    return {
        "item": conformity_item(judged, "the calibrated pose error")[1],
        "table": conformity_table(judged, what),
    }
