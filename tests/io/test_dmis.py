"""Tests of the DMIS output reader (hexatherm.io.dmis)."""

from __future__ import annotations

import math
from collections import Counter
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.errors import InputError
from hexatherm.io.dmis import (
    Feature,
    features_from_text,
    looks_like_dmis,
    read_dmis,
    read_dmis_features,
)
from hexatherm.io.records import iso_to_seconds

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "dmis-samples"  # copied from shared/
EXAMPLE1 = SAMPLES / "Example1.dmo"
EXAMPLE2 = SAMPLES / "Example2.dmo"
IMPELLER = SAMPLES / "impeller-part-1.dmo"
needs_samples = pytest.mark.skipif(not SAMPLES.is_dir(), reason="real DMIS samples not available")

# A small file as hexatherm expects them: spheres <label>_<ball>, points
# <label>_<ball>_<n>, nominals and tolerances to read past, times per step.
HEXATHERM_DMO = """\
DMISMN/'hexatherm session',05.3
UNITS/MM,ANGDEC
FILNAM/'session.dmo'
DATE=2024/05/02
TIME=10:00:00
F(O_B1)=FEAT/SPHERE,OUTER,CART,0,0,0,25.4
FA(O_B1)=FEAT/SPHERE,OUTER,CART,100.0012,200.0023,-50.0004,25.4011
TA(O_B1_X)=TOL/CORTOL,XAXIS,0.0012,INTOL
FA(O_B2)=FEAT/SPHERE,CART,$$ second ball
   -100.0008,200.0019,-49.9997,$$
   25.3994
TIME=10:05:30
FA(S1_B1_1)=FEAT/POINT,CART,112.7012,200.0023,-50.0004,1,0,0
FA(S1_B1_2)=FEAT/POINT,CART,87.2988,200.0023,-50.0004
FA(S1_B1_3)=FEAT/POINT,CART,100.0012,212.7023,-50.0004,0,1,0
ENDFIL
"""


def write(tmp_path: Path, text: str, name: str = "run.dmo", newline: str = "\n") -> Path:
    """Write text (with ``\\n`` replaced by ``newline``) as UTF-8 and return its path."""
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode("utf-8"))
    return path


def by_label(features: list[Feature]) -> dict[str, Feature]:
    return {feature.label: feature for feature in features}


def dated(body: str) -> str:
    return "DATE=2024/05/02\nTIME=10:00:00\n" + body


# ---------------------------------------------------------------------------
# Real files written by CMM software


@needs_samples
@pytest.mark.parametrize(
    ("path", "counts"),
    [
        (EXAMPLE1, {"CONE": 1, "SPHERE": 1, "CPARLN": 2, "CIRCLE": 2}),
        (EXAMPLE2, {"POINT": 8, "CYLINDER": 1}),
        (IMPELLER, {"POINT": 159, "CYLINDER": 2, "CIRCLE": 1}),
    ],
)
def test_real_samples_counts(path: Path, counts: dict[str, int]) -> None:
    features = read_dmis_features(path)
    assert Counter(feature.type for feature in features) == counts
    assert len(features) == sum(counts.values())
    lines = [feature.line for feature in features]
    assert lines == sorted(lines)
    assert all(feature.xyz_mm is not None and feature.time is not None for feature in features)


