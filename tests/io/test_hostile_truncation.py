"""A file cut anywhere never yields a wrong number (issue 12, item 7).

Property tests: a measurement file (points CSV, DMIS output, through both of each
reader's lanes) is cut at a random byte. Read as it is, it is refused, unless the cut
falls where a complete file could end (a line end of a CSV, after ``ENDFIL``). Read
with ``allow_truncated``, every row it gives is a row of the complete file, number
for number, in order: the record that the cut may have shortened is gone. And the
fast lanes give what the general readers give, warnings included.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.errors import InputError
from hexatherm.io import csvfile, dmis
from hexatherm.io.records import Records


def points_csv(rng: np.random.Generator, rows: int = 24) -> str:
    lines = ["label,ball,x,y,z,time,i,j,k"]
    for r in range(rows):
        xyz = ",".join(repr(float(v)) for v in rng.normal(100, 50, 3))
        ijk = ",".join(repr(float(v)) for v in rng.normal(size=3))
        lines.append(
            f"S{r // 8},B{r // 4 % 2 + 1},{xyz},2024-03-05T07:{r // 60:02d}:{r % 60:02d},{ijk}"
        )
    return "\n".join(lines) + "\n"


def points_dmo(rng: np.random.Generator, rows: int = 24) -> str:
    lines = ["DMISMN/'cut',04.0", "UNITS/MM,ANGDEC", "DATE=2024/03/05"]
    for r in range(rows):
        xyz = ",".join(repr(float(v)) for v in rng.normal(100, 50, 3))
        ijk = ",".join(repr(float(v)) for v in rng.normal(size=3))
        lines += [
            f"TIME=07:{r // 60:02d}:{r % 60:02d}",
            f"FA(S{r // 8}_B{r // 4 % 2 + 1}_{r % 4 + 1})=FEAT/POINT,CART,{xyz},{ijk}",
            f"OUTPUT/FA(S{r // 8}_B{r // 4 % 2 + 1}_{r % 4 + 1})",
        ]
    return "\n".join(lines + ["ENDFIL"]) + "\n"


def general_dmis(path: Path, **options: bool) -> list[Records]:
    text = dmis._read_text(path)
    return dmis.records_from_features(
        dmis.features_from_text(text, path, allow_truncated=options.get("allow_truncated", False)),
        path,
    )


def general_csv(path: Path, **options: bool) -> Records:
    fast = csvfile._fast_measurement_csv
    csvfile._fast_measurement_csv = lambda *args: None  # type: ignore[assignment]
    try:
        return csvfile.read_measurement_csv(path, **options)
    finally:
        csvfile._fast_measurement_csv = fast


def outcome(read, path: Path, **options: bool):
    """(records or error text, warning texts) of one read."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = read(path, **options)
        except InputError as error:
            result = f"InputError: {error}"
    return result, [str(w.message) for w in caught]


def rows(result) -> dict[int, tuple[str, str, tuple[float, ...]]]:
    records = result if isinstance(result, Records) else (result[0] if result else None)
    if records is None:
        return {}
    values = np.column_stack((records.xyz_mm, records.ijk, records.time_s))
    return {
        int(line): (str(label), str(ball), tuple(v.tolist()))
        for line, label, ball, v in zip(
            records.line, records.label, records.ball, values, strict=True
        )
    }


def same(a, b) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    if isinstance(a, Records):
        a, b = [a], [b]
    return len(a) == len(b) and all(rows([x]) == rows([y]) for x, y in zip(a, b, strict=True))


SETTINGS = settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


@SETTINGS
@given(seed=st.integers(0, 3), fraction=st.floats(0, 1), general=st.booleans())
def test_a_cut_dmis_file_is_refused_or_read_without_its_cut_record(
    tmp_path_factory, seed, fraction, general
):
    full = points_dmo(np.random.default_rng(seed))
    if general:
        full = full.replace("\n", " $$ general\n", 1)
    folder = tmp_path_factory.mktemp("cut")
    complete = folder / "complete.dmo"
    complete.write_text(full)
    truth = rows(dmis.read_dmis(complete))
    cut = int(fraction * len(full))
    path = folder / "cut.dmo"
    path.write_text(full[:cut])
    strict, strict_warnings = outcome(dmis.read_dmis, path)
    after_endfil = full[:cut].rstrip().endswith("ENDFIL")
    assert isinstance(strict, str) != after_endfil, strict
    assert strict_warnings == []
    assert same(strict, outcome(general_dmis, path)[0])
    loose, loose_warnings = outcome(dmis.read_dmis, path, allow_truncated=True)
    assert not isinstance(loose, str), loose
    kept = rows(loose)
    assert all(truth[line] == row for line, row in kept.items())  # no number changed
    assert list(kept) == sorted(truth)[: len(kept)]  # a prefix of the file's records
    if not after_endfil:
        assert len(loose_warnings) == (1 if full[:cut].strip() else 0)  # the last one dropped
    want, want_warnings = outcome(general_dmis, path, allow_truncated=True)
    assert same(loose, want) and loose_warnings == want_warnings


@SETTINGS
@given(seed=st.integers(0, 3), fraction=st.floats(0, 1), general=st.booleans())
def test_a_cut_csv_file_is_refused_or_read_without_its_cut_row(
    tmp_path_factory, seed, fraction, general
):
    full = points_csv(np.random.default_rng(seed))
    folder = tmp_path_factory.mktemp("cut")
    complete = folder / "points.csv"
    complete.write_text(full)
    truth = rows(csvfile.read_measurement_csv(complete))
    cut = int(fraction * len(full))
    text = full[:cut]
    path = folder / "cut-points.csv"
    path.write_text(text)
    read = general_csv if general else csvfile.read_measurement_csv
    strict, _ = outcome(read, path)
    at_line_end = text.endswith("\n") and text.count("\n") >= 2
    assert isinstance(strict, str) != at_line_end, strict
    if isinstance(strict, str):
        assert strict.startswith(f"InputError: {path}:")
    else:
        assert rows(strict) == {line: truth[line] for line in rows(strict)}
    loose, _ = outcome(read, path, allow_truncated=True)
    if isinstance(loose, str):  # nothing left but the header, or less
        assert text.count("\n") <= 1, loose
        return
    kept = rows(loose)
    assert kept and all(truth[line] == row for line, row in kept.items())
    assert list(kept) == sorted(truth)[: len(kept)]
    assert same(loose, outcome(general_csv, path, allow_truncated=True)[0])
