"""The shared writer of result CSVs: fixed decimals per unit, checked against Decimal."""

from __future__ import annotations

from decimal import ROUND_HALF_EVEN, Decimal

import numpy as np
import pandas as pd

from hexatherm.io import csvout
from hexatherm.io.csvfile import centres_to_csv
from hexatherm.io.csvout import RESOLUTION, csv_bytes, csv_text, fixed_text, resolution_of
from hexatherm.io.records import Records
from hexatherm.workflows.replay import DEFAULT_TOLERANCES


def test_fixed_text_rounds_as_decimal_arithmetic_does() -> None:
    # a second method: the exact binary value rounded by Decimal; a true tie (0.0625
    # at 1e-3 is exact in binary) goes to the even neighbour in both
    rng = np.random.default_rng(3)
    values = np.concatenate(
        [
            rng.normal(0, 1, 2000) * 10.0 ** rng.integers(-9, 4, 2000),
            [0.0, -0.0, 5e-8, -5e-8, 0.0625, -0.0625],
        ]
    )
    for step in (1e-7, 1e-4, 1e-3, 1e-6):
        # and values on and about the half steps, where the scaled product may mislead,
        # and beyond 2^50 steps, where the vectorized digits give way to format
        halves = (np.arange(-300, 300) + 0.5) * step
        values = np.concatenate(
            [values, halves, np.nextafter(halves, 0), 2.0**55 * step * np.array([1, -3])]
        )
        quantum = Decimal(1).scaleb(round(np.log10(step)))
        expected = [
            format(Decimal(v).quantize(quantum, ROUND_HALF_EVEN), "f") for v in values.tolist()
        ]
        zero = format(Decimal(0).quantize(quantum), "f")
        expected = [zero if Decimal(e) == 0 else e for e in expected]
        assert fixed_text(values, step) == expected


def test_nan_is_empty_and_inf_as_pandas_writes_it() -> None:
    assert fixed_text(np.array([np.nan, np.inf, -np.inf]), 1e-3) == ["", "inf", "-inf"]


def test_only_float_columns_with_a_unit_are_rounded_and_rounded_false_is_exact() -> None:
    frame = pd.DataFrame(
        {
            "label": ["S1", "S2"],
            "Tx_mm": [1 / 3, -1e-9],
            "n": [25, 3],
            "weight_after": [1 / 3, 0.5],
            "dt_before_s": [1 / 3, np.nan],
            "ok_form": [True, False],
        }
    )
    assert csv_text(frame).splitlines() == [
        "label,Tx_mm,n,weight_after,dt_before_s,ok_form",
        "S1,0.3333333,25,0.3333333333333333,0.3333333333333333,True",
        "S2,0.0000000,3,0.5,,False",
    ]
    exact = pd.read_csv(__import__("io").StringIO(csv_text(frame, rounded=False)))
    assert exact["Tx_mm"].tolist() == [1 / 3, -1e-9]


def test_fit_spheres_centres_are_written_at_the_mm_and_um_resolutions() -> None:
    rec = Records(
        path="p.csv",
        kind="centres",
        label=np.array(["O"]),
        ball=np.array(["B1"]),
        xyz_mm=np.array([[1 / 3, -2 / 3, 1e-12]]),
        time_s=np.array([0.0]),
        time_kind="seconds",
        line=np.array([2]),
        diameter_mm=np.array([25.4 + 1e-9]),
        extra={"form_um": np.array([1 / 7]), "n": np.array([25]), "u_um": np.array([0.25])},
    )
    header, row = centres_to_csv(rec).splitlines()
    assert header == "label,ball,x,y,z,time,diameter,form_um,n,u_um"
    assert row == "O,B1,0.3333333,-0.6666667,0.0000000,0.0,25.4000000,0.1429,25,0.2500"


def test_replay_tolerates_a_value_flipping_one_step() -> None:
    for unit, step in RESOLUTION.items():
        assert DEFAULT_TOLERANCES[unit] >= 1.5 * step * (1 - 1e-12), unit


