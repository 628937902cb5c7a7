"""CSV readers: kinds, times, extension columns, and a fuzz test of their error type."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.errors import InputError
from hexatherm.io.csvfile import centres_to_csv, read_measurement_csv
from hexatherm.io.measurements import read_measurements
from hexatherm.io.temperatures import read_temperatures

CENTRES = "label,ball,x,y,z,time\nO,B1,1.5,2,3,0\nO,B2,4,5,6,1.5\n"


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return path


def test_centres_and_times(tmp_path):
    rec = read_measurement_csv(write(tmp_path, "c.csv", CENTRES))
    assert rec.kind == "centres" and rec.time_kind == "seconds"
    np.testing.assert_array_equal(rec.xyz_mm, [[1.5, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(rec.line, [2, 3])
    iso = CENTRES.replace(",0\n", ",2020-01-01T00:00:00Z\n").replace(
        ",1.5\n", ",2020-01-01T01:00:01+01:00\n"
    )
    rec = read_measurement_csv(write(tmp_path, "c2.csv", iso))
    assert rec.time_kind == "iso" and rec.time_s[1] - rec.time_s[0] == 1.0


def test_kind_by_columns_name_and_content(tmp_path):
    pts = "label,ball,x,y,z,time\n" + "".join(f"O,B1,{i},0,0,{i}\n" for i in range(4))
    assert read_measurement_csv(write(tmp_path, "m.csv", pts)).kind == "points"
    assert (
        read_measurement_csv(
            write(
                tmp_path, "centres-x.csv", pts.splitlines()[0] + "\n" + pts.splitlines()[1] + "\n"
            )
        ).kind
        == "centres"
    )
    rec = read_measurement_csv(
        write(tmp_path, "a.csv", "label,ball,x,y,z,time,i,j,k\nO,B1,0,0,0,0,0,0,-1\n")
    )
    assert rec.kind == "points" and rec.ijk.tolist() == [[0.0, 0.0, -1.0]]


def test_centres_round_trip_with_extension_columns(tmp_path):
    rec = read_measurement_csv(write(tmp_path, "c.csv", CENTRES))
    rec.extra.update(
        {"form_um": np.array([1.0, 2.0]), "n": np.array([25, 25]), "u_um": np.array([0.1, 0.2])}
    )
    text = centres_to_csv(rec.__class__(**{**rec.__dict__, "diameter_mm": np.array([25.4] * 2)}))
    again = read_measurement_csv(write(tmp_path, "again.csv", text))
    np.testing.assert_array_equal(again.xyz_mm, rec.xyz_mm)
    np.testing.assert_array_equal(again.extra["u_um"], [0.1, 0.2])


def test_centre_covariance_round_trip(tmp_path):
    """A centre's full covariance written per axis and correlation, read back to the
    rounding of its columns (u 1e-4 um, r 1e-6), on both readers (clean file, blanks)."""
    rec = read_measurement_csv(write(tmp_path, "c.csv", CENTRES))
    a = np.array([[0.3, 0.05, -0.1], [0.0, 0.4, 0.2], [0.0, 0.0, 0.9]]) * 1e-3
    cov = np.stack([a @ a.T, 4 * a.T @ a])
    u_um = np.sqrt(np.trace(cov, axis1=1, axis2=2) / 3) * 1e3  # as fit-spheres writes it
    rec.extra.update({"cov_centre_mm2": cov, "u_um": u_um})
    text = centres_to_csv(rec)
    assert text.splitlines()[0].endswith(",u_um,u_x_um,u_y_um,u_z_um,r_xy,r_xz,r_yz")
    for name, body in (("a.csv", text), ("b.csv", text.replace(",", ", "))):
        again = read_measurement_csv(write(tmp_path, name, body))
        np.testing.assert_allclose(again.extra["cov_centre_mm2"], cov, rtol=0, atol=3e-10)
        assert again.extra["cov_from_file"].tolist() == [True, True]


@pytest.mark.parametrize(
    ("columns", "row", "pattern"),
    [
        ("u_x_um,u_y_um", "0.1,0.2", r"c.csv:1: field 'u_z_um': give u_x_um, u_y_um, u_z_um"),
        ("u_x_um,u_y_um,u_z_um,r_xy", "1,1,1,0", r"c.csv:1: field 'r_xz': give r_xy, r_xz"),
        ("r_xy,r_xz,r_yz", "0,0,0", r"c.csv:1: field 'r_xy': correlations need"),
        ("u_x_um,u_y_um,u_z_um", "0.1,,0.2", r"c.csv:3: field 'u_y_um': u_y_um is empty"),
        ("u_x_um,u_y_um,u_z_um,r_xy,r_xz,r_yz", "1,1,1,1.5,0,0", r"c.csv:3: field 'r_xy': a corr"),
        (
            "u_x_um,u_y_um,u_z_um,r_xy,r_xz,r_yz",
            "1,1,1,0.9,0.9,-0.9",
            r"c.csv:3: field 'r_xy': .*"
            "no correlation matrix",
        ),
        ("u_x_um,u_y_um,u_z_um", "1,0,1", r"c.csv:3: field 'u_y_um': a standard uncertainty"),
    ],
)
def test_centre_covariance_columns_refused(tmp_path, columns, row, pattern):
    first = ",".join(["1"] * len(columns.split(",")))
    text = f"label,ball,x,y,z,time,{columns}\nO,B1,1,2,3,0,{first}\nO,B2,1,2,3,1,{row}\n"
    with pytest.raises(InputError, match=pattern):
        read_measurement_csv(write(tmp_path, "c.csv", text))


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("label,ball,x,y,time\n", r"c.csv:1: header must start with label,ball,x,y,z,time"),
        (
            CENTRES + "O,B3,1,2,3,2020-01-01\n",
            r"c.csv:4: field 'time': time '2020-01-01'"
            "|c.csv:2: field 'time'",
        ),
        (CENTRES + "O,B1,1,2,3,4\n", r"c.csv:4: field 'label': duplicate centre"),
        (CENTRES + "O,B 3,1,2,3,4\n", r"c.csv:4: field 'ball': 'B 3' must match"),
        (CENTRES + "O,B3,1,2,nan,4\n", r"c.csv:4: field 'z': not a finite number: 'nan'"),
        (CENTRES + "O,B3,1,2,3,\n", r"c.csv:4: field 'time': missing time"),
        ("label,ball,x,y,z,time,colour\nO,B1,1,2,3,4,red\n", r"c.csv:1: field 'colour': unknown"),
        ("", r"c.csv:1: empty file"),
        (b"label,ball,x,y,z,time\nO,B1,1,2,3,\xff\n", r"c.csv:2: not UTF-8"),
    ],
)
def test_errors_name_file_line_field(tmp_path, text, pattern):
    with pytest.raises(InputError, match=pattern):
        read_measurement_csv(write(tmp_path, "c.csv", text))


def test_temperatures(tmp_path):
    text = (
        "time,leg1,leg2,leg3,leg4,leg5,leg6,air\n0,20,20,20,20,20,20,19.5\n"
        "30,21,21,21,21,21,21,19.6\n"
    )
    temps = read_temperatures(write(tmp_path, "t.csv", text))
    assert temps.legs_C.shape == (2, 6) and temps.others_C["air"].tolist() == [19.5, 19.6]
    with pytest.raises(InputError, match=r"t2.csv:3: field 'time': time goes backwards"):
        read_temperatures(write(tmp_path, "t2.csv", text.replace("\n30,", "\n-30,")))


def test_reader_chosen_by_content(tmp_path):
    path = write(
        tmp_path,
        "noext",
        "DMISMN/'x',04.0\nDATE=2020/01/01\nTIME=10:00:00\n"
        "FA(S1_B1)=FEAT/SPHERE,OUTER,CART,1,2,3,25.4\nENDFIL\n",
    )
    [rec] = read_measurements(path)
    assert rec.kind == "centres" and rec.diameter_mm.tolist() == [25.4]


LINES = [
    CENTRES.splitlines()[0],
    "O,B1,1,2,3,0",
    "label,ball,x,y,z,time,i,j,k",
    "S1,B2,1e3,-2.5,3,2020-01-01T00:00:00",
    "S1,B2,,,,",
    '"a",b,1,2,3,4',
    ",,,",
    "x",
]


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    st.one_of(
        st.binary(max_size=300),
        st.lists(st.one_of(st.sampled_from(LINES), st.text(max_size=30)), max_size=8).map(
            lambda rows: "\n".join(rows).encode("utf-8", "surrogatepass")
        ),
    )
)
def test_fuzz_readers_raise_only_input_error(tmp_path, data):
    path = tmp_path / "fuzz.csv"
    try:
        path.write_bytes(data)
    except UnicodeEncodeError:
        return
    for reader in (read_measurement_csv, read_temperatures, read_measurements):
        try:
            reader(path)
        except InputError:
            pass
