"""The DMIS reader's fast lane reads a file a chunk of lines at a time (issue 37, item 2).

What is in effect where a chunk starts (``UNITS``, ``DATE``, ``TIME``) comes from the
chunks before it, a label column widens when a later chunk has longer labels, and a file
cut short is cut where the whole file would be: with chunks of a few bytes, the records,
errors and warnings are those of the general reader, which reads the whole text. And the
memory the fast lane takes is the records' and a chunk's, not the file's text.
"""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.io import dmis
from hexatherm.io.records import Records
from tests.io.test_hostile_truncation import outcome
from tests.io.test_speed_paths import assert_same_records, mutated_dmis, points_dmo

CHUNKS = [1, 2, 7, 64, 301, 1 << 22]


def general(path: Path, allow_truncated: bool = False) -> list[Records]:
    text = dmis._read_text(path)
    features = dmis.features_from_text(text, path, allow_truncated=allow_truncated)
    return dmis.records_from_features(features, path)


def assert_reads_as_general(path: Path, chunk: int, allow_truncated: bool = False) -> None:
    saved = dmis._CHUNK_BYTES
    dmis._CHUNK_BYTES = chunk
    try:
        got, got_warnings = outcome(dmis.read_dmis, path, allow_truncated=allow_truncated)
    finally:
        dmis._CHUNK_BYTES = saved
    want, want_warnings = outcome(general, path, allow_truncated=allow_truncated)
    if isinstance(got, str) or isinstance(want, str):
        assert got == want
    else:
        assert_same_records(got, want)
    assert got_warnings == want_warnings


def long_session(tmp_path: Path, newline: str = "\r\n", points: int = 4) -> Path:
    """Points of 12 steps (labels O, S1 ... S11: the label column widens), 2 balls of
    ``points`` points, inches, one DATE at the top: what is in effect comes from far
    before most chunks."""
    text = points_dmo(n_steps=12, balls=2, points=points).replace("UNITS/MM", "UNITS/INCH")
    lines = text.split("\r\n")
    dates = [n for n, line in enumerate(lines) if line.startswith("DATE=")]
    for n in dates[1:]:
        lines[n] = ""  # blank: the first DATE stays in effect
    path = tmp_path / "long.dmo"
    path.write_bytes(newline.join(lines).encode())
    return path


@pytest.mark.parametrize("chunk", CHUNKS)
@pytest.mark.parametrize("newline", ["\r\n", "\n"])
def test_chunks_read_as_the_whole_text(tmp_path, chunk, newline):
    path = long_session(tmp_path, newline)
    assert dmis._fast_records(path.read_bytes(), path) is not None  # the fast lane reads it
    assert_reads_as_general(path, chunk)
    records = dmis.read_dmis(path)
    assert records[0].label.dtype == np.dtype("<U3")  # S11
    assert records[0].xyz_mm[0, 0] == pytest.approx(float(path.read_text().split(",")[4]) * 25.4)


@pytest.mark.parametrize("chunk", CHUNKS)
def test_chunks_keep_context_read_one_by_one(tmp_path, chunk):
    """UNITS, DATE and TIME that the general parser reads (other spellings) carry over too,
    and so do the spheres read one by one."""
    text = points_dmo(n_steps=3, balls=2, points=3)
    text = text.replace("UNITS/MM,ANGDEC", " units / cm , angdec", 1)
    text = text.replace("DATE=2024/03/05", "date = '2024-03-05'", 1)
    text = text.replace("TIME=07:00:02", "Time=7:00:02.5", 1)
    text = text.replace("OUTPUT/FA(O_B1_3)", "FA(O_B1)=FEAT/SPHERE,OUTER,CART,1,2,3,25.4", 1)
    path = tmp_path / "mixed.dmo"
    path.write_text(text)
    assert dmis._fast_records(path.read_bytes(), path) is not None
    assert_reads_as_general(path, chunk)


