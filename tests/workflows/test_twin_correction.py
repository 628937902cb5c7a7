"""Poses corrected by the twin from the thermocouples alone (``process --method twin``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hexatherm.core.effects import ThermocoupleLog, make_effect
from hexatherm.core.twin import twin_corrected
from hexatherm.workflows.process.pipeline import process_session
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session

LAG = make_effect("leg_thermal_lag", NOMINAL_HIDDEN["leg_thermal_lag"])
DRIFT = make_effect("cmm_drift", NOMINAL_HIDDEN["cmm_drift"])


def errors_um(folder: Path, effects: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Translation errors (um) of twin-corrected and reference-corrected targets vs the truth."""
    result = process_session(folder)
    temps = result.temperatures
    assert temps is not None
    log = ThermocoupleLog(temps.time_s, temps.legs_C, temps.others_C.get("air"))
    session = result.session
    twin = twin_corrected(
        session.hexapod,
        session.plan,
        result.centres.times_s,
        log,
        session.balls.centres_mm,
        result.registration.platform2cmm,
        effects,
    )
    truth = pd.read_csv(folder / "truth" / "steps.csv")
    true_corr = truth[[c for c in truth.columns if "_truecorr_" in c]].to_numpy()
    idx = result.correction.target_index
    return (
        (twin[idx] - true_corr[idx])[:, :3] * 1e3,
        (result.correction.corrected - true_corr[idx])[:, :3] * 1e3,
    )


@pytest.mark.parametrize("hidden", [(LAG,), (LAG, DRIFT)], ids=["lag", "lag+drift"])
def test_a_twin_with_the_true_effects_gives_the_true_corrected_poses(
    tmp_path: Path, hidden: tuple
) -> None:
    spec = dataclasses.replace(
        diagnosis_campaign(hidden, 2, n_targets=5),
        point_noise_mm=0.0,
        repeatability_mm=0.0,
        thermocouple_noise_C=0.0,
    )
    write_twin_session(spec, tmp_path / "s")
    twin, _ = errors_um(tmp_path / "s", hidden)
    # what is left: temperatures logged to 1 mK every 30 s, joined by straight lines
    assert np.abs(twin).max() < 0.02
    without, _ = errors_um(tmp_path / "s", ())
    assert np.abs(without).max() > 3.0


def test_a_better_model_pays_off_on_a_noisy_campaign(tmp_path: Path) -> None:
    write_twin_session(diagnosis_campaign((LAG,), 9, n_targets=8), tmp_path / "s")
    with_lag, by_references = errors_um(tmp_path / "s", (LAG,))
    without, _ = errors_um(tmp_path / "s", ())
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    assert rms(with_lag) < 0.25 * rms(without)
    # as good as the references' correction, within the noise of one measured frame
    assert rms(with_lag) < 1.5 * rms(by_references)


def test_process_method_twin_adds_the_twin_columns(tmp_path: Path) -> None:
    import yaml
    from click.testing import CliRunner

    from hexatherm.cli import main
    from hexatherm.workflows.process.outputs import CONTRACT_COLUMNS, pose_columns

    write_twin_session(diagnosis_campaign((LAG,), 6, n_targets=4), tmp_path / "s")
    model = yaml.safe_load((tmp_path / "s" / "hexapod.yaml").read_text())
    model["thermal_model"] = {"effects": [LAG.as_dict()]}
    (tmp_path / "lag.yaml").write_text(yaml.safe_dump(model))
    runner = CliRunner()
    out = tmp_path / "out"
    result = runner.invoke(
        main,
        [
            "process",
            str(tmp_path / "s"),
            "-o",
            str(out),
            "--method",
            "twin",
            "--hexapod",
            str(tmp_path / "lag.yaml"),
        ],
    )
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(out / "poses.csv")
    assert list(poses.columns[:14]) == CONTRACT_COLUMNS
    assert list(poses.columns[14:20]) == pose_columns("twin")
    assert "twin-corrected - commanded" in result.stdout
    truth = pd.read_csv(tmp_path / "s" / "truth" / "steps.csv").set_index("label")
    true_corr = truth.loc[poses["label"], pose_columns("truecorr")[:3]].to_numpy()
    twin_err = poses[pose_columns("twin")[:3]].to_numpy() - true_corr
    conv_err = poses[pose_columns("conv")[:3]].to_numpy() - true_corr
    assert np.sqrt(np.mean(twin_err**2)) < 0.2 * np.sqrt(np.mean(conv_err**2))
    # the session's own hexapod (no lag) is the default model: a worse twin
    plain = runner.invoke(
        main, ["process", str(tmp_path / "s"), "-o", str(tmp_path / "p"), "--method", "twin"]
    )
    assert plain.exit_code == 0, plain.output
    plain_err = (
        pd.read_csv(tmp_path / "p" / "poses.csv")[pose_columns("twin")[:3]].to_numpy() - true_corr
    )
    assert np.sqrt(np.mean(twin_err**2)) < 0.5 * np.sqrt(np.mean(plain_err**2))
    # --hexapod alone is a mistake, not silently ignored
    alone = runner.invoke(
        main,
        [
            "process",
            str(tmp_path / "s"),
            "-o",
            str(tmp_path / "q"),
            "--hexapod",
            str(tmp_path / "lag.yaml"),
        ],
    )
    assert alone.exit_code == 2 and "--method twin" in alone.output
    assert not (tmp_path / "q").exists()
