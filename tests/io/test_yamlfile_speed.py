"""The plan's fast line reader gives what the general YAML reader gives.

``read_plan`` reads a plan in the layout of ``plan_to_yaml`` line by line and
leaves every other layout, and every plan with an error, to the general reader
(``YamlDoc``): the same plan bit for bit, the same messages (file, line, field).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hexatherm.core.plan import Plan
from hexatherm.errors import InputError
from hexatherm.io.config import plan_to_yaml, read_plan
from hexatherm.io.config.plan import _plan_from_doc, _read_plan_fast
from hexatherm.io.yamlfile import PLAIN_NUMBER, YamlDoc, plain_numbers, plain_tag
from tests.sessions import small_plan

SPEC_PLAN = """\
format: hexatherm-plan/1
reference_pose: [0, 0, -40, 0, 0, 0]
points_per_ball: 25                      # optional, default 25
steps:                                   # in the order they are measured
  - {label: O,  kind: origin,    pose: [0, 0, 0, 0, 0, 0]}
  - {label: R0, kind: reference, pose: [0, 0, -40, 0, 0, 0]}
  - {label: S1, kind: target,    pose: [1.5, -2.25e-3, 3E+2, 0.0, -0.0, 7e5]}
  - {label: R1, kind: reference, pose: [0, 0, -40, 0, 0, 0]}
"""


def general(text: str) -> Plan:
    """The plan as the general reader gives it."""
    return _plan_from_doc(YamlDoc.from_text(text, "plan.yaml"))


def outcome(read, text: str) -> tuple[str, ...]:
    """A plan as bytes, or the error message: equal outcomes are the same plan or error."""
    try:
        plan = read(text)
    except InputError as exc:
        return ("error", str(exc))
    return (
        "plan",
        repr(plan.labels),
        repr(plan.kinds),
        plan.poses.dtype.str,
        repr(plan.poses.shape),
        plan.poses.tobytes().hex(),
        plan.reference_pose.dtype.str,
        plan.reference_pose.tobytes().hex(),
        repr(plan.points_per_ball),
    )


def read_plan_text(text: str) -> Plan:
    """The plan as ``read_plan`` gives it: fast when it can, else general."""
    fast = _read_plan_fast(text)
    return general(text) if fast is None else fast


def assert_fast(text: str) -> None:
    """The fast reader takes ``text`` and gives the general reader's plan."""
    fast = _read_plan_fast(text)
    assert fast is not None
    assert outcome(lambda _: fast, text) == outcome(general, text)


# ----------------------------------------------------------------------------- same plans
def test_fast_reader_gives_the_general_readers_plan():
    for plan in (small_plan(1), small_plan(300, seed=7)):
        text = plan_to_yaml(plan)
        assert_fast(text)
        assert outcome(read_plan_text, text) == outcome(general, text)
        np.testing.assert_array_equal(_read_plan_fast(text).poses, plan.poses)


def test_read_plan_takes_the_fast_reader(tmp_path, monkeypatch):
    path = tmp_path / "plan.yaml"
    path.write_text(plan_to_yaml(small_plan(20)))
    want = outcome(general, path.read_text())

    def no_yaml(*args, **kwargs):
        raise AssertionError("read as YAML")

    monkeypatch.setattr(YamlDoc, "from_text", no_yaml)
    assert outcome(lambda _: read_plan(path), "") == want


