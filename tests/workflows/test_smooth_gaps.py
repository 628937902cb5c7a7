"""The smooth fit's own error where the references cannot see it (issue 35, item 6).

Its Type A part (the references' standardized residuals, pooled over the session) sees
the fit's error where the fit has data. A target in a long gap between references is
farther from any data than a reference is from its neighbours, and there the error of
both the smooth fit and the straight line is larger than any residual shows: with a
30 min pause mid-session while the mats heat the legs, smooth claimed 0.32 of the corrected
Tx's RMS error against the twin's truth and 0.54 of Tz's (20 replicas). The thermocouple
log shows the heating's history inside the gap; the fit's error on a growth shaped as the
log is now added to each target's own u.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.process.summary import uncertainty_summary
from hexatherm.workflows.process.uncertainty import pose_uncertainty
from hexatherm.workflows.simulate.twinsession import (
    Heating,
    TwinSessionSpec,
    pose_columns,
    simulate_session,
    write_files,
)
from tests.sessions import BALLS, LEG_GAIN_C, ROOT, small_plan

GAIN = LEG_GAIN_C
#: replicas where the smooth fit is used (it is in 17 of the first 20 seeds)
REPLICAS = 12


def gap_session(folder: Path, seed: int) -> Path:
    """6 targets, 7 references, mats on at 1000 s (tau 600 s), a 30 min pause before
    the fourth reference; centres fitted to 25 points over 70 deg, 1 um point noise,
    ``cmm:`` stating it."""
    plan = small_plan(6, 1)
    spec = TwinSessionSpec(
        name=folder.name,
        hexapod_text=(ROOT / "configs" / "symetrie-like.yaml").read_text(),
        balls=BALLS,
        plan=plan,
        heating=Heating(on_s=1000.0, tau_s=600.0, gain_C=GAIN),
        seed=seed,
        output="centres",
        fit_centres=True,
        point_noise_mm=1e-3,
        pauses_s=tuple(1800.0 if i == 7 else 0.0 for i in range(len(plan.labels))),
    )
    write_files(simulate_session(spec).files, folder)
    cmm = "cmm: {point_noise_um: 1.0, points_per_ball: 25, cap_angle_deg: 70}\n"
    (folder / "session.yaml").write_text((folder / "session.yaml").read_text() + cmm)
    return folder


def test_a_long_gap_between_references_is_in_the_smooth_fits_u(tmp_path: Path) -> None:
    errors, claimed, lines = [], [], []
    for seed in range(20):
        folder = gap_session(tmp_path / f"r{seed}", seed)
        result = process_session(folder, interpolation="smooth")
        if result.correction.smooth is None or not result.correction.smooth.used:
            continue
        u = pose_uncertainty(result)
        truth = pd.read_csv(folder / "truth" / "steps.csv").set_index("label")
        labels = [result.session.plan.labels[i] for i in result.correction.target_index]
        errors.append(result.correction.corrected - truth.loc[labels, pose_columns("truecorr")])
        claimed.append(u.corrected_u)
        lines = uncertainty_summary(u)
        if len(errors) == REPLICAS:
            break
    assert len(errors) == REPLICAS
    e, c = np.concatenate(errors), np.concatenate(claimed)
    ratio = np.sqrt(np.mean(c**2, axis=0) / np.mean(e**2, axis=0))
    # 12 x 6 errors per component, dominated in Tx and Tz by the gap's targets (a bias
    # the log foresees, the same on every seed), noise elsewhere (to about 10 %): before
    # 0.33, 1.04, 0.56, 1.00, 1.01, 0.93 (80 seeds); now 1.00, 1.04, 1.02, 0.96, 1.00, 0.98
    # (the 17 of seeds 0-19 where smooth is used)
    assert np.all((ratio > 0.8) & (ratio < 1.3)), ratio
    assert any("shaped as the thermocouple log" in line for line in lines)


def test_a_long_gap_without_a_log_is_warned_of(tmp_path: Path) -> None:
    folder = gap_session(tmp_path / "g", 0)
    logged = process_session(folder, interpolation="smooth")
    with_log = uncertainty_summary(pose_uncertainty(logged))
    session = folder / "session.yaml"
    lines = session.read_text().splitlines(keepends=True)
    session.write_text("".join(x for x in lines if not x.startswith("temperatures:")))
    result = process_session(folder, interpolation="smooth")
    assert result.correction.smooth is not None and result.correction.smooth.used
    without = uncertainty_summary(pose_uncertainty(result))
    # the references' spacing: 400 s, and 2200 s across the pause
    assert any(x.startswith("warning: references up to 5.5x their median") for x in without)
    assert not any(x.startswith("warning: references up to") for x in with_log)