@needs_samples
def test_example1_sphere_and_quirks() -> None:
    features = by_label(read_dmis_features(EXAMPLE1))
    assert list(features) == [
        "Cono_9",
        "Esfera_10",
        "Coliso_11",
        "Rectángulo_12",
        "Círculo_13",
        "Círculo_14",
    ]
    sphere = features["Esfera_10"]
    assert sphere.type == "SPHERE"
    assert sphere.xyz_mm == (74.8580, 58.0652, 3.7478)
    assert sphere.size_mm == 27.8511
    assert sphere.ijk is None
    assert sphere.values == ("CART", 74.8580, 58.0652, 3.7478, 27.8511)
    assert sphere.line == 53
    assert sphere.time == datetime(2018, 3, 7, 19, 49, 29)
    # ",$$" continuations over four lines.
    cone = features["Cono_9"]
    assert cone.line == 44
    assert cone.values == ("CART", 74.9658, 92.9064, -13.7822, -0.0050, 0.0023, 0.9999, 90.0010)
    assert cone.ijk == (-0.0050, 0.0023, 0.9999)
    assert cone.size_mm is None
    # "$" continuations that split a number ("-0.$" / "0036"), UTF-8 labels.
    rectangle = features["Rectángulo_12"]
    assert rectangle.values[:3] == ("INNER", "FLAT", "CART")
    assert rectangle.ijk == (-0.0036, 0.0024, 0.9999)
    circle = features["Círculo_13"]
    assert circle.ijk == (-0.0027, -0.0019, 0.9999)
    assert circle.size_mm == 14.9137


@needs_samples
def test_example1_records() -> None:
    (centres,) = read_dmis(EXAMPLE1)
    assert centres.kind == "centres"
    assert centres.label.tolist() == ["Esfera"]
    assert centres.ball.tolist() == ["10"]
    np.testing.assert_array_equal(centres.xyz_mm, [[74.8580, 58.0652, 3.7478]])
    np.testing.assert_array_equal(centres.diameter_mm, [27.8511])
    assert centres.time_kind == "iso"
    assert centres.time_s.tolist() == [iso_to_seconds("2018-03-07T19:49:29")]
    assert centres.line.tolist() == [53]
    assert centres.path == str(EXAMPLE1)


@needs_samples
def test_example2_points_and_cylinder() -> None:
    features = read_dmis_features(EXAMPLE2)
    points = [feature for feature in features if feature.type == "POINT"]
    assert [point.label for point in points] == [
        "SP-00",
        "SP-01",
        "SP-07",
        "SP-11",
        "SP-18",
        "SP-21",
        "SP-24",
        "SP-25",
    ]
    assert points[1].xyz_mm == (13.8900, -4.2917, 39.7539)
    assert points[1].ijk == (0.3776, 0.6982, 0.6081)
    assert all(point.ijk is not None for point in points)
    cylinder = features[-1]
    assert (cylinder.label, cylinder.type) == ("Cilindro_1", "CYLINDER")
    assert cylinder.values[:2] == ("INNER", "CART")  # written as "INNER, CART"
    assert cylinder.xyz_mm == (-0.0001, 0.0003, 5.0602)
    assert cylinder.ijk == (-0.0002, 0.0, 0.9999)
    assert cylinder.size_mm == 95.9710
    assert cylinder.time == datetime(2018, 4, 13, 15, 43, 48)


@needs_samples
def test_impeller_unfinished_double_dollar_continuation() -> None:
    features = by_label(read_dmis_features(IMPELLER))
    # "0,0,1,$$" followed by "OUTPUT/..." ends the statement.
    plane = features["Upper_Plane"]
    assert plane.type == "POINT"
    assert plane.line == 2107
    assert plane.xyz_mm == (0.0294, 0.4428, 44.3366)
    assert plane.ijk == (0.0, 0.0, 1.0)
    assert features["Upper_Cylinder"].size_mm == 22.0
    circle = features["Upper_Circle"]  # "...,-0$" / ".0002,..."
    assert circle.ijk == (-0.0005, -0.0002, 0.9999)
    assert features["SP_00"].xyz_mm == features["SP_00"].values[1:4]


@needs_samples
@pytest.mark.parametrize(("path", "label"), [(EXAMPLE2, "'SP-00'"), (IMPELLER, "'SP_00'")])
def test_real_samples_do_not_follow_hexatherm_naming(path: Path, label: str) -> None:
    with pytest.raises(InputError, match=f"point label {label} does not follow") as info:
        read_dmis(path)
    assert info.value.field == "label"
    assert info.value.line is not None


# ---------------------------------------------------------------------------
# Quirks, one at a time


