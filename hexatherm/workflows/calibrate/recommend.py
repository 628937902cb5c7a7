"""``calibrate``'s recommendation: apply the calibrated geometry, or keep the controller
as it is, with the tests it rests on (:mod:`hexatherm.core.calibration.significance`),
and, when it says apply, the geometry in the form a controller takes
(``controller.yaml``, :func:`controller_yaml`).

**Apply** when every one of these holds: the model explains the poses (the chi-square
test); the parameters' change is significant (joint chi-square test at
:data:`~hexatherm.core.calibration.significance.ALPHA`); and, when the residuals after
are held out (``--level auto``), the calibrated geometry predicts the targets it was not
fitted to significantly better in translation or rotation (mean reduction of the squared
residual beyond ``k`` times its uncertainty) and significantly worse in neither. With a
forced level the residuals after are in sample (every fit reduces them): the
recommendation then rests on the parameters' test alone, and says so. Otherwise: **no
significant change: keep the controller as it is**.

**The controller's form.** The fit's parameters are joint centres and, per leg ``i``, an
offset ``dq_i`` and a gain ``g_i`` with ``q_true_i = q_cmd_i + dq_i + g_i (q_cmd_i -
q_home_i)`` (:mod:`hexatherm.core.calibration`): ``dq_i > 0`` means the real leg is
*longer* than the controller believes at its home length. A controller that adds a
per-leg correction ``c_i`` to the length it drives must be given ``c_i = -dq_i`` (and
a travel scale ``1 / (1 + g_i)``) to reach the geometric length. The joints' rigid part
goes into the frames both makers' controllers take (Symétrie's user and object frames,
``C_CFG_CS``/``CFG#CS``; PI's work and tool frames), with its uncertainty and what it
leaves (:mod:`hexatherm.workflows.calibrate.frames`). The rest (the joints' non-rigid
part, the offsets and gains) has no publicly documented controller parameter in the
sources searched (docs/calibrate.md), so ``controller.yaml`` keeps it in a documented
neutral form: joint centres (base in frame O, platform in the platform frame, mm), the
offsets and the corrections with their signs, the gains, each with its expanded
uncertainty; the maker's service, or the lab with the maker's documentation, enters them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from hexatherm.core.calibration.significance import (
    ALPHA,
    ChangeTest,
    Improvement,
    improvement,
    parameter_change_test,
)
from hexatherm.workflows.calibrate.frames import frames_record
from hexatherm.workflows.calibrate.run import Calibration, machine_hexapod

#: the format tag of ``controller.yaml``
CONTROLLER_FORMAT = "hexatherm-controller-geometry/2"


@dataclass(frozen=True)
class Recommendation:
    """The recommendation and the tests it rests on.

    Attributes
    ----------
    apply : bool
    changes : ChangeTest
        The parameters' change against their covariance.
    translation, rotation : Improvement
        Residuals before (nominal) and after (calibrated) over the targets, um and urad.
    heldout : bool
        Whether the residuals after are held out.
    explained : bool
        Whether the model explains the poses.
    coverage_factor : float
        ``k`` of the improvement's test.
    """

    apply: bool
    changes: ChangeTest
    translation: Improvement
    rotation: Improvement
    heldout: bool
    explained: bool
    coverage_factor: float

    def headline(self) -> str:
        """The recommendation in one line."""
        if self.apply:
            return (
                "Recommendation: APPLY the calibrated geometry (controller.yaml: the "
                "controller's form, docs/calibrate.md)."
            )
        return "Recommendation: no significant change: keep the controller as it is."

    def reasons(self) -> list[str]:
        """The tests, in words, with their numbers."""
        k = self.coverage_factor
        c = self.changes
        lines = [
            f"Parameters' change against their uncertainty: chi\u00b2 = {c.chi_square:.1f} for "
            f"{c.dof} degrees of freedom, p = {c.p:.2g} ("
            + ("significant" if c.significant else "not significant")
            + f" at {ALPHA:g})."
        ]
        where = "held out" if self.heldout else "in sample"
        for name, unit, imp in (
            ("translation", "\u00b5m", self.translation),
            ("rotation", "\u00b5rad", self.rotation),
        ):
            word = {1: "better", -1: "WORSE", 0: "no significant change"}[imp.verdict(k)]
            lines.append(
                f"RMS residual {name} ({where}): nominal {imp.rms_before:.3f} {unit}, "
                f"calibrated {imp.rms_after:.3f} {unit}; mean reduction of the squared "
                f"residual {imp.mean:.4g} \u00b1 {k * imp.u:.2g} {unit}\u00b2 (k = {k:g}): {word}."
            )
        if not self.heldout:
            lines.append(
                "The residuals after are in sample (a forced --level): every fit reduces "
                "them, so the recommendation rests on the parameters' test alone; "
                "--level auto gives held-out residuals."
            )
        if not self.explained:
            lines.append("The model does not explain the poses: nothing is to be applied.")
        return lines


def recommend(run: Calibration, coverage_factor: float = 2.0) -> Recommendation:
    """The recommendation for ``run`` (see the module text)."""
    fit = run.fit
    mask = np.asarray(fit.model.mask, dtype=bool)
    change = (fit.parameters - fit.model.theta0)[mask]
    changes = parameter_change_test(change, np.asarray(fit.covariance)[np.ix_(mask, mask)])
    before, after = run.residuals_before_um_urad, run.residuals_after_um_urad
    translation = improvement(before[:, :3], after[:, :3])
    rotation = improvement(before[:, 3:], after[:, 3:])
    verdicts = [translation.verdict(coverage_factor), rotation.verdict(coverage_factor)]
    better = max(verdicts) == 1 and min(verdicts) >= 0
    apply = bool(fit.explains_poses and changes.significant and (better or not run.heldout))
    return Recommendation(
        apply,
        changes,
        translation,
        rotation,
        run.heldout,
        bool(fit.explains_poses),
        coverage_factor,
    )


def controller_record(run: Calibration, coverage_factor: float = 2.0) -> dict[str, Any]:
    """``controller.yaml``'s content: the calibrated geometry in a controller's terms."""
    fit = run.fit
    hexapod = machine_hexapod(run)
    nominal = run.campaign.nominal
    k = coverage_factor
    u = fit.std_errors
    home = nominal.zero_pose_leg_length_mm()
    offsets, gains = fit.leg_offsets_mm, fit.leg_gains
    n_offset, n_gain = 36, 42  # the parameters' order: base, platform, offsets, gains
    legs = []
    for i in range(6):
        legs.append(
            {
                "leg": i + 1,
                "base_joint_mm": [round(float(v), 7) for v in hexapod.base_joints_mm[i]],
                "platform_joint_mm": [round(float(v), 7) for v in hexapod.platform_joints_mm[i]],
                "home_length_mm": round(float(home[i]), 7),
                "length_offset_mm": round(float(offsets[i]), 7),
                "length_offset_U_mm": round(float(k * u[n_offset + i]), 7),
                "actuator_correction_mm": round(float(-offsets[i]), 7),
                "gain": float(gains[i]),
                "gain_U": float(k * u[n_gain + i]),
                "travel_scale": float(1.0 / (1.0 + gains[i])),
            }
        )
    return {
        "format": CONTROLLER_FORMAT,
        "hexapod": nominal.name,
        "level": fit.level,
        "coverage_factor": k,
        "frames": "base_joint_mm in frame O (the platform frame at the zero command, with "
        "no controller frames); platform_joint_mm in the platform frame (the frame the "
        "balls define); mm; home_length_mm: the nominal legs at the campaign's origin step "
        "(the zero command with the frames set during the campaign)",
        "sign_conventions": "q_true = q_cmd + length_offset + gain (q_cmd - home_length): "
        "length_offset > 0: the real leg is longer than the controller believes at its "
        "home length; a controller that adds a correction to the length it drives takes "
        "actuator_correction = -length_offset, and scales the travel from home by "
        "travel_scale = 1 / (1 + gain)",
        "controller_frames": frames_record(run, coverage_factor),
        "legs_parameters": "the joints' non-rigid part, the leg offsets and gains: no public "
        "source searched documents the Symetrie or PI controller parameters that hold them "
        "(docs/calibrate.md); give legs: to the maker's service",
        "legs": legs,
    }


def controller_yaml(run: Calibration, coverage_factor: float = 2.0) -> str:
    """``controller.yaml``'s text (:func:`controller_record`)."""
    import yaml

    header = (
        "# The calibrated geometry in a controller's terms (hexatherm calibrate): enter it\n"
        "# only as docs/calibrate.md says (sign conventions below).\n"
    )
    return header + yaml.safe_dump(
        controller_record(run, coverage_factor), sort_keys=False, allow_unicode=True
    )
