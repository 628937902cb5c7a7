"""Text tables laid out as bytes (``io/texttable.py``) are pandas' ``to_string``, byte for
byte: pandas itself is the second method, on random and hostile columns, in blocks of
1, 3 and more rows."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hexatherm.io.records import seconds_to_iso_texts
from hexatherm.io.texttable import (
    FloatColumn,
    IntColumn,
    IsoColumn,
    TextColumn,
    text_column,
    text_table,
)


def pandas_text(frame: pd.DataFrame) -> bytes:
    """What ``hexatherm inspect`` printed before: pandas' table and ``echo``'s line break."""
    text = frame.to_string(index=False, na_rep="", float_format=lambda v: f"{v:.4f}")
    return (text + "\n").encode("ascii")


def laid_out(columns: list[tuple[str, object]], rows: int, block_rows: int) -> bytes:
    return b"".join(text_table(columns, rows, block_rows))  # type: ignore[arg-type]


def hostile_floats(rng: np.random.Generator, n: int) -> np.ndarray:
    """Magnitudes from 1e-9 to 1e17, both signs, half steps of the 4th decimal and
    their neighbours, zeros of both signs, NaN and infinities."""
    halves = (np.round(rng.uniform(-1000, 1000, n) * 2e4) + 1) / 2e4
    pool = np.concatenate(
        [
            rng.uniform(-600, 600, n),
            rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-9, 17, n),
            halves,
            np.nextafter(halves, np.inf),
            np.nextafter(halves, -np.inf),
            rng.uniform(-0.00006, 0.00006, n),
            [0.0, -0.0, np.nan, np.inf, -np.inf, 9999.99995, -9999.99995, 0.00005, -0.00005],
        ]
    )
    return rng.choice(pool, n)


@pytest.mark.parametrize("seed", range(12))
def test_random_tables_are_pandas_own_text(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 400))
    names = ["O_B1", "R0_B2", "T12_B3", "x", "a long label_of_a_step", "", " lead", "a b"]
    codes = rng.integers(0, len(names), n)
    floats = [hostile_floats(rng, n) for _ in range(3)]
    # a column of one kind of number each: the ordinary, all NaN, small, huge
    scale = [1.0, np.nan, 1e-3, 1e12][seed % 4]
    floats.append(rng.uniform(-1, 1, n) * scale)
    ints = rng.integers(-(10 ** int(rng.integers(0, 18))), 10 ** int(rng.integers(1, 18)), n)
    seconds = rng.uniform(0, 4e9, n)
    frame = pd.DataFrame(
        {
            "line": ints,
            "label": np.array(names)[codes],
            "type": "POINT",
            **{f"f{k}": v for k, v in enumerate(floats)},
            "time": seconds_to_iso_texts(seconds),
            "seconds": seconds,
        }
    )
    label = text_column(names, codes, n)
    assert label is not None
    columns = [
        ("line", IntColumn(ints)),
        ("label", label),
        ("type", TextColumn(["POINT"], None, n)),
        *((f"f{k}", FloatColumn(v)) for k, v in enumerate(floats)),
        ("time", IsoColumn(seconds)),
        ("seconds", FloatColumn(seconds)),
    ]
    expected = pandas_text(frame)
    for block_rows in (1, 3, 64, 1000):
        assert laid_out(columns, n, block_rows) == expected


def test_integer_extremes_and_texts_no_row_uses() -> None:
    ints = np.array([0, -1, 9, 10, -10, 2**63 - 1, -(2**63), 7])
    texts = ["a", "bb", "a much longer text than any row's"]
    codes = np.array([0, 1, 0, 1, 0, 1, 0, 0])
    frame = pd.DataFrame({"n": ints, "s": np.array(texts)[codes]})
    columns = [("n", IntColumn(ints)), ("s", TextColumn(texts, codes, 8))]
    for block_rows in (1, 5, 8):
        assert laid_out(columns, 8, block_rows) == pandas_text(frame)


def test_times_before_1970_are_written_by_datetime() -> None:
    seconds = np.array([-86400.0 * 365.25 * 30, 0.0, 1.7e9, -0.5])
    frame = pd.DataFrame({"time": seconds_to_iso_texts(seconds)})
    assert laid_out([("time", IsoColumn(seconds))], 4, 2) == pandas_text(frame)


def test_texts_pandas_escapes_or_counts_otherwise_are_left_to_it() -> None:
    for texts in (["a\tb"], ["a\nb"], ["a\rb"], ["Öse"], ["ok", "步"]):
        assert text_column(texts, None, 1) is None
    assert text_column(["ok", "a\\b", "x;y"], None, 1) is not None
