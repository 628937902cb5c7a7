"""A noise-free session the twin explains exactly, with constant air: an air-driven effect
moves no prediction there. Its fit used to feed NaN steps to the trust region and end
in a traceback; now it keeps its start and nothing is added."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from hexatherm.cli import main

ROOT = Path(__file__).resolve().parents[2]
MAT = "{gain_C: 3.0, tau_s: 2400, power: [[300, null]]}"
SCENARIO = f"""format: hexatherm-scenario/1
hexapod: {ROOT / "configs" / "symetrie-like.yaml"}
balls: {ROOT / "configs" / "balls-3.yaml"}
plan: {{targets: [[5, 0, 0, 0, 0, 0], [0, 5, 0, 1, 0, 0], [0, 0, 5, 0, 1, 0]],
        reference_pose: [0, 0, -40, 0, 0, 0], cycles: 3}}
heating: {{mats: [{", ".join([MAT] * 6)}]}}
"""


def test_a_noise_free_session_with_constant_air_is_diagnosed_without_error(
    tmp_path: Path,
) -> None:
    (tmp_path / "scenario.yaml").write_text(SCENARIO)
    made = CliRunner().invoke(
        main, ["simulate", str(tmp_path / "scenario.yaml"), "-o", str(tmp_path / "s")]
    )
    assert made.exit_code == 0, made.output
    result = CliRunner().invoke(main, ["diagnose", str(tmp_path / "s"), "-o", str(tmp_path / "d")])
    assert result.exit_code == 0, result.output
    assert "nothing passes: the model is kept as it is" in result.stdout