def test_dollar_continuation_splits_number_and_label(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        dated("FA(S1_$\nB1)=FEAT/SPH$\nERE,CART,1.2$\n5,-0.$\n0019,3,25.$\n4\nENDFIL\n"),
    )
    (sphere,) = read_dmis_features(path)
    assert sphere.label == "S1_B1"
    assert sphere.type == "SPHERE"
    assert sphere.xyz_mm == (1.25, -0.0019, 3.0)
    assert sphere.size_mm == 25.4
    assert sphere.line == 3


def test_dollar_continuation_is_raw_text(tmp_path: Path) -> None:
    # The blanks of the next line are kept: "1" + " 5" is "1 5", not a number.
    path = write(tmp_path, dated("FA(S1_B1)=FEAT/SPHERE,CART,1$\n 5,2,3,25\n"))
    with pytest.raises(InputError, match=r"x is not a number: '1 5'"):
        read_dmis_features(path)


def test_double_dollar_comments_and_continuations(tmp_path: Path) -> None:
    text = dated(
        "$$ a comment line\n"
        "FA(S1_B1)=FEAT/SPHERE,OUTER,CART,$$ centre follows\n"
        "\n"
        "   $$ a comment inside the continuation\n"
        "   1.5,2.5,$$\n"
        "   3.5,$$\n"
        "   25.4 $$ diameter\n"
        "FA(S1_B2_1)=FEAT/POINT,CART,$$\n"
        "  1,2,3,$$\n"
        "  0,0,1,$$\n"
        "OUTPUT/FA(S1_B2_1)\n"
        "TEXT/OPER,'price: $$5'\n"
        "ENDFIL\n"
    )
    sphere, point = read_dmis_features(write(tmp_path, text))
    assert sphere.xyz_mm == (1.5, 2.5, 3.5)
    assert sphere.size_mm == 25.4
    assert sphere.line == 4
    # Continued with ",$$" but followed by a new statement: ends there.
    assert point.line == 10
    assert point.values == ("CART", 1.0, 2.0, 3.0, 0.0, 0.0, 1.0)
    assert point.ijk == (0.0, 0.0, 1.0)


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_crlf_and_lf_read_the_same(tmp_path: Path, newline: str) -> None:
    features = read_dmis_features(write(tmp_path, HEXATHERM_DMO, newline=newline))
    assert features == read_dmis_features(write(tmp_path, HEXATHERM_DMO, "lf.dmo"))
    assert [feature.label for feature in features] == [
        "O_B1",
        "O_B2",
        "S1_B1_1",
        "S1_B1_2",
        "S1_B1_3",
    ]
    assert features[1].xyz_mm == (-100.0008, 200.0019, -49.9997)
    assert features[1].size_mm == 25.3994


def test_lines_starting_with_blank_or_comma(tmp_path: Path) -> None:
    text = dated(
        "OUTPUT/FA(S1_B1),TA(S1_B1_X)\n"
        ",TA(S1_B1_Y)\n"
        "   FA(S1_B1)=FEAT/SPHERE,CART,1,2,3\n"
        ",25\n"
        "\tFA(S1_B2)=FEAT/SPHERE,CART,4,5,6,25\n"
    )
    first, second = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert (first.xyz_mm, first.size_mm, first.line) == ((1.0, 2.0, 3.0), 25.0, 5)
    assert (second.xyz_mm, second.line) == ((4.0, 5.0, 6.0), 7)


def test_empty_fields(tmp_path: Path) -> None:
    text = dated(
        "F(C1)=FEAT/CIRCLE,INNER,CART,32.5,75.5,-10,,,,15\n"
        "FA(C1)=FEAT/CIRCLE,INNER,CART,32.5,75.5,-10,,,,15\n"
        "FA(P1)=FEAT/POINT,CART,1,2,3,,,\n"
    )
    circle, point = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert circle.values == ("INNER", "CART", 32.5, 75.5, -10.0, None, None, None, 15.0)
    assert circle.xyz_mm == (32.5, 75.5, -10.0)
    assert circle.ijk is None
    assert circle.size_mm == 15.0
    assert point.ijk is None


