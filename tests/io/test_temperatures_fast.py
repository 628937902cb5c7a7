"""The thermocouple log's fast path gives what the general reader gives: the same log,
or the same error (no timing here: bench/floor.py measures)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.errors import InputError
from hexatherm.io import temperatures
from hexatherm.io.temperatures import Temperatures, read_temperatures


def log_csv(seconds: bool = False, air: bool = True, rows: int = 40, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    head = "time,leg1,leg2,leg3,leg4,leg5,leg6" + (",air" if air else "")
    lines = [head]
    for i in range(rows):
        t = f"{i * 30.0:.1f}" if seconds else f"2024-03-05T07:{30 + i // 2:02d}:{i % 2 * 30:02d}"
        values = rng.normal(20, 0.5, 7 if air else 6)
        lines.append(",".join([t, *(f"{v:.3f}" for v in values)]))
    return "\n".join(lines) + "\n"


def outcome(path: Path, fast: bool, monkeypatch: pytest.MonkeyPatch) -> Temperatures | str:
    with monkeypatch.context() as patch:
        if not fast:
            patch.setattr(temperatures, "_fast_temperatures", lambda text, path: None)
        try:
            return read_temperatures(path)
        except InputError as exc:
            return str(exc)


def check(path: Path, monkeypatch: pytest.MonkeyPatch, takes_fast: bool = False) -> None:
    got, want = outcome(path, True, monkeypatch), outcome(path, False, monkeypatch)
    if takes_fast:
        text = path.read_text(encoding="utf-8")
        assert temperatures._fast_temperatures(text, str(path)) is not None
    if isinstance(want, str):
        assert got == want
        return
    assert isinstance(got, Temperatures)
    assert (got.path, got.time_kind, got.time_aware) == (want.path, want.time_kind, want.time_aware)
    assert np.array_equal(got.time_s, want.time_s)
    assert np.array_equal(got.legs_C, want.legs_C)
    assert got.others_C.keys() == want.others_C.keys()
    for name, values in got.others_C.items():
        assert np.array_equal(values, want.others_C[name])


@pytest.mark.parametrize("seconds", [False, True])
@pytest.mark.parametrize("air", [False, True])
def test_clean_logs_take_the_fast_path(tmp_path, monkeypatch, seconds, air):
    path = tmp_path / "temperatures.csv"
    path.write_text(log_csv(seconds, air))
    check(path, monkeypatch, takes_fast=True)


CLEAN = log_csv()


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("\n2024-03-05T07:30:30,", "\n 2024-03-05T07:30:30,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30 ,"),
        ("\n2024-03-05T07:30:30,", "\n\n2024-03-05T07:30:30,"),
        ("\n2024-03-05T07:30:30,", '\n"2024-03-05T07:30:30",'),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30,1,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30,,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30,nan,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30,293.15,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30,-70,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:29:30,"),
        ("\n2024-03-05T07:30:30,", "\n2024-03-05T07:30:30+01:00,"),
        ("\n2024-03-05T07:30:30,", "\n12.5,"),
        ("\n2024-03-05T07:30:30,", "\n,"),
        ("\n2024-03-05T07:30:30,", "\nyesterday,"),
        (",air\n", ",leg1\n"),
        (",air\n", ",\n"),
        (",air\n", "\n"),
        (",air\n", ",air,extra\n"),
        ("time,leg1", "Time,leg1"),
        ("\n", "\r\n"),
    ],
)
def test_variants_read_as_the_general_reader(tmp_path, monkeypatch, old, new):
    assert old in CLEAN
    path = tmp_path / "temperatures.csv"
    path.write_text(CLEAN.replace(old, new, 1), newline="")
    check(path, monkeypatch)


def test_a_log_cut_short_reads_as_the_general_reader(tmp_path, monkeypatch):
    path = tmp_path / "temperatures.csv"
    lines = CLEAN.splitlines()
    path.write_text("\n".join([*lines[:10], lines[10][:14], *lines[11:]]) + "\n")
    check(path, monkeypatch)


_TOKENS = [",", "\n", " ", '"', "nan", "inf", "-", ".", "e", "T", ":", "0", "9", "\t", "+01:00"]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_fuzz_fast_path_equals_general_reader(tmp_path_factory, data):
    text = list(
        log_csv(seconds=data.draw(st.booleans()), rows=6, seed=data.draw(st.integers(0, 3)))
    )
    for _ in range(data.draw(st.integers(min_value=1, max_value=3))):
        at = data.draw(st.integers(min_value=0, max_value=len(text)))
        if data.draw(st.booleans()):
            del text[at : at + data.draw(st.integers(min_value=1, max_value=8))]
        else:
            text[at:at] = data.draw(st.sampled_from(_TOKENS))
    path = tmp_path_factory.getbasetemp() / "temperatures.csv"
    path.write_text("".join(text), newline="")
    with pytest.MonkeyPatch.context() as monkeypatch:
        check(path, monkeypatch)
