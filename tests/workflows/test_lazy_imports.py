"""Commands leave unloaded the scipy modules they do not use (0.1-0.35 s of CPU each at
every start): diagnose never loads scipy.stats, process on a small session never loads
scipy.sparse. Each check runs a fresh interpreter and reads its sys.modules."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.shipped import SHIPPED

SESSIONS = SHIPPED


def _loaded(code: str, modules: tuple[str, ...]) -> dict[str, bool]:
    report = f"print(' '.join(str(m in sys.modules) for m in {modules!r}))"
    out = subprocess.run(
        [sys.executable, "-c", f"import sys\n{code}\n{report}\n"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return dict(zip(modules, (word == "True" for word in out[-len(modules) :]), strict=True))


def _process_code(session: str, out: Path) -> str:
    """A script that runs ``process`` on a shipped session into ``out`` (and fails on a
    non-zero exit)."""
    return (
        "from hexatherm.cli import main\n"
        "try:\n"
        f"    main(['process', {str(SESSIONS / session)!r}, '-o', {str(out)!r}])\n"
        "except SystemExit as stop:\n"
        "    assert not stop.code, stop.code\n"
    )


#: runs ``process`` on a shipped session as :func:`_process_code` does and prints gc's count
#: of frozen objects once the command's module is imported and after the command, then every
#: module left loaded
PROCESS_SCRIPT = """import gc, sys
from hexatherm.cli import main
before = gc.get_freeze_count()
try:
    main(["process", {session!r}, "-o", {out!r}])
except SystemExit as stop:
    assert not stop.code, stop.code
print(before, gc.get_freeze_count())
print(" ".join(sorted(sys.modules)))
"""


@dataclass(frozen=True)
class Processed:
    """``process`` of a shipped session in a fresh interpreter: the modules it left loaded,
    gc's frozen objects before and after the command, and its output folder."""

    modules: frozenset[str]
    frozen: tuple[int, int]
    out: Path

    def loaded(self, modules: tuple[str, ...]) -> dict[str, bool]:
        return {m: m in self.modules for m in modules}


@pytest.fixture(scope="module")
def processed(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Processed]:
    """``processed(session)``: :data:`PROCESS_SCRIPT` run once per session in this module
    (the same command in the same fresh interpreter for every test that reads it; none
    writes into its output)."""
    done: dict[str, Processed] = {}

    def run(session: str) -> Processed:
        if session not in done:
            out = tmp_path_factory.mktemp(session) / "out"
            code = PROCESS_SCRIPT.format(session=str(SESSIONS / session), out=str(out))
            lines = subprocess.run(
                [sys.executable, "-c", code], check=True, capture_output=True, text=True
            ).stdout.splitlines()
            before, after = (int(n) for n in lines[-2].split())
            done[session] = Processed(frozenset(lines[-1].split()), (before, after), out)
        return done[session]

    return run


def test_diagnose_does_not_import_scipy_stats() -> None:
    code = (
        "import hexatherm.cli, hexatherm.cli.diagnose\n"
        "import hexatherm.workflows.diagnose.run, hexatherm.workflows.diagnose.outputs\n"
        "import hexatherm.workflows.diagnose.report\n"
    )
    assert _loaded(code, ("scipy.stats", "scipy.optimize")) == {
        "scipy.stats": False,
        "scipy.optimize": True,  # the check sees what is loaded: the fits need this one
    }


def test_process_of_a_small_session_does_not_import_scipy_sparse(
    processed: Callable[[str], Processed],
) -> None:
    """paper-zero-pose: its covariance between targets takes the dense path."""
    run = processed("paper-zero-pose")
    assert run.loaded(("scipy.sparse", "pandas")) == {"scipy.sparse": False, "pandas": True}
    assert (run.out / "covariance.csv").is_file()


def test_process_keeps_the_collector_off_its_imports(
    processed: Callable[[str], Processed],
) -> None:
    """Once its modules are loaded, a command freezes them (gc.freeze: full collections
    no longer walk numpy's, pandas' and scipy's objects); the results are the replay's."""
    run = processed("paper-zero-pose")
    before, after = run.frozen
    assert before == 0 and after > 10000, run.frozen
    assert run.loaded(("numpy",)) == {"numpy": True}
    expected = SESSIONS / "paper-zero-pose" / "expected" / "poses.csv"
    assert (run.out / "poses.csv").read_bytes() == expected.read_bytes()


def test_process_without_repeats_or_tolerances_loads_no_scipy(
    processed: Callable[[str], Processed],
) -> None:
    """paper-zero-pose-dmis (O and R0 measured once, no --tolerance): nothing of scipy is
    needed, and its import is a fifth of a small process's CPU (issue 37); the conformity
    rules that `--tolerance`'s help names come without ``scipy.special``."""
    run = processed("paper-zero-pose-dmis")
    assert run.loaded(("scipy", "pandas")) == {"scipy": False, "pandas": True}
    assert (run.out / "poses.csv").is_file()