def test_sphere_with_and_without_inner_outer(tmp_path: Path) -> None:
    text = dated(
        "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25\n"
        "FA(S1_B2)=FEAT/SPHERE,OUTER,CART,1,2,3,25\n"
        "FA(S1_B3)=FEAT/SPHERE,INNER,CART,1,2,3,25\n"
        "fa(S1_B4)=feat/sphere,outer,cart,1,2,3,25\n"
    )
    features = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert [feature.xyz_mm for feature in features] == [(1.0, 2.0, 3.0)] * 4
    assert [feature.size_mm for feature in features] == [25.0] * 4
    assert [feature.type for feature in features] == ["SPHERE"] * 4


def test_units_inch_converts_lengths_not_directions(tmp_path: Path) -> None:
    text = dated(
        "UNITS/INCH,ANGDEC\n"
        "FA(S1_B1)=FEAT/SPHERE,CART,1,-2,0.5,1\n"
        "FA(S1_B1_1)=FEAT/POINT,CART,1,0,0,0.6,0.8,0\n"
        "FA(C1)=FEAT/CYLINDER,INNER,CART,1,1,1,0,0,1,2\n"
        "UNITS/MM,ANGDEC\n"
        "FA(S1_B2)=FEAT/SPHERE,CART,1,-2,0.5,1\n"
    )
    inch, point, cylinder, mm = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert inch.xyz_mm == (25.4, -50.8, 12.7)
    assert inch.size_mm == 25.4
    assert inch.values == ("CART", 1.0, -2.0, 0.5, 1.0)  # as written
    assert point.xyz_mm == (25.4, 0.0, 0.0)
    assert point.ijk == (0.6, 0.8, 0.0)
    assert cylinder.size_mm == 50.8
    assert cylinder.ijk == (0.0, 0.0, 1.0)
    assert mm.xyz_mm == (1.0, -2.0, 0.5)
    assert mm.size_mm == 1.0


@pytest.mark.parametrize(
    ("units", "scale"), [("MM", 1.0), ("CM", 10.0), ("M", 1000.0), ("FEET", 304.8)]
)
def test_other_dmis_length_units(tmp_path: Path, units: str, scale: float) -> None:
    text = dated(f"UNITS/{units}\nFA(S1_B1)=FEAT/SPHERE,CART,1,2,0,1\n")
    (sphere,) = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert sphere.xyz_mm == (scale, 2 * scale, 0.0)
    assert sphere.size_mm == scale


def test_polar_coordinates(tmp_path: Path) -> None:
    text = dated(
        "FA(S1_B1)=FEAT/SPHERE,POL,10,90,5,25\n"
        "UNITS/INCH,ANGRAD\n"
        f"FA(S1_B2_1)=FEAT/POINT,POL,1,{math.pi},2,-1,0,0\n"
    )
    sphere, point = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert sphere.xyz_mm == pytest.approx((0.0, 10.0, 5.0), abs=1e-12)
    assert sphere.size_mm == 25.0
    assert point.xyz_mm == pytest.approx((-25.4, 0.0, 50.8), abs=1e-12)
    assert point.ijk == (-1.0, 0.0, 0.0)


def test_date_and_time_assignment(tmp_path: Path) -> None:
    text = (
        "FA(S0_B1)=FEAT/SPHERE,CART,1,2,3,25\n"
        "DATE=2024/05/02\n"
        "FA(S0_B2)=FEAT/SPHERE,CART,1,2,3,25\n"
        "TIME=23:59:58\n"
        "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25\n"
        "FA(S1_B2)=FEAT/SPHERE,CART,1,2,3,25\n"
        "DATE=2024/05/03\n"
        "TIME=00:00:01.25\n"
        "FA(S2_B1_1)=FEAT/POINT,CART,1,2,3\n"
    )
    features = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert [feature.time for feature in features] == [
        None,
        None,
        datetime(2024, 5, 2, 23, 59, 58),
        datetime(2024, 5, 2, 23, 59, 58),
        datetime(2024, 5, 3, 0, 0, 1, 250000),
    ]


