"""What an operator does when ``diagnose`` says NOT ADEQUATE (docs/diagnose.md): which
results stay valid, what to measure again, what to add, read from where the unexplained
residual shows (:class:`~hexatherm.core.diagnosis.adequacy.Adequacy`).

The reasoning: ``process``'s correction rests on the measured references, not on the
twin; an effect the twin lacks that moves the references with time (a thermal one)
is in the references and is corrected, while one that shows at the targets and not at
the references (pose-dependent: a geometry error, a leg's error over its stroke) is not:
it stays in the corrected poses, of the size of the unexplained RMS.
"""

from __future__ import annotations

import numpy as np

from hexatherm.core.diagnosis.adequacy import Adequacy


def _worse(v: Adequacy, kind: str) -> float:
    """How far the residual of ``kind`` steps lies above its floor (ratio; 0: unknown)."""
    rms, floor = v.kind_rms_um.get(kind, np.nan), v.kind_floor_um.get(kind, np.nan)
    if v.kind_count.get(kind, 0) < 3 or not (np.isfinite(rms) and floor > 0):
        return 0.0
    return float(rms / floor)


def next_steps(v: Adequacy) -> list[str]:
    """The next steps after NOT ADEQUATE, one sentence each (empty when adequate)."""
    if v.adequate:
        return []
    at_targets, at_references = _worse(v, "target"), _worse(v, "reference")
    thermal = any("temperature" in f.test for f in v.findings) or (
        np.isfinite(v.temperature_rho) and abs(v.temperature_rho) > 0.5
    )
    unexplained = f"{v.unexplained_rms_um:.3f} um RMS"
    steps = []
    if at_targets > 1.3 and at_targets > 1.3 * max(at_references, 1.0):
        steps.append(
            f"Still valid: process's reference-corrected poses, with care: the unexplained "
            f"part shows at the targets ({at_targets:.1f}x its floor) more than at the "
            f"references ({at_references:.1f}x): a pose-dependent effect the references do "
            f"not see, left in the corrected poses; add {unexplained} to their uncertainty "
            "or calibrate the geometry (hexatherm calibrate) before using them."
        )
    else:
        steps.append(
            "Still valid: process's reference-corrected poses and their U (the correction "
            "rests on the measured references, which carry what the twin misses"
            + (", a thermal effect here" if thermal else "")
            + "). Not valid: the twin's model (diagnose's hexapod.yaml) for process "
            "--method twin, calibrate --poses twin or simulate's predictions."
        )
    if np.all(np.isfinite(v.part_rms_um)) and np.all(v.part_floor_um > 0):
        ratio = v.part_rms_um / v.part_floor_um
        q = int(np.argmax(ratio))
        if ratio[q] > 1.3 * max(float(np.median(ratio)), 1.0):
            t0 = float(np.nanmin(v.part_span_s))
            a, b = (v.part_span_s[q] - t0) / 3600.0
            steps.append(
                f"Measure again: the steps of quarter {q + 1} ({a:.1f}-{b:.1f} h), where "
                f"the residual is {ratio[q]:.1f}x its floor: check the log for a door, a "
                "draught, a tool change or a bad probing there first."
            )
    steps.append(
        "Add: "
        + (
            "thermocouples on the base, the platform and the air beside the legs (the "
            "residual follows the temperature), and "
            if thermal
            else ""
        )
        + "a reference R between every two targets (the drift sampled twice as often), "
        "then diagnose the new session; a repeated O and R0 (plan: repeats) tell the "
        "CMM's scatter from the hexapod's."
    )
    return steps
