"""The package's floors: imports point down only, and no module imports itself back; a
command (``cli``) imports only the workflows, the errors and the texts.

``cli -> workflows -> {io, devices} -> {core, session} -> {errors, typing}``

Every import is counted, the lazy ones inside functions too (a lazy import hides a
cycle from the interpreter, not from the reader). Within one floor imports are
allowed, except that ``core`` never imports ``session`` (the maths knows nothing of
sessions). The checker is tested on a small package with a deliberate upward import
and a deliberate cycle, so that a checker that sees nothing cannot pass.
"""

from __future__ import annotations

import ast
import functools
import textwrap
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "hexatherm"

#: module prefix -> floor (longest prefix wins)
FLOORS = {
    "": 0,  # the package's __init__: the version only
    "errors": 0,
    "typing": 0,
    "text": 0,  # how numbers and poses are written in messages
    "data": 0,  # package data (YAML), no code
    "core": 1,
    "session": 1,
    "limits": 1,  # the one table of limits (pure Python, below session)
    "io": 2,
    "devices": 2,
    "workflows": 3,
    "cli": 4,
    "__main__": 4,
}
FLOOR_NAMES = {
    0: "errors/typing/text",
    1: "core/session",
    2: "io/devices",
    3: "workflows",
    4: "cli",
}
#: (importer prefix, imported prefix) pairs forbidden although on one floor
FORBIDDEN_SIDEWAYS = {("core", "session")}


@functools.cache
def _parsed(text: str, filename: str) -> ast.Module:
    """``ast.parse`` of a module's text, once per text and name: five checkers walk the
    package's 200 modules (1.5 s of CPU to parse them), none changes a tree."""
    return ast.parse(text, filename)


def parsed(path: Path) -> ast.Module:
    """The syntax tree of the file ``path`` as it reads now."""
    return _parsed(path.read_text(encoding="utf-8"), str(path))


def modules_of(root: Path) -> dict[str, Path]:
    """Dotted module names (``core.geometry``; ``""`` for the package) -> file."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def floor_of(module: str) -> int:
    """The floor of a module, by the longest matching prefix of :data:`FLOORS`."""
    best, floor = -1, None
    for prefix, value in FLOORS.items():
        if (module == prefix or module.startswith(prefix + ".") or prefix == "") and len(
            prefix
        ) > best:
            best, floor = len(prefix), value
    assert floor is not None
    return floor


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The package module an absolute import name lands on (a submodule if it is one)."""
    if name == "hexatherm":
        return ""
    if not name.startswith("hexatherm."):
        return None
    dotted = name[len("hexatherm.") :]
    while dotted and dotted not in modules:
        dotted = dotted.rpartition(".")[0]
    return dotted


def import_edges(root: Path, package: str = "hexatherm") -> list[tuple[str, str, int]]:
    """Every (importer, imported, line) pair inside the package, lazy imports included."""
    modules = modules_of(root)
    edges = []
    for module, path in modules.items():
        for node in ast.walk(parsed(path)):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative: resolve against this module's package
                    base = (
                        module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                    )
                    base = base[: len(base) - (node.level - 1)] if node.level > 1 else base
                    stem = ".".join([package, *[b for b in base if b]])
                    mod = f"{stem}.{node.module}" if node.module else stem
                else:
                    mod = node.module or ""
                names = [f"{mod}.{alias.name}" for alias in node.names] + [mod]
            for name in names:
                target = _resolve(name.replace(f"{package}.", "hexatherm.", 1), modules)
                if target is not None and target != module:
                    edges.append((module, target, node.lineno))
    # ``from hexatherm.x import name`` lists both the module and module.name: keep the
    # most specific target per import line
    specific = {}
    for importer, target, line in edges:
        key = (importer, line)
        specific.setdefault(key, set()).add(target)
    result = []
    for (importer, line), targets in specific.items():
        for target in targets:
            if not any(t != target and t.startswith(target + ".") for t in targets) or target == "":
                result.append((importer, target, line))
    return sorted(set(result))


def layer_violations(root: Path) -> list[str]:
    """Upward and forbidden sideways imports, one readable line each."""
    problems = []
    for importer, target, line in import_edges(root):
        if target == "":
            continue  # the version
        a, b = floor_of(importer), floor_of(target)
        sideways = any(
            (importer == i or importer.startswith(i + "."))
            and (target == t or target.startswith(t + "."))
            for i, t in FORBIDDEN_SIDEWAYS
        )
        if b > a or sideways:
            problems.append(
                f"hexatherm.{importer} (line {line}, {FLOOR_NAMES[a]}) imports "
                f"hexatherm.{target} ({FLOOR_NAMES[b]})"
            )
    return problems


