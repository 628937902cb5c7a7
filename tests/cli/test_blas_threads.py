"""The command line runs BLAS on one thread unless the environment says otherwise (issue 26):
a threaded BLAS spins on a shared machine for the small matrices hexatherm factorizes."""

from __future__ import annotations

import os
import subprocess
import sys

from hexatherm.cli import BLAS_THREAD_VARIABLES

PROBE = (
    "import hexatherm.cli, numpy, os; "
    "print(' '.join(os.environ[n] for n in hexatherm.cli.BLAS_THREAD_VARIABLES)); "
    "print(numpy.__name__)"
)


def run(env: dict[str, str]) -> list[str]:
    done = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True
    )
    return done.stdout.split()


def test_one_blas_thread_by_default() -> None:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    assert run(env)[: len(BLAS_THREAD_VARIABLES)] == ["1"] * len(BLAS_THREAD_VARIABLES)


def test_the_users_setting_is_kept() -> None:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    env["OPENBLAS_NUM_THREADS"] = "3"
    assert run(env)[0] == "3"


def test_numpy_is_not_imported_before_the_setting() -> None:
    # the variables only work when set before numpy loads its BLAS: importing the
    # command line (what runs before the setting) must not import numpy
    done = subprocess.run(
        [sys.executable, "-c", "import sys, hexatherm.cli; print('numpy' in sys.modules)"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.strip() == "False"
