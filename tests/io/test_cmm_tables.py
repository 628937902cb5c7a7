"""What CMM software exports, read as a session's measurements: Zeiss Calypso table
files (a folder of runs) and any table through a column map in ``session.yaml``.

The held-out check: the shipped twin session ``paper-zero-pose`` (simulated by the
twin, ``sessions/make_paper_zero_pose.py``) written as Calypso runs and as a foreign
table (``;``, decimal comma, inch) gives the poses of its centres CSV, to the files'
resolution. Then the hostile variants, each refused in one line naming file, line and
field.
"""

from __future__ import annotations

import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from hexatherm.errors import InputError, InputWarning, PlanError
from hexatherm.io.config import read_plan, read_session
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.files import MAX_MEASUREMENT_BYTES
from hexatherm.io.measurements import read_measurements
from hexatherm.io.records import Records
from hexatherm.workflows.process.pipeline import ProcessResult, process_session
from tests.io.cmmexports import INCH_MM, step_times, write_calypso, write_foreign_table
from tests.shipped import SHIPPED as SHIPPED_SESSIONS

ROOT = Path(__file__).resolve().parents[2]
FEATURES = {"B1": "Kugel_1", "B2": "Kugel_2", "B3": "Kugel_3"}
CALYPSO = (
    "measurements:\n"
    "  - {file: calypso, format: calypso, step_field: partnb, encoding: latin-1,\n"
    "     balls: {Kugel_1: B1, Kugel_2: B2, Kugel_3: B3}}\n"
)
TABLE = (
    "measurements:\n"
    "  - file: export.csv\n"
    "    columns: {feature: Merkmal, x: X, y: Y, z: Z, diameter: Durchmesser,\n"
    "              time: [Datum, Uhrzeit]}\n"
    "    feature_pattern: '(?P<step>[^.]+)\\.(?P<ball>.+)'\n"
    "    delimiter: ';'\n"
    "    decimal: ','\n"
    "    unit: inch\n"
    "    time_format: '%d.%m.%Y %H:%M:%S'\n"
)


def make(tmp_path: Path, measurements: str, name: str = "s") -> Path:
    """The twin session copied, its measurements replaced by ``measurements``."""
    folder = tmp_path / name
    source = SHIPPED_SESSIONS / "paper-zero-pose"
    folder.mkdir()
    for file in ("hexapod.yaml", "balls.yaml", "plan.yaml", "centres.csv", "temperatures.csv"):
        shutil.copy(source / file, folder / file)
    text = (source / "session.yaml").read_text()
    (folder / "session.yaml").write_text(
        text.replace("measurements: [centres.csv]\n", measurements)
    )
    return folder


def centres(folder: Path) -> Records:
    return read_measurement_csv(folder / "centres.csv")


def labels(folder: Path) -> tuple[str, ...]:
    return read_plan(folder / "plan.yaml").labels


def calypso_session(tmp_path: Path, name: str = "s", **options: object) -> Path:
    folder = make(tmp_path, CALYPSO, name)
    write_calypso(centres(folder), labels(folder), folder / "calypso", FEATURES, **options)
    return folder


def table_session(tmp_path: Path, name: str = "s", **options: object) -> Path:
    folder = make(tmp_path, TABLE, name)
    write_foreign_table(centres(folder), folder / "export.csv", **options)
    return folder


def deviation(a: ProcessResult, b: ProcessResult) -> tuple[float, float]:
    """Largest difference of conventional and corrected poses: translations (mm),
    rotations (deg)."""
    d = np.concatenate(
        [
            a.correction.conventional - b.correction.conventional,
            a.correction.corrected - b.correction.corrected,
        ]
    )
    return float(np.abs(d[:, :3]).max()), float(np.abs(d[:, 3:]).max())


def csv_at_resolution(folder: Path, decimals: int, per_step_time: bool, scale: float) -> Path:
    """The session's centres CSV as the export holds them: coordinates rounded as the
    export writes them (``decimals`` in a unit of ``scale`` mm), the runs' times."""
    rec = centres(folder)
    xyz = np.round(rec.xyz_mm / scale, decimals) * scale
    times = rec.time_s
    if per_step_time:
        by_step = step_times(rec, labels(folder))
        times = np.array([by_step[str(label)] for label in rec.label])
    lines = ["label,ball,x,y,z,time"]
    for label, ball, p, t in zip(rec.label, rec.ball, xyz, times, strict=True):
        stamp = np.datetime64(int(t), "s")
        lines.append(f"{label},{ball},{float(p[0])!r},{float(p[1])!r},{float(p[2])!r},{stamp}")
    (folder / "rounded.csv").write_text("\n".join(lines) + "\n")
    session = folder / "rounded.yaml"
    text = (folder / "session.yaml").read_text()
    head, _, tail = text.partition("measurements:")
    tail = tail[tail.index("temperatures:") :]
    session.write_text(head + "measurements: [rounded.csv]\n" + tail)
    return session


