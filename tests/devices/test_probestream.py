"""The probe-stream record parser and line splitter (no serial port involved)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hexatherm.devices.probestream import (
    MAX_LINE,
    LineSplitter,
    format_number,
    parse_numbers,
    parse_record,
)


@pytest.mark.parametrize(
    ("line", "xyz"),
    [
        (b"X+0123.4567 Y-0001.2345 Z+0456.7890", (123.4567, -1.2345, 456.789)),
        (b"X=1.2 Y=3.4 Z=5.6", (1.2, 3.4, 5.6)),
        (b"1.2,3.4,5.6", (1.2, 3.4, 5.6)),
        (b"  1.2 ; -3.4 ;\t5.6  ", (1.2, -3.4, 5.6)),
        (b"1.2\t3.4\t5.6", (1.2, 3.4, 5.6)),
        (b"x:1.5, y:-2, z:.25", (1.5, -2.0, 0.25)),
        (b"X+ 0012.5000Y- 0003.0000Z+ 0001.0000", (12.5, -3.0, 1.0)),
        (b"X=1.2mm Y=3.4mm Z=5.6mm", (1.2, 3.4, 5.6)),
        (b"1.2 mm, 3.4 mm, 5.6 mm", (1.2, 3.4, 5.6)),
        (b"1.2, 3.4, 5.6 MM", (1.2, 3.4, 5.6)),
        (b"X=1 Y=2 Z=0.5 in", (25.4, 50.8, 12.7)),
        (b'1", 2", 0.5"', (25.4, 50.8, 12.7)),
        ("1000µm 2000µm -500µm".encode(), (1.0, 2.0, -0.5)),
        (b"1e2,-2.5E-1,3", (100.0, -0.25, 3.0)),
        (b"\x02X=1 Y=2 Z=3\x03", (1.0, 2.0, 3.0)),  # STX/ETX framing
        (b"\x00\x00X=1 Y=2 Z=3\x11", (1.0, 2.0, 3.0)),  # NUL padding, XON
    ],
)
def test_accepted_record_formats(line, xyz):
    record = parse_record(line)
    assert record.kind == "point", record
    assert record.xyz_mm == pytest.approx(xyz, abs=1e-12)


def test_default_unit_applies_to_numbers_without_a_suffix():
    assert parse_record(b"1,2,3", default_unit="inch").xyz_mm == pytest.approx((25.4, 50.8, 76.2))
    # an explicit unit wins over the default
    assert parse_record(b"1mm,2mm,3mm", default_unit="inch").xyz_mm == (1.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="unknown unit"):
        parse_record(b"1,2,3", default_unit="furlong")


@pytest.mark.parametrize(
    ("line", "kind"),
    [
        (b"", "blank"),
        (b"\x02\x03", "blank"),
        (b"OK", "text"),
        (b"?POS", "text"),
        (b"> PRINT", "text"),
        (b"MEAS", "text"),
        (b"1.2,3.4", "garbage"),  # two numbers
        (b"1.2,3.4,5.6,7.8", "garbage"),  # four numbers
        (b"1,2;3,4;5,6", "garbage"),  # decimal commas
        (b"X=1 Y=2", "garbage"),
        (b"G1 X10 Y20 Z5", "garbage"),  # an echoed machine command is not a point
        (b"X=1 Y=2 Z=3 W=4", "garbage"),
        (b"1mm 2in 3mm", "garbage"),  # mixed units
        (b"X=1 Y=\x07 2 Z=3", "garbage"),
        (b"\xff\xfe\x80 12 \x9c", "garbage"),
        (b"12.3.4,5,6", "garbage"),
    ],
)
def test_lines_that_are_not_points(line, kind):
    record = parse_record(line)
    assert record.kind == kind
    assert record.xyz_mm is None
    assert record.reason


def test_splitter_cr_lf_crlf_and_mixed():
    splitter = LineSplitter()
    assert splitter.feed(b"a\rb\nc\r\nd\n\re") == [b"a", b"b", b"c", b"d"]
    assert splitter.pending == b"e"
    assert splitter.feed(b"\r\n") == [b"e"]
    assert splitter.pending == b""


def test_splitter_keeps_a_partial_line_until_its_end_arrives():
    splitter = LineSplitter()
    assert splitter.feed(b"X+0001.0000 Y+00") == []
    assert splitter.feed(b"") == []
    assert splitter.pending == b"X+0001.0000 Y+00"
    assert splitter.feed(b"02.0000 Z+0003.0000\r") == [b"X+0001.0000 Y+0002.0000 Z+0003.0000"]
    # the LF of the CRLF comes in the next chunk: no empty line, nothing pending
    assert splitter.feed(b"\n") == []
    assert splitter.pending == b""


def test_splitter_reset_drops_the_partial_line():
    splitter = LineSplitter()
    splitter.feed(b"1,2,3\r\n4,5")
    assert splitter.reset() == b"4,5"
    assert splitter.feed(b",6\r\n") == [b",6"]


def test_splitter_cuts_endless_noise():
    splitter = LineSplitter()
    lines = splitter.feed(b"\xaa" * (2 * MAX_LINE + 10))
    assert [len(line) for line in lines] == [MAX_LINE, MAX_LINE]
    assert len(splitter.pending) == 10


record_lines = st.lists(
    st.one_of(
        st.builds(
            lambda x, y, z: f"X{x:+010.4f} Y{y:+010.4f} Z{z:+010.4f}".encode(),
            *[st.floats(-999, 999, allow_nan=False)] * 3,
        ),
        st.builds(
            lambda x, y, z: f"{x},{y},{z}".encode(), *[st.floats(-1e4, 1e4, allow_nan=False)] * 3
        ),
        st.binary(max_size=40).map(lambda b: b.replace(b"\r", b"").replace(b"\n", b"")),
    ),
    max_size=25,
)


@settings(max_examples=150, deadline=None)
@given(lines=record_lines, ends=st.data(), cuts=st.data())
def test_chunking_never_changes_the_lines_or_the_records(lines, ends, cuts):
    """Any line ends, any chunking: the same lines and the same parse as all at once."""
    stream = b""
    for line in lines:
        stream += line + ends.draw(st.sampled_from([b"\r", b"\n", b"\r\n", b"\n\r"]))
    positions = sorted(cuts.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    chunks = [stream[a:b] for a, b in zip([0, *positions], [*positions, len(stream)], strict=True)]
    splitter = LineSplitter()
    got = [line for chunk in chunks for line in splitter.feed(chunk)]
    assert got == [line for line in lines if line]
    assert splitter.pending == b""
    assert [parse_record(g) for g in got] == [parse_record(line) for line in lines if line]


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=80))
def test_arbitrary_bytes_never_raise(data):
    record = parse_record(data)
    assert record.kind in ("point", "blank", "text", "garbage")
    if record.kind == "point":
        assert record.xyz_mm is not None and len(record.xyz_mm) == 3


@settings(max_examples=200, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False, width=64))
def test_numbers_are_written_to_read_back_exactly(value):
    assert float(format_number(value)) == value
    text = f"{value!r},{value!r},{value!r}"
    if "e" not in text and "inf" not in text:
        assert parse_record(text.encode()).xyz_mm == (value + 0.0,) * 3


def test_temperature_lines():
    assert parse_numbers(b"20.1,20.2,20.3,20.4,20.5,20.6\r") == (20.1, 20.2, 20.3, 20.4, 20.5, 20.6)
    assert parse_numbers("21.0°C 21.1°C 21.2C 21.3 21.4 21.5 19.0 18.5") == (
        21.0,
        21.1,
        21.2,
        21.3,
        21.4,
        21.5,
        19.0,
        18.5,
    )
    assert parse_numbers(b"20.1,20.2,20.3,20.4,20.5") is None
    assert parse_numbers(b"T1=20.1 T2=20.2 T3 T4 T5 T6") is None


@pytest.mark.parametrize(
    "line", [b"X=1e400 Y=0 Z=0", b"1,2,1e999", b"-1e309;0;0", b"X+1e400mm Y0mm Z0mm"]
)
def test_numbers_that_overflow_are_never_a_point(line):
    record = parse_record(line)
    assert record.kind == "garbage" and record.xyz_mm is None
    assert record.reason == "a number overflows (not finite)"


def test_temperature_lines_that_overflow_are_refused():
    assert parse_numbers("20, 20, 20, 20, 20, 1e400") is None
    assert parse_numbers("20, 20, 20, 20, 20, 1e-400") == (20.0,) * 5 + (0.0,)
