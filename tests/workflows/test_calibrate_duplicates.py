"""``calibrate A B`` compares its sessions by what they measured, not by their bytes
(issue 36, item 1).

B being A's measurements re-saved by a spreadsheet (15 significant digits), rounded to
1 nm or shifted by 1 nm was accepted, every parameter's u divided by sqrt(2); a fifth
or 45 % of A's centres copied into another session passed without a word. The truth
here is how the files were made: twin sessions of one hexapod, one plan and one true
geometry, simulated with two noise seeds and no heating (their references, at one pose
all session long, then differ by the CMM's noise alone: the closest two independent
sessions come), and copies of one edited as the audit did.
"""

from __future__ import annotations

import csv
import io
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hexatherm.cli import main
from hexatherm.io.scenario import read_scenario
from hexatherm.workflows.simulate.run import simulate
from hexatherm.workflows.simulate.twinsession import write_files
from tests.sessions import calibration_scenario, calibration_targets

N_TARGETS = 8


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def twin(root: Path, seed: int) -> Path:
    """A session of 8 targets (0.3 um probing noise, 8 points per ball, legs at rest),
    the plan and the true geometry the same for every ``seed``, the noise its own."""
    text = calibration_scenario(
        calibration_targets(7, N_TARGETS),
        geometry_seed=107,
        seed=seed,
        name=f"twin{seed}",
        points_per_ball=8,
        cmm={"point_noise_um": 0.3},
    )
    path = root / f"twin{seed}.yaml"
    path.write_text(text)
    folder = root / f"twin{seed}"
    write_files(simulate(read_scenario(path)).files, folder)
    return folder


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("duplicates")
    return twin(root, 1), twin(root, 2)


def rows(session: Path) -> tuple[list[str], list[list[str]]]:
    lines = list(csv.reader(io.StringIO((session / "centres.csv").read_text())))
    return lines[0], lines[1:]


def write_rows(session: Path, header: list[str], body: list[list[str]]) -> None:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows([header, *body])
    (session / "centres.csv").write_text(out.getvalue())


def edited(session: Path, to: Path, edit) -> Path:
    """A copy of ``session`` whose centres' x, y, z are ``edit(float) -> str``."""
    shutil.copytree(session, to)
    header, body = rows(to)
    cols = [header.index(name) for name in ("x", "y", "z")]
    for row in body:
        for c in cols:
            row[c] = edit(float(row[c]))
    write_rows(to, header, body)
    return to


def refusal(result) -> str:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1, result.output
    return lines[0]


EDITS = {
    "spreadsheet 15 digits": lambda v: f"{v:.15g}",
    "rounded to 1 nm": lambda v: f"{v:.6f}",
    "shifted by 1 nm": lambda v: repr(v + 1e-6),
}


@pytest.mark.parametrize("name", list(EDITS))
def test_a_session_in_other_digits_is_refused_naming_both(
    pair: tuple[Path, Path], tmp_path: Path, name: str
) -> None:
    a = pair[0]
    b = edited(a, tmp_path / "b", EDITS[name])
    assert (b / "centres.csv").read_bytes() != (a / "centres.csv").read_bytes()
    n = len(rows(a)[1])
    line = refusal(run("calibrate", a, b, "-o", tmp_path / "out", "--level", "offsets"))
    assert line.startswith(f"Error: {b / 'session.yaml'}: field 'measurements': ")
    assert f"all {n} of its measured ball centres are those of {a / 'session.yaml'}" in line
    assert not (tmp_path / "out").exists()


def shared(a: Path, b: Path, to: Path, share: float) -> tuple[Path, int]:
    """A copy of ``b`` whose centres, on a seeded ``share`` of its rows, are ``a``'s of the
    same step and ball (a's digits)."""
    shutil.copytree(b, to)
    header, body = rows(to)
    _, theirs = rows(a)
    where = {(r[0], r[1]): r for r in theirs}
    cols = [header.index(name) for name in ("x", "y", "z")]
    picked = np.random.default_rng(5).choice(len(body), round(share * len(body)), replace=False)
    for i in picked:
        source = where[(body[i][0], body[i][1])]
        for c in cols:
            body[i][c] = source[c]
    write_rows(to, header, body)
    return to, len(picked)


@pytest.mark.parametrize("share", [0.2, 0.45])
def test_a_fifth_or_more_of_the_centres_shared_is_refused(
    pair: tuple[Path, Path], tmp_path: Path, share: float
) -> None:
    a, b = pair
    c, k = shared(a, b, tmp_path / "c", share)
    n = len(rows(a)[1])
    line = refusal(run("calibrate", a, c, "-o", tmp_path / "out", "--level", "offsets"))
    assert f"{k} of its {n} measured ball centres are those of {a / 'session.yaml'}" in line
    assert str(c / "session.yaml") in line


def test_a_few_centres_shared_are_warned_of(pair: tuple[Path, Path], tmp_path: Path) -> None:
    a, b = pair
    c, k = shared(a, b, tmp_path / "c", 0.05)
    done = run("calibrate", a, c, "-o", tmp_path / "out", "--level", "offsets")
    assert done.exit_code == 0, done.output
    warned = [line for line in done.output.splitlines() if "measured ball centres" in line]
    assert len(warned) == 1, done.output
    assert warned[0].startswith(f"warning: {c / 'session.yaml'}: {k} of its ")
    assert str(a / "session.yaml") in warned[0]


def test_two_sessions_of_one_hexapod_and_plan_are_taken(
    pair: tuple[Path, Path], tmp_path: Path
) -> None:
    a, b = pair
    done = run("calibrate", a, b, "-o", tmp_path / "out", "--level", "offsets")
    assert done.exit_code == 0, done.output
    assert "measured ball centres" not in done.output
    assert f"calibrated from {2 * N_TARGETS} corrected poses of 2 session(s)" in done.output
