"""``plan --calibration N`` (issue 15, item 5): N targets kept from the candidates by
D-optimality beat N random ones on the worst predicted pose uncertainty; candidates that
cannot identify the level are refused, naming why."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.core.calibration import predicted_sigma
from hexatherm.io.config import read_hexapod, read_plan

ROOT = Path(__file__).resolve().parents[2]
HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BASE = ["plan", "--hexapod", str(HEXAPOD), "--balls", str(ROOT / "configs" / "balls-3.yaml")]
BOX = ["--box", "Tx=-20:20", "--box", "Ty=-20:20", "--box", "Tz=-15:15"]
ROT = ["--box", "Rx=-4:4", "--box", "Ry=-4:4", "--box", "Rz=-8:8"]


def test_the_chosen_targets_beat_random_ones(tmp_path: Path) -> None:
    args = [*BASE, "--random", "200", "--seed", "3", *BOX, *ROT]
    everything = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "all.yaml")])
    assert everything.exit_code == 0, everything.output
    chosen = CliRunner().invoke(
        main, [*args, "--calibration", "30", "-o", str(tmp_path / "c.yaml")]
    )
    assert chosen.exit_code == 0, chosen.output
    plan = read_plan(tmp_path / "c.yaml")
    candidates = read_plan(tmp_path / "all.yaml")
    picked = plan.poses[plan.target_indices]
    pool = candidates.poses[candidates.target_indices]
    assert len(picked) == 30
    # every chosen target is one of the candidates, and the message numbers them
    assert all(np.any(np.all(np.isclose(pool, p), axis=1)) for p in picked)
    numbers = re.search(r"kept 30 of the candidates \(([\d, ]+)", chosen.stderr)
    assert numbers is not None
    indices = [int(k) - 1 for k in numbers.group(1).split(", ")]
    np.testing.assert_allclose(pool[indices], picked)
    # the worst predicted sigma over the candidates, against the first 30 random ones
    nominal = read_hexapod(HEXAPOD)
    worst = predicted_sigma(nominal, picked, pool)[:, :3].max()
    random_worst = predicted_sigma(nominal, pool[:30], pool)[:, :3].max()
    assert random_worst / worst >= 1.5
    assert f"at most {worst:.2f} um" in chosen.stderr
    # one O and one R0 limit a calibration from corrected poses: the user is told
    assert "note: O and R0 are measured once" in chosen.stderr
    repeats = ["--origin-repeats", "4", "--reference0-repeats", "4"]
    out = tmp_path / "r.yaml"
    repeated = CliRunner().invoke(main, [*args, "--calibration", "30", *repeats, "-o", str(out)])
    assert repeated.exit_code == 0, repeated.output
    assert "measured once" not in repeated.stderr
    assert read_plan(out).labels.count("R0-4") == 1


def test_translation_only_candidates_are_refused_with_the_reason(tmp_path: Path) -> None:
    out = tmp_path / "c.yaml"
    args = [*BASE, "--random", "100", "--seed", "3", *BOX, "--calibration", "30", "-o", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 1, result.output
    assert "rank 24 of 42" in result.output and "Rx, Ry, Rz" in result.output
    assert not out.exists()


def test_the_criterion_is_the_users_and_the_gain_over_random_is_printed(tmp_path: Path) -> None:
    args = [*BASE, "--random", "120", "--seed", "5", *BOX, *ROT, "--calibration", "12"]
    out = tmp_path / "i.yaml"
    result = CliRunner().invoke(
        main, [*args, "--calibration-criterion", "i-optimal", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    everything = tmp_path / "all.yaml"
    assert CliRunner().invoke(main, [*BASE, "--random", "120", "--seed", "5", *BOX, *ROT,
                                     "-o", str(everything)]).exit_code == 0  # fmt: skip
    plan, pool_plan = read_plan(out), read_plan(everything)
    pool = pool_plan.poses[pool_plan.target_indices]
    sigma = predicted_sigma(read_hexapod(HEXAPOD), plan.poses[plan.target_indices], pool)
    worst, rms = sigma[:, :3].max(), np.sqrt(np.mean(sigma[:, :3] ** 2))
    line = re.search(r"design \(i-optimal\): .* at most ([\d.]+) um, ([\d.]+) um RMS; "
                     r"12 random candidates \(median of 20 draws\): ([\d.]+) um, ([\d.]+) um RMS "
                     r"\(([\d.]+)x, ([\d.]+)x", result.stderr)  # fmt: skip
    assert line is not None, result.stderr
    assert float(line.group(1)) == round(worst, 2) and float(line.group(2)) == round(rms, 2)
    assert float(line.group(6)) > 1.0  # the design beats random choices on the mean
    bad = CliRunner().invoke(main, [*args, "--calibration-criterion", "a-optimal"])
    assert bad.exit_code == 2
