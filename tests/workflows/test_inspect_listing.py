"""``inspect``'s listing laid out from the records' arrays is the table pandas wrote
before (``Listing.text``, the former code: the records' DataFrame and its
``to_string``), byte for byte, on points and centres files, ISO times and seconds, a
session's files, and in blocks of a few rows."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io import texttable
from hexatherm.workflows.inspect import Listing, feature_listing, session_reading

SESSIONS = Path(__file__).resolve().parents[2] / "sessions"


def pandas_bytes(listing: Listing) -> bytes:
    return (listing.text() + "\n").encode("ascii")


def same_as_pandas(listing: Listing) -> None:
    blocks = listing.text_blocks()
    assert blocks is not None
    assert b"".join(blocks) == pandas_bytes(listing)
    counted = listing.frame()["type"].value_counts()
    assert listing.counts() == [(str(k), int(n)) for k, n in counted.items()]


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(texttable, "BLOCK_ROWS", 7)


def test_points_centres_and_sessions_list_as_pandas_did() -> None:
    for path in (
        SESSIONS / "serial-capture" / "points.csv",
        SESSIONS / "paper-zero-pose" / "centres.csv",
        SESSIONS / "calibration-campaign" / "centres.csv",
    ):
        same_as_pandas(feature_listing(path))
    for session in ("serial-capture", "paper-zero-pose", "calibration-campaign"):
        _, listing = session_reading(SESSIONS / session)
        assert listing.files
        same_as_pandas(listing)


def test_times_in_seconds_and_negative_coordinates(tmp_path: Path) -> None:
    points = pd.read_csv(SESSIONS / "serial-capture" / "points.csv")
    rng = np.random.default_rng(3)
    points["time"] = np.round(rng.uniform(-5, 5000, len(points)), 3)
    points["x"] = -points["x"]
    points.loc[::7, "z"] = -0.00001
    path = tmp_path / "seconds.csv"
    points.to_csv(path, index=False)
    listing = feature_listing(path)
    assert listing.records[0].time_kind == "seconds"
    same_as_pandas(listing)


def test_names_pandas_would_count_otherwise_go_to_pandas(tmp_path: Path) -> None:
    # a step's name is plain ASCII (the readers refuse others), a file's need not be
    session = tmp_path / "s"
    shutil.copytree(SESSIONS / "serial-capture", session, ignore=shutil.ignore_patterns("expected"))
    (session / "points.csv").rename(session / "pünkte.csv")
    yaml = session / "session.yaml"
    yaml.write_text(yaml.read_text().replace("[points.csv]", "[pünkte.csv]"))
    _, listing = session_reading(session)
    assert listing.text_blocks() is None
    result = CliRunner().invoke(main, ["inspect", str(session)])
    assert result.exit_code == 0, result.output
    assert result.stdout == listing.text() + "\n"


def test_the_command_prints_the_laid_out_table() -> None:
    path = SESSIONS / "serial-capture" / "points.csv"
    result = CliRunner().invoke(main, ["inspect", str(path)])
    assert result.exit_code == 0, result.output
    listing = feature_listing(path)
    assert result.stdout_bytes == pandas_bytes(listing)
    assert f"{len(listing)} features ({len(listing)} POINT)" in result.stderr