def cut_ends(full: bytes) -> dict[str, int]:
    """Where to cut a points file that ends ``... TIME, FA, OUTPUT, ENDFIL``, by what the
    cut leaves: its last line cut inside, or ended by its CR alone, or whole (a chunk
    that lacks its line end, ends in CR, ends in LF), and of the last record the blank
    line before it (a DATE blanked), its TIME,
    its FA line (in the last chunk), its OUTPUT (the FA line in an earlier chunk when the
    chunks are lines), then all of it and part of ENDFIL."""
    time_at = full.rindex(b"\r\nTIME=") + 2
    fa_at = full.index(b"\r\n", time_at) + 2
    fa_end = full.index(b"\r\n", fa_at)
    output_end = full.index(b"\r\n", fa_end + 2)
    endfil_at = full.rindex(b"ENDFIL")
    return {
        "the CR of the blank line before it": time_at - 1,
        "inside the last TIME": time_at + 7,
        "inside the last FA's label": fa_at + 6,
        "inside the last FA's numbers": (fa_at + fa_end) // 2,
        "the last FA line and its CR": fa_end + 1,
        "the last FA line": fa_end + 2,
        "inside the last OUTPUT": fa_end + 10,
        "the last OUTPUT and its CR": output_end + 1,
        "the last record, no ENDFIL": endfil_at,
        "inside ENDFIL": endfil_at + 4,
    }


@pytest.mark.parametrize("chunk", [5, 64, 1 << 22])
def test_a_cut_file_is_cut_where_the_whole_file_is(tmp_path, chunk):
    """At each end of :func:`cut_ends`, and in one chunk at every 7th end of the last 200
    bytes too: the records, error and warnings of the general reader.

    With small chunks (every line a chunk, or a few lines) the file has one point a
    ball: a read takes a few milliseconds a chunk, and what a cut tests is the file's
    end and the context carried to it, which 24 records carry as 96 do (the chunks'
    context over the longer file: :func:`test_chunks_read_as_the_whole_text`). The ends
    are those a chunk can end on (inside a line, on its CR, on its line end) in every
    part of the last record, where every 29th end of the last 200 bytes fell inside
    lines only.

    Chunks of 5 bytes stand for 1 byte too: either way a chunk ends at every line end
    read (5 bytes may also take a blank line after it), and what follows the file's last
    line end, where it is cut, is the same last chunk; the whole file is read in chunks
    of 1 byte by :func:`test_chunks_read_as_the_whole_text`."""
    small = chunk < 1 << 20
    full = long_session(tmp_path, points=1 if small else 4).read_bytes()
    ends = sorted(set(cut_ends(full).values()))
    if not small:
        ends += range(len(full) - 200, len(full), 7)
    path = tmp_path / "cut.dmo"
    for end in ends:
        path.write_bytes(full[:end])
        for allow in (False, True):
            assert_reads_as_general(path, chunk, allow_truncated=allow)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=mutated_dmis(), chunk=st.sampled_from(CHUNKS), allow=st.booleans())
def test_fuzz_chunked_fast_lane_equals_general_reader(tmp_path_factory, data, chunk, allow):
    path = tmp_path_factory.getbasetemp() / "fuzz-chunks.dmo"
    path.write_bytes(data)
    assert_reads_as_general(path, chunk, allow_truncated=allow)


def test_memory_is_the_records_and_a_chunk_not_the_text(tmp_path, monkeypatch):
    """Traced peak of a read beyond the records it returns: under a third of the file
    (chunks of 16 KiB; reading the whole text, as the reader did, takes more than two
    files' worth)."""
    path = tmp_path / "big.dmo"
    path.write_text(points_dmo(n_steps=40, balls=3, points=100))
    size = path.stat().st_size
    assert size > 2_000_000
    monkeypatch.setattr(dmis, "_CHUNK_BYTES", 1 << 14, raising=False)
    monkeypatch.setattr(dmis, "_COLUMN_BYTES", 1 << 16, raising=False)
    warm = tmp_path / "warm.dmo"  # imports done, on a file as short as they need
    warm.write_text(points_dmo(n_steps=2, balls=3, points=5))
    dmis.read_dmis(warm)
    tracemalloc.start()
    try:
        records = dmis.read_dmis(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    (points,) = records
    assert len(points) == 40 * 3 * 100
    kept = sum(
        array.nbytes
        for array in (points.label, points.ball, points.xyz_mm, points.time_s, points.line)
    )
    kept += points.ijk.nbytes + points.extra["n"].nbytes
    assert peak - kept < size / 3, (peak, kept, size)
