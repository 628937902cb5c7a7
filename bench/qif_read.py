"""What reading a QIF 3 results file costs (a script, not a test).

Run with ``python bench/qif_read.py [STEPS]`` (1000 by default). It writes, the way the
tests' stand-in for CMM software does (``tests/io/qifwriter.py``), a results file of
STEPS steps x 3 balls x 25 probed points (1000 steps: 3,000 spheres, 75,000 points,
7.5 MB) and prints the time of

- the read as ``process`` does it (every element read validated against the shipped
  QIF 3.0 schema where it lies: ``FileUnits``, each ``SphereFeatureItem``,
  ``SphereFeatureMeasurement`` and ``MeasuredPointSet``);
- the same read without the validation (the parse, the numbers, the records);
- a whole-document validation (what the tests do to what hexatherm writes);

after compiling the schema once (printed too), and the process's peak memory. The
figures quoted in docs/formats.md section 7.6 come from here.
"""

from __future__ import annotations

import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import hexatherm.io.qif as qif
from hexatherm.io.qifschema import check_document, schema
from hexatherm.io.records import Records

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.io.qifwriter import results_qif  # noqa: E402


def main(n_steps: int = 1000, per_ball: int = 25) -> None:
    labels = np.repeat([f"S{i}" for i in range(n_steps)], 3 * per_ball)
    balls = np.tile(np.repeat(["B1", "B2", "B3"], per_ball), n_steps)
    n = len(labels)
    rng = np.random.default_rng(0)
    records = Records(
        "bench", "points", labels, balls, rng.normal(300, 50, (n, 3)),
        1.5e9 + np.arange(n, dtype=float), "iso", np.arange(n) + 2,
    )  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "results.qif"
        path.write_bytes(results_qif(records))
        print(f"file: {path.stat().st_size / 1e6:.1f} MB, {3 * n_steps} spheres, {n} points")
        start = time.perf_counter()
        schema()
        print(f"schema compiled: {time.perf_counter() - start:.2f} s")
        start = time.perf_counter()
        assert len(qif.read_qif(path)[0]) == n
        print(f"read, validating what is read: {time.perf_counter() - start:.2f} s")
        checked = qif.check_element
        qif.check_element = lambda element, where: None  # type: ignore[assignment]
        try:
            start = time.perf_counter()
            qif.read_qif(path)
            print(f"read without validation: {time.perf_counter() - start:.2f} s")
        finally:
            qif.check_element = checked
        start = time.perf_counter()
        check_document(path)
        print(f"whole-document validation: {time.perf_counter() - start:.2f} s")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory of the process: {peak:.0f} MB")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:2]))