def test_hexatherm_naming_into_records(tmp_path: Path) -> None:
    path = write(tmp_path, HEXATHERM_DMO)
    centres, points = read_dmis(path)

    assert centres.kind == "centres"
    assert centres.label.tolist() == ["O", "O"]
    assert centres.ball.tolist() == ["B1", "B2"]
    np.testing.assert_array_equal(
        centres.xyz_mm, [[100.0012, 200.0023, -50.0004], [-100.0008, 200.0019, -49.9997]]
    )
    np.testing.assert_array_equal(centres.diameter_mm, [25.4011, 25.3994])
    assert centres.time_kind == "iso"
    assert centres.time_s.tolist() == [iso_to_seconds("2024-05-02T10:00:00")] * 2
    assert centres.line.tolist() == [7, 9]
    assert centres.ijk is None
    assert len(centres) == 2

    assert points.kind == "points"
    assert points.label.tolist() == ["S1"] * 3
    assert points.ball.tolist() == ["B1"] * 3
    assert points.extra["n"].tolist() == ["1", "2", "3"]
    assert points.xyz_mm.shape == (3, 3)
    np.testing.assert_array_equal(points.ijk, [[1, 0, 0], [np.nan] * 3, [0, 1, 0]])
    assert points.time_s.tolist() == [iso_to_seconds("2024-05-02T10:05:30")] * 3
    assert points.line.tolist() == [13, 14, 15]
    assert points.diameter_mm is None
    assert points.path == str(path)


def test_records_kinds_are_omitted_when_empty(tmp_path: Path) -> None:
    only_points = dated(
        "FA(S1_B1_1)=FEAT/POINT,CART,1,2,3\n"
        "FA(Datum)=FEAT/PLANE,CART,0,0,0,0,0,1\n"
        "FA(Bore)=FEAT/CIRCLE,INNER,CART,0,0,0,0,0,1,10\n"
    )
    (points,) = read_dmis(write(tmp_path, only_points + "ENDFIL\n"))
    assert points.kind == "points"
    assert read_dmis(write(tmp_path, "DMISMN/'empty',05.3\nENDFIL\n")) == []


def test_nominals_tolerances_and_malformed_other_statements_are_read_past(
    tmp_path: Path,
) -> None:
    text = dated(
        "F(S1_B1)=FEAT/SPHERE,CART,abc\n"
        "T(S1_B1_X)=TOL/CORTOL,XAXIS,\n"
        "OUTPUT/FA(S1_B1),TA(\n"
        "TA(S1_B1_X)=TOL/CORTOL,XAXIS,-0.0341,INTOL\n"
        "GARBAGE ,,, ((\n"
        "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25\n"
        "FA(Pattern)=FEAT/PATERN,F(a),F(b)\n"
    )
    sphere, pattern = read_dmis_features(write(tmp_path, text + "ENDFIL\n"))
    assert sphere.line == 8
    assert (pattern.type, pattern.xyz_mm, pattern.values) == ("PATERN", None, ("F(a)", "F(b)"))


def test_utf8_bom_and_labels(tmp_path: Path) -> None:
    path = tmp_path / "bom.dmo"
    path.write_bytes(
        "\ufeffDATE=2024/05/02\nFA(Círculo_13)=FEAT/POINT,CART,1,2,3\nENDFIL\n".encode()
    )
    (feature,) = read_dmis_features(path)
    assert feature.label == "Círculo_13"
    assert feature.line == 2


# ---------------------------------------------------------------------------
# Bad input


