"""Times with a UTC offset in the inputs come out with one (issue 16, item 2): never as a
UTC time without an offset, which reads as local time (2 h off for +02:00 inputs)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from hexatherm.cli import main
from tests.shipped import SHIPPED

ROOT = Path(__file__).resolve().parents[2]
STAMP = re.compile(r"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?)")


def naive_copy(folder: Path) -> Path:
    """paper-zero-pose without its ``utc_offset:``: its times as a CMM's clock gives them."""
    shutil.copytree(SHIPPED / "paper-zero-pose", folder, ignore=shutil.ignore_patterns("results"))
    text = (folder / "session.yaml").read_text()
    assert 'utc_offset: "+00:00"\n' in text
    (folder / "session.yaml").write_text(text.replace('utc_offset: "+00:00"\n', ""))
    return folder


def test_offsets_survive_processing_and_naive_times_stay_naive(tmp_path: Path) -> None:
    naive = naive_copy(tmp_path / "naive")
    aware = tmp_path / "aware"
    shutil.copytree(naive, aware)
    for name in ("centres.csv", "temperatures.csv"):
        text = (aware / name).read_text()
        (aware / name).write_text(STAMP.sub(r"\1+02:00", text))
    for session in (naive, aware):
        result = CliRunner().invoke(main, ["process", str(session)])
        assert result.exit_code == 0, result.output
    plain = pd.read_csv(naive / "results" / "poses.csv")
    zoned = pd.read_csv(aware / "results" / "poses.csv")
    assert not plain["time"].str.contains(r"[+Z]").any()  # no offset was known: none made up
    assert zoned["time"].str.endswith("+00:00").all()
    # the same instants: a clock reading at +02:00 is two hours earlier in UTC
    shifted = pd.to_datetime(plain["time"]) - pd.Timedelta(hours=2)
    instants = pd.to_datetime(zoned["time"], utc=True).dt.tz_localize(None)
    assert (instants == shifted).all()
    assert pd.to_datetime(zoned["time"]).dt.tz is not None  # opens tz-aware in pandas
    legs = pd.read_csv(aware / "results" / "legs.csv")
    assert legs["time"].str.endswith("+00:00").all()


def test_a_session_can_say_where_its_naive_times_were_taken(tmp_path: Path) -> None:
    naive = naive_copy(tmp_path / "naive")
    local = tmp_path / "local"
    shutil.copytree(naive, local)
    text = (local / "session.yaml").read_text()
    (local / "session.yaml").write_text(text + 'utc_offset: "+01:00"\n')
    for session in (naive, local):
        result = CliRunner().invoke(main, ["process", str(session)])
        assert result.exit_code == 0, result.output
    plain = pd.read_csv(naive / "results" / "poses.csv")
    zoned = pd.read_csv(local / "results" / "poses.csv")
    instants = pd.to_datetime(zoned["time"], utc=True).dt.tz_localize(None)
    assert (instants == pd.to_datetime(plain["time"]) - pd.Timedelta(hours=1)).all()
    numbers = [c for c in plain.columns if c.endswith(("_mm", "_deg", "_um", "_urad"))]
    pd.testing.assert_frame_equal(zoned[numbers], plain[numbers])  # one shift of every clock
    (local / "session.yaml").write_text(text + "utc_offset: 1\n")
    bad = CliRunner().invoke(main, ["process", str(local), "--overwrite"])
    assert bad.exit_code == 1 and "field 'utc_offset'" in bad.output


def test_a_simulated_session_declares_its_clock_and_its_times_open_tz_aware(
    tmp_path: Path,
) -> None:
    """The twin's clock is UTC: simulate says so, so process's times carry +00:00 and
    are the twin's own step times (truth/steps.csv, written naive) as instants."""
    scenario = ROOT / "configs" / "scenarios" / "calibration-campaign.yaml"
    session = tmp_path / "twin"
    runner = CliRunner()
    result = runner.invoke(main, ["simulate", str(scenario), "-o", str(session)])
    assert result.exit_code == 0, result.output
    assert yaml.safe_load((session / "session.yaml").read_text())["utc_offset"] == "+00:00"
    result = runner.invoke(main, ["process", str(session), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    poses = pd.read_csv(tmp_path / "out" / "poses.csv")
    times = pd.to_datetime(poses["time"])
    assert times.dt.tz is not None
    truth = pd.read_csv(session / "truth" / "steps.csv").set_index("label")
    expected = pd.to_datetime(truth.loc[poses["label"], "time"]).dt.tz_localize("UTC")
    assert (times.to_numpy() == expected.to_numpy()).all()


@pytest.mark.parametrize(
    "session", sorted(p.parent.parent.name for p in SHIPPED.glob("*/expected/poses.csv"))
)
def test_every_shipped_poses_file_opens_with_floats_and_tz_aware_times(session: str) -> None:
    """What ``process`` writes for the shipped sessions (``expected/``, which replay holds
    equal to it) opens in pandas as it should: every number with a unit as float64, the
    deviation columns equal (pose - commanded) to the file's resolution, times tz-aware."""
    poses = pd.read_csv(SHIPPED / session / "expected" / "poses.csv")
    with_unit = [c for c in poses.columns if c.rsplit("_", 1)[-1] in ("mm", "deg", "um", "urad")]
    assert len(with_unit) > 30
    assert all(poses[c].dtype == "float64" for c in with_unit), poses.dtypes[with_unit]
    assert poses["label"].map(type).eq(str).all()
    times = pd.to_datetime(poses["time"])
    assert str(times.dt.tz) == "UTC"
    for kind in ("conv", "corr"):
        # half a step of the pose (1e-7 mm or deg) and of the deviation (1e-4 um, 1e-3 urad)
        for axis, unit, scale, tolerance in (
            ("Tx", "mm", 1e3, 0.5e-4 + 0.5e-4),
            ("Rz", "deg", np.pi / 180 * 1e6, 0.5e-7 * np.pi / 180 * 1e6 + 0.5e-3),
        ):
            pose = poses[f"{axis}_{kind}_{unit}"] - poses[f"{axis}_cmd_{unit}"]
            deviation = poses[f"d{axis}_{kind}_{'um' if unit == 'mm' else 'urad'}"]
            assert (pose * scale - deviation).abs().max() <= tolerance * 1.001
