"""QIF 3 results: what CMM software writes, read to the same records as hexatherm's CSVs;
the consortium's own samples; hostile files refused in one line."""

from __future__ import annotations

import re
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.errors import InputError
from hexatherm.io.csvfile import read_measurement_csv
from hexatherm.io.measurements import is_qif, read_measurements
from hexatherm.io.qif import read_qif, scan_qif
from hexatherm.io.qifschema import check_document
from tests.io.qifwriter import results_qif
from tests.sessions import make_session

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "qif"
#: the consortium's samples: sphere count and feature measurements read past, or the refusal
READ = {
    "QIF_PTS_SAMPLE.QIF": 14,
    "QIF_Results_Sample.QIF": 6,
    "mitutoyo_results_serialized_pass_fail_sample.QIF": 0,
    "testPython30.qif": 4,
    "SheetMetal_QIF_Results_sample_1.QIF": 21,
    "WIDGET_QIF_RESULTS.QIF": 19,
    "Exploded_Results1.QIF": 0,
    "Mixed_Exploded_Results1.QIF": 0,
}
REFUSED = {"simplePlan.QIF": 11, "check_y1_inch.QIF": 8}


@pytest.fixture(scope="module")
def centres(tmp_path_factory):
    folder = tmp_path_factory.mktemp("qif") / "s"
    make_session(folder, output="centres", n_targets=2, noise_mm=1e-3)
    return read_measurement_csv(folder / "centres.csv")


@pytest.fixture(scope="module")
def points(tmp_path_factory):
    folder = tmp_path_factory.mktemp("qif") / "p"
    make_session(folder, output="points", n_targets=1, point_noise_mm=1e-3)
    return read_measurement_csv(folder / "points.csv")


def write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def refusal(path: Path, **kwargs) -> str:
    with pytest.raises(InputError) as caught:
        read_measurements(path, **kwargs)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{path}:")
    return message


# -- what CMM software writes ------------------------------------------------------------


def test_centres_in_mm_read_exactly(tmp_path, centres):
    u = {"x": np.full(len(centres), 1.5), "y": np.full(len(centres), 2.0), "z": np.arange(1.0, 19)}
    qif = write(tmp_path / "c.qif", results_qif(centres, uncertainty_um=u))
    check_document(qif)  # the official schema, whole
    (rec,) = read_measurements(qif)
    assert rec.kind == "centres" and rec.time_kind == "iso" and rec.time_aware is False
    assert (rec.label == centres.label).all() and (rec.ball == centres.ball).all()
    assert np.array_equal(rec.xyz_mm, centres.xyz_mm)  # shortest round-trip digits
    assert np.array_equal(rec.time_s, centres.time_s)
    assert centres.diameter_mm is None and (rec.diameter_mm == 25.4).all()  # the CMM's
    cov = rec.extra["cov_centre_mm2"]
    np.testing.assert_allclose(np.sqrt(cov[:, 2, 2]) * 1e3, u["z"], rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(cov[:, 0, 0]) * 1e3, 1.5, rtol=1e-12)
    assert np.all(cov[:, 0, 1] == 0) and rec.extra["cov_from_file"].all()
    # every row points at its SphereFeatureMeasurement's line
    lines = qif.read_text().splitlines()
    assert all("<SphereFeatureMeasurement" in lines[n - 1] for n in rec.line)


def test_inch_is_converted_to_mm(tmp_path, centres):
    u = {"combined": np.full(len(centres), 2.54)}
    qif = write(tmp_path / "c.qif", results_qif(centres, unit="inch", uncertainty_um=u))
    check_document(qif)
    text = qif.read_text()
    first = re.search(r"<Location[^>]*>([^<]+)</Location>", text.split("<Results>")[1])
    x_inch = float(first.group(1).split()[0])
    assert x_inch == pytest.approx(centres.xyz_mm[0, 0] / 25.4, rel=1e-15)  # inch in the file
    (rec,) = read_measurements(qif)
    np.testing.assert_allclose(rec.xyz_mm, centres.xyz_mm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.diameter_mm, 25.4, rtol=1e-15)  # 1 inch
    np.testing.assert_allclose(rec.extra["u_um"], 2.54, rtol=1e-12)  # 0.0001 inch
    assert "inch (25.4 mm)" in scan_qif(qif).unit