@pytest.mark.parametrize(
    ("body", "message", "line", "field"),
    [
        (
            "FA(S1_B1)=FEAT/SPHERE,CART,1,abc,3,25\n",
            r"FA\(S1_B1\)=FEAT/SPHERE: y is not a number: 'abc'",
            3,
            "y",
        ),
        ("FA(S1_B1)=FEAT/SPHERE,CART,1,2,3\n", "missing diameter: only 3 values", 3, "diameter"),
        ("FA(S1_B1)=FEAT/SPHERE,CART,1,,3,25\n", "empty y", 3, "y"),
        ("FA(S1_B1)=FEAT/SPHERE,CART,1e999,2,3,25\n", "x is not a number: '1e999'", 3, "x"),
        ("FA(S1_B1_1)=FEAT/POINT,CART,1,2\n", "missing z", 3, "z"),
        ("FA(S1_B1_1)=FEAT/POINT,CART,1,2,3,0,1\n", "incomplete direction: missing k", 3, "k"),
        ("FA(S1_B1_1)=FEAT/POINT,CART,1,2,3,0,,1\n", "incomplete direction: empty j", 3, "j"),
        ("FA(S1_B1_1)=FEAT/POINT,CART,1,2,3,0,x,1\n", "j is not a number: 'x'", 3, "j"),
        ("FA(S1_B1_1)=FEAT/POINT,1,2,3\n", "expected CART or POL", 3, "coordinates"),
        (
            "FA(S1_B1)=FEAT/SPHERE,ROUND,CART,1,2,3,25\n",
            "unexpected ROUND before CART",
            3,
            "modifier",
        ),
        ("FA(S1_B1_1)=FEAT/POINT,INNER,CART,1,2,3\n", "expected nothing", 3, "modifier"),
        ("FA(C1)=FEAT/CIRCLE,INNER,CART,1,2,3,0,0,1\n", "missing diameter", 3, "diameter"),
        (
            "FA(S1_B1_1)=FEAT/POINT,CART,1,2,3,0,0,1,0\n",
            r"7 values after CART, expected x, y, z\[, i, j, k\]: unexpected 0.0",
            3,
            "values",
        ),
        (
            "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25\n,junk\n",
            "5 values after CART, expected x, y, z, diameter: unexpected 'junk'",
            3,
            "values",
        ),
        ("FA(S1_B1)=FEAT/\n", "bad feature type ''", 3, "type"),
        ("FA(S1_B1)=FEAT/SPH ERE,CART,1,2,3,25\n", "bad feature type 'SPH ERE'", 3, "type"),
        ("FA()=FEAT/SPHERE,CART,1,2,3,25\n", "empty label", 3, "label"),
        ("FA(S1_B1=FEAT/SPHERE,CART,1,2,3,25\n", "malformed label", 3, "label"),
        ("FA(S1_B1)=OBTAIN/SPHERE,CART,1,2,3,25\n", "expected '=FEAT/<type>,...'", 3, None),
        ("UNITS/FURLONG,ANGDEC\n", "unknown length unit 'FURLONG'", 3, "units"),
        ("UNITS/MM,GRADS\n", "unknown angle unit 'GRADS'", 3, "units"),
        ("UNITS/MM,ANGDMS\nFA(S1_B1)=FEAT/SPHERE,POL,1,2,3,4\n", "ANGDMS are not", 4, "angle"),
        ("DATE=07/03/2018\n", r"not a date: '07/03/2018' \(expected YYYY/MM/DD\)", 3, "date"),
        ("DATE=2018/02/30\n", "not a date: '2018/02/30'", 3, "date"),
        ("TIME=25:00:00\n", "not a time: '25:00:00'", 3, "time"),
        ("FA(S1_B1)=FEAT/SPHERE,CART,$\n", "ends inside a statement continued with '\\$'", 3, None),
        (
            "FA(S1_B1)=FEAT/SPHERE,CART,$$\n 1,2,$$\n",
            "ends inside a statement continued with ',\\$\\$'",
            3,
            None,
        ),
        ("OUTPUT/FA(S1_B1),T$\n\n\n", "ends inside a statement continued", 3, None),
        # A statement over several lines is located at its first line.
        ("ENDFIL\nFA(S1_B1)=FEAT/SPHERE,$\nCART,$\n1,2,q,25\n", "z is not a number", 4, "z"),
    ],
)
def test_bad_input(tmp_path: Path, body: str, message: str, line: int, field: str | None) -> None:
    path = write(tmp_path, dated(body))
    with pytest.raises(InputError, match=message) as info:
        read_dmis_features(path)
    error = info.value
    assert (error.path, error.line, error.field) == (str(path), line, field)
    where = f"{path}:{line}: " + (f"field '{field}': " if field else "")
    assert str(error).startswith(where)


