"""``pytest -n 2`` keeps a module that shares a fixture in one test process
(:mod:`tests.scheduling`): the modules it finds, and the units it hands out."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.scheduling import SUITE, shared_fixtures, shares_a_fixture, unit_of

SOURCE = """
import pytest

@pytest.fixture(scope="module")
def campaign(tmp_path_factory): ...

@pytest.fixture(scope="session", autouse=True)
def _everywhere(): ...

@pytest.fixture
def per_test(): ...

@pytest.fixture(scope="function")
def also_per_test(): ...

@pytest.fixture(scope="class")
def per_class(): ...
"""


def test_the_shared_fixtures_of_a_source_are_the_wider_scoped_not_autouse_ones() -> None:
    assert shared_fixtures(SOURCE) == {"campaign", "per_class"}


def test_the_modules_that_share_are_found_by_definition_and_by_a_conftests_fixture() -> None:
    # a module-scoped fixture of its own (the wheel built once)
    assert shares_a_fixture(SUITE / "test_wheel.py", SUITE)
    # the session-scoped diagnosed campaigns of tests/workflows/conftest.py
    assert shares_a_fixture(SUITE / "workflows" / "test_adequacy.py", SUITE)
    # neither: its tests go out one by one
    assert not shares_a_fixture(SUITE / "test_layers.py", SUITE)


def test_the_units_are_a_sharing_module_whole_and_any_other_test_alone(
    pytestconfig: pytest.Config,
) -> None:
    root = Path(pytestconfig.rootpath)
    wheel = (SUITE / "test_wheel.py").relative_to(root).as_posix()
    layers = (SUITE / "test_layers.py").relative_to(root).as_posix()
    for test in ("test_a", "test_b[1-x::y]"):
        assert unit_of(f"{wheel}::{test}", root, SUITE) == wheel
        assert unit_of(f"{layers}::{test}", root, SUITE) == f"{layers}::{test}"
    doctest = "hexatherm/text.py::hexatherm.text.format_number"
    assert unit_of(doctest, root, SUITE) == doctest
