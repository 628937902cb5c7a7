"""The commands' one calls (issue 34 item 2): what an outcome says is what the command
wrote, read back from its files (plan, simulate), and an interrupted ``run`` says what
became of the hexapod however early it is stopped."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hexatherm.workflows.run.run
from hexatherm.cli import INTERRUPTED, main
from hexatherm.io.config import read_plan
from hexatherm.workflows.plan import PlanFiles, PlanRequest, write_plan
from hexatherm.workflows.simulate.run import SimulateRequest, simulate_folder
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"


def _request(**changes: object) -> PlanRequest:
    return PlanRequest(
        hexapod_path=CONFIGS / "symetrie-like.yaml",
        balls_path=CONFIGS / "balls-3.yaml",
        reference_pose=[0, 0, -40, 0, 0, 0],
        n_random=4,
        seed=2,
        box_lower=[-3, -3, 0, 0, 0, -1],
        box_upper=[3, 3, 0, 0, 0, 1],
        origin_repeats=2,
        reference0_repeats=3,
        **changes,  # type: ignore[arg-type]
    )


def test_the_plan_outcome_is_the_plan_written(tmp_path: Path) -> None:
    shown = write_plan(_request(), PlanFiles())
    assert shown.written == () and shown.stdout is not None
    out, checklist = tmp_path / "plan.yaml", tmp_path / "checklist.md"
    done = write_plan(_request(checklist=True), PlanFiles(out=out, checklist=checklist))
    assert done.stdout is None and done.written == (out, checklist)  # -o first
    assert out.read_text() == shown.stdout  # the same plan, to a file or to the screen
    assert checklist.read_text() == done.made.checklist
    plan = read_plan(out)  # the counts, from the file written
    labels = list(plan.labels)
    origin = [x for x in labels if re.fullmatch(r"O(-[0-9]+)?", x)]
    reference0 = [x for x in labels if re.fullmatch(r"R0(-[0-9]+)?", x)]
    assert (done.n_origin, done.n_reference0) == (len(origin), len(reference0)) == (2, 3)
    assert done.n_targets == sum(x.startswith("S") for x in labels) == 4
    assert sorted(done.repeat_labels) == sorted(origin + reference0)


def test_the_simulate_outcome_is_the_truth_written(tmp_path: Path) -> None:
    scenario = CONFIGS / "scenarios" / "serial-capture.yaml"
    out = tmp_path / "s"
    done = simulate_folder(SimulateRequest(out, scenario=scenario, seed=5))
    steps = pd.read_csv(out / "truth" / "steps.csv")
    targets = steps[steps["kind"] == "target"]
    assert len(targets) > 0
    axes = ["Tx", "Ty", "Tz", "Rx", "Ry", "Rz"]
    true = targets[[f"{a}_true_{'mm' if a[0] == 'T' else 'deg'}" for a in axes]].to_numpy()
    corr = targets[[f"{a}_truecorr_{'mm' if a[0] == 'T' else 'deg'}" for a in axes]].to_numpy()
    error = true - corr
    assert [t.label for t in done.targets] == list(targets["label"])
    assert done.n_targets == len(targets) and done.n_steps == len(steps)
    np.testing.assert_allclose(
        [t.translation_um for t in done.targets],
        np.linalg.norm(error[:, :3], axis=1) * 1e3,
        rtol=1e-9,
        atol=1e-9,
    )
    np.testing.assert_allclose(
        [t.rotation_urad for t in done.targets],
        np.radians(np.linalg.norm(error[:, 3:], axis=1)) * 1e6,
        rtol=1e-9,
        atol=1e-9,
    )
    assert {p.relative_to(out) for p in done.written} >= {Path("truth/steps.csv")}


def test_run_interrupted_while_reading_its_files_says_nothing_moved(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def interrupt(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(hexatherm.workflows.run.run, "load_files", interrupt)
    session = tmp_path / "session"
    source = SHIPPED / "paper-zero-pose"
    result = CliRunner().invoke(
        main,
        [
            "run",
            str(source / "plan.yaml"),
            "--cmm",
            "ipp://127.0.0.1:1",
            "--controller",
            "symetrie://127.0.0.1:1",
            "--session",
            str(session),
            "--hexapod",
            str(source / "hexapod.yaml"),
            "--balls",
            str(source / "balls.yaml"),
            "--origin-on-cmm",
            "450,320,210,0,0,15",
        ],
    )
    assert result.exit_code == INTERRUPTED, result.output
    assert (
        "interrupted (Ctrl-C): nothing was moved (the hexapod controller was not contacted); "
        "nothing was written" in result.output
    )
    assert not session.exists()