def test_undecodable_bytes(tmp_path: Path) -> None:
    path = tmp_path / "latin1.dmo"
    path.write_bytes("DATE=2024/05/02\nFA(Círculo_13)=FEAT/POINT,CART,1,2,3\n".encode("latin-1"))
    with pytest.raises(InputError, match=r"latin1\.dmo:2: not UTF-8 text: byte 0xed"):
        read_dmis_features(path)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="file not found"):
        read_dmis(tmp_path / "nowhere.dmo")


@pytest.mark.parametrize(
    ("body", "message", "line", "field"),
    [
        ("FA(S1B1)=FEAT/SPHERE,CART,1,2,3,25\n", "sphere label 'S1B1' does not follow", 3, "label"),
        (
            "FA(S1_B1_1)=FEAT/SPHERE,CART,1,2,3,25\n",
            "sphere label 'S1_B1_1' does not follow hexatherm's naming <label>_<ball> ",
            3,
            "label",
        ),
        (
            "FA(S1_B1)=FEAT/POINT,CART,1,2,3\n",
            "point label 'S1_B1' does not follow hexatherm's naming <label>_<ball>_<n> ",
            3,
            "label",
        ),
        ("FA(S1_B.1_1)=FEAT/POINT,CART,1,2,3\n", "point label 'S1_B.1_1'", 3, "label"),
    ],
)
def test_read_dmis_rejects_foreign_labels(
    tmp_path: Path, body: str, message: str, line: int, field: str
) -> None:
    path = write(tmp_path, dated(body) + "ENDFIL\n")
    with pytest.raises(InputError, match=message) as info:
        read_dmis(path)
    assert (info.value.line, info.value.field) == (line, field)


@pytest.mark.parametrize(
    "head", ["", "DATE=2024/05/02\n", "TIME=10:00:00\n", "DATE=2024/05/02\nUNITS/INCH\n"]
)
def test_read_dmis_needs_date_and_time(tmp_path: Path, head: str) -> None:
    body = head + "FA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25\n"
    path = write(tmp_path, body + "ENDFIL\n")
    line = body.count("\n")
    with pytest.raises(
        InputError, match=rf"run\.dmo:{line}: field 'time': FA\(S1_B1\) has no DATE= and TIME="
    ):
        read_dmis(path)


def test_features_from_text_matches_file_reader(tmp_path: Path) -> None:
    path = write(tmp_path, HEXATHERM_DMO)
    assert features_from_text(HEXATHERM_DMO, path) == read_dmis_features(path)


# ---------------------------------------------------------------------------
# Content sniffing


@pytest.mark.parametrize(
    ("head", "expected"),
    [
        ("DMISMN/'C:\\part.dmo',04.0\r\nUNITS/MM,ANGDEC\r\n", True),
        ("\ufeffDMISMD/'x',05.3", True),
        ("  \n\nunits/mm,angdec\n", True),
        ("FILNAM/'x'", True),
        ("$$ header comment\nFA(S1_B1)=FEAT/SPHERE,CART,1,2,3,25", True),
        ("F(Esfera_$\n10)=FEAT/SPHERE", True),
        ("DATE=2018/03/07", True),
        ("TIME = 19:49:29", True),
        ("ENDFIL", True),
        ("", False),
        ("$$ only a comment\n", False),
        ("label,ball,x,y,z,time\n", False),
        ("time,leg1,leg2,leg3,leg4,leg5,leg6\n", False),
        ("format: hexatherm-session/1\n", False),
        ("WHATEVER/1,2,3", False),
        ("X(a)=1", False),
        ("NAME=value", False),
        ("#!/bin/sh", False),
    ],
)
def test_looks_like_dmis(head: str, expected: bool) -> None:
    assert looks_like_dmis(head) is expected


