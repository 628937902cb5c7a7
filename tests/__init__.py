"""hexatherm's tests.

Imported before anything else of theirs (``tests/conftest.py`` is ``tests.conftest``):
the command line's module is imported here first, before numpy loads its BLAS, so that
the test processes run BLAS on one thread as the commands do (``hexatherm.cli`` sets
``OPENBLAS_NUM_THREADS`` and the like unless the environment says otherwise; it imports
no numpy: tests/cli/test_blas_threads.py). Without it the conftest's ``import numpy``
came first, and each pytest-xdist worker ran OpenBLAS with a thread per core, spinning
while the other worker held the second core (docs/speed.md, the test suite).
"""

import hexatherm.cli  # noqa: F401
