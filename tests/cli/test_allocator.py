"""The C allocator while a command computes (``hexatherm.cli.allocator``): what a step
frees is handed to the next step's arrays without new pages from the kernel; the
long-lived commands and a user's own allocator settings are left alone."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest
from click.testing import CliRunner

from hexatherm.cli import allocator, main

#: in a fresh interpreter: the page faults of writing a 64 MB array, of writing it again
#: after it was freed, after ``keep_freed_memory(COMMAND)`` (argv[1])
SCRIPT = """
import resource, sys
import numpy as np
from hexatherm.cli.allocator import keep_freed_memory
kept = keep_freed_memory(sys.argv[1])
def faults(): return resource.getrusage(resource.RUSAGE_SELF).ru_minflt
a = faults(); x = np.ones(1 << 23); b = faults(); del x
y = np.ones(1 << 23); c = faults()
print(kept, b - a, c - b)
"""


def _faults(command: str, env: dict[str, str] | None = None) -> tuple[bool, int, int]:
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, command],
        check=True,
        capture_output=True,
        text=True,
        env=env,
    ).stdout.split()
    return out[0] == "True", int(out[1]), int(out[2])


def _clean_environment() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k not in allocator.ALLOCATOR_VARIABLES}


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
    reason="glibc's allocator",
)
def test_a_freed_array_is_reused_without_new_pages() -> None:
    """After the setting, the second 64 MB array takes the first's pages (no faults);
    without it (``run``, long-lived) both are paged in afresh (glibc hands back a block
    above its mmap threshold, at most 32 MB, when it is freed)."""
    kept, first, again = _faults("process", _clean_environment())
    assert kept
    assert first > 0
    assert again <= max(2, first // 100)
    kept, first, again = _faults("run", _clean_environment())
    assert not kept
    assert again > first // 2


def test_long_lived_commands_and_the_users_settings_keep_the_defaults(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    for command in sorted(allocator.LONG_LIVED):
        assert not allocator.keep_freed_memory(command)
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "131072")
    assert not allocator.keep_freed_memory("process")


def test_the_command_line_names_the_command(monkeypatch: pytest.MonkeyPatch) -> None:
    """The group asks for the setting with the command it runs."""
    asked: list[str | None] = []
    monkeypatch.setattr(allocator, "keep_freed_memory", asked.append)
    result = CliRunner().invoke(main, ["process", "--help"])
    assert result.exit_code == 0
    assert asked == ["process"]
