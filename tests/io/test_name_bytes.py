"""The points reader's names cut from the file's bytes (issue 37, io10k) against the way
they replaced: pandas reading the names as categories, spread to the rows."""

from __future__ import annotations

import numpy as np
import pytest

from hexatherm.core.plan import NAME_PATTERN
from hexatherm.io import csvcolumns, csvfile


def test_name_bytes_are_the_name_pattern():
    for code in range(256):
        char = chr(code)
        assert csvcolumns.NAME_BYTES[code] == (NAME_PATTERN.fullmatch(char) is not None), code


def _name(rng, alphabet: str = "ABZaz09-Sx") -> str:
    width = int(rng.choice([1, 2, 3, 7, 8, 9, 15, 16, 17, 40, 64]))
    return "".join(rng.choice(list(alphabet), width))


def _file(rng, rows: int, ijk: bool, runs: bool) -> bytes:
    """A points CSV whose labels and balls come in runs (a step's ball probed point after
    point) or change on every row, of 1 to 64 bytes."""
    labels = [_name(rng) for _ in range(6)]
    balls = [_name(rng) for _ in range(4)]
    head = "label,ball,x,y,z,time" + (",i,j,k" if ijk else "")
    lines = [head]
    for n in range(rows):
        step = n * len(labels) // rows if runs else int(rng.integers(len(labels)))
        ball = (n // 5) % len(balls) if runs else int(rng.integers(len(balls)))
        row = [labels[step], balls[ball]]
        row += [repr(float(v)) for v in rng.normal(100, 50, 3)]
        row += [f"2024-03-05T07:{n // 60 % 60:02d}:{n % 60:02d}.{n % 1000:03d}"]
        row += [f"{v:.4f}" for v in rng.normal(size=3)] if ijk else []
        lines.append(",".join(row))
    return ("\n".join(lines) + "\n").encode()


def _former(raw: bytes, monkeypatch) -> object:
    """The reader before: names read by pandas (the cut from the bytes turned off)."""
    with monkeypatch.context() as patch:
        patch.setattr(csvfile, "times_and_names_from_bytes", lambda *args: None)
        return csvfile._fast_measurement_csv(raw, "p.csv", None)


def _same(new, old) -> None:
    assert (new is None) == (old is None)
    if new is None:
        return
    for name in ("label", "ball", "xyz_mm", "time_s", "line", "ijk"):
        a, b = getattr(new, name), getattr(old, name)
        assert (a is None) == (b is None), name
        if a is not None:
            assert a.dtype == b.dtype, name
            np.testing.assert_array_equal(a, b)
    assert (new.kind, new.time_kind, new.time_aware) == (old.kind, old.time_kind, old.time_aware)


#: hostile edits: separators, bytes names may not hold, a longer name, a blank line
_HOSTILE = [b",", b"\n", b"_", b".", b"+", b"!", b"\x01", b"7", b"-", b"x" * 70, b"\n\n", b",,"]


@pytest.mark.parametrize("seed", range(16))
def test_names_cut_from_the_bytes_are_the_former_names(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    scan = int(rng.choice([64, 300, 4096, 1 << 21]))
    monkeypatch.setattr(csvcolumns, "_TIME_SCAN", scan)
    # blocks of 64 or 300 bytes: 80 rows cross dozens of block edges (more rows cost
    # seconds of the reader's per-block steps and cross no new kind of edge)
    rows = int(rng.integers(1, 400 if scan >= 4096 else 80))
    raw = _file(rng, rows, ijk=bool(seed % 2), runs=seed % 4 < 2)
    cut = csvcolumns.times_and_names_from_bytes(raw, 5, 9 if seed % 2 else 6, (0, 1))
    assert cut is not None  # the clean file is cut
    cases = [raw]
    for _ in range(25):  # one hostile edit each, anywhere past the header
        at = int(rng.integers(raw.find(b"\n") + 1, len(raw)))
        edit = _HOSTILE[int(rng.integers(len(_HOSTILE)))]
        cases.append(raw[:at] + edit + raw[at + int(rng.integers(0, 3)) :])
    for case in cases:
        _same(csvfile._fast_measurement_csv(case, "p.csv", None), _former(case, monkeypatch))


def test_names_are_cut_or_left_to_pandas_by_their_bytes():
    rng = np.random.default_rng(7)
    raw = _file(rng, 50, ijk=False, runs=True)
    label = raw.split(b"\n")[1].split(b",")[0]
    assert csvcolumns.times_and_names_from_bytes(raw, 5, 6, (0, 1)) is not None
    for bad in (b"S_1", b"x" * 65, b"S.1"):
        changed = raw.replace(b"\n" + label + b",", b"\n" + bad + b",", 1)
        assert csvcolumns.times_and_names_from_bytes(changed, 5, 6, (0, 1)) is None
    longest = raw.replace(b"\n" + label + b",", b"\n" + b"y" * 64 + b",", 1)
    cut = csvcolumns.times_and_names_from_bytes(longest, 5, 6, (0, 1))
    assert cut is not None and cut[2][0][0] == "y" * 64 and cut[2][0].dtype == np.dtype("U64")
    # names after the time are not cut (they need not be followed by 16 bytes)
    assert csvcolumns.times_and_names_from_bytes(raw, 1, 6, (0, 2)) is None


#: every blank the reader strips, and bytes below ',' that are not blanks
_BELOW_COMMA = [*(c.encode() for c in csvcolumns.ASCII_BLANKS), b"\x01", b"\x0d", b"!", b"+"]


@pytest.mark.parametrize("seed", range(8))
def test_the_cut_finds_the_blanks_the_former_scan_found(seed, monkeypatch):
    """The cut's ``no_blanks`` (issue 37, p10k) against the former way: a scan of the
    whole file for blanks (``csvfile._blank_free``) before the cut."""
    rng = np.random.default_rng(100 + seed)
    monkeypatch.setattr(csvcolumns, "_TIME_SCAN", int(rng.choice([64, 300, 1 << 21])))
    ijk = bool(seed % 2)
    count = 9 if ijk else 6
    raw = _file(rng, int(rng.integers(1, 80)), ijk=ijk, runs=seed % 4 < 2)
    cases = [raw]
    for _ in range(40):
        at = int(rng.integers(raw.find(b"\n") + 1, len(raw)))
        edit = _BELOW_COMMA[int(rng.integers(len(_BELOW_COMMA)))]
        cases.append(raw[:at] + edit + raw[at + int(rng.integers(0, 2)) :])
    blanks = 0
    for case in cases:
        new = csvcolumns.times_and_names_from_bytes(case, 5, count, (0, 1), True)
        plain = csvcolumns.times_and_names_from_bytes(case, 5, count, (0, 1))
        former = plain if csvfile._blank_free(case) else None
        blanks += not csvfile._blank_free(case)
        assert (new is None) == (former is None)
        if new is not None:
            assert former is not None
            np.testing.assert_array_equal(new[0], former[0])
            assert new[1] == former[1]
            for a, b in zip(new[2], former[2], strict=True):
                np.testing.assert_array_equal(a, b)
        _same(csvfile._fast_measurement_csv(case, "p.csv", None), _former(case, monkeypatch))
    assert blanks >= 10  # the edits put blanks in most cases
