"""Odd option values and bad sessions on the command line (issue 12, items 5, 6, 9-11, 13, 14).

Every case: a usage error (exit 2, click's ``Invalid value for '--option'``) or an input
error (exit 1), one line after ``Error:`` naming the option or the file, line and field,
no traceback, the session's files byte-identical and no output left behind.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from tests.sessions import ROOT, make_session
from tests.shipped import SHIPPED

DATUMS = SHIPPED / "register-datums"


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cli") / "s"
    make_session(folder)
    shutil.rmtree(folder / "truth")
    return folder


@pytest.fixture
def session(pristine, tmp_path):
    target = tmp_path / "s"
    shutil.copytree(pristine, target)
    return target


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def error_line(output: str) -> str:
    lines = [x for x in output.splitlines() if x.startswith("Error: ")]
    assert len(lines) == 1, output
    return lines[0]


#: option values refused before anything is read: (command, args, exit code, pattern)
USAGE = {
    "process --mc -1": ("process", ["--mc", "-1"], r"'--mc': -1 is not in the range 0<=x<="),
    "process --mc 1": ("process", ["--mc", "1"], r"'--mc': Monte Carlo needs at least 2 draws"),
    "process --mc huge": ("process", ["--mc", "10000000"], r"'--mc': 10000000 is not in"),
    "process --mc 2.5": ("process", ["--mc", "2.5"], r"'--mc': '2\.5' is not a valid integer"),
    "process --mc nan": ("process", ["--mc", "nan"], r"'--mc': 'nan' is not a valid integer"),
    "process --seed -1": ("process", ["--seed", "-1"], r"'--seed': -1 is not in the range"),
    "process --seed 2^70": ("process", ["--seed", str(2**70)], r"'--seed': \d+ is not in"),
    "process --seed text": ("process", ["--seed", "abc"], r"'--seed': 'abc' is not a valid"),
    "process --distance-tolerance-um nan": (
        "process",
        ["--distance-tolerance-um", "nan"],
        r"'--distance-tolerance-um': 'nan' is not a number",
    ),
    "process --distance-tolerance-um -1": (
        "process",
        ["--distance-tolerance-um", "-1"],
        r"'--distance-tolerance-um': '-1': must be >= 0",
    ),
    "process --distance-tolerance-um empty": (
        "process",
        ["--distance-tolerance-um", ""],
        r"'--distance-tolerance-um': '' is not a number",
    ),
    "process --registration-tolerance-um nan": (
        "process",
        ["--registration-tolerance-um", "nan"],
        r"'--registration-tolerance-um': 'nan' is not a number",
    ),
    "process --registration-tolerance-um -inf": (
        "process",
        ["--registration-tolerance-um", "-inf"],
        r"'--registration-tolerance-um': '-inf': must be >= 0",
    ),
    "process --pose-tolerance nan": (
        "process",
        ["--pose-tolerance", "nan,1"],
        r"'--pose-tolerance': 'nan' is not a number",
    ),
    "process --pose-tolerance one number": (
        "process",
        ["--pose-tolerance", "2"],
        r"'--pose-tolerance': '2': expected MM,DEG \(e\.g\. 2,1\) or inf",
    ),
    "process --pose-tolerance three numbers": (
        "process",
        ["--pose-tolerance", "1,2,3"],
        r"'--pose-tolerance': '1,2,3': expected MM,DEG",
    ),
    "process --pose-tolerance zero": (
        "process",
        ["--pose-tolerance", "0,1"],
        r"'--pose-tolerance': '0': must be > 0",
    ),
    "process --pose-tolerance negative": (
        "process",
        ["--pose-tolerance", "2,-1"],
        r"'--pose-tolerance': '-1': must be > 0",
    ),
    "process --pose-tolerance text": (
        "process",
        ["--pose-tolerance", "a,b"],
        r"'--pose-tolerance': 'a' is not a number",
    ),
    "process --interpolation bogus": (
        "process",
        ["--interpolation", "cubic"],
        r"'--interpolation': 'cubic' is not one of",
    ),
    "process --method bogus": ("process", ["--method", "magic"], r"'--method': 'magic' is not"),
    "process --hexapod without twin": (
        "process",
        ["--hexapod", ROOT / "configs" / "symetrie-like.yaml"],
        r"'--hexapod': --hexapod is the twin's model: use it with --method twin",
    ),
    "process --pose-tolerance empty": (
        "process",
        ["--pose-tolerance", ""],
        r"'--pose-tolerance': '': expected MM,DEG",
    ),
    "replay --tol-mm nan": ("replay", ["--tol-mm", "nan"], r"'--tol-mm': 'nan' is not a number"),
    "replay --tol-mm -1": ("replay", ["--tol-mm", "-1"], r"'--tol-mm': '-1': must be >= 0"),
    "replay --tol-deg inf": ("replay", ["--tol-deg", "inf"], r"'--tol-deg': 'inf': must be"),
    "replay --tol-deg text": ("replay", ["--tol-deg", "x"], r"'--tol-deg': 'x' is not a number"),
    "register --diameter-tolerance-um nan": (
        "register",
        ["--diameter-tolerance-um", "nan"],
        r"'--diameter-tolerance-um': 'nan' is not a number",
    ),
    "register --diameter-tolerance-um -1": (
        "register",
        ["--diameter-tolerance-um", "-1"],
        r"'--diameter-tolerance-um': '-1': must be >= 0",
    ),
}


def command_line(command: str, session: Path, tmp_path: Path) -> list[object]:
    if command == "process":
        return ["process", session]
    if command == "report":
        return ["report", session]
    if command == "replay":
        return ["replay", session.parent]
    assert command == "register"
    return ["register", DATUMS / "points.csv", "--datums", DATUMS / "datums.yaml", "-o",
            tmp_path / "balls.yaml"]  # fmt: skip


@pytest.mark.parametrize("case", list(USAGE))
def test_usage_error(session, tmp_path, case):
    command, args, pattern = USAGE[case]
    before, datums = snapshot(session), snapshot(DATUMS)
    result = run(*command_line(command, session, tmp_path), *args)
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit) and "Traceback" not in result.output
    line = error_line(result.output)
    assert re.search(r"^Error: Invalid value for " + pattern, line), line
    assert snapshot(session) == before and snapshot(DATUMS) == datums
    assert not (tmp_path / "balls.yaml").exists()


def edit(name: str, old: str, new: str):
    def mutate(folder: Path) -> None:
        text = (folder / name).read_text()
        assert old in text
        (folder / name).write_text(text.replace(old, new, 1))

    return mutate


def swap_xy(folder: Path) -> None:
    lines = (folder / "centres.csv").read_text().splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        f = line.split(",")
        f[2], f[3] = f[3], f[2]
        out.append(",".join(f))
    (folder / "centres.csv").write_text("\n".join(out) + "\n")


def stop_log_early(folder: Path) -> None:
    lines = (folder / "temperatures.csv").read_text().splitlines(keepends=True)
    (folder / "temperatures.csv").write_text("".join(lines[: len(lines) // 2]))


#: bad sessions: (mutation, extra args, pattern of the error line)
INPUT = {
    "process: mirrored centres": (
        swap_xy,
        ["process"],
        [],
        r"^Error: step R0: measured pose relative to O .* likeliest cause: mirrored axes",
    ),
    "report: mirrored centres": (
        swap_xy,
        ["report"],
        [],
        r"^Error: step R0: .*mirrored axes",
    ),
    "process: log stopped early": (
        stop_log_early,
        ["process"],
        [],
        r"^Error: .*temperatures\.csv: field 'time': step \S+ at \S+ is outside the "
        r"thermocouple log, after its last row \(the log spans \S+ to \S+\)",
    ),
    "process --method twin: log stopped early": (
        stop_log_early,
        ["process"],
        ["--method", "twin"],
        r"^Error: .*temperatures\.csv: field 'time': step \S+ at \S+ is outside",
    ),
    "diagnose: log stopped early": (
        stop_log_early,
        ["diagnose"],
        [],
        r"^Error: .*temperatures\.csv: field 'time': step \S+ at \S+ is outside",
    ),
    "process: CTE in ppm": (
        edit("hexapod.yaml", "cte: 2.31e-05", "cte: 23.1"),
        ["process"],
        [],
        r"^Error: .*hexapod\.yaml:\d+: field 'legs\.segments\[0\]\.cte': .* \(ppm/K\? write "
        r"23\.1e-6\)$",
    ),
    "process: reference temperature in kelvin": (
        edit("hexapod.yaml", "reference_temperature: 20.0", "reference_temperature: 293.15"),
        ["process"],
        [],
        r"^Error: .*hexapod\.yaml:\d+: field 'legs\.reference_temperature': .*looks like kelvin",
    ),
    "process: pose_check NaN": (
        edit("session.yaml", "measurements:", "pose_check: {tolerance_mm: .nan}\nmeasurements:"),
        ["process"],
        [],
        r"^Error: .*session\.yaml:\d: field 'pose_check\.tolerance_mm': expected a number > 0",
    ),
}


@pytest.mark.parametrize("case", list(INPUT))
def test_input_error(session, case):
    mutate, command, args, pattern = INPUT[case]
    mutate(session)
    before = snapshot(session)
    result = run(*command, session, *args)
    assert result.exit_code == 1, result.output
    assert isinstance(result.exception, SystemExit) and "Traceback" not in result.output
    assert re.search(pattern, error_line(result.output)), result.output
    assert snapshot(session) == before  # no results/, report.html or diagnosis/ behind


def test_register_refuses_a_wrong_diameter_and_writes_nothing(tmp_path):
    datums = tmp_path / "datums.yaml"
    datums.write_text((DATUMS / "datums.yaml").read_text().replace("B2: 25.4", "B2: 26.4"))
    out = tmp_path / "balls.yaml"
    result = run("register", DATUMS / "points.csv", "--datums", datums, "-o", out)
    assert result.exit_code == 1 and "Traceback" not in result.output
    line = error_line(result.output)
    assert re.search(
        r"points\.csv:\d+: field 'ball': ball B2: fitted diameter 25\.40\d\d mm is -99\d\.\d um "
        r"from the nominal 26\.4000 mm \(tolerance 20 um, --diameter-tolerance-um\)",
        line,
    ), line
    assert not out.exists()
    # --diameter-tolerance-um inf lets it through (a deliberate choice)
    assert run("register", DATUMS / "points.csv", "--datums", datums, "-o", out,
               "--diameter-tolerance-um", "inf").exit_code == 0  # fmt: skip


def test_process_says_when_there_is_no_thermocouple_log(session):
    edit("session.yaml", "temperatures: temperatures.csv\n", "")(session)
    result = run("process", session, "-o", session / "out")
    assert result.exit_code == 0, result.output
    assert "warning: no thermocouple log in the session" in result.output
    assert re.search(
        r"temperature\s+temperature_change_C\s+worst\s+n/a .* n/a \(could not run: no "
        r"thermocouple log in the session\)",
        result.output,
    ), result.output
    quality = (session / "out" / "quality.csv").read_text().splitlines()
    header = quality[0].split(",")
    value, ok = header.index("temperature_change_C"), header.index("ok_temperature")
    # could not run: no value, and nothing failed
    assert {(row.split(",")[value], row.split(",")[ok]) for row in quality[1:]} == {("", "True")}


def test_pose_tolerance_option_lets_a_known_deviation_through(session):
    lines = (session / "centres.csv").read_text().splitlines()
    out = [lines[0]]
    for line in lines[1:]:
        f = line.split(",")
        if f[0] == "S2":
            f[4] = repr(float(f[4]) + 5.0)  # z of S2's balls, 5 mm up
        out.append(",".join(f))
    (session / "centres.csv").write_text("\n".join(out) + "\n")
    refused = run("process", session, "-o", session / "out")
    assert refused.exit_code == 1 and "step S2: measured pose" in error_line(refused.output)
    assert not (session / "out").exists()
    accepted = run("process", session, "-o", session / "out", "--pose-tolerance", "6,1")
    assert accepted.exit_code == 0, accepted.output
    off = run("process", session, "-o", session / "out2", "--pose-tolerance", "inf")
    assert off.exit_code == 0, off.output


def test_replay_with_an_expected_file_is_a_mismatch(tmp_path):
    root = tmp_path / "sessions"
    shutil.copytree(SHIPPED / "serial-capture", root / "serial-capture")
    shutil.rmtree(root / "serial-capture" / "expected")
    (root / "serial-capture" / "expected").write_text("x\n")
    before = snapshot(root)
    for args in ([], ["--update"]):
        result = run("replay", root, *args)
        assert result.exit_code == 1 and "Traceback" not in result.output
        assert "serial-capture/expected: not a folder" in result.output
        assert error_line(result.output) == "Error: 1 of 1 session(s) do not replay"
    assert snapshot(root) == before


def test_replay_update_lists_what_it_rewrote(tmp_path):
    root = tmp_path / "sessions"
    shutil.copytree(SHIPPED / "serial-capture", root / "serial-capture")
    expected = root / "serial-capture" / "expected"
    (expected / "README.md").write_text("kept\n")
    legs = expected / "legs.csv"
    legs.write_text(legs.read_text().replace("O,origin,", "O,reference,", 1))
    result = run("replay", root, "--update")
    assert result.exit_code == 0, result.output
    assert "rewrote serial-capture/expected/legs.csv" in result.output
    assert "rewrote" not in result.output.replace("rewrote serial-capture/expected/legs.csv", "")
    assert (expected / "README.md").read_text() == "kept\n"
    assert run("replay", root).exit_code == 0