def _python_fixed(values: np.ndarray, step: float) -> list[str]:
    """The second method of fixed decimals: Python's ``format``, value by value."""
    decimals = round(-np.log10(step))
    texts = [format(v, f".{decimals}f") for v in values.tolist()]
    zero = format(0.0, f".{decimals}f")
    return ["" if t == "nan" else zero if float(t) == 0 else t for t in texts]


def _pandas_text(frame: pd.DataFrame, rounded: bool) -> str:
    """The second method: pandas' to_csv on the frame with its rounded columns as text."""
    frame = frame.copy()
    for column in frame.columns:
        step = resolution_of(column) if rounded else None
        if step is not None and frame[column].dtype == np.float64:
            frame[column] = _python_fixed(frame[column].to_numpy(), step)
    return frame.to_csv(index=False, lineterminator="\n")


def test_the_joined_text_is_what_pandas_writes() -> None:
    rng = np.random.default_rng(5)
    n = 200
    floats = rng.normal(0, 1, n) * 10.0 ** rng.integers(-12, 17, n)
    floats[::17] = np.nan
    floats[5], floats[6] = np.inf, -0.0
    base = {
        "label": [f"S{i}" for i in range(n)],
        "Tx_mm": floats,
        "weight_after": floats[::-1].copy(),
        "n": rng.integers(-5, 5000, n),
        "ok_form": rng.random(n) > 0.5,
        "ok_time_gap": [True, False, ""] * (n // 3) + [True] * (n % 3),
        "failed": ["form;diameter", ""] * (n // 2),
    }
    frames = [
        pd.DataFrame(base),
        pd.DataFrame({**base, "file": ["a,b.csv"] * n}),  # quotes: pandas writes it
        pd.DataFrame({**base, "failed": [None, "form"] * (n // 2)}),  # a missing text
        pd.DataFrame({"Tx_mm": floats}),  # one column
        pd.DataFrame({"label": [], "Tx_mm": []}),  # no rows
        pd.DataFrame({**base, "label": [f"S{i}\u00b5" for i in range(n)]}),  # not ASCII
        pd.DataFrame({**base, "failed": ["a\x00", "b"] * (n // 2)}),  # a NUL: pandas
        pd.DataFrame({**base, "Tx_um": floats * 1e3, "Rx_urad": floats, "x": -floats}),
    ]
    for frame in frames:
        for rounded in (True, False):
            assert csv_text(frame, rounded) == _pandas_text(frame, rounded)
            # the bytes written (process's tables): the text's UTF-8, laid out or pandas'
            assert csv_bytes(frame, rounded) == _pandas_text(frame, rounded).encode("utf-8")


def _former_digits(n: np.ndarray, count: int) -> np.ndarray:
    """``csvout._digits`` as it was before issue 37's second round (each four digits
    gathered as a row of four bytes): the reference the gather of 4-byte words is held to."""
    chunks = -(-count // 4)
    out = np.empty((*n.shape, 4 * chunks), np.uint8)
    rest = n
    for k in range(chunks):
        rest, low = np.divmod(rest, 10000)
        out[..., 4 * (chunks - 1 - k) : 4 * (chunks - k)] = csvout._DIGITS4[low]
    return out[..., 4 * chunks - count :]


def test_digits_as_words_are_the_former_digit_rows() -> None:
    # issue 37 (write10k): every count, every shape the writer gives, the edges of a
    # four-digit chunk and of the 2**50 steps the writer formats itself, and beyond
    rng = np.random.default_rng(37)
    edges = np.array([0, 1, 9, 10, 9999, 10000, 10001, 99_999_999, 2**50 - 1, 2**50, 2**62])
    for count in range(1, 20):
        for shape in ((0,), (1,), (7,), (50, 3), (4, 5, 2)):
            n = rng.integers(0, 2**62, shape) // 10 ** rng.integers(0, 18, shape)
            for values in (n, np.resize(edges, shape)):
                new = csvout._digits(values, count)
                np.testing.assert_array_equal(new, _former_digits(values, count))
                assert new.shape == (*shape, count)
    # and the texts: the last `count` digits, zero padded
    assert bytes(csvout._digits(np.array([1234567]), 9)[0]) == b"001234567"


def _former_field(column: pd.Series) -> tuple[np.ndarray, np.ndarray] | None:
    """``csvout``'s field of a column before issue 37's seventh round: a Python text per
    cell (``_cells``), laid out by ``_text_field``; the reference of ``_column_field``."""
    texts = csvout._cells(column)
    return None if texts is None else csvout._text_field(texts)


def _written(cell: tuple[np.ndarray, np.ndarray] | None) -> list[bytes] | None:
    """Each row's bytes of a field (what the writer takes of it), or None."""
    if cell is None:
        return None
    field, used = cell
    return [bytes(row[mask]) for row, mask in zip(field, used, strict=True)]


def test_column_fields_are_the_former_texts_per_cell() -> None:
    # issue 37 (io10k): flags, whole numbers and pandas' str columns laid out without a
    # text per cell; random and hostile columns against the former writer, cell by cell
    rng = np.random.default_rng(3707)
    n = 300
    words = ["S1", "origin", "R0", "", "a b", "µm", "x,y", 'q"', "line\nbreak", "2024-03-05"]
    columns = [
        pd.Series(rng.random(n) > 0.5),
        pd.Series(np.zeros(n, bool)),
        pd.Series(np.ones(n, bool)),
        pd.Series(rng.integers(-(2**63), 2**63 - 1, n, dtype=np.int64, endpoint=True)),
        pd.Series(np.array([0, -1, 1, 2**63 - 1, -(2**63)] * 60, dtype=np.int64)),
        pd.Series(rng.choice(words[:6], n), dtype="str"),
        pd.Series([f"S{i}" for i in rng.integers(0, 40, n)], dtype="str"),
        pd.Series(rng.choice(words, n), dtype="str"),  # cells to quote: pandas
        pd.Series(["a", None] * (n // 2), dtype="str"),  # a missing text: pandas
        pd.Series(["a\x00", "b"] * (n // 2), dtype="str"),  # a NUL: pandas
        pd.Series([], dtype="str"),
        pd.Series([], dtype=bool),
        pd.Series([], dtype=np.int64),
        pd.Series(rng.choice(words[:3], n), dtype=object),
        pd.Series([True, "ok", False] * (n // 3), dtype=object),
        pd.Series([True, 1, "x"] * (n // 3), dtype=object),  # mixed types: pandas
        pd.Series(np.arange(n, dtype=np.int32)),  # pandas
        pd.Series(rng.normal(size=n)),
    ]
    for column in columns:
        assert _written(csvout._column_field(column)) == _written(_former_field(column)), (
            column.dtype,
            column.head(3).tolist(),
        )
    # whole tables (laid out here; with a cell to quote, by pandas): pandas' bytes
    for count in (7, 8):
        frame = pd.DataFrame({f"c{j}": column for j, column in enumerate(columns[:count])})
        frame["Tx_mm"] = rng.normal(size=n)
        for rounded in (True, False):
            assert csv_text(frame, rounded) == _pandas_text(frame, rounded)


def test_four_digit_table_is_the_formatted_texts() -> None:
    """``_DIGITS4`` made by numpy (issue 37, p10k) against the texts it was made of."""
    from hexatherm.io import csvout

    former = np.frombuffer("".join(f"{i:04d}" for i in range(10000)).encode(), np.uint8)
    np.testing.assert_array_equal(csvout._DIGITS4, former.reshape(10000, 4))
    assert csvout._DIGITS4.dtype == np.uint8 and csvout._DIGITS4.flags.c_contiguous
