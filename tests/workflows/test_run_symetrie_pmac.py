"""``hexatherm run`` with a Symétrie Power PMAC (gpascii over telnet) controller.

The twin's machines as ``serve-twin --dialect symetrie-pmac`` serves them, in process, on
one ManualClock (see tests/workflows/test_run.py). Truth: the twin's prediction at the
times the run measured, and its hexapod's IGM.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.serve import TwinMachines
from tests.workflows.test_run import URAD, check_complete, make_bench, step_times


def test_run_completes_a_campaign_with_the_gpascii_controller(tmp_path: Path) -> None:
    bench = make_bench(tmp_path)
    bench.machines.close()
    bench.machines = TwinMachines(bench.world, dialect="symetrie-pmac", seed=3)
    try:
        assert bench.machines.controller_url.startswith("symetrie-pmac://127.0.0.1:")
        assert bench.dry_run() == 6 and bench.world.model.moves == 0
        result = bench.run()
        plan = bench.files.plan
        assert result.n_points == len(plan.labels) * 3 * plan.points_per_ball
        check_complete(bench)
        processed = process_session(bench.session)
        truth = bench.world.truth(plan, step_times(bench.session, plan.labels))
        idx = processed.correction.target_index
        err = processed.correction.corrected - truth.corrected_pose[idx]
        assert np.abs(err[:, :3]).max() * 1e3 < 0.3
        assert np.abs(err[:, 3:]).max() * URAD < 10.0
        steps = pd.read_csv(bench.session / "steps.csv")
        assert list(steps["label"]) == list(plan.labels)
        q = bench.world.hexapod.igm(plan.poses)
        np.testing.assert_allclose(steps[[f"q_leg{i}_mm" for i in range(1, 7)]], q, atol=1e-4)
        log = (bench.session / "controller.log").read_text()
        sent = [line for line in log.splitlines() if ' > "' in line]
        assert sum(line.endswith('c_cmd=C_MOVE_PTP"') for line in sent) == len(plan.labels)
        assert "deltatau" not in log  # the password is never logged
    finally:
        bench.machines.close()
