"""Hostile and truncated input files: every reader refuses them cleanly (issue 12).

Table-driven: each case writes one input file (or a FIFO, a device, a folder, a
socket, a dangling link), calls a reader and expects an ``InputError`` (a
``HexathermError``) whose one-line message names the file, the line and the field
(file-level refusals have no line), with the input left byte-identical and nothing
written beside it. Readers that could block (FIFOs) run in a thread joined with a
timeout, so that a regression fails instead of hanging.
"""

from __future__ import annotations

import os
import socket
import threading
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hexatherm.errors import HexathermError, InputError, InputWarning
from hexatherm.io import files
from hexatherm.io.config import read_hexapod
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.dmis import read_dmis, read_dmis_features
from hexatherm.io.files import MAX_MEASUREMENT_BYTES, MAX_YAML_BYTES
from hexatherm.io.measurements import read_measurements
from hexatherm.io.records import Records, check_time_zones
from hexatherm.io.temperatures import read_temperatures
from hexatherm.io.yamlfile import YamlDoc
from tests.waiting import SAFETY_S

TIMEOUT_S = SAFETY_S  # a safety net against a hang, never what decides a pass


def call_with_timeout(function: Callable[[], Any], timeout: float = TIMEOUT_S) -> Any:
    """``function()``'s result, or the exception it raised; fails if it does not finish."""
    outcome: dict[str, Any] = {}

    def run() -> None:
        try:
            outcome["result"] = function()
        except BaseException as error:  # noqa: BLE001 - handed to the test
            outcome["error"] = error

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(timeout)
    assert not thread.is_alive(), f"the reader did not return within {timeout} s (blocked?)"
    if "error" in outcome:
        return outcome["error"]
    return outcome["result"]


def snapshot(folder: Path) -> dict[str, bytes | str]:
    """Every entry of a folder: a regular file's bytes, or the kind of anything else."""
    out: dict[str, bytes | str] = {}
    for entry in sorted(folder.iterdir()):
        if entry.is_symlink():
            out[entry.name] = f"link->{os.readlink(entry)}"
        elif entry.is_file():
            out[entry.name] = entry.read_bytes()
        else:
            out[entry.name] = "dir" if entry.is_dir() else "special"
    return out


# ----------------------------------------------------------------------------- inputs
HEADER = "label,ball,x,y,z,time,diameter,form_um,n,u_um"
ROW = "S1,B2,12.5,-3.25,7.125,2020-01-01T10:15:30.250000,25.4,1.5,25,0.8"
CENTRES = (
    HEADER
    + "\n"
    + "O,B1,1.5,2,3,2020-01-01T10:00:00,25.4,1,25,0.5\n"
    + "O,B2,4,5,6,2020-01-01T10:01:00,25.4,1,25,0.5\n"
)
POINTS = "label,ball,x,y,z,time\n" + "".join(
    f"O,{ball},{k},{k + 1},{k + 2},2020-01-01T10:{m:02d}:{k:02d}\n"
    for m, ball in enumerate(("B1", "B2", "B3"))
    for k in range(5)
)
TEMPS = "time,leg1,leg2,leg3,leg4,leg5,leg6\n" + "".join(
    f"2020-01-01T10:0{k}:00,20.1,20.2,20.3,20.4,20.5,20.6\n" for k in range(3)
)
DMIS_HEAD = "DMISMN/'hostile',05.3\nUNITS/MM,ANGDEC\nDATE=2024/05/02\nTIME=10:00:00\n"
RECORD = "FA(S1_B2_7)=FEAT/POINT,CART,12.5,-3.25,7.125,0.6,0.8,0"


def dmis_points(balls: tuple[str, ...] = ("B1", "B2"), n: int = 4) -> str:
    lines = []
    for b, ball in enumerate(balls):
        lines.append(f"TIME=10:0{b}:00")
        lines += [
            f"FA(S1_{ball}_{k})=FEAT/POINT,CART,{k},{b},{k + b},0,0,1" for k in range(1, n + 1)
        ]
    return DMIS_HEAD + "\n".join(lines) + "\n"