def test_points_are_read_as_a_points_file(tmp_path, points):
    qif = write(tmp_path / "p.qif", results_qif(points, unit="inch", location_offset_mm=0.5))
    check_document(qif)
    (rec,) = read_measurements(qif)
    assert rec.kind == "points" and len(rec) == len(points)
    assert (rec.label == points.label).all() and (rec.ball == points.ball).all()
    np.testing.assert_allclose(rec.xyz_mm, points.xyz_mm, rtol=0, atol=1e-12)
    # a sphere's points carry its TimeStamp (written as the mean of its points' times)
    groups = rec.label.astype(object) + rec.ball.astype(object)
    for group in np.unique(groups):
        mine = groups == group
        assert np.ptp(rec.time_s[mine]) == 0
        assert rec.time_s[mine][0] == pytest.approx(points.time_s[mine].mean(), abs=1e-6)
    lines = qif.read_text().splitlines()
    assert float(lines[rec.line[0] - 1].split()[0]) * 25.4 == pytest.approx(rec.xyz_mm[0, 0])


def test_names_on_the_measurement_and_by_a_map(tmp_path, centres):
    def german(step, ball):
        return f"Kugel {ball[1:]} Pos {step}"

    qif = write(tmp_path / "c.qif", results_qif(centres, names=german, name_on="measurement"))
    check_document(qif)
    message = refusal(qif)  # off the map and off hexatherm's naming
    assert "field 'FeatureName'" in message and "'Kugel 1 Pos O'" in message
    names = {german(s, b): f"{s}_{b}" for s, b in zip(centres.label, centres.ball, strict=True)}
    names["Kugel 3 Pos O"] = None  # read past
    (rec,) = read_measurements(qif, names=names)
    assert len(rec) == len(centres) - 1 and "O_B3" not in set(rec.label + "_" + rec.ball)
    assert scan_qif(qif, names=names).skipped[0][1] == "Kugel 3 Pos O"


def test_a_time_from_the_results_when_a_feature_has_none(tmp_path, centres):
    text = results_qif(centres).decode()
    untimed = re.sub(r"<TimeStamp>[^<]*</TimeStamp>\s*", "", text)
    qif = write(tmp_path / "c.qif", untimed.encode())
    message = refusal(qif)
    assert "field 'TimeStamp'" in message and "has no TimeStamp" in message
    line = int(message.split(":")[1])
    assert "<SphereFeatureMeasurement" in untimed.splitlines()[line - 1]
    start = (
        '<MeasurementResults id="\\1">\n<InspectionTraceability>'
        "<InspectionStart>2026-11-27T10:00:00Z</InspectionStart></InspectionTraceability>"
    )
    timed = re.sub(r'<MeasurementResults id="(\d+)">', start, untimed)
    qif = write(tmp_path / "t.qif", timed.encode())
    check_document(qif)
    (rec,) = read_measurements(qif)
    start = datetime(2026, 11, 27, 10, tzinfo=UTC).timestamp()
    assert rec.time_aware is True and (rec.time_s == start).all()


def test_inspect_says_what_it_read(tmp_path, points, centres):
    qif = write(tmp_path / "p.qif", results_qif(points, unit="inch"))
    result = CliRunner().invoke(main, ["inspect", str(qif)])
    assert result.exit_code == 0, result.output
    assert "length unit inch (25.4 mm), converted to mm" in result.output
    steps = list(dict.fromkeys(points.label.tolist()))
    spheres = len(steps) * 3
    assert f"{spheres} spheres: steps {', '.join(steps)}; balls B1, B2, B3" in result.output
    assert "SPHERE+25" in result.output and f"({len(points)} points)" in result.output
    assert "names: hexatherm's <step>_<ball>" in result.output