@pytest.mark.parametrize(
    "mutate",
    [
        lambda t: t,
        lambda t: t.replace("\n", "\r\n"),
        lambda t: t.replace("\n  - ", "\n- "),
        lambda t: t.replace(
            "points_per_ball: 25                      # optional, default 25\n", ""
        ),
        lambda t: t.replace("points_per_ball: 25", "points_per_ball: 4"),
        lambda t: t.replace("format: hexatherm-plan/1\n", "") + "format: hexatherm-plan/1\n",
        lambda t: "# a plan\n\n" + t.replace("\n  - {label: R0", "\n\n    # R0\n  - {label: R0"),
        lambda t: t.replace("S1,", "12,").replace("R1,", "0,"),
        lambda t: t.replace("label: O,", "label: y,").replace("R0,", "no-1,"),
        lambda t: t.replace("{label: S1, ", "{ label:   S1 ,").replace("7e5]}", "7e5 ] }  "),
    ],
)
def test_fast_reader_layouts(mutate):
    assert_fast(mutate(SPEC_PLAN))


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("label: S1", "label: 'S1'"),  # quoted
        ("label: S1", "label: 010"),  # YAML 1.1 octal: label 8
        ("label: S1", "label: 0x1F"),  # hex: label 31
        ("1.5,", "+1.5,"),
        ("1.5,", "1_5.0,"),
        ("1.5,", ".5,"),
        ("1.5,", "-0,"),  # the int 0
        ("1.5,", "1.5\t,"),
        ("# optional", "# optional, 25 °C"),
        ("{label: S1, kind: target,    pose:", "{kind: target, label: S1, pose:"),
        ("  - {label: R1", "  -\n    {label: R1"),
        ("format: hexatherm-plan/1", "---\nformat: hexatherm-plan/1"),
    ],
)
def test_other_layouts_are_read_as_yaml(old, new):
    text = SPEC_PLAN.replace(old, new, 1)
    assert text != SPEC_PLAN
    assert _read_plan_fast(text) is None
    assert outcome(read_plan_text, text) == outcome(general, text)
    general(text)  # all valid plans


def test_octal_label_reads_as_yaml_says(tmp_path):
    path = tmp_path / "plan.yaml"
    path.write_text(SPEC_PLAN.replace("label: S1", "label: 010"))
    assert read_plan(path).labels[2] == "8"


# ----------------------------------------------------------------------------- same errors
@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "pose: [1.5, -2.25e-3, 3E+2, 0.0, -0.0, 7e5]",
            "pose: [1.5, 2, 3, 4, 5]",
            "plan.yaml:7: field 'steps[2].pose': expected a list of 6 numbers, got [1.5, 2, 3, 4, 5]",  # noqa: E501
        ),
        (
            "7e5]",
            "7e999]",
            "plan.yaml:7: field 'steps[2].pose[5]': expected a finite number, got inf",
        ),
        (
            "label: R1, kind: reference, pose: [0, 0, -40",
            "label: R1, kind: reference, pose: [0, 0, -41",
            "plan.yaml:8: field 'steps[3].pose': reference step pose [0.0, 0.0, -41.0, 0.0, 0.0, "
            "0.0] differs from reference_pose [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]",
        ),
        (
            "label: R1",
            "label: S1",
            "plan.yaml:8: field 'steps[3]': step S1: duplicate label (also step 3)",
        ),
        (
            "label: S1",
            "label: yes",
            "plan.yaml:7: field 'steps[2].label': expected a label, got True",
        ),
        (
            "label: S1",
            "label: 2024-01-01",
            "plan.yaml:7: field 'steps[2].label': expected a label, got datetime.date(2024, 1, 1)",
        ),
        (
            "kind: target",
            "kind: targte",
            "plan.yaml:7: field 'steps[2].kind': expected one of origin, reference, target, "
            "got 'targte'",
        ),
        (
            "label: R0, kind: reference",
            "label: R0, kind: origin",
            "plan.yaml:6: field 'steps[1]': step R0: only one origin step is allowed",
        ),
        (
            "points_per_ball: 25",
            "points_per_ball: 0",
            "plan.yaml:3: field 'points_per_ball': must be positive, got 0.0",
        ),
        (
            "points_per_ball: 25",
            "points_per_ball: 25\nnote: x",
            "plan.yaml:4: field 'note': unknown key; expected one of: format, reference_pose, "
            "points_per_ball, steps",
        ),
        (
            "points_per_ball: 25",
            "points_per_ball: 25\npoints_per_ball: 25",
            "plan.yaml:4: field 'points_per_ball': duplicate key",
        ),
        (
            "format: hexatherm-plan/1",
            "format: hexatherm-plan/2",
            "plan.yaml:1: field 'format': expected format 'hexatherm-plan/1', got "
            "'hexatherm-plan/2'",
        ),
        (
            "  - {label: O,  kind: origin,    pose: [0, 0, 0, 0, 0, 0]}\n",
            "",
            "plan.yaml:5: field 'steps[0]': step R0: the first step must be the origin "
            "(kind: origin)",
        ),
        (
            "  - {label: R1",
            "    - {label: R1",
            "plan.yaml:8: invalid YAML: did not find expected '-' indicator",
        ),
    ],
)
def test_errors_are_the_general_readers(tmp_path, old, new, message):
    text = SPEC_PLAN.replace(old, new, 1)
    assert text != SPEC_PLAN
    assert _read_plan_fast(text) is None
    path = tmp_path / "plan.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as exc:
        read_plan(path)
    assert str(exc.value) == f"{tmp_path}/{message}"
    assert outcome(read_plan_text, text) == outcome(general, text)