def test_a_plain_process_loads_only_what_it_uses(processed: Callable[[str], Processed]) -> None:
    """Without tolerances, the twin or a hexapod's effects, process loads none of their
    modules (each compiled at every start where Python keeps no bytecode, issue 37), nor
    importlib.metadata for the libraries' versions, which provenance.json records all the
    same, as importlib.metadata gives them."""
    from importlib import metadata

    run = processed("paper-zero-pose-dmis")  # no scipy: it reads both of them
    lazy = (
        "hexatherm.workflows.process.conformity",
        "hexatherm.core.conformity",
        "hexatherm.workflows.process.twin",
        "hexatherm.core.effects",
        "importlib.metadata",
        "numpy.char",
    )
    assert run.loaded(lazy) == dict.fromkeys(lazy, False)
    provenance = json.loads((run.out / "provenance.json").read_text())
    assert provenance["libraries"] == {
        name: metadata.version(name) for name in ("numpy", "scipy", "pandas")
    }


def test_process_of_a_csv_session_loads_no_dmis_or_qif_reader(
    processed: Callable[[str], Processed],
) -> None:
    """A session of CSV files loads neither the DMIS reader nor the QIF one with lxml (about
    60 ms of a 0.4 s floor where Python keeps no bytecode, issue 37); a DMIS session loads
    the DMIS reader, and still not lxml."""
    lazy = ("hexatherm.io.dmis", "hexatherm.io.qif", "hexatherm.io.qifrecords", "lxml")
    csv = processed("paper-zero-pose")
    assert csv.loaded(lazy) == dict.fromkeys(lazy, False)
    assert (csv.out / "poses.csv").is_file()
    dmis = processed("paper-zero-pose-dmis")
    assert dmis.loaded(lazy) == {**dict.fromkeys(lazy, False), "hexatherm.io.dmis": True}


#: what a plain ``process`` of a points CSV must not load: the figures' and pages' libraries
#: (matplotlib with Pillow, jinja2, markdown-it), the QIF reader's lxml, scipy (no repeats
#: of O or R0, no tolerances), the other readers and the other commands' workflows
#: (each a start-up cost of every run, issue 37)
NOT_FOR_PROCESS = (
    "matplotlib",
    "PIL",
    "jinja2",
    "markdown_it",
    "lxml",
    "scipy",
    "hexatherm.io.dmis",
    "hexatherm.io.qif",
    "hexatherm.core.diagnosis",
    "hexatherm.core.twin",
    "hexatherm.core.calibration",
    "hexatherm.workflows.report",
    "hexatherm.workflows.diagnose",
)


def test_process_of_a_points_csv_loads_no_heavy_module(tmp_path: Path) -> None:
    """serial-capture (points.csv, spheres fitted): none of :data:`NOT_FOR_PROCESS` is
    imported, while the modules of its own path are (the check sees what is loaded)."""
    out = tmp_path / "out"
    code = _process_code("serial-capture", out)
    own = ("pandas", "hexatherm.io.csvfile", "hexatherm.core.spherefit", "yaml", "click")
    loaded = _loaded(code, NOT_FOR_PROCESS + own)
    assert loaded == {**dict.fromkeys(NOT_FOR_PROCESS, False), **dict.fromkeys(own, True)}
    expected = SESSIONS / "serial-capture" / "expected" / "poses.csv"
    assert (out / "poses.csv").read_bytes() == expected.read_bytes()


def test_diagnose_leaves_process_pipeline_and_report_page_unloaded() -> None:
    """diagnose's modules (those its command imports, its page's included) leave out what
    it never calls: process's pipeline (correction, checks, carry), the sphere fits (a
    session of centres), process's output tables, and report's own page and tables, which
    ``hexatherm.workflows.report`` loads on first use."""
    code = (
        "import hexatherm.cli, hexatherm.cli.diagnose, hexatherm.io.config\n"
        "import hexatherm.io.outputs, hexatherm.workflows.diagnose.command\n"
        "import hexatherm.workflows.diagnose.run, hexatherm.workflows.diagnose.outputs\n"
        "import hexatherm.workflows.diagnose.report\n"
    )
    lazy = (
        "hexatherm.workflows.process.pipeline",
        "hexatherm.core.correction",
        "hexatherm.core.spherefit",
        "hexatherm.workflows.process.outputs",
        "hexatherm.workflows.process.views",
        "hexatherm.workflows.report.html",
        "hexatherm.workflows.report.tables",
    )
    used = ("hexatherm.workflows.report.page", "hexatherm.core.diagnosis")
    loaded = _loaded(code, lazy + used)
    assert loaded == {**dict.fromkeys(lazy, False), **dict.fromkeys(used, True)}


def test_report_package_gives_every_name_of_its_modules() -> None:
    """Every name of ``hexatherm.workflows.report.__all__`` is its module's object, the
    lazy ones too (PEP 562); ``verdict`` stays the function though its module shares the
    name; an unknown name is an AttributeError."""
    code = (
        "import importlib, hexatherm.workflows.report as r\n"
        "import hexatherm.workflows.report.html\n"  # loads the verdict module too
        "assert callable(r.verdict) and r.verdict.__module__.endswith('.verdict')\n"
        "for name, module in r.LAZY.items():\n"
        "    own = importlib.import_module(r.__name__ + '.' + module)\n"
        "    assert getattr(r, name) is getattr(own, name), name\n"
        "assert set(r.LAZY) <= set(r.__all__) and set(r.__all__) <= set(dir(r))\n"
        "assert all(getattr(r, name) is not None for name in r.__all__)\n"
        "try:\n"
        "    r.no_such_name\n"
        "except AttributeError:\n"
        "    pass\n"
        "else:\n"
        "    raise AssertionError('no AttributeError')\n"
    )
    assert _loaded(code, ("hexatherm.workflows.report.tables",)) == {
        "hexatherm.workflows.report.tables": True
    }