def csv_last_line_cuts() -> list[tuple[str, str, str]]:
    """A centres row cut inside each of its fields, as the file's last line (no line end):
    (id, text, field it is cut in)."""
    columns, values = HEADER.split(","), ROW.split(",")
    cases = []
    for index, (column, value) in enumerate(zip(columns, values, strict=True)):
        head = ",".join(values[:index])
        cut = value[: max(1, len(value) // 2)]
        text = CENTRES + (head + "," if head else "") + cut
        cases.append((f"csv-cut-last-in-{column}", text, column))
    return cases


def csv_middle_cuts() -> list[tuple[str, str, int, str]]:
    """A centres row cut inside each field, followed by a complete row (a file damaged in
    the middle): (id, text, line, field the message must name)."""
    columns, values = HEADER.split(","), ROW.split(",")
    cases = []
    for index, column in enumerate(columns[:-1]):  # cut before the last: fields are missing
        cut = ",".join(values[:index] + [values[index][: max(1, len(values[index]) // 2)]])
        text = CENTRES + cut + "\n" + ROW.replace("S1", "S2") + "\n"
        cases.append((f"csv-cut-middle-in-{column}", text, 4, columns[index + 1]))
    return cases


def dmis_record_cuts() -> list[tuple[str, str, str]]:
    """A DMIS point record cut inside each of its fields, the file ending there
    (no ENDFIL): (id, text, field named: the cut one, or the first missing one)."""
    names = ["label", "type", "coordinates", "x", "y", "z", "i", "j", "k"]
    # where each field ends in RECORD: cut in its middle
    label_end = RECORD.index(")")
    starts = {
        "label": 3,
        "type": RECORD.index("/") + 1,
        "coordinates": RECORD.index("CART"),
    }
    pieces = RECORD.split(",")
    offset = len(",".join(pieces[:2])) + 1  # after "...POINT,CART,"
    for k, name in enumerate(("x", "y", "z", "i", "j", "k")):
        starts[name] = offset
        offset += len(pieces[2 + k]) + 1
    cases = []
    for name in names:
        start = starts[name]
        end = RECORD.find(",", start + 1) if name not in ("label",) else label_end
        end = len(RECORD) if end < 0 else end
        cut = RECORD[: start + max(1, (end - start) // 2)]
        # a record cut inside a number with more to come misses the next field: named
        expected = {"x": "y", "y": "z", "i": "j", "j": "k"}.get(name, name)
        cases.append((f"dmis-cut-in-{name}", DMIS_HEAD + cut, expected))
    return cases


# ----------------------------------------------------------------------------- the table
def csv_reader(path: Path) -> Any:
    return read_measurement_csv(path)


def measurements(path: Path) -> Any:
    return read_measurements(path)


def dmis_reader(path: Path) -> Any:
    return read_dmis(path)


def yaml_reader(path: Path) -> Any:
    return YamlDoc.load(path)


def temps_reader(path: Path) -> Any:
    return read_temperatures(path)


@dataclass(frozen=True)
class Case:
    id: str
    name: str  # file name
    content: bytes
    read: Callable[[Path], Any]
    line: int | None
    field: str | None
    message: str  # a piece of the message


def case(
    id: str,
    name: str,
    text: str | bytes,
    read: Callable[[Path], Any],
    line: int | None,
    field: str | None,
    message: str,
) -> Case:
    data = text.encode("utf-8") if isinstance(text, str) else text
    return Case(id, name, data, read, line, field, message)


HEXAPOD_TEXT = (Path(__file__).resolve().parents[2] / "configs" / "symetrie-like.yaml").read_text()
#: the line of the calibration record's (one) entry
CALIBRATION_LINE = len(HEXAPOD_TEXT.splitlines()) + 2


def calibrated_hexapod(entry: str) -> str:
    return HEXAPOD_TEXT + f"calibration:\n  {entry}\n"


LAUGHS = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [" + ", ".join([f"*{chr(97 + i)}"] * 10) + "]\n"
    for i in range(8)
)

CASES: list[Case] = [
    # encodings
    case("utf16-bom-csv", "c.csv", CENTRES.encode("utf-16"), csv_reader, 1, None, "UTF-16"),
    case("utf16le-csv", "c.csv", CENTRES.encode("utf-16-le"), csv_reader, 1, None, "UTF-16"),
    case("utf32-dmis", "r.dmo", dmis_points().encode("utf-32"), dmis_reader, 1, None, "UTF-32"),
    case("utf16-yaml", "s.yaml", "format: x\n".encode("utf-16"), yaml_reader, 1, None, "UTF-16"),
    case(
        "latin1-csv",
        "c.csv",
        (CENTRES + "Ö,B1,1,2,3,2020-01-01T10:00:00,,,,\n").encode("latin-1"),
        csv_reader,
        4,
        None,
        "not UTF-8",
    ),
    case(
        "latin1-dmis",
        "r.dmo",
        (dmis_points() + "FA(Círculo)=FEAT/POINT,CART,1,2,3\nENDFIL\n").encode("latin-1"),
        dmis_reader,
        15,
        None,
        "not UTF-8",
    ),
    case("nul-csv", "c.csv", CENTRES + "O,B3\x00\n", csv_reader, 4, None, "NUL byte"),
    # bombs and deep nesting
    case("billion-laughs", "s.yaml", LAUGHS, yaml_reader, 5, "e[7]", "aliases expand"),
    case(
        "nest-30000-flow",
        "s.yaml",
        "a: " + "[" * 30000 + "]" * 30000,
        yaml_reader,
        1,
        "a[0][0][0][0][0]...",
        "deeper than 100",
    ),
    case(
        "nest-30000-map",
        "s.yaml",
        "a: " + "{b: " * 30000 + "}" * 30000,
        yaml_reader,
        1,
        "a.b.b.b.b.b...",
        "deeper than 100",
    ),
    case(
        "nest-1000",
        "s.yaml",
        "a: " + "[" * 1000 + "]" * 1000,
        yaml_reader,
        1,
        "a[0][0][0][0][0]...",
        "deeper than 100",
    ),
    case(
        "nest-block-150",
        "s.yaml",
        "a:\n" + "".join(" " * (i + 1) + "- \n" for i in range(150)),
        yaml_reader,
        101,
        "a[0][0][0][0][0]...",
        "deeper than 100",
    ),
    case(
        "alias-self",
        "s.yaml",
        "legs: &x {segments: [*x]}\n",
        yaml_reader,
        1,
        "legs.segments[0]",
        "contains it",
    ),
    case(
        "alias-too-deep",
        "s.yaml",
        "a: &x " + "[" * 60 + "]" * 60 + "\nb: " + "[" * 50 + "*x" + "]" * 50 + "\n",
        yaml_reader,
        2,
        "b[0][0][0][0][0]...",
        "nests deeper",
    ),
    # truncated and odd times
    case(
        "time-T10:1",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T10:1,,,,\n",
        csv_reader,
        4,
        "time",
        "two-digit fields",
    ),
    case(
        "time-09:35:5",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T09:35:5,,,,\n",
        csv_reader,
        4,
        "time",
        "two-digit fields",
    ),
    case(
        "date-2019-12-2",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2019-12-2T09:35:05,,,,\n",
        csv_reader,
        4,
        "time",
        "two-digit fields",
    ),
    case(
        "date-only",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2019-12-02,,,,\n",
        csv_reader,
        4,
        "time",
        "two-digit fields",
    ),
    case(
        "time-feb-30",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-02-30T10:00:00,,,,\n",
        csv_reader,
        4,
        "time",
        "not a valid date",
    ),
    case(
        "time-hour-24",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T24:00:00,,,,\n",
        csv_reader,
        4,
        "time",
        "not a valid date",
    ),
    case(
        "time-arabic-digits",
        "c.csv",
        CENTRES + "O,B3,1,2,3,٢٠٢٠-01-01T10:00:00,,,,\n",
        csv_reader,
        4,
        "time",
        "two-digit fields",
    ),
    case(
        "time-mixed-offsets",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T12:02:00+02:00,,,,\n",
        csv_reader,
        4,
        "time",
        "mixed naive and offset-aware",
    ),
    case(
        "temps-mixed-offsets",
        "t.csv",
        TEMPS + "2020-01-01T10:04:00Z,20,20,20,20,20,20\n",
        temps_reader,
        5,
        "time",
        "mixed naive",
    ),
    case(
        "time-seconds-and-iso",
        "c.csv",
        CENTRES + "O,B3,1,2,3,1234.5,,,,\n",
        csv_reader,
        4,
        "time",
        "number of seconds",
    ),
    # numbers
    *(
        case(
            f"u_um-{text}",
            "c.csv",
            CENTRES + f"O,B3,1,2,3,2020-01-01T10:02:00,25.4,1,25,{text}\n",
            csv_reader,
            4,
            "u_um",
            message,
        )
        for text, message in (
            ("0", ">= 0.001 um"),
            ("-1", ">= 0.001 um"),
            # issue 36, item 2: taken, a pose's U was 0.0000 and every target conformed
            ("1e-9", "no CMM knows a ball centre better than a nanometre"),
            ("1e-300", ">= 0.001 um"),
            ("0.00099", ">= 0.001 um"),
            ("1e300", "<= 1000 um"),
            ("1000.5", "<= 1000 um"),
            ("nan", "not a finite number"),
            ("inf", "not a finite number"),
            ("1e400", "not a finite number"),
        )
    ),
    *(
        case(
            f"coordinate-{column}-{text}",
            "p.csv",
            POINTS
            + ",".join(
                ["O", "B4"]
                + [text if c == column else "1" for c in "xyz"]
                + ["2020-01-01T10:05:00"]
            )
            + "\n",
            csv_reader,
            17,
            column,
            "not a finite number",
        )
        for column, text in (("x", "1e400"), ("y", "nan"), ("z", "-inf"), ("x", "Infinity"))
    ),
    case(
        "diameter-0",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T10:02:00,0,1,25,0.5\n",
        csv_reader,
        4,
        "diameter",
        "> 0 mm",
    ),
    case(
        "n-fraction",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T10:02:00,25.4,1,2.5,0.5\n",
        csv_reader,
        4,
        "n",
        "whole number",
    ),
    case(
        "form-negative",
        "c.csv",
        CENTRES + "O,B3,1,2,3,2020-01-01T10:02:00,25.4,-1,25,0.5\n",
        csv_reader,
        4,
        "form_um",
        ">= 0 um",
    ),
    case(
        "temps-kelvin",
        "t.csv",
        TEMPS + "2020-01-01T10:04:00,20,20,293.15,20,20,20\n",
        temps_reader,
        5,
        "leg3",
        "kelvin",
    ),
    # a repeated or unnamed column (pandas would rename it "air.1" or "Unnamed: 7")
    case(
        "temps-air-twice",
        "t.csv",
        TEMPS.replace("leg6\n", "leg6,air,air\n", 1).replace("\n2", ",20,21\n2"),
        temps_reader,
        1,
        "air",
        "appears twice",
    ),
    case(
        "temps-unnamed-column",
        "t.csv",
        TEMPS.replace("leg6\n", "leg6,\n", 1).replace("\n2", ",20\n2"),
        temps_reader,
        1,
        None,
        "column 8 of the header has no name",
    ),
    case(
        "centres-diameter-twice",
        "c.csv",
        CENTRES.replace(HEADER, HEADER + ",diameter", 1),
        csv_reader,
        1,
        "diameter",
        "appears twice",
    ),
    # finite, but no CMM coordinate (a number run wild, a file in um): read_measurements
    case(
        "centres-z-1e300",
        "c.csv",
        CENTRES.replace("O,B2,4,5,6,", "O,B2,4,5,1e300,", 1),
        measurements,
        3,
        "z",
        "farther than 100 m from the CMM's origin",
    ),
    case(
        "dmis-points-in-um",
        "r.dmo",
        DMIS_HEAD + "FA(S1_B1_1)=FEAT/POINT,CART,426706.9,406933.4,240000.7\nENDFIL\n",
        measurements,
        5,
        "x",
        "426707 mm: farther than 100 m",
    ),
    case(
        "dmis-x-1e999",
        "r.dmo",
        DMIS_HEAD + "FA(S1_B1_1)=FEAT/POINT,CART,1e999,2,3\nENDFIL\n",
        dmis_reader,
        5,
        "x",
        "not a number",
    ),
    # duplicates
    case(
        "ball-probed-twice-csv",
        "p.csv",
        POINTS + "".join(f"O,B1,{k},1,2,2020-01-01T10:09:{k:02d}\n" for k in range(4)),
        csv_reader,
        17,
        "ball",
        "lines 2-6 and 17-20",
    ),
    case(
        "centre-twice-csv",
        "c.csv",
        CENTRES + "O,B1,1,2,3,2020-01-01T10:09:00,,,,\n",
        csv_reader,
        4,
        "label",
        "also on line 2",
    ),
    case(
        "dmis-label-twice",
        "r.dmo",
        dmis_points().replace("FA(S1_B1_3)", "FA(S1_B1_2)") + "ENDFIL\n",
        dmis_reader,
        8,
        "label",
        "S1_B1_2 seen twice (also on line 7)",
    ),
    case(
        "dmis-ball-probed-twice",
        "r.dmo",
        dmis_points(("B1", "B2", "B1")) + "ENDFIL\n",
        dmis_reader,
        16,
        "ball",
        "lines 6-9 and 16-19",
    ),
    case(
        "dmis-sphere-twice",
        "r.dmo",
        DMIS_HEAD + "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25\nFA(S1_B2)=FEAT/SPHERE,CART,4,5,6,25\n"
        "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3.001,25\nENDFIL\n",
        dmis_reader,
        7,
        "label",
        "duplicate centre",
    ),
    # truncation
    *(
        case(id, "c.csv", text, csv_reader, 4, field, "without a line break")
        for id, text, field in csv_last_line_cuts()
    ),
    *(
        case(id, "c.csv", text, csv_reader, line, field, "")
        for id, text, line, field in csv_middle_cuts()
    ),
    case(
        "temps-cut",
        "t.csv",
        TEMPS + "2020-01-01T10:04:00,20.1,20.2,20.3,20",
        temps_reader,
        5,
        "leg4",
        "without a line break",
    ),
    *(
        case(id, "r.dmo", text, dmis_reader, 5, field, "ENDFIL")
        for id, text, field in dmis_record_cuts()
    ),
    case(
        "dmis-no-endfil", "r.dmo", dmis_points(), dmis_reader, 14, "k", "does not end with ENDFIL"
    ),
    case(
        "dmis-cut-in-continuation",
        "r.dmo",
        DMIS_HEAD + "FA(S1_B1_1)=FEAT/POINT,CART,1,$\n2.$",
        dmis_reader,
        5,
        None,
        "ends inside a statement continued",
    ),
    case(
        "dmis-cut-after-continuation",
        "r.dmo",
        DMIS_HEAD + "FA(S1_B1_1)=FEAT/POINT,CART,1,$\n2.",
        dmis_reader,
        5,
        "z",
        "missing z: only 2 values after CART (the file does not end with ENDFIL",
    ),
    case("dmis-empty", "r.dmo", b"", dmis_reader, 1, None, "does not end with ENDFIL"),
    case(
        "dmis-after-endfil",
        "r.dmo",
        dmis_points() + "ENDFIL\n" + RECORD + "\n",
        dmis_reader,
        16,
        "k",
        "does not end with ENDFIL",
    ),
    case("dmis-features-no-endfil", "r.dmo", dmis_points(), read_dmis_features, 14, "k", "ENDFIL"),
    case("dmis-by-content", "run.txt", dmis_points(), measurements, 14, "k", "ENDFIL"),
    # a fixed segment of 1e300 mm: named in a few digits, not the 300 of the number
    case(
        "hexapod-segment-1e300",
        "h.yaml",
        HEXAPOD_TEXT.replace("length: 160.0}", "length: 1e300}", 1),
        read_hexapod,
        25,
        "legs",
        "leg 1: the fixed segments (1e+300 mm) are longer than the leg in the zero pose",
    ),
    # a hexapod file's calibration record (issue 22, "Also")
    case(
        "calibration-level-bogus",
        "h.yaml",
        calibrated_hexapod("level: bogus"),
        read_hexapod,
        CALIBRATION_LINE,
        "calibration.level",
        "expected one of offsets, joints, joints+gains, got 'bogus'",
    ),
    case(
        "calibration-written-yesterday",
        "h.yaml",
        calibrated_hexapod("written: yesterday"),
        read_hexapod,
        CALIBRATION_LINE,
        "calibration.written",
        "expected an ISO 8601 time with its UTC offset",
    ),
    case(
        "calibration-written-month-13",
        "h.yaml",
        calibrated_hexapod('written: "2026-13-01T10:00:00+01:00"'),
        read_hexapod,
        CALIBRATION_LINE,
        "calibration.written",
        "not a valid date and time",
    ),
    case(
        "calibration-poses-bogus",
        "h.yaml",
        calibrated_hexapod("poses: measured"),
        read_hexapod,
        CALIBRATION_LINE,
        "calibration.poses",
        "expected one of corrected, conventional, twin, got 'measured'",
    ),
    case(
        "calibration-sha256-not-hex",
        "h.yaml",
        calibrated_hexapod("twin_model_sha256: abc"),
        read_hexapod,
        CALIBRATION_LINE,
        "calibration.twin_model_sha256",
        "expected a SHA-256: 64 hexadecimal digits",
    ),
]


@pytest.mark.parametrize("hostile", CASES, ids=[c.id for c in CASES])
def test_hostile_file_is_refused_naming_file_line_field(tmp_path: Path, hostile: Case) -> None:
    path = tmp_path / hostile.name
    path.write_bytes(hostile.content)
    before = snapshot(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing dropped quietly either
        outcome = call_with_timeout(lambda: hostile.read(path))
    assert isinstance(outcome, InputError), f"accepted: {outcome!r}"
    assert isinstance(outcome, HexathermError)
    message = str(outcome)
    assert "\n" not in message and "Traceback" not in message
    assert (outcome.path, outcome.line, outcome.field) == (str(path), hostile.line, hostile.field)
    where = f"{path}:{hostile.line}: " if hostile.line is not None else f"{path}: "
    what = f"field '{hostile.field}': " if hostile.field is not None else ""
    assert message.startswith(where + what), message
    assert hostile.message in message, message
    assert snapshot(tmp_path) == before  # the input untouched, nothing written


def test_enough_hostile_cases() -> None:
    assert len(CASES) >= 40 and len({c.id for c in CASES}) == len(CASES)


# ----------------------------------------------------------------------------- non-regular
def make_fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def make_socket(path: Path) -> Path:
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.close()  # the socket file stays
    return path


def make_dangling(path: Path) -> Path:
    path.symlink_to(path.parent / "nowhere")
    return path


def make_dev_zero(path: Path) -> Path:
    path.symlink_to("/dev/zero")
    return path


def make_directory(path: Path) -> Path:
    path.mkdir()
    return path


READERS: dict[str, Callable[[Path], Any]] = {
    "csv": csv_reader,
    "temps": temps_reader,
    "measurements": measurements,
    "dmis": dmis_reader,
    "dmis-features": read_dmis_features,
    "yaml": yaml_reader,
}
SPECIALS: dict[str, tuple[Callable[[Path], Path], str]] = {
    "fifo": (make_fifo, "is a named pipe (FIFO), expected a regular file"),
    "dev-zero": (make_dev_zero, "is a character device, expected a regular file"),
    "directory": (make_directory, "is a directory, expected a file"),
    "socket": (make_socket, "is a socket, expected a regular file"),
    "dangling-link": (make_dangling, "file not found (a dangling symbolic link to"),
}


@pytest.mark.parametrize("special", list(SPECIALS))
@pytest.mark.parametrize("reader", list(READERS))
def test_non_regular_files_are_refused_without_blocking(
    tmp_path: Path, reader: str, special: str
) -> None:
    make, message = SPECIALS[special]
    suffix = {"dmis": ".dmo", "dmis-features": ".dmo", "yaml": ".yaml"}.get(reader, ".csv")
    path = make(tmp_path / f"input{suffix}")
    before = snapshot(tmp_path)
    outcome = call_with_timeout(lambda: READERS[reader](path))
    assert isinstance(outcome, InputError), f"accepted: {outcome!r}"
    assert str(outcome) == f"{path}: {message}" or str(outcome).startswith(f"{path}: {message}")
    assert snapshot(tmp_path) == before


def test_dev_zero_itself(tmp_path: Path) -> None:
    outcome = call_with_timeout(lambda: read_measurements(Path("/dev/zero")))
    assert str(outcome) == "/dev/zero: is a character device, expected a regular file"


def test_a_fifo_swapped_in_after_the_first_look_does_not_block(tmp_path: Path, monkeypatch) -> None:
    """The opened file is checked again: a FIFO that appears between stat and open is
    opened without blocking and refused."""
    path = tmp_path / "c.csv"
    path.write_text(CENTRES)
    real = files.refusal

    def swap(where, *, limit):  # the first look sees a regular file, then it becomes a FIFO
        verdict = real(where, limit=limit)
        os.unlink(where)
        os.mkfifo(where)
        return verdict

    monkeypatch.setattr(files, "refusal", swap)
    outcome = call_with_timeout(lambda: files.read_bytes(path))
    assert str(outcome) == f"{path}: is a named pipe (FIFO), expected a regular file"


@pytest.mark.parametrize(
    ("reader", "name", "limit"),
    [
        (yaml_reader, "big.yaml", MAX_YAML_BYTES),
        (dmis_reader, "big.dmo", MAX_MEASUREMENT_BYTES),
        (csv_reader, "big.csv", MAX_MEASUREMENT_BYTES),
    ],
)
def test_files_above_the_size_bound_are_refused_unread(tmp_path: Path, reader, name, limit):
    path = tmp_path / name
    with open(path, "wb") as handle:  # sparse: no disk, no time
        handle.truncate(limit + 1)
    outcome = call_with_timeout(lambda: reader(path))
    assert isinstance(outcome, InputError)
    assert str(outcome) == (
        f"{path}: the file is {limit + 1:,} bytes, above the limit of {limit:,} bytes "
        "for this kind of file"
    )


def test_the_bound_holds_while_reading_a_file_that_claims_size_zero() -> None:
    path = Path("/proc/self/maps")  # a regular file of st_size 0 that has content
    if not path.is_file() or path.stat().st_size != 0:
        pytest.skip("no /proc")
    assert len(files.read_bytes(path)) > 100
    outcome = call_with_timeout(lambda: files.read_bytes(path, limit=100))
    assert (
        str(outcome) == f"{path}: the file is more than 100 bytes, above the limit of 100 bytes "
        "for this kind of file"
    )


# ----------------------------------------------------------------------------- options
def general(text: str) -> str:
    """The same DMIS text read by the general reader (a comment on the first line)."""
    first, _, rest = text.partition("\n")
    return first + " $$ general reader\n" + rest


@pytest.mark.parametrize("lane", ["fast", "general"])
def test_allow_truncated_drops_the_last_dmis_record_with_a_warning(tmp_path: Path, lane: str):
    complete = dmis_points(n=4)
    cut = complete + RECORD[:40]  # a fifth record cut in its y
    if lane == "general":
        complete, cut = general(complete), general(cut)
    path = tmp_path / "r.dmo"
    path.write_text(cut)
    with pytest.warns(InputWarning) as caught:
        (got,) = read_dmis(path, allow_truncated=True)
    assert [str(w.message) for w in caught] == [
        f"{path}:15: the file does not end with ENDFIL (cut short?): its last record "
        "FA(S1_B2_7) and what follows it dropped"
    ]
    (path.parent / "ok.dmo").write_text(complete + "ENDFIL\n")
    (want,) = read_dmis(path.parent / "ok.dmo")  # the truth: the file without the cut record
    np.testing.assert_array_equal(got.xyz_mm, want.xyz_mm)
    assert got.line.tolist() == want.line.tolist() and len(got) == 8


@pytest.mark.parametrize("lane", ["fast", "general"])
def test_allow_truncated_drops_a_complete_last_record_too(tmp_path: Path, lane: str):
    """Without ENDFIL nothing tells a complete last record from a cut one: it goes."""
    text = dmis_points(n=4)
    if lane == "general":
        text = general(text)
    path = tmp_path / "r.dmo"
    path.write_text(text)
    with pytest.warns(InputWarning, match=r"r\.dmo:14: .* FA\(S1_B2_4\)"):
        (got,) = read_dmis(path, allow_truncated=True)
    assert len(got) == 7 and got.line.max() == 13


def test_allow_truncated_csv_drops_the_unfinished_line(tmp_path: Path) -> None:
    path = tmp_path / "c.csv"
    path.write_text(CENTRES + ROW[:30])
    with pytest.warns(
        InputWarning, match=r"c\.csv:4: the file ends without a line break, inside field 'time'"
    ):
        got = read_measurement_csv(path, allow_truncated=True)
    assert got.label.tolist() == ["O", "O"] and got.line.tolist() == [2, 3]


def test_keep_later_keeps_the_later_group(tmp_path: Path) -> None:
    path = tmp_path / "p.csv"
    later = "".join(f"O,B1,{k},1,2,2020-01-01T10:09:{k:02d}\n" for k in range(4))
    path.write_text(POINTS + later)
    with pytest.warns(
        InputWarning,
        match=r"p\.csv:2: step O ball B1 probed twice: "
        r"the earlier group \(lines 2-6\) dropped, lines 17-20 kept",
    ):
        got = read_measurement_csv(path, keep_later=True)
    b1 = got.ball == "B1"
    assert got.line[b1].tolist() == [17, 18, 19, 20]
    np.testing.assert_array_equal(got.xyz_mm[b1, 0], [0, 1, 2, 3])
    assert len(got) == 10 + 4


@pytest.mark.parametrize("lane", ["fast", "general"])
def test_keep_later_on_dmis_reprobed_ball(tmp_path: Path, lane: str) -> None:
    text = dmis_points(("B1", "B2", "B1")) + "ENDFIL\n"
    if lane == "general":
        text = general(text)
    path = tmp_path / "r.dmo"
    path.write_text(text)
    with pytest.warns(InputWarning, match="probed twice"):
        (got,) = read_dmis(path, keep_later=True)
    assert got.line[got.ball == "B1"].tolist() == [16, 17, 18, 19]
    assert got.extra["n"].tolist() == ["1", "2", "3", "4"] * 2


# ----------------------------------------------------------------------------- odd but valid
def test_year_9999_and_other_odd_valid_times_are_read(tmp_path: Path) -> None:
    times = [
        "9999-12-31T23:59:59.5",
        "0001-01-01T00:00:00",
        "2262-04-12T00:00:00",
        "2020-02-29T12:00",
    ]
    path = tmp_path / "c.csv"
    path.write_text(
        "label,ball,x,y,z,time\n" + "".join(f"O,B{i},1,2,3,{t}\n" for i, t in enumerate(times))
    )
    got = read_measurement_csv(path, kind="centres")
    epoch = datetime(1970, 1, 1, tzinfo=UTC)
    want = [(datetime.fromisoformat(t).replace(tzinfo=UTC) - epoch).total_seconds() for t in times]
    np.testing.assert_array_equal(got.time_s, want)
    assert got.time_aware is False


def test_offsets_in_every_layout_are_read(tmp_path: Path) -> None:
    times = [
        "2020-01-01T12:00:00+02:00",
        "2020-01-01T10:00:00Z",
        "2020-01-01T11:00:00+0100",
        "2020-01-01T09:00:00-01",
    ]
    path = tmp_path / "c.csv"
    path.write_text(
        "label,ball,x,y,z,time\n" + "".join(f"O,B{i},1,2,3,{t}\n" for i, t in enumerate(times))
    )
    got = read_measurement_csv(path, kind="centres")
    assert got.time_aware is True
    assert np.all(got.time_s == datetime(2020, 1, 1, 10, tzinfo=UTC).timestamp())


def test_times_of_files_compared_across_a_session(tmp_path: Path) -> None:
    aware = tmp_path / "c.csv"
    aware.write_text(CENTRES.replace(":00,25.4", ":00Z,25.4"))
    naive_temps = tmp_path / "t.csv"
    naive_temps.write_text(TEMPS)
    centres, temps = read_measurement_csv(aware), read_temperatures(naive_temps)
    assert (centres.time_aware, temps.time_aware) == (True, False)
    with pytest.raises(InputError) as info:
        check_time_zones([centres, temps])
    assert str(info.value).startswith(
        f"{naive_temps}: field 'time': times naive (no UTC offset) here "
        f"but with a UTC offset in {aware}"
    )
    dmo = tmp_path / "r.dmo"
    dmo.write_text(dmis_points() + "ENDFIL\n")
    (points,) = read_dmis(dmo)
    check_time_zones([points, temps])  # both naive: fine
    with pytest.raises(
        InputError, match=rf"^{aware}:2: field 'time': times with a UTC offset here but naive"
    ):
        check_time_zones([points, centres])


def test_concat_refuses_mixed_time_zones(tmp_path: Path) -> None:
    from hexatherm.io.records import concat_records

    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text(CENTRES)
    b.write_text(CENTRES.replace(":00,25.4", ":00+01:00,25.4"))
    with pytest.raises(InputError, match="mixed|naive"):
        concat_records([read_measurement_csv(a), read_measurement_csv(b)])
    joined = concat_records([read_measurement_csv(a), read_measurement_csv(a)])
    assert joined.time_aware is False and isinstance(joined, Records)


def test_calibration_record_choices_are_calibrates() -> None:
    """The hexapod reader's levels and poses are the ones calibrate writes."""
    from hexatherm.core.calibration import LEVELS
    from hexatherm.io.config.hexapod import CALIBRATION_LEVELS, CALIBRATION_POSES
    from hexatherm.workflows.calibrate.run import POSE_KINDS

    assert CALIBRATION_LEVELS == LEVELS and CALIBRATION_POSES == POSE_KINDS
