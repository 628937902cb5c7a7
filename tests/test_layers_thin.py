"""The commands moved by issue 34 item 2 (acquire, plan, run, serve-twin, simulate and the
shared options) import only the workflows, the errors and their ``cli`` siblings: their
steps live in their workflows (``tests/test_layers.py``'s floors, held tighter here)."""

from __future__ import annotations

from pathlib import Path

from tests.test_layers import PACKAGE, _package, import_edges

#: the six modules of this move
SIX = ("cli.acquire", "cli.plan", "cli.run", "cli.serve_twin", "cli.simulate", "cli.options")
#: the command modules held to the rule here: all six
THIN = SIX
#: what they may import of the package
ALLOWED = ("workflows", "errors", "cli")


def below_the_workflows(root: Path, modules: tuple[str, ...] = THIN) -> list[str]:
    """Imports by ``modules`` of anything but :data:`ALLOWED`, one line each."""
    return [
        f"hexatherm.{importer} (line {line}) imports hexatherm.{target}"
        for importer, target, line in import_edges(root)
        if importer in modules
        and target != ""
        and not any(target == a or target.startswith(a + ".") for a in ALLOWED)
    ]


def test_the_moved_commands_import_only_workflows_errors_and_cli() -> None:
    assert below_the_workflows(PACKAGE) == []


def test_the_check_finds_a_command_that_imports_io_core_devices_or_session(
    tmp_path: Path,
) -> None:
    root = _package(
        tmp_path,
        {
            "cli/plan.py": "def f():\n    from hexatherm.io.outputs import write\n",
            "cli/run.py": "import hexatherm.devices.controller\n",
            "cli/simulate.py": "from hexatherm.workflows.simulate import run\n",
            "cli/options.py": "from hexatherm.core.conformity import RULES\n",
            "cli/acquire.py": "from hexatherm.session import Balls\n"
            "from hexatherm.errors import E\n",
            "workflows/simulate/run.py": "",
            "io/outputs.py": "write = 1\n",
            "devices/controller.py": "",
            "core/conformity.py": "RULES = ()\n",
            "session.py": "Balls = 1\n",
            "errors.py": "E = 1\n",
        },
    )
    assert [p.split(" (")[0] for p in below_the_workflows(root, SIX)] == [
        "hexatherm.cli.acquire",
        "hexatherm.cli.options",
        "hexatherm.cli.plan",
        "hexatherm.cli.run",
    ]


def test_a_decision_rule_is_checked_against_the_conformity_s_own_rules(tmp_path: Path) -> None:
    """``--decision-rule`` (cli/options.py) reads the rules through the workflows; the
    usage error names core.conformity's rules, and a rule of them is taken."""
    from click.testing import CliRunner

    from hexatherm.cli import main
    from hexatherm.core.conformity import RULES
    from tests.shipped import SHIPPED

    session = SHIPPED / "paper-zero-pose"
    bad = CliRunner().invoke(main, ["process", str(session), "--decision-rule", "bogus"])
    assert bad.exit_code == 2
    assert f"'bogus': one of {', '.join(RULES)}" in bad.output
    out = tmp_path / "out"
    good = CliRunner().invoke(
        main, ["process", str(session), "--decision-rule", RULES[1], "-o", str(out)]
    )
    assert good.exit_code == 0, good.output
