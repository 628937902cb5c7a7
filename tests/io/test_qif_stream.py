"""The QIF reader parses a file incrementally (issue 37, item 2): a results file of scanned
points is several times the CSV's size, so the parse must not keep the tree. Each
feature read is cleared, and the point records are made per sphere and per range of a
point set, not per point."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import hexatherm.io.qif as qif
from hexatherm.io.qifrecords import Sphere, _point_records
from hexatherm.io.records import Records
from tests.io.qifwriter import results_qif


def scanned(n_steps: int, per_ball: int) -> Records:
    labels = np.repeat([f"S{i}" for i in range(n_steps)], 3 * per_ball)
    balls = np.tile(np.repeat(["B1", "B2", "B3"], per_ball), n_steps)
    n = len(labels)
    rng = np.random.default_rng(5)
    xyz = np.round(rng.normal(300, 50, (n, 3)), 4)
    times = 1.5e9 + np.arange(n, dtype=float) // 50
    return Records("t", "points", labels, balls, xyz, times, "iso", np.arange(n) + 2)


def test_the_tree_stays_small_while_a_large_file_is_parsed(tmp_path, monkeypatch):
    """Elements alive in the parsed tree, sampled through the parse of 1200 spheres of 40
    points (over 20,000 elements in the file): under a thousand (the elements read, which
    are cleared, and those the parser has read ahead in its buffer; the whole tree would
    hold every one)."""
    path = tmp_path / "scan.qif"
    path.write_bytes(results_qif(scanned(400, 40)))
    largest = [0]
    iterate = qif.iter_elements

    def watched(*args, **kwargs):
        root = None
        for count, (event, element) in enumerate(iterate(*args, **kwargs)):
            root = element if root is None else root
            if count % 97 == 0:
                largest[0] = max(largest[0], sum(1 for _ in root.iter()))
            yield event, element

    monkeypatch.setattr(qif, "iter_elements", watched)
    (points,) = qif.read_qif(path)
    assert len(points) == 400 * 3 * 40
    assert path.read_bytes().count(b"</") > 20_000  # elements in the file
    assert 0 < largest[0] < 1000, largest[0]


def test_point_records_are_those_made_point_by_point():
    """Against the records made one point at a time (the reader's former way): ranges of
    whole sets, of parts of sets, and of one point, sets shared by two spheres."""
    rng = np.random.default_rng(2)
    sets = {
        str(k): (rng.normal(size=(n, 3)), 10 * k + np.arange(n, dtype=np.int64))
        for k, n in ((3, 5), (17, 12), (250, 1), (1001, 30))
    }
    spheres = []
    for step, ball, refs in (
        ("O", "B1", [("3", 1, None, 4)]),
        ("O", "B2", [("17", 2, 11, 5), ("250", 1, 1, 6)]),
        ("S12", "B3", [("1001", 1, 30, 7)]),
        ("S12", "B10", [("17", 12, 12, 8), ("3", 2, 4, 9)]),
    ):
        sphere = Sphere(1, f"{step}_{ball}", step, ball, None, math.nan, "2024-03-05T07:30:00")
        sphere.point_sets.extend(refs)
        spheres.append(sphere)
    got = _point_records("f.qif", spheres, sets, aware=False)
    label, ball, number, xyz, line = [], [], [], [], []
    for sphere in spheres:
        for set_id, first, last, _ in sphere.point_sets:
            values, lines = sets[set_id]
            for i in range(first, (len(values) if last is None else last) + 1):
                label.append(sphere.step)
                ball.append(sphere.ball)
                number.append(f"{set_id}-{i}")
                xyz.append(values[i - 1])
                line.append(lines[i - 1])
    for name, want in (
        ("label", np.array(label, dtype=np.str_)),
        ("ball", np.array(ball, dtype=np.str_)),
        ("line", np.array(line, dtype=np.int64)),
        ("xyz_mm", np.array(xyz)),
    ):
        array = getattr(got, name)
        assert array.dtype == want.dtype and np.array_equal(array, want), name
    want_n = np.array(number, dtype=np.str_)
    assert got.extra["n"].dtype == want_n.dtype and np.array_equal(got.extra["n"], want_n)
    assert np.all(got.time_s == got.time_s[0]) and np.isnan(got.ijk).all()
    assert [s.points for s in spheres] == [5, 11, 30, 4]


def test_a_scanned_file_reads_as_its_records(tmp_path: Path):
    records = scanned(4, 400)
    path = tmp_path / "scan.qif"
    path.write_bytes(results_qif(records))
    (points,) = qif.read_qif(path)
    assert np.array_equal(points.xyz_mm, records.xyz_mm)
    assert np.array_equal(points.label, records.label)
    assert np.array_equal(points.ball, records.ball)
