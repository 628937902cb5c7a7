"""How ``pytest -n 2`` hands the tests to its two processes (:mod:`tests.conftest`).

xdist's default (``--dist load``) hands them out in slices of the collection, in
order, down to a test or two at the end: a module whose tests fall on both sides of
a cut computes its module-scoped fixture (four ``run`` campaigns, a wheel built and
installed, a report printed by Chromium, the replicas of a statistical test) in both
processes, each paying for the whole. Here a module that defines such a fixture, or
asks for a session-scoped one of a ``conftest.py``, goes to one process whole; every
other test is handed out alone, as before. The biggest modules go first, so that no
long one is left to run alone at the end.

xdist's own ``--dist loadgroup`` (an ``xdist_group`` mark on the tests) would do the
same, but it groups by rewriting the tests' ids, which pytest 9.2 no longer reads
(pytest-dev/pytest-xdist#1386: the mark is silently ignored); ``--dist loadfile``
would also serialise the many light modules' tests, which gain nothing from it.

Which modules share a fixture is read from their source (:mod:`ast`), as the
controlling process sees only the tests' ids.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

from xdist.scheduler import LoadScopeScheduling

#: the test suite's folder
SUITE = Path(__file__).resolve().parent

#: the scopes whose fixtures one test process computes once for all the tests that ask
SHARED_SCOPES = frozenset({"class", "module", "package", "session"})


def _is_fixture(decorator: ast.expr) -> ast.Call | None:
    """The ``pytest.fixture(...)`` call of a decorator, if it is one with arguments."""
    if isinstance(decorator, ast.Call):
        func = decorator.func
        name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
        if name == "fixture":
            return decorator
    return None


def shared_fixtures(source: str) -> frozenset[str]:
    """The fixtures ``source`` defines with a scope wider than a test, autouse ones left
    out (every test has them: nothing to keep together)."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.FunctionDef):
            continue
        for decorator in node.decorator_list:
            call = _is_fixture(decorator)
            if call is None:
                continue
            keywords = {k.arg: k.value for k in call.keywords}
            scope = keywords.get("scope")
            autouse = keywords.get("autouse")
            if (
                isinstance(scope, ast.Constant)
                and scope.value in SHARED_SCOPES
                and not (isinstance(autouse, ast.Constant) and autouse.value)
            ):
                names.add(node.name)
    return frozenset(names)


def _arguments(source: str) -> set[str]:
    """Every argument name of every function in ``source`` (a test asks for a fixture
    by naming it)."""
    return {
        arg.arg
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.FunctionDef)
        for arg in node.args.args
    }


@cache
def _conftest_fixtures(folder: Path) -> frozenset[str]:
    path = folder / "conftest.py"
    return shared_fixtures(path.read_text("utf-8")) if path.is_file() else frozenset()


@cache
def shares_a_fixture(path: Path, suite: Path) -> bool:
    """Whether the test module ``path`` defines a fixture wider than a test, or asks for
    one of a ``conftest.py`` between it and the suite's folder ``suite``."""
    source = path.read_text("utf-8")
    if shared_fixtures(source):
        return True
    wanted = _arguments(source)
    folder = path.parent
    while folder == suite or suite in folder.parents:
        if wanted & _conftest_fixtures(folder):
            return True
        folder = folder.parent
    return False


def unit_of(nodeid: str, root: Path, suite: Path) -> str:
    """The unit a test goes out in: its module (its path from ``root``, the rootdir)
    where the module shares a fixture (:func:`shares_a_fixture`), else the test alone."""
    module = nodeid.split("::", 1)[0]
    path = (root / module).resolve()
    if path.suffix == ".py" and suite in path.parents and path.is_file():
        if shares_a_fixture(path, suite):
            return module
    return nodeid


class ModuleFixtureScheduling(LoadScopeScheduling):
    """xdist's scope scheduling on the units of :func:`unit_of`."""

    def __init__(self, config, log=None) -> None:  # type: ignore[no-untyped-def]
        super().__init__(config, log)
        self._root = Path(config.rootpath)

    def _split_scope(self, nodeid: str) -> str:
        return unit_of(nodeid, self._root, SUITE)
