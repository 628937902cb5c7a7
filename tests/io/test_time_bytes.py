"""The points reader's shortcuts of issue 37 against the ways they replaced: ISO times
converted from their bytes field by field against pandas' parser (and ``datetime``), the
one-pass blank check against a search for each blank."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np
import pandas as pd
import pytest

from hexatherm.errors import InputError
from hexatherm.io import csvcolumns, csvfile
from hexatherm.io.csvcolumns import ASCII_BLANKS, column_times

LAYOUTS = [
    "%Y-%m-%dT%H:%M:%S.%f",
    "%Y-%m-%d %H:%M:%S",
    "%Y-%m-%dT%H:%M",
    "%Y-%m-%dT%H:%M:%S.%fZ",
    "%Y-%m-%dT%H:%M:%S.%f+02:00",
    "%Y-%m-%dT%H:%M:%S-0530",
    "%Y-%m-%dT%H:%M:%S.%f-11",
]


def times(rng, layout, n=400, digits=6):
    """``n`` random times of ``layout`` (leap days, year ends, 1678-2261), the fraction cut
    to ``digits`` digits (or padded to 9 with random digits)."""
    start = datetime(1678, 1, 1, tzinfo=UTC).timestamp()
    stop = datetime(2261, 12, 31, tzinfo=UTC).timestamp()
    stamps = rng.uniform(start, stop, n)
    fixed = [datetime(2024, 2, 29, 23, 59, 59, 999999, UTC), datetime(2000, 12, 31, tzinfo=UTC)]
    out = []
    for t in [*fixed, *(datetime(1970, 1, 1, tzinfo=UTC) + timedelta(seconds=s) for s in stamps)]:
        text = t.strftime(layout)
        if ".%f" in layout:
            head, tail = text.split(".", 1)
            frac, rest = tail[:6], tail[6:]
            frac = (frac + "".join(rng.choice(list("0123456789"), 3)))[:digits]
            text = f"{head}.{frac}{rest}"
        out.append(text)
    return out


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("digits", [1, 3, 6, 9])
def test_times_from_bytes_are_pandas_seconds(rng, layout, digits):
    values = times(rng, layout, digits=digits)
    frame = pd.DataFrame({"time": np.array(values, dtype=object)}, index=np.arange(len(values)) + 2)
    fast, kind, aware = column_times(frame, "t.csv")
    assert kind == "iso" and aware == (layout.endswith(("Z", "00", "30", "11")))
    text = frame["time"]
    slow, slow_aware = csvcolumns._iso_seconds(text, frame.index.to_numpy(), "t.csv")
    assert slow_aware == aware
    np.testing.assert_array_equal(fast, slow)  # the same seconds, to the bit
    # and pandas' own seconds (its total_seconds, not our rule for them)
    stamps = pd.to_datetime(text, utc=True, format="ISO8601")
    np.testing.assert_array_equal(fast, (stamps - pd.Timestamp(0, tz="UTC")).dt.total_seconds())
    # the shortcut did run: the fields come from the bytes
    block = csvcolumns._iso_block(text.to_numpy(dtype=object))
    assert block is not None and csvcolumns._block_seconds(block[0], block[1]) is not None


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("digits", [1, 6, 9])
@pytest.mark.parametrize("day", ["1969-12-31", "2024-02-29", "2261-12-31", "1678-01-01"])
def test_times_of_one_day_are_pandas_seconds(rng, layout, digits, day):
    """A block whose times share their date (its days converted once, from the first
    row), and the same block with its last time a day later, against pandas to the bit."""
    start = datetime.fromisoformat(day).replace(tzinfo=UTC)
    values = [
        (start + timedelta(seconds=float(s))).strftime(layout)
        for s in np.sort(rng.uniform(0.0, 86399.999999, 300))
    ]
    if ".%f" in layout:  # the fraction cut (or padded) to `digits`
        values = [
            f"{v.split('.', 1)[0]}.{(v.split('.', 1)[1][:6] + '123')[:digits]}"
            f"{v.split('.', 1)[1][6:]}"
            for v in values
        ]
    later = (start + timedelta(days=1, seconds=5)).strftime(layout)
    if ".%f" in layout:
        later = f"{later.split('.', 1)[0]}.{'7' * digits}{later.split('.', 1)[1][6:]}"
    for rows in (values, [*values[:-1], later]):
        if rows[-1].startswith("2262"):
            continue  # beyond pandas' nanoseconds
        text = pd.Series(np.array(rows, dtype=object))
        block = csvcolumns._iso_block(text.to_numpy(dtype=object))
        assert block is not None
        fast = csvcolumns._block_seconds(block[0], block[1])
        assert fast is not None
        stamps = pd.to_datetime(text, utc=True, format="ISO8601")
        np.testing.assert_array_equal(fast, (stamps - pd.Timestamp(0, tz="UTC")).dt.total_seconds())


def test_an_invalid_date_shared_by_every_row_is_left_to_pandas():
    for day in ("2023-02-29", "2024-04-31", "2024-00-10", "2300-01-01"):
        values = [f"{day}T10:00:0{i}" for i in range(5)]
        block = csvcolumns._iso_block(np.array(values, dtype=object))
        assert block is not None and csvcolumns._block_seconds(block[0], block[1]) is None


@pytest.mark.parametrize(
    "bad",
    [
        "2023-02-29T10:00:00",
        "2024-13-01T10:00:00",
        "2024-04-31T10:00:00",
        "2024-01-01T24:00:00",
        "2024-01-01T10:60:00",
        "2024-01-01T10:00:60",
        "2300-01-01T10:00:00",
    ],
)
def test_a_time_out_of_range_is_left_to_pandas_and_datetime(bad):
    """A field out of its range (or a year beyond pandas' nanoseconds) is not converted
    from the bytes: the general conversion decides (an error naming the line, or the
    year 2300's seconds)."""
    values = ["2024-01-01T10:00:00"] * 3 + [bad]
    block = csvcolumns._iso_block(np.array(values, dtype=object))
    assert block is not None and csvcolumns._block_seconds(block[0], block[1]) is None
    frame = pd.DataFrame({"time": np.array(values, dtype=object)}, index=[2, 3, 4, 5])
    if bad.startswith("2300"):
        seconds = column_times(frame, "t.csv")[0]
        assert seconds[-1] == datetime(2300, 1, 1, 10, tzinfo=UTC).timestamp()
    else:
        with pytest.raises(InputError, match="t.csv:5: field 'time': not a valid date"):
            column_times(frame, "t.csv")


def test_blank_check_in_one_pass_finds_every_blank():
    clean = b"label,ball,x\nO,B1,1.5\nS1,B2,2.5\n"
    assert csvfile._blank_free(clean)
    for blank in ASCII_BLANKS:
        for at in (0, 14, len(clean) - 2):
            dirty = clean[:at] + blank.encode() + clean[at:]
            assert not csvfile._blank_free(dirty), (blank, at)
    # control bytes that are not blanks: still blank-free (the search decides)
    assert csvfile._blank_free(clean.replace(b"S1", b"S\x01"))
    monkey = clean * 50
    assert csvfile._blank_free(monkey)


def _points_file(rng, values: list[str], ijk: bool) -> bytes:
    """A points CSV (three steps, two balls) with ``values`` as its times, in order."""
    head = "label,ball,x,y,z,time" + (",i,j,k" if ijk else "")
    rows = []
    for n, value in enumerate(values):
        row = [("O", "R0", "S1")[n * 3 // len(values)], ("B1", "B2")[n % 2]]
        row += [repr(float(v)) for v in rng.normal(100, 50, 3)] + [value]
        row += [f"{v:.4f}" for v in rng.normal(size=3)] if ijk else []
        rows.append(",".join(row))
    return ("\n".join([head, *rows]) + "\n").encode()


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("ijk", [True, False])
@pytest.mark.parametrize("scan", [None, 64, 4096])
def test_times_cut_from_the_file_are_the_parsed_columns(rng, layout, ijk, scan, monkeypatch):
    """The times cut out of a clean file's bytes (pandas then leaves the column out) are
    the seconds, kind and offset of reading the column as text, to the bit, in blocks
    of any size; and the cut is taken."""
    if scan is not None:
        monkeypatch.setattr(csvcolumns, "_TIME_SCAN", scan)
    raw = _points_file(rng, times(rng, layout, n=300, digits=int(rng.integers(1, 10))), ijk)
    columns = 9 if ijk else 6
    cut = csvcolumns.iso_times_from_bytes(raw, 5, columns)
    assert cut is not None
    fast = csvfile._fast_measurement_csv(raw, "p.csv", None)
    monkeypatch.setattr(csvfile, "iso_times_from_bytes", lambda *args: None)
    text = csvfile._fast_measurement_csv(raw, "p.csv", None)
    assert fast is not None and text is not None
    assert (fast.time_kind, fast.time_aware) == (text.time_kind, text.time_aware)
    np.testing.assert_array_equal(fast.time_s, text.time_s)
    np.testing.assert_array_equal(fast.time_s, cut[0])
    for name in ("label", "ball", "xyz_mm", "line"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(text, name))


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("T07:30:01", "T07:30:1"),  # a shorter time
        ("T07:30:01", "T07:30:01Z"),  # another layout
        ("T07:30:01", "T07:30:61"),  # out of range: pandas and datetime say
        ("\nR0,", "\nR0,1,"),  # a field too many
        (",B2,", ",B2"),  # a field too few
        ("\nR0,", "\n\nR0,"),  # a blank line
        ("2024-03-05T07:30:02", "2024-03-05X07:30:02"),
    ],
)
def test_times_not_cut_from_an_unusual_file(rng, old, new):
    """Anything but one ISO layout in full lines is left to pandas' reading of the column."""
    values = [f"2024-03-05T07:30:{s:02d}" for s in range(1, 13)]
    raw = _points_file(rng, values, ijk=False)
    assert csvcolumns.iso_times_from_bytes(raw, 5, 6) is not None
    changed = raw.replace(old.encode(), new.encode(), 1)
    assert changed != raw
    assert csvcolumns.iso_times_from_bytes(changed, 5, 6) is None


def _former_iso_times_from_bytes(raw: bytes, column: int, count: int):
    """``iso_times_from_bytes`` as it was before issue 37's second round (the separators
    told apart by ``np.isin``, every time's bytes gathered index by index): the reference
    the faster cut is held to."""
    data = np.frombuffer(raw, dtype=np.uint8)
    start = raw.find(b"\n") + 1
    if start <= 0 or start >= data.size or not 1 <= column < count:
        return None
    seconds = []
    layout = None
    while start < data.size:
        end = raw.rfind(b"\n", start, start + csvcolumns._TIME_SCAN) + 1
        if end <= start:
            end = raw.find(b"\n", start) + 1
        part = data[start:end]
        found = np.flatnonzero(part <= 44)
        found = found[np.isin(part[found], np.array([44, 10], dtype=np.uint8))]
        if found.size % count:
            return None
        cuts = found.reshape(-1, count)
        if not (part[cuts[:, -1]] == 10).all() or (part[cuts[:, :-1]] == 10).any():
            return None
        first = cuts[:, column - 1] + 1
        width = cuts[0, column] - first[0]
        if width <= 0 or (cuts[:, column] - first != width).any():
            return None
        block = csvcolumns._iso_codes(part[first[:, None] + np.arange(width)])
        if block is None or (layout is not None and block[1:] != layout):
            return None
        layout = block[1:]
        block_seconds = csvcolumns._block_seconds(block[0], layout[0])
        if block_seconds is None:
            return None
        seconds.append(block_seconds)
        start = end
    assert layout is not None
    return np.concatenate(seconds), layout[1]


#: what a hostile edit puts into a clean file: separators, bytes below ',' that a clean
#: file may hold ('+', '!'), a line feed, a digit where a separator was, a longer field
_HOSTILE = [b",", b"\n", b"+", b"!", b"*", b"7", b",,", b"\n\n", b"2024-03-05T07:30:02"]


@pytest.mark.parametrize("seed", range(12))
def test_the_faster_cut_is_the_former_one_on_clean_and_hostile_files(seed, monkeypatch):
    # issue 37 (write10k): the separators told apart by two comparisons instead of
    # np.isin, and each line's time taken as a row of the block's windows; the seconds,
    # the offset flag and every refusal (None) are the former code's, in blocks of any size
    rng = np.random.default_rng(seed)
    monkeypatch.setattr(csvcolumns, "_TIME_SCAN", int(rng.choice([64, 300, 4096, 1 << 21])))
    layout = LAYOUTS[seed % len(LAYOUTS)]
    ijk = bool(seed % 2)
    raw = _points_file(rng, times(rng, layout, n=200, digits=int(rng.integers(1, 10))), ijk)
    columns = 9 if ijk else 6
    cases = [raw]
    for _ in range(30):  # one hostile edit each, anywhere past the header
        at = int(rng.integers(raw.find(b"\n") + 1, len(raw)))
        edit = _HOSTILE[int(rng.integers(len(_HOSTILE)))]
        cases.append(raw[:at] + edit + raw[at + int(rng.integers(0, 3)) :])
    cases.append(raw.replace(b"+", b"-"))  # offsets of the other sign, where there are
    refused = 0
    for case in cases:
        for column, count in ((5, columns), (1, columns), (5, columns + 1)):
            new = csvcolumns.iso_times_from_bytes(case, column, count)
            old = _former_iso_times_from_bytes(case, column, count)
            assert (new is None) == (old is None)
            refused += new is None
            if new is not None and old is not None:
                np.testing.assert_array_equal(new[0], old[0])
                assert new[1] == old[1]
    assert csvcolumns.iso_times_from_bytes(raw, 5, columns) is not None  # the clean file
    assert refused > len(cases)  # the hostile edits were refused, as before


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("scan", [None, 64, 4096])
def test_times_cut_from_the_first_column_are_the_parsed_column(rng, layout, scan, monkeypatch):
    """A thermocouple log's times (its first column) cut from the bytes are the seconds and
    offset flag of reading the column as text (``column_times``), to the bit; a line with
    a field too many or too few, or a time of another layout, is not cut."""
    if scan is not None:
        monkeypatch.setattr(csvcolumns, "_TIME_SCAN", scan)
    values = times(rng, layout, n=150, digits=int(rng.integers(1, 10)))
    temps = rng.normal(20, 0.5, (len(values), 6))
    lines = ["time,leg1,leg2,leg3,leg4,leg5,leg6"]
    lines += [
        ",".join([v, *(f"{t:.3f}" for t in row)]) for v, row in zip(values, temps, strict=True)
    ]
    raw = ("\n".join(lines) + "\n").encode()
    cut = csvcolumns.iso_times_from_bytes(raw, 0, 7)
    assert cut is not None
    frame = pd.DataFrame({"time": np.array(values, dtype=object)}, index=np.arange(len(values)) + 2)
    seconds, kind, aware = column_times(frame, "t.csv")
    np.testing.assert_array_equal(cut[0], seconds)
    assert kind == "iso" and cut[1] == aware
    second = raw.index(b"\n", raw.index(b"\n") + 1) + 1  # the second data line's start
    for changed in (
        raw[:second] + b"1," + raw[second:],  # a field too many
        raw[:-8] + raw[-8:].replace(b",", b"", 1),  # a field too few, on the last line
        raw[:second] + raw[second:].replace(b":", b"-", 1),  # another layout on one line
    ):
        assert csvcolumns.iso_times_from_bytes(changed, 0, 7) is None