# ------------------------------------------------------------------ same numbers


def test_calypso_runs_give_the_poses_of_the_centres_csv(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    calypso = process_session(folder)
    # the same numbers (seven decimals, one time per run) in hexatherm's CSV: equal
    same = process_session(csv_at_resolution(folder, 7, True, 1.0))
    assert max(deviation(calypso, same)) < 1e-9
    # and the full-resolution CSV: the runs' 1e-7 mm resolution (5e-8 mm per coordinate,
    # about doubled through the registration of three balls); the run time is the mean of
    # its balls' times, as the CSV's step time is, so the correction sees the same times
    reference = process_session(csv_at_resolution(folder, 12, False, 1.0))
    mm, deg = deviation(calypso, reference)
    assert mm < 2e-7 and deg < 2e-7
    assert mm > 0  # the rounding is there: the comparison can fail


def test_calypso_runs_in_time_order_without_a_step_field(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path, step_in_header=False)
    text = (folder / "session.yaml").read_text().replace(" step_field: partnb,", "")
    (folder / "session.yaml").write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = process_session(folder)
    said = [str(w.message) for w in caught if issubclass(w.category, InputWarning)]
    assert len(said) == 1 and "time order" in said[0] and "run002 -> R0" in said[0]
    by_header = process_session(calypso_session(tmp_path, "t"))
    assert deviation(result, by_header) == (0.0, 0.0)


def test_a_foreign_table_in_inch_gives_the_poses_of_the_centres_csv(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    table = process_session(folder)
    read = read_measurements(
        folder / "export.csv", spec=read_session(folder).formats[folder / "export.csv"]
    )[0]
    rec = centres(folder)
    assert list(read.label) == list(rec.label) and list(read.ball) == list(rec.ball)
    assert np.array_equal(read.time_s, rec.time_s)
    # 8 decimals of an inch: 2.54e-7 mm, half of it per coordinate at worst
    assert np.abs(read.xyz_mm - rec.xyz_mm).max() <= 0.5e-8 * INCH_MM * (1 + 1e-9)
    same = process_session(csv_at_resolution(folder, 8, False, INCH_MM))
    assert max(deviation(table, same)) < 1e-9
    mm, deg = deviation(table, process_session(csv_at_resolution(folder, 12, False, 1.0)))
    assert 0 < mm < 5e-7 and deg < 5e-7


# ------------------------------------------------------------------ hostile variants


def refused(folder: Path | str) -> InputError:
    with pytest.raises(InputError) as caught:
        process_session(folder)
    return caught.value


def test_a_unit_that_is_not_a_length_unit_is_refused(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    text = (folder / "session.yaml").read_text().replace("unit: inch", "unit: cm")
    (folder / "session.yaml").write_text(text)
    error = refused(folder)
    assert error.path.endswith("session.yaml") and error.field == "measurements[0].unit"
    assert error.line == text.split("\n").index("    unit: cm") + 1


def test_a_calypso_row_in_an_unknown_unit_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    chr_file = folder / "calypso" / "run003_chr.txt"
    raw = chr_file.read_bytes().replace(b"\tmm\t", b"\tcm\t", 3)
    chr_file.write_bytes(raw)
    error = refused(folder)
    # line 2 is the alignment plane's characteristic: no sphere, its unit not read
    assert (error.path, error.line, error.field) == (str(chr_file), 3, "unit")


def test_an_inch_table_declared_in_mm_stops_at_the_ball_distances(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    text = (folder / "session.yaml").read_text().replace("unit: inch", "unit: mm")
    (folder / "session.yaml").write_text(text)
    with pytest.raises(PlanError, match="step O"):
        process_session(folder)


def test_calypso_runs_in_inch_read_as_mm(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path, unit="inch")
    inch = read_session(folder)
    mm = calypso_session(tmp_path, "mm")
    a = read_measurements(folder / "calypso", spec=inch.formats[folder / "calypso"])
    b = read_measurements(mm / "calypso", spec=read_session(mm).formats[mm / "calypso"])
    difference = np.abs(
        np.concatenate([r.xyz_mm for r in a]) - np.concatenate([r.xyz_mm for r in b])
    )
    # 7 decimals of an inch (1.27e-6 mm at worst) beside 7 of a mm (5e-8 mm)
    assert 0 < difference.max() <= 0.5e-7 * INCH_MM + 0.5e-7


def test_a_missing_time_is_refused(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    lines = (folder / "export.csv").read_text().split("\n")
    lines[5] = lines[5].rsplit(";", 1)[0] + ";"
    (folder / "export.csv").write_text("\n".join(lines))
    error = refused(folder)
    assert (error.line, error.field) == (6, "Datum")
    assert "time" in error.message


def test_a_run_header_without_time_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    hdr = folder / "calypso" / "run002_hdr.txt"
    hdr.write_bytes(hdr.read_bytes().replace(b"\ttime\t", b"\tzeit\t"))
    error = refused(folder)
    assert (error.path, error.field) == (str(hdr), "time")


def test_a_feature_named_off_the_map_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    chr_file = folder / "calypso" / "run004_chr.txt"
    chr_file.write_bytes(chr_file.read_bytes().replace(b"Kugel_2", b"Kugel_9"))
    error = refused(folder)
    assert (error.path, error.field) == (str(chr_file), "featureid")
    assert "Kugel_2" in error.message and "Kugel_9" in error.message


def test_a_table_ball_off_the_balls_file_is_refused(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    export = folder / "export.csv"
    export.write_text(export.read_text().replace("S1.B2;", "S1.B4;"))
    error = refused(folder)
    assert (error.path, error.field) == (str(export), "ball")
    assert "B4" in error.message


def test_a_truncated_table_is_refused(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    export = folder / "export.csv"
    export.write_bytes(export.read_bytes()[:-20])
    error = refused(folder)
    assert error.path == str(export) and error.line == 67
    assert "cut short" in error.message


def test_a_truncated_calypso_run_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    chr_file = folder / "calypso" / "run005_chr.txt"
    chr_file.write_bytes(chr_file.read_bytes()[:-300])
    error = refused(folder)
    assert error.path == str(chr_file) and error.line is not None


def test_a_run_without_its_header_file_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    (folder / "calypso" / "run003_hdr.txt").unlink()
    error = refused(folder)
    assert error.path == str(folder / "calypso" / "run003_chr.txt")
    assert "run003_hdr.txt" in error.message


def test_a_column_map_naming_a_missing_column_names_the_session_file(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    export = folder / "export.csv"
    export.write_text(export.read_text().replace("Durchmesser", "Diameter", 1))
    error = refused(folder)
    assert error.path == str(folder / "session.yaml") and error.line == 8
    assert error.field == "measurements[0].columns.diameter" and "'Durchmesser'" in error.message


def test_a_step_given_by_two_runs_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    hdr = folder / "calypso" / "run005_hdr.txt"
    other = (folder / "calypso" / "run003_hdr.txt").read_bytes().split(b"\r\n")[1].split(b"\t")[1]
    lines = hdr.read_bytes().split(b"\r\n")
    cells = lines[1].split(b"\t")
    cells[1] = other
    lines[1] = b"\t".join(cells)
    hdr.write_bytes(b"\r\n".join(lines))
    error = refused(folder)
    assert (error.path, error.line, error.field) == (str(hdr), 2, "partnb")


def test_a_table_giving_a_step_twice_is_refused(tmp_path: Path) -> None:
    folder = table_session(tmp_path)
    export = folder / "export.csv"
    lines = export.read_text().split("\n")
    export.write_text("\n".join([*lines[:-1], lines[4], ""]))
    error = refused(folder)
    assert error.path == str(export) and error.line == 68


@pytest.mark.parametrize("which", ["table", "calypso"])
def test_a_file_beyond_two_gigabytes_is_refused_unread(tmp_path: Path, which: str) -> None:
    if which == "table":
        folder = table_session(tmp_path)
        big = folder / "export.csv"
    else:
        folder = calypso_session(tmp_path)
        big = folder / "calypso" / "run002_chr.txt"
    with open(big, "r+b") as sparse:  # a sparse file: no 2 GB written
        sparse.truncate(MAX_MEASUREMENT_BYTES + 1)
    error = refused(folder)
    assert error.path == str(big) and "limit" in error.message


@pytest.mark.parametrize(
    ("change", "field", "words"),
    [
        ("    unit: inch\n", "measurements[0].colour", "unknown key"),
        ("x: X, ", "measurements[0].columns", "missing the x column"),
        (
            "    feature_pattern: '(?P<step>[^.]+)\\.(?P<ball>.+)'\n",
            "measurements[0].columns.feature",
            "feature_pattern",
        ),
        ("(?P<step>[^.]+)", "measurements[0].feature_pattern", "(?P<step>"),
        ("    delimiter: ';'\n", "measurements[0].decimal", "cannot be the delimiter"),
    ],
)
def test_the_column_map_is_checked_strictly(
    tmp_path: Path, change: str, field: str, words: str
) -> None:
    folder = table_session(tmp_path)
    text = (folder / "session.yaml").read_text()
    assert change in text
    if change == "    unit: inch\n":
        text = text.replace(change, change + "    colour: blue\n")
    elif change == "    delimiter: ';'\n":
        text = text.replace(change, "    delimiter: ','\n")
    elif change.startswith("(?P<step>"):
        text = text.replace(change, "(?P<stage>[^.]+)")
    else:
        text = text.replace(change, "")
    (folder / "session.yaml").write_text(text)
    error = refused(folder)
    assert error.path == str(folder / "session.yaml") and error.line is not None
    assert error.field == field and words in error.message


def test_the_cli_says_one_line_and_no_traceback(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from hexatherm.cli import main

    folder = calypso_session(tmp_path)
    (folder / "calypso" / "run003_hdr.txt").unlink()
    result = CliRunner().invoke(main, ["process", str(folder), "-o", str(tmp_path / "out")])
    assert result.exit_code != 0 and "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "run003_hdr.txt" in lines[0]
    assert not os.path.exists(tmp_path / "out")


def test_inspect_says_what_a_session_reads_before_processing(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from hexatherm.cli import main

    folder = calypso_session(tmp_path, step_in_header=False)
    text = (folder / "session.yaml").read_text().replace(" step_field: partnb,", "")
    (folder / "session.yaml").write_text(text)
    result = CliRunner().invoke(main, ["inspect", str(folder), "--csv"])
    assert result.exit_code == 0, result.output
    said = result.stderr.splitlines()
    assert any("time order" in line and "run001 -> O" in line for line in said)
    entry = next(line for line in said if line.startswith("calypso: Calypso runs"))
    for words in (
        "22 runs",
        "steps by the runs' time order",
        "Kugel_1 -> B1",
        "unit mm",
        "66 centres",
        "22 steps (O, R0, S1 ...)",
        "balls B1, B2, B3",
        "2019-12-20T09:01:30.000000 .. 2019-12-20T10:11:30.000000",
    ):
        assert words in entry, words
    import io

    import pandas as pd

    table = pd.read_csv(io.StringIO(result.stdout))
    rec = centres(folder)
    assert len(table) == len(rec) and set(table["file"]) == {
        f"run{k:03d}_chr.txt" for k in range(1, 23)
    }
    assert np.abs(table[["x_mm", "y_mm", "z_mm"]].to_numpy() - rec.xyz_mm).max() < 5.1e-8

    table_folder = table_session(tmp_path, "t")
    result = CliRunner().invoke(main, ["inspect", str(table_folder / "session.yaml")])
    assert result.exit_code == 0, result.output
    entry = next(line for line in result.stderr.splitlines() if line.startswith("export.csv"))
    for words in (
        "feature <- Merkmal",
        "time <- Datum+Uhrzeit",
        "delimiter ';'",
        "decimal ','",
        "unit inch",
        "time %d.%m.%Y %H:%M:%S",
        "66 centres",
    ):
        assert words in entry, words


def test_a_run_header_without_its_values_is_refused(tmp_path: Path) -> None:
    folder = calypso_session(tmp_path)
    hdr = folder / "calypso" / "run007_hdr.txt"
    hdr.write_bytes(hdr.read_bytes().split(b"\r\n")[0] + b"\r\n")
    error = refused(folder)
    assert (error.path, error.line) == (str(hdr), 2) and "no line of values" in error.message


def test_calypso_runs_in_utf16_with_decimal_commas_read_the_same(tmp_path: Path) -> None:
    plain = calypso_session(tmp_path)
    other = calypso_session(tmp_path, "u")
    for path in sorted((other / "calypso").glob("*.txt")):
        text = path.read_bytes().decode("latin-1")
        if path.name.endswith("_chr.txt"):
            text = text.replace(".", ",")
        path.write_bytes(text.encode("utf-16"))  # with its byte order mark
    a = read_measurements(plain / "calypso", spec=read_session(plain).formats[plain / "calypso"])
    b = read_measurements(other / "calypso", spec=read_session(other).formats[other / "calypso"])
    assert [list(r.label) for r in a] == [list(r.label) for r in b]
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.xyz_mm, y.xyz_mm) and np.array_equal(x.time_s, y.time_s)