def import_cycles(root: Path) -> list[list[str]]:
    """The import cycles (strongly connected components of more than one module)."""
    graph: dict[str, set[str]] = {}
    for importer, target, _ in import_edges(root):
        if target:
            graph.setdefault(importer, set()).add(target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    counter = [0]

    def visit(node: str) -> None:  # Tarjan's algorithm
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for succ in sorted(graph.get(node, ())):
            if succ not in index:
                visit(succ)
                low[node] = min(low[node], low[succ])
            elif succ in on_stack:
                low[node] = min(low[node], index[succ])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return cycles


#: what a ``cli`` module may import of the package: the workflows (a command's steps),
#: the errors (its exit codes), the other ``cli`` modules and the package's version;
#: never ``io``, ``core``, ``devices``, ``session`` or ``limits`` (issue 34: options,
#: messages and exit codes only; rasterio's ``rio`` commands are the model)
CLI_MAY_IMPORT = ("workflows", "errors", "cli", "")


def thick_cli(root: Path) -> list[str]:
    """``cli`` imports of anything but :data:`CLI_MAY_IMPORT`, one readable line each."""
    problems = []
    for importer, target, line in import_edges(root):
        if not importer.startswith("cli"):
            continue
        if not any(target == t or target.startswith(t + ".") for t in CLI_MAY_IMPORT):
            problems.append(
                f"hexatherm.{importer} (line {line}) imports hexatherm.{target}: a command "
                "holds options, messages and exit codes; its steps go in its workflow"
            )
    return problems


def test_the_commands_import_only_workflows_errors_and_texts() -> None:
    assert thick_cli(PACKAGE) == []


def test_the_checker_refuses_a_command_that_imports_core_or_io(tmp_path: Path) -> None:
    root = _package(
        tmp_path,
        {
            "cli/process.py": "from hexatherm.workflows.process import run\n"
            "from hexatherm.errors import E\n",
            "cli/report.py": "def f():\n    from hexatherm.io.outputs import write\n",
            "cli/plan.py": "import hexatherm.core.planning\n",
            "workflows/process.py": "run = 1\n",
            "io/outputs.py": "write = 1\n",
            "core/planning.py": "",
            "errors.py": "E = 1\n",
        },
    )
    assert [p.split(" (")[0] for p in thick_cli(root)] == [
        "hexatherm.cli.plan",
        "hexatherm.cli.report",
    ]


def test_the_package_has_no_upward_import() -> None:
    assert layer_violations(PACKAGE) == []


def test_the_package_has_no_import_cycle() -> None:
    assert import_cycles(PACKAGE) == []


def test_every_module_has_a_floor() -> None:
    """A new top-level module must be given a floor on purpose, not fall into floor 0."""
    top = {m.split(".")[0] for m in modules_of(PACKAGE) if m}
    assert top <= set(FLOORS), f"modules without a floor: {sorted(top - set(FLOORS))}"


def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "hexatherm"
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    for folder in [root, *[p for p in root.rglob("*") if p.is_dir()]]:
        (folder / "__init__.py").touch()
    return root


def test_the_checker_finds_a_deliberate_upward_import(tmp_path: Path) -> None:
    root = _package(
        tmp_path,
        {
            "core/geometry.py": "import numpy\n",
            "workflows/process.py": "from hexatherm.core.geometry import numpy\n",
            # the deliberate mistake: maths that imports a workflow, lazily
            "core/hexapod.py": "def f():\n    from hexatherm.workflows.process import numpy\n",
            "io/config.py": "from hexatherm.session import Balls\n",
            "session.py": "Balls = 1\n",
        },
    )
    assert layer_violations(root) == [
        "hexatherm.core.hexapod (line 2, core/session) imports hexatherm.workflows.process "
        "(workflows)"
    ]


def test_the_checker_finds_maths_that_knows_of_sessions(tmp_path: Path) -> None:
    root = _package(tmp_path, {"core/x.py": "from hexatherm.session import S\n", "session.py": ""})
    assert len(layer_violations(root)) == 1


@pytest.mark.parametrize(
    "files",
    [
        {"io/a.py": "import hexatherm.io.b\n", "io/b.py": "from hexatherm.io import a\n"},
        {"io/a.py": "from .b import x\n", "io/b.py": "def f():\n    from .a import y\n"},
    ],
)
def test_the_checker_finds_a_deliberate_cycle(tmp_path: Path, files: dict[str, str]) -> None:
    root = _package(tmp_path, files)
    assert import_cycles(root) == [["io.a", "io.b"]]


#: modules longer than :data:`MAX_LINES` that are one cohesive algorithm (docs/design.md)
LONG_MODULES = {
    "io.dmis",
    "workflows.acquire.recorder",
    "workflows.run.campaign",
    "core.spherefit",
    "core.hexapod",
    "core.effects",
    "core.propagation",
}
MAX_LINES = 600


def long_modules(root: Path) -> set[str]:
    """Modules outside ``cli`` longer than :data:`MAX_LINES` lines."""
    return {
        name
        for name, path in modules_of(root).items()
        if not (name == "cli" or name.startswith("cli."))
        and len(path.read_text().splitlines()) > MAX_LINES
    }


def test_long_modules_are_the_argued_ones() -> None:
    assert long_modules(PACKAGE) <= LONG_MODULES


def exceptions_outside_errors(root: Path) -> list[str]:
    """Public classes deriving (by name) from an exception or warning, defined outside
    ``errors.py``."""
    found = []
    for name, path in modules_of(root).items():
        if name == "errors":
            continue
        for node in ast.walk(parsed(path)):
            if not isinstance(node, ast.ClassDef) or node.name.startswith("_"):
                continue
            bases = [ast.unparse(b).split(".")[-1] for b in node.bases]
            if any(b.endswith(("Error", "Exception", "Warning")) for b in bases):
                found.append(f"{name}.{node.name}")
    return found


def test_every_exception_lives_in_errors() -> None:
    assert exceptions_outside_errors(PACKAGE) == []


def test_the_checkers_find_a_long_module_and_a_stray_exception(tmp_path: Path) -> None:
    root = _package(
        tmp_path,
        {
            "io/big.py": "x = 1\n" * (MAX_LINES + 1),
            "cli/big.py": "x = 1\n" * (MAX_LINES + 1),
            "io/stray.py": "class StrayError(ValueError):\n    pass\n",
            "io/private.py": "class _Stop(Exception):\n    pass\n",
            "errors.py": "class GoodError(Exception):\n    pass\n",
        },
    )
    assert long_modules(root) == {"io.big"}
    assert exceptions_outside_errors(root) == ["io.stray.StrayError"]


#: the only modules of the package that may import the simulated instruments (issue 34,
#: item 4): the simulators themselves and ``serve-twin``'s workflow
SIMULATOR_USERS = ("devices.sim", "workflows.serve")


def simulator_imports(root: Path) -> list[str]:
    """Imports of ``devices.sim`` by a module that is not one of :data:`SIMULATOR_USERS`."""
    return [
        f"hexatherm.{importer} (line {line}) imports hexatherm.{target}"
        for importer, target, line in import_edges(root)
        if (target == "devices.sim" or target.startswith("devices.sim."))
        and not any(importer == u or importer.startswith(u + ".") for u in SIMULATOR_USERS)
    ]


def test_the_simulated_instruments_live_in_a_room_of_their_own() -> None:
    """The drivers a lab runs (``devices``), and every command but ``serve-twin``, import
    no simulator: the twin they are tested against reads apart from them."""
    assert simulator_imports(PACKAGE) == []
    assert (PACKAGE / "devices" / "sim" / "__init__.py").is_file()
    assert not list((PACKAGE / "devices").glob("*sim.py"))


def test_the_checker_finds_a_driver_that_imports_a_simulator(tmp_path: Path) -> None:
    root = _package(
        tmp_path,
        {
            "devices/__init__.py": "",
            "devices/pi.py": "from hexatherm.devices.sim.pi import PISimulator\n",
            "devices/sim/__init__.py": "",
            "devices/sim/pi.py": "PISimulator = 1\n",
            "workflows/__init__.py": "",
            "workflows/serve.py": "from hexatherm.devices.sim import pi\n",
        },
    )
    assert simulator_imports(root) == [
        "hexatherm.devices.pi (line 1) imports hexatherm.devices.sim.pi"
    ]
