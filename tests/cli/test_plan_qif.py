"""``plan --qif``: the plan as a QIF 3 document of sphere features, valid by the schema."""

from __future__ import annotations

import numpy as np
import pytest
from lxml import etree

from hexatherm.errors import InputError
from hexatherm.io.config import read_balls, read_plan
from hexatherm.io.qif import read_qif
from hexatherm.io.qifschema import QIF_NS, check_document
from tests.cli.test_plan import BALLS, base_args, run


def test_plan_qif_names_every_ball_of_every_step_at_its_nominal_centre(tmp_path):
    origin = (450.0, 320.0, 210.0)  # frame O on the CMM: a pure translation
    result = run(
        *base_args(tmp_path),
        "-o",
        tmp_path / "plan.yaml",
        "--qif",
        tmp_path / "plan.qif",
        "--origin-on-cmm",
        ",".join(f"{v:g}" for v in origin) + ",0,0,0",
    )
    assert result.exit_code == 0, result.output
    assert f"wrote {tmp_path / 'plan.qif'}" in result.output
    check_document(tmp_path / "plan.qif")  # the official QIF 3 schema, whole
    plan, balls = read_plan(tmp_path / "plan.yaml"), read_balls(BALLS)
    root = etree.parse(str(tmp_path / "plan.qif")).getroot()
    ns = {"q": QIF_NS}
    names = root.xpath("//q:SphereFeatureItem/q:FeatureName/text()", namespaces=ns)
    assert names == [f"{s}_{b}" for s in plan.labels for b in balls.names]
    nominal = {
        n.get("id"): [float(v) for v in n.findtext("q:Location", namespaces=ns).split()]
        for n in root.xpath("//q:SphereFeatureNominal", namespaces=ns)
    }
    items = root.xpath("//q:SphereFeatureItem", namespaces=ns)
    centres = np.array([nominal[i.findtext("q:FeatureNominalId", namespaces=ns)] for i in items])
    centres = centres.reshape(len(plan.labels), len(balls.names), 3)
    # at a pose that is a pure translation the balls are where the platform frame puts them
    for step, pose in enumerate(plan.poses):
        if np.all(pose[3:] == 0):
            expected = balls.centres_mm + np.asarray(origin) + pose[:3]
            np.testing.assert_allclose(centres[step], expected, rtol=0, atol=1e-9)
    assert np.sum(np.all(plan.poses[:, 3:] == 0, axis=1)) >= 2  # O and the Tz=10 target
    steps = root.xpath("//q:OrderedPlanRoot/q:Steps/q:NumberedPlanElement", namespaces=ns)
    assert len(steps) == len(names)
    # a plan is no results file: the reader says so
    with pytest.raises(InputError, match="a QIF document without Results"):
        read_qif(tmp_path / "plan.qif")


def test_plan_qif_needs_the_origin_on_the_cmm(tmp_path):
    result = run(*base_args(tmp_path), "--qif", tmp_path / "p.qif")
    assert result.exit_code == 2 and "--qif needs --origin-on-cmm" in result.stderr
    assert not (tmp_path / "p.qif").exists()