# ----------------------------------------------------------------------------- scalars
@settings(max_examples=300, deadline=None)
@given(st.from_regex(re.compile(PLAIN_NUMBER), fullmatch=True))
def test_plain_numbers_are_yaml_numbers(text):
    doc = YamlDoc.from_text(f"a: [{text}]\n", "n.yaml")
    try:
        want = doc.number("a", 0)
    except InputError:
        want = None
    got = plain_numbers([text])
    if got is None:
        assert want is None or text == "-0"
    else:
        assert want is not None and np.float64(got[0]).tobytes() == np.float64(want).tobytes()


@pytest.mark.parametrize(
    ("text", "tag"),
    [
        ("S1", "str"),
        ("on", "bool"),
        ("No", "bool"),
        ("null", "null"),
        ("12", "int"),
        ("1e5", "float"),
        ("2024-01-01", "timestamp"),
        ("y", "str"),
        ("a-1", "str"),
    ],
)
def test_plain_tag(text, tag):
    assert plain_tag(text) == tag
    value = YamlDoc.from_text(f"a: {text}\n", "t.yaml").data["a"]
    assert (type(value).__name__ == "str") == (tag == "str")


# ----------------------------------------------------------------------------- fuzzing
EDITS = st.lists(
    st.tuples(
        st.integers(0, 10_000),
        st.integers(0, 3),
        st.sampled_from(
            [
                " ",
                "\n",
                "-",
                "0",
                "1",
                "e",
                ".",
                ",",
                ":",
                "#",
                "[",
                "]",
                "{",
                "}",
                "'",
                "\t",
                "\r",
                "+",
                "_",
                "y",
                "O",
                "-0",
                "  - ",
            ]
        ),
    ),
    min_size=1,
    max_size=3,
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(EDITS)
def test_fuzzed_plans_read_as_yaml_says(edits):
    text = SPEC_PLAN
    for position, cut, insert in edits:
        position %= len(text) + 1
        text = text[:position] + insert + text[position + cut :]
    assert outcome(read_plan_text, text) == outcome(general, text)


def test_an_origin_off_zero_is_refused_by_the_fast_reader_too() -> None:
    """The fuzzed test above found it (one '1' typed into O's pose): the fast reader took
    an origin step off the zero pose that the general reader refuses."""
    text = SPEC_PLAN.replace("kind: origin,    pose: [0,", "kind: origin,    pose: [10,", 1)
    assert text != SPEC_PLAN
    assert outcome(read_plan_text, text) == outcome(general, text)
    assert outcome(general, text)[0] == "error"


def test_a_missing_vector_takes_its_default_and_a_given_one_is_checked() -> None:
    """A vector with a default was refused as 'missing (required)' when left out of a
    scenario (origin_on_cmm) or a datums file (origin_offset)."""
    doc = YamlDoc.from_text("a: [1, 2, 3]\nb: [1, x, 3]\n", "d.yaml")
    assert doc.vector("missing", size=3, default=[0, 0, 1]) == [0.0, 0.0, 1.0]
    assert doc.vector("a", size=3, default=[0, 0, 0]) == [1.0, 2.0, 3.0]
    with pytest.raises(InputError, match="d.yaml:2: field 'b\\[1\\]'"):
        doc.vector("b", size=3, default=[0, 0, 0])
    with pytest.raises(InputError, match="missing"):
        doc.vector("missing", size=3)
