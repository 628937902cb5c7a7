"""A hostile-input audit, round 3 (issue 36): ``--overwrite`` across commands, lab templates
that do not end, escape their folder or sit beside huge files, and small tracebacks.

Each case is refused in one line (exit status 1, no traceback), nothing is written and
no input or other command's output is touched; or, for the positive cases, the same
command replaces its own output.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.cli.options import template_files
from hexatherm.errors import InputError
from hexatherm.io import provenance
from hexatherm.io.manifest import read_manifest
from hexatherm.io.outputs import output_dir
from hexatherm.io.provenance import run_context
from hexatherm.workflows.report import sandbox
from hexatherm.workflows.report.render import check_template_dir, render_page
from hexatherm.workflows.report.sandbox import MAX_OPERATIONS
from tests.audit import ROOT, hashes, refusal, session_copy
from tests.shipped import SHIPPED as SHIPPED_SESSIONS
from tests.workflows.test_audit_report import templates as lab_folder

HEXAPOD = ROOT / "configs" / "symetrie-like.yaml"
BALLS = ROOT / "configs" / "balls-3.yaml"


def invoke(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def write_plan(folder: Path) -> Path:
    """``plan -o folder/plan.yaml`` (with its DMIS program and checklist)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "t.csv").write_text("Tx,Ty,Tz,Rx,Ry,Rz\n5,-3,2,0.5,-0.4,3\n")
    made = invoke(
        "plan", "--hexapod", HEXAPOD, "--balls", BALLS, "--targets", folder / "t.csv",
        "-o", folder / "plan.yaml", "--dmis", folder / "plan.dmi",
        "--origin-on-cmm", "400,300,100,0,0,0", "--checklist", folder / "check.md",
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    return folder / "plan.yaml"


# ------------------------------------------------- item 4: --overwrite, same command only


def test_report_overwrite_does_not_replace_the_plan(tmp_path):
    plan = write_plan(tmp_path / "lab")
    session = session_copy(tmp_path)
    before = hashes(tmp_path / "lab", session)
    result = invoke("report", session, "-o", plan, "--overwrite")
    line = refusal(result)
    assert "plan.yaml (written by hexatherm plan, not report)" in line, line
    assert hashes(tmp_path / "lab", session) == before


def test_plan_overwrite_replaces_its_own_plan(tmp_path):
    plan = write_plan(tmp_path / "lab")
    first = plan.read_bytes()
    (tmp_path / "lab" / "t.csv").write_text("Tx,Ty,Tz,Rx,Ry,Rz\n1,2,3,0,0,0\n")
    again = invoke(
        "plan", "--hexapod", HEXAPOD, "--balls", BALLS, "--targets", tmp_path / "lab" / "t.csv",
        "-o", plan, "--overwrite",
    )  # fmt: skip
    assert again.exit_code == 0, again.output
    assert plan.read_bytes() != first
    assert read_manifest(plan.parent).commands["plan.yaml"] == "plan"


def test_a_file_without_a_record_of_its_command_is_not_replaced(tmp_path):
    """A file hexatherm's manifest lists without the command that wrote it (a script's,
    or an older hexatherm's) is not a report's to replace."""
    out = tmp_path / "out"
    with output_dir(out) as tmp:  # outside a command line: no command recorded
        (tmp / "report.html").write_text("<p>a script's page</p>\n")
    session = session_copy(tmp_path)
    before = hashes(out)
    line = refusal(invoke("report", session, "-o", out / "report.html", "--overwrite"))
    assert "report.html (written by hexatherm with no record of its command)" in line, line
    assert hashes(out) == before


def processed(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    session = session_copy(tmp_path)
    done = invoke("process", session, "--mc", 0)
    assert done.exit_code == 0, done.output
    return session, hashes(session / "results")


def test_diagnose_and_calibrate_overwrite_do_not_replace_process_results(tmp_path):
    session, results = processed(tmp_path)
    for command in ("diagnose", "calibrate"):
        line = refusal(invoke(command, session, "-o", session / "results", "--overwrite"))
        assert f"(written by hexatherm process, not {command})" in line, line
        assert hashes(session / "results") == results
    again = invoke("process", session, "--mc", 0, "--overwrite")  # its own: replaced
    assert again.exit_code == 0, again.output
    assert read_manifest(session / "results").commands["poses.csv"] == "process"


def test_process_overwrite_does_not_replace_a_diagnosis(tmp_path):
    session = session_copy(tmp_path)
    diagnosis = tmp_path / "diagnosis"
    with run_context("diagnose", [str(session)], {}), output_dir(diagnosis) as tmp:
        (tmp / "diagnosis.json").write_text("{}\n")
    before = hashes(diagnosis)
    line = refusal(invoke("process", session, "-o", diagnosis, "--overwrite"))
    assert "diagnosis.json, provenance.json (written by hexatherm diagnose, not process)" in line
    assert hashes(diagnosis) == before


def test_a_manifest_nested_past_the_parser_vouches_for_nothing(tmp_path):
    session, _ = processed(tmp_path)
    (session / "results" / ".hexatherm-manifest.json").write_text("[" * 200_000)
    before = hashes(session / "results")
    line = refusal(invoke("process", session, "--mc", 0, "--overwrite"))
    assert "not written by hexatherm: no .hexatherm-manifest.json" in line, line
    assert hashes(session / "results") == before


# ------------------------------------------ item 5: a lab's template that does not end


def page_refused(folder: Path) -> InputError:
    """The lab's ``closing.html.j2`` rendered alone: refused in one line, naming it."""
    with pytest.raises(InputError) as caught:
        render_page("closing.html.j2", folder.resolve())
    error = caught.value
    assert "\n" not in str(error) and error.path == str(folder.resolve() / "closing.html.j2")
    return error


@pytest.mark.parametrize(
    ("body", "said"),
    [
        # a loop that does not end in any useful time: 10^10 iterations
        (
            "{% for i in range(100000) %}{% for j in range(100000) %}{% endfor %}{% endfor %}",
            f"more than {MAX_OPERATIONS} loop iterations and calls",
        ),
        # the same over a string: no call at all in the loops
        (
            "{% set s = 'x' * 100000 %}{% for a in s %}{% for b in s %}{% endfor %}{% endfor %}",
            f"more than {MAX_OPERATIONS} loop iterations and calls",
        ),
        ("{{ 'x' * 100000 * 100000 }}", "a repetition of 10000000000 items"),
        ("{{ 10 ** (10 ** 7) }}", "a power of 40000000 bits"),
        ("{{ range(10 ** 9) | length }}", "range() of 1000000000 numbers"),
        ("{{ '{:>999999999}'.format(1) }}", "a formatted string of 1000000012 items"),
        ("{{ '%0999999999d' % 1 }}", "a formatted string of 1000000011 items"),
        ("{{ 'x' | center(10 ** 9) }}", "a centred string of 1000000001 items"),
        ("{{ 'ab' | replace('a', 'x' * 10000000) | replace('x', 'yy' * 5) }}", "a replacement"),
        # doubling with ~ in a loop of 40 steps: 2^40 characters
        (
            "{% set ns = namespace(s='x') %}{% for i in range(40) %}"
            "{% set ns.s = ns.s ~ ns.s %}{% endfor %}{{ ns.s | length }}",
            "a value of 33554432 items",
        ),
        ("{{ 1 / 0 }}", "template: ZeroDivisionError: division by zero"),
        ("{{ 'a' + 1 }}", "template: TypeError: can only concatenate str"),
    ],
)
def test_a_template_that_does_not_end_or_fills_the_memory_is_refused(tmp_path, body, said):
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": f"<p>\n{body}\n</p>\n"})
    error = page_refused(folder)
    assert said in error.message and error.line == 2, error


def test_an_asset_embedded_2000_times_is_refused_by_the_pages_size(tmp_path, monkeypatch):
    monkeypatch.setattr(sandbox, "MAX_PAGE_CHARS", 8 * 2**20)  # 256 MiB, as small as a test
    png = b"\x89PNG\r\n\x1a\n" + bytes(2**20)
    loop = "{% for i in range(2000) %}<img src=\"{{ asset('logo.png') }}\">{% endfor %}"
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": loop, "logo.png": png})
    error = page_refused(folder)
    assert f"a page of more than {8 * 2**20} characters" in error.message, error


def test_what_no_check_sees_is_bounded_by_the_memory_net(tmp_path, monkeypatch):
    """``tojson`` of a list holding one long string ten times: no check of the sandbox
    counts it; the address space's bound refuses it (Linux)."""
    if not Path("/proc/self/statm").exists():
        pytest.skip("no /proc/self/statm")
    monkeypatch.setattr(sandbox, "MAX_RENDER_BYTES", 256 * 2**20)
    body = "{% set s = 'x' * 16000000 %}{{ ([s] * 40) | tojson | length }}"
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": body, "ok.j2": "<p>fine</p>"})
    error = page_refused(folder)
    assert "the page needs too much memory" in error.message, error
    assert render_page("ok.j2", folder.resolve()) == "<p>fine</p>"  # the process lives on


def test_a_bounded_template_still_renders(tmp_path):
    """The bounds leave a lab's ordinary template alone (a loop, a join, a format)."""
    body = (
        "{% for i in range(3) %}{{ '%03d' % i }}{% endfor %} {{ ['a', 'b'] | join('-') }} "
        "{{ '{:>6}'.format('x') }} {{ 2 ** 10 }} {{ 'ab' * 3 }} {{ 'x' | center(5) }}"
    )
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": body})
    page = render_page("closing.html.j2", folder.resolve())
    assert page == "000001002 a-b      x 1024 ababab   x  "


# ---------------------------------- item 6: links out of the folder, names computed


def test_a_linked_sub_folder_is_refused_by_templates_as_by_assets(tmp_path):
    elsewhere = lab_folder(tmp_path / "elsewhere", {"x.j2": "<p>secret</p>\n"})
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": '{% include "sub/x.j2" %}\n'})
    (folder / "sub").symlink_to(elsewhere, target_is_directory=True)
    with pytest.raises(InputError, match="a link out of the template folder") as caught:
        check_template_dir(folder)
    assert caught.value.path == str(folder.resolve() / "sub" / "x.j2")


def test_a_file_read_by_a_computed_name_is_refused_and_a_named_one_is_in_the_provenance(
    tmp_path,
):
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": '{% include "sub/a.j2" %}\n'})
    lab_folder(folder / "sub", {"a.j2": "<p>a</p>\n", "b.j2": "<p>b</p>\n"})
    assert template_files(folder.resolve()) == [
        folder.resolve() / "closing.html.j2",
        folder.resolve() / "sub" / "a.j2",
    ]
    assert render_page("closing.html.j2", folder.resolve()) == "<p>a</p>\n"
    computed = lab_folder(tmp_path / "c", {"closing.html.j2": "{% include 'sub/' ~ n %}\n"})
    lab_folder(computed / "sub", {"b.j2": "<p>b</p>\n"})
    with pytest.raises(InputError, match="name computed while rendering") as caught:
        render_page("closing.html.j2", computed.resolve(), n="b.j2")
    assert caught.value.path == str(computed.resolve() / "sub" / "b.j2")


# ------------------------------------ item 7: what is read is hashed, nothing else


def test_a_huge_file_nothing_reads_is_neither_read_nor_hashed(tmp_path, monkeypatch):
    session = session_copy(tmp_path)
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": "<p>closing</p>\n"})
    with open(folder / "archive.bin", "wb") as handle:
        handle.truncate(100 * 2**30)  # sparse: 100 GiB that no disk holds
    hashed: list[Path] = []
    real = provenance._sha256

    def spy(path: Path) -> str:
        assert path.name != "archive.bin", "the unused 100 GiB file is hashed"
        hashed.append(path)
        return real(path)

    monkeypatch.setattr(provenance, "_sha256", spy)
    out = tmp_path / "report.html"
    done = invoke("report", session, "--template-dir", folder, "-o", out)
    assert done.exit_code == 0, done.output
    assert folder / "closing.html.j2" in hashed
    page = out.read_text(encoding="utf-8")
    assert "closing.html.j2" in page and "archive.bin" not in page


def test_a_huge_asset_is_refused_before_it_is_hashed(tmp_path):
    folder = lab_folder(tmp_path / "t", {"closing.html.j2": "<img src=\"{{ asset('a.png') }}\">"})
    with open(folder / "a.png", "wb") as handle:
        handle.truncate(100 * 2**30)
    with pytest.raises(InputError, match="asset 'a.png': 107374182400 bytes") as caught:
        template_files(folder.resolve())
    assert caught.value.path == str(folder.resolve() / "closing.html.j2") and caught.value.line == 1


# ------------------------------------------------------------------- the low list


@pytest.mark.parametrize(
    ("air", "field"),
    [("1e308", "heating.air_C"), ("[[0, 20.0], [14400, 1.0e+308]]", "heating.air_C[1][1]")],
)
def test_an_ambient_of_1e308_degC_is_refused(tmp_path, air, field):
    text = (SHIPPED_SESSIONS / "with-hidden-effect" / "truth" / "scenario.yaml").read_text()
    text = text.replace("../symetrie-like.yaml", str(ROOT / "configs" / "symetrie-like.yaml"))
    text = text.replace("../balls-3.yaml", str(BALLS))
    text = text.replace("air_C: [[0, 20.0], [14400, 20.2]]", f"air_C: {air}")
    assert f"air_C: {air}" in text
    (tmp_path / "scenario.yaml").write_text(text)
    line = refusal(invoke("simulate", tmp_path / "scenario.yaml", "-o", tmp_path / "out"))
    assert f"field '{field}': a temperature must be within [-60, 150] degC" in line, line
    assert not (tmp_path / "out").exists()


def test_a_tolerance_repeated_in_two_options_is_a_usage_error(tmp_path):
    session = session_copy(tmp_path)
    result = invoke("process", session, "--tolerance", "Tx=2um", "--tolerance", "Tx=5um,Ty=1um")
    assert result.exit_code == 2, result.output
    assert "'Tx=5um,Ty=1um': Tx is given twice (in two --tolerance options)" in result.output
    assert not (session / "results").exists()


def test_a_name_in_diagnoses_markdown_has_no_raw_markup():
    """The hexapod's name went into report.md as a code span: literal for CommonMark, but
    a raw ``<script>`` in the file for anything else that reads it."""
    from hexatherm.workflows.diagnose.report.tables import md_code

    shown = md_code("<script>hx</script> & co")
    assert "<" not in shown.replace("\\<", "") and "&" not in shown.replace("\\&", "")
    assert shown == "\\<script\\>hx\\</script\\> \\& co"
    assert md_code("s/session.yaml") == "`s/session.yaml`"


def test_a_plan_message_shows_the_files_mapping_not_a_python_dict(tmp_path):
    session = session_copy(tmp_path)
    plan = session / "plan.yaml"
    plan.write_text(
        plan.read_text().replace("reference_pose: [0, 0, -40, 0, 0, 0]", "reference_pose: {x: 1}")
    )
    line = refusal(invoke("process", session, "--mc", 0))
    assert line.endswith("field 'reference_pose': expected a list of 6 numbers, got {x: 1}"), line


def test_u_um_contradicting_the_covariance_columns_is_said(tmp_path):
    from hexatherm.errors import InputWarning
    from hexatherm.io.csvfile import read_measurement_csv

    head = "label,ball,x,y,z,time,u_um,u_x_um,u_y_um,u_z_um\n"
    rows = "O,B1,1,2,3,0,{u},0.3,0.4,0.5\nO,B2,4,5,6,1,0.41,0.3,0.4,0.5\n"
    # sqrt((0.09 + 0.16 + 0.25) / 3) = 0.408 um: 0.41 agrees; 0.05 does not
    (tmp_path / "agree.csv").write_text(head + rows.format(u="0.408"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_measurement_csv(tmp_path / "agree.csv")
    (tmp_path / "c.csv").write_text(head + rows.format(u="0.05"))
    with pytest.warns(InputWarning) as said:
        read_measurement_csv(tmp_path / "c.csv")
    assert len(said) == 1
    assert str(said[0].message) == (
        f"{tmp_path / 'c.csv'}:2: field 'u_um': 0.05 um contradicts the covariance columns "
        "u_x_um, u_y_um, u_z_um (sqrt(tr C / 3) = 0.4082 um, more than 5% apart)"
    )


def test_1e400_is_not_the_word_inf(tmp_path):
    """``--pose-tolerance inf`` turns the check off on purpose; ``1e400`` overflowed to the
    same infinity and turned it off without a word."""
    session = session_copy(tmp_path)
    result = invoke("process", session, "--pose-tolerance", "1e400,1")
    assert result.exit_code == 2, result.output
    assert "'1e400': beyond a float's range (inf is written inf)" in result.output
    assert not (session / "results").exists()


def test_a_hexapod_with_every_joint_in_one_plane_is_refused_naming_the_file(tmp_path):
    """Every joint at y = 33 mm: the legs cannot hold the platform; the FGM's message
    named no file, and a command that reaches the kinematics otherwise ends there."""
    session = session_copy(tmp_path)
    hexapod = session / "hexapod.yaml"
    text = re.sub(r"- \[([-\d.]+), [-\d.]+, ([-\d.]+)\]", r"- [\1, 33.0, \2]", hexapod.read_text())
    hexapod.write_text(text)
    line = refusal(invoke("process", session, "--mc", 0))
    assert f"{hexapod}:" in line and "field 'platform_joints': the joints make no hexapod" in line