@needs_samples
@pytest.mark.parametrize("path", [EXAMPLE1, EXAMPLE2, IMPELLER])
def test_looks_like_dmis_on_samples(path: Path) -> None:
    assert looks_like_dmis(path.read_text(encoding="utf-8")[:200])


# ---------------------------------------------------------------------------
# Fuzz: whatever the bytes, the readers return or raise InputError

_SOURCES = [HEXATHERM_DMO.encode("utf-8")] + (
    [path.read_bytes() for path in (EXAMPLE1, EXAMPLE2, IMPELLER)] if SAMPLES.is_dir() else []
)
_TOKENS = [
    b"$",
    b"$$",
    b",$$\r\n",
    b",",
    b",,",
    b"\r\n",
    b"\n",
    b"\r",
    b" ",
    b"'",
    b"(",
    b")",
    b"=",
    b"/",
    b"FA(",
    b"FA(S1_B1)=FEAT/SPHERE,CART,",
    b"FA(S1_B1_1)=FEAT/POINT,CART,",
    b")=FEAT/",
    b"SPHERE",
    b"POINT",
    b"CYLINDER",
    b"INNER,",
    b"POL,",
    b"UNITS/INCH,ANGRAD\n",
    b"UNITS/MM,ANGDMS\n",
    b"DATE=2024/02/29\n",
    b"TIME=12:00:00\n",
    b"1e999",
    b"-0.",
    b"\xff",
    b"\xc3",
    b"\xef\xbb\xbf",
    b"\x00",
    b"\xe2\x80\xa8",
]


@st.composite
def mutated_files(draw: st.DrawFn) -> bytes:
    """A sample file with a few random deletions, insertions, truncations and splices."""
    data = bytearray(draw(st.sampled_from(_SOURCES)))
    for _ in range(draw(st.integers(min_value=1, max_value=6))):
        operation = draw(
            st.sampled_from(["delete", "insert", "token", "replace", "truncate", "splice", "copy"])
        )
        at = draw(st.integers(min_value=0, max_value=len(data)))
        if operation == "delete":
            del data[at : at + draw(st.integers(min_value=1, max_value=40))]
        elif operation == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=20))
        elif operation == "token":
            data[at:at] = draw(st.sampled_from(_TOKENS))
        elif operation == "replace" and at < len(data):
            data[at] = draw(st.integers(min_value=0, max_value=255))
        elif operation == "truncate":
            del data[at:]
        elif operation == "splice":
            other = draw(st.sampled_from(_SOURCES))
            cut = draw(st.integers(min_value=0, max_value=len(other)))
            data[at:] = other[cut:]
        elif operation == "copy":
            size = draw(st.integers(min_value=1, max_value=200))
            data[at:at] = data[max(0, at - size) : at]
    return bytes(data)


def _returns_or_raises_input_error(path: Path) -> None:
    for reader in (read_dmis_features, read_dmis):
        try:
            result = reader(path)
        except InputError as error:
            assert error.path == str(path)
            assert error.line is not None and error.line >= 1
        else:
            assert isinstance(result, list)
    looks_like_dmis(path.read_bytes()[:400].decode("utf-8", errors="replace"))


_FUZZ = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@_FUZZ
@given(data=st.binary(max_size=2000))
def test_fuzz_random_bytes(tmp_path_factory: pytest.TempPathFactory, data: bytes) -> None:
    path = tmp_path_factory.getbasetemp() / "fuzz-bytes.dmo"
    path.write_bytes(data)
    _returns_or_raises_input_error(path)


@_FUZZ
@given(data=mutated_files())
def test_fuzz_mutated_samples(tmp_path_factory: pytest.TempPathFactory, data: bytes) -> None:
    path = tmp_path_factory.getbasetemp() / "fuzz-mutated.dmo"
    path.write_bytes(data)
    _returns_or_raises_input_error(path)