# -- the consortium's samples --------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(READ))
def test_every_results_sample_is_read(name):
    path = SAMPLES / name
    assert is_qif(path)
    read = scan_qif(path)
    assert read.spheres == [] and read.records == []
    assert sum(read.others.values()) == READ[name]
    result = CliRunner().invoke(main, ["inspect", str(path)])
    assert result.exit_code == 0 and "no sphere feature measured" in result.output


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_samples_without_results_are_refused(name):
    message = refusal(SAMPLES / name)
    assert f":{REFUSED[name]}: field 'QIFDocument': a QIF document without Results" in message


# -- hostile files -----------------------------------------------------------------------


def test_an_unknown_or_contradictory_unit_is_refused(tmp_path, centres):
    text = results_qif(centres).decode()
    furlong = text.replace("<UnitName>mm</UnitName>", "<UnitName>furlong</UnitName>")
    furlong = re.sub(r"<UnitConversion>.*?</UnitConversion>", "", furlong, flags=re.S)
    assert "unknown length unit 'furlong'" in refusal(write(tmp_path / "f.qif", furlong.encode()))
    wrong = text.replace("<Factor>0.001</Factor>", "<Factor>0.0254</Factor>")
    message = refusal(write(tmp_path / "w.qif", wrong.encode()))
    assert "field 'Factor'" in message and "contradicts itself" in message
    none = re.sub(r"<FileUnits>.*?</FileUnits>", "", text, flags=re.S)
    assert "states no length unit" in refusal(write(tmp_path / "n.qif", none.encode()))


def test_a_truncated_file_is_refused(tmp_path, centres):
    data = results_qif(centres)
    message = refusal(write(tmp_path / "t.qif", data[: len(data) // 2]))
    assert "the XML ends early" in message or "not well-formed" in message


@pytest.mark.parametrize(
    "doctype",
    [
        '<!DOCTYPE QIFDocument [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;'
        '&a;&a;"><!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;'
        '&c;&c;&c;&c;"><!ENTITY e "&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;">]>',
        '<!DOCTYPE QIFDocument [<!ENTITY e SYSTEM "file:///etc/passwd">]>',
        '<!DOCTYPE QIFDocument SYSTEM "http://example.invalid/qif.dtd">',
    ],
    ids=["billion-laughs", "external-entity", "external-dtd"],
)
def test_a_dtd_is_refused_before_any_content(tmp_path, centres, doctype):
    text = results_qif(centres).decode()
    text = text.replace("?>\n", f"?>\n{doctype}\n", 1)
    text = text.replace("<Application>", "<Application>&e;", 1) if "&" in doctype else text
    message = refusal(write(tmp_path / "b.qif", text.encode()))
    assert "field 'DOCTYPE'" in message and "declares a DTD" in message


def test_a_huge_file_is_refused_by_its_size(tmp_path, centres):
    big = tmp_path / "big.qif"
    with open(big, "wb") as stream:  # sparse: no 2 GiB written
        stream.write(results_qif(centres)[:100])
        stream.truncate(2 * 1024**3 + 1)
    assert "above the limit of 2,147,483,648 bytes" in refusal(big)
    small = write(tmp_path / "s.qif", results_qif(centres))
    with pytest.raises(InputError, match="above the limit of 1,000 bytes"):
        read_qif(small, limit=1000)


def test_other_xml_and_non_xml_are_refused(tmp_path):
    other = write(tmp_path / "o.qif", b'<?xml version="1.0"?>\n<svg xmlns="x"/>\n')
    assert ":2: field 'svg': not a QIF 3 document" in refusal(other)
    assert "not XML" in refusal(write(tmp_path / "c.qif", b"label,ball,x,y,z,time\n"))
    wrong_ns = write(tmp_path / "n.qif", b'<QIFDocument versionQIF="3.0.0" idMax="0"/>')
    assert "expected QIFDocument in namespace" in refusal(wrong_ns)


def test_an_element_breaking_the_schema_is_refused(tmp_path, centres):
    text = results_qif(centres).decode()
    bad = re.sub(
        r"(<SphereFeatureMeasurement[^>]*>.*?<Diameter>)[^<]*", r"\1abc", text, count=1, flags=re.S
    )
    message = refusal(write(tmp_path / "d.qif", bad.encode()))
    line = int(message.split(":")[1])
    assert "<Diameter>abc</Diameter>" in bad.splitlines()[line - 1]
    assert "field 'Diameter': breaks the QIF 3 schema" in message
    extra = text.replace("<TimeStamp>", "<Colour>red</Colour><TimeStamp>", 1)
    message = refusal(write(tmp_path / "e.qif", extra.encode()))
    assert "field 'Colour': breaks the QIF 3 schema" in message


def test_content_sniffing_and_a_refusal_on_the_command_line(tmp_path, centres):
    renamed = write(tmp_path / "export.xml", results_qif(centres))
    assert is_qif(renamed) and len(read_measurements(renamed)[0]) == len(centres)
    bad = write(tmp_path / "b.qif", results_qif(centres)[:-40])
    result = CliRunner().invoke(main, ["inspect", str(bad)])
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1 and str(bad) in result.output


def test_a_range_of_a_point_set_and_a_range_out_of_it(tmp_path, points):
    text = results_qif(points).decode()
    first = re.search(r"<WholePointSetId>(\d+)</WholePointSetId>", text)
    ranged = text.replace(
        first.group(0), f'<RangePointSetId range="3 12">{first.group(1)}</RangePointSetId>'
    )
    qif = write(tmp_path / "r.qif", ranged.encode())
    check_document(qif)
    (rec,) = read_measurements(qif)
    assert len(rec) == len(points) - 15  # points 3 to 12 of the first ball's 25
    np.testing.assert_array_equal(rec.xyz_mm[:10], points.xyz_mm[2:12])
    assert rec.extra["n"][0] == f"{first.group(1)}-3"
    beyond = text.replace(
        first.group(0), f'<RangePointSetId range="3 40">{first.group(1)}</RangePointSetId>'
    )
    message = refusal(write(tmp_path / "b.qif", beyond.encode()))
    assert "field 'PointList': points 3 to 40 of MeasuredPointSet" in message


def test_inspect_lists_foreign_names_and_shows_a_sessions_map(tmp_path, centres):
    def german(step, ball):
        return f"Kugel {ball[1:]} Pos {step}"

    qif = write(tmp_path / "c.qif", results_qif(centres, names=german))
    plain = CliRunner().invoke(main, ["inspect", str(qif)])
    assert plain.exit_code == 0, plain.output
    assert f"{len(centres)} spheres named neither <step>_<ball> nor by a map" in plain.output
    assert "'Kugel 1 Pos O'" in plain.output and "process refuses them" in plain.output
    names = "".join(
        f'  "{german(s, b)}": {s}_{b}\n' for s, b in zip(centres.label, centres.ball, strict=True)
    )
    session = tmp_path / "session.yaml"
    session.write_text(f"format: hexatherm-session/1\nfeature_names:\n{names}")
    mapped = CliRunner().invoke(main, ["inspect", str(qif), "--session", str(session)])
    assert mapped.exit_code == 0, mapped.output
    assert "names mapped by feature_names: 'Kugel 1 Pos O' -> O_B1" in mapped.output
    assert "neither" not in mapped.output and " O_B1 " in mapped.output


def test_deep_nesting_is_refused_not_recursed(tmp_path):
    deep = b'<QIFDocument xmlns="http://qifstandards.org/xsd/qif3">' + b"<a>" * 100_000
    message = refusal(write(tmp_path / "d.qif", deep))
    assert message.endswith("not well-formed XML: Excessive depth in document: 256")
