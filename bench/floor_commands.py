"""``fit-spheres``, ``inspect``, ``diagnose`` and ``calibrate`` against their floor
(a script, not a test; issue 37, item 1).

How to run it (from a checkout, its environment active, ``PYTHONPATH`` unset or this
checkout)::

    mkdir /tmp/before && git archive f556510 | tar -x -C /tmp/before  # the code before
    python bench/floor_commands.py --baseline /tmp/before --pairs 3 --bytecode
    python bench/floor_commands.py --baseline /tmp/before --commands inspect \\
        --rows 1000x400 --pairs 5

Issue 37's item 1 holds ``process`` and the commands that read the same files to 2x the
floor's CPU and 1.5x the floor's peak memory on a scanning session (1000 targets x 400
points a ball, 2.4 million points, a 149 MB points CSV) and at 10,000 targets (x 25
points, 1.5 million points). ``process`` is measured by ``bench/floor.py --issue37``;
this script measures the four others on the same sessions, with the same floor and the
same runner (it imports them from ``bench/floor.py``: the sessions simulated by
``bench/speed.py`` once and cached in ``bench/.cache/``, the floor ``python -c "import
numpy, pandas; pandas.read_csv(POINTS)"``, each run a fresh process on one BLAS thread,
its CPU the user + system time of the child, its peak the child's ``ru_maxrss``).

Each command runs as a user runs it on that session:

- ``fit-spheres POINTS -o centres.csv``: every sphere of the points file;
- ``inspect POINTS``: the text table of every point (standard output to a file);
- ``diagnose SESSION -o DIR``: the session read, its spheres fitted, the search for
  missing effects against the twin, its files and figures;
- ``calibrate SESSION -o DIR``: the session processed as ``process`` does (the session is
  a campaign: every target is a pose of the calibration), the level chosen (``auto``),
  its files and report.

For every (row, command) the floor, the code at ``--baseline`` (``before``) and this
checkout (or ``--code DIR``, ``now``) run in alternating triples; the script prints each
triple, the medians of the CPU ratios to the floor and of now / before, and the median
peaks, then one table of all. Before timing, each side's outputs (its files and
standard output; not ``provenance.json`` and ``manifest.json``, which hold times and
the code's version) are compared byte for byte and any difference is printed. The
machine's load (1-minute average) is printed with every figure: compare the paired
ratios when the machine is shared.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import sys
from datetime import UTC, datetime
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import floor  # noqa: E402
from floor import LAST_PEAK_MB, timed  # noqa: E402
from speed import CACHE  # noqa: E402

#: the rows: (targets, points per ball); the scanning session and the 10,000 targets
ROWS = ((1000, 400), (10000, 25))
COMMANDS = ("fit-spheres", "inspect", "diagnose", "calibrate")
#: files of an output folder that hold times or the code's version, not results
VOLATILE = {"provenance.json", "manifest.json", ".hexatherm-manifest.json"}


def command_line(command: str, folder: Path, points: Path, out: Path) -> list[str]:
    """The arguments of ``hexatherm`` that run ``command`` on a row's session into ``out``."""
    if command == "fit-spheres":
        return ["fit-spheres", str(points), "-o", str(out / "centres.csv"), "--overwrite"]
    if command == "inspect":
        return ["inspect", str(points)]
    if command in ("diagnose", "calibrate"):
        return [command, str(folder), "-o", str(out / command), "--overwrite"]
    raise ValueError(command)


def hexatherm_run(arguments: list[str], out: Path) -> list[str]:
    """``python -m hexatherm ARGUMENTS`` with its standard output into ``out/stdout.txt``
    (the shell ``exec``s it: the measured child is hexatherm itself)."""
    out.mkdir(parents=True, exist_ok=True)
    return [
        "/bin/sh",
        "-c",
        'out="$1"; shift; exec "$@" > "$out"',
        "sh",
        str(out / "stdout.txt"),
        sys.executable,
        "-m",
        "hexatherm",
        *arguments,
    ]


#: a time written today (a run's own: ``written:``, the report's date), not a result
TODAY = re.compile(
    datetime.now(UTC).strftime("%Y-%m-%d").encode() + rb"T\d\d:\d\d:\d\d(\.\d+)?(\+00:00)?"
)


def differences(a: Path, b: Path) -> list[str]:
    """The files of two output folders that are not the same bytes (but :data:`VOLATILE`,
    and the times written today, :data:`TODAY`)."""
    found = []
    names = {p.relative_to(a) for p in a.rglob("*") if p.is_file()}
    names |= {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    for name in sorted(names):
        if name.name in VOLATILE:
            continue
        left, right = a / name, b / name
        if not (left.is_file() and right.is_file()):
            found.append(f"{name}: only in {'before' if left.is_file() else 'now'}")
        elif TODAY.sub(b"", left.read_bytes()) != TODAY.sub(b"", right.read_bytes()):
            found.append(f"{name}: differs")
    return found


def measure(
    command: str,
    targets: int,
    per_ball: int,
    before: Path,
    now: Path,
    pairs: int,
    out_root: Path,
) -> dict[str, float | str]:
    """Alternating triples (floor, before, now) of one command on one row."""
    folder, points, floor_command = floor._row(targets, per_ball)
    # one output folder for both (the report names it), each side's first outputs kept
    out = out_root / "run"
    run = hexatherm_run(command_line(command, folder, points, out), out)
    codes = {"before": before, "now": now}
    # once each, to warm the file cache and compile the modules; then their outputs
    for side, code in codes.items():
        timed(run, code)
        out.rename(out_root / side)
        out.mkdir()
    changed = differences(out_root / "before", out_root / "now")
    name = f"{targets} x {per_ball}"
    print(f"\n{command}, {name} ({points.name}): outputs before and now", flush=True)
    print("  the same bytes" if not changed else "  " + "\n  ".join(changed), flush=True)
    triples, peaks, loads = [], [], []
    for _ in range(pairs):
        cpu, peak = [], []
        for side in (None, "before", "now"):
            if side is None:
                cpu.append(timed(floor_command)[1])
            else:
                cpu.append(timed(run, codes[side])[1])
            peak.append(LAST_PEAK_MB[0])
        loads.append(os.getloadavg()[0])
        triples.append(cpu)
        peaks.append(peak)
        print(
            f"  CPU floor {cpu[0]:7.3f} s, before {cpu[1]:7.3f} s ({cpu[1] / cpu[0]:5.2f}x), "
            f"now {cpu[2]:7.3f} s ({cpu[2] / cpu[0]:5.2f}x); peak {peak[0]:.0f}, "
            f"{peak[1]:.0f}, {peak[2]:.0f} MB; load {loads[-1]:.1f}",
            flush=True,
        )
    now_ratios = [t[2] / t[0] for t in triples]
    row: dict[str, float | str] = {
        "command": command,
        "row": name,
        "floor_s": statistics.median(t[0] for t in triples),
        "before_ratio": statistics.median(t[1] / t[0] for t in triples),
        "now_ratio": statistics.median(now_ratios),
        "now_min": min(now_ratios),
        "now_max": max(now_ratios),
        "paired": statistics.median(t[2] / t[1] for t in triples),
        "floor_mb": statistics.median(p[0] for p in peaks),
        "before_mb": statistics.median(p[1] for p in peaks),
        "now_mb": statistics.median(p[2] for p in peaks),
        "load": statistics.median(loads),
        "same": "yes" if not changed else "NO",
    }
    return row


def table(rows: list[dict[str, float | str]], pairs: int) -> None:
    """Every (row, command) side by side: medians of the CPU ratios and of the peaks."""
    print(f"\nissue 37 item 1, CPU (user + system), medians of {pairs} alternating triples")
    print(
        f"{'command':>12} {'row':>11} {'floor s':>8} {'before/fl':>9} {'now/fl':>7} "
        f"{'(range)':>11} {'now/bef':>7} {'MB floor':>8} {'before':>7} {'now':>6} "
        f"{'now/fl':>6} {'load':>5} {'same':>4} {'met':>4}"
    )
    for r in rows:
        mem = float(r["now_mb"]) / float(r["floor_mb"])
        met = float(r["now_ratio"]) <= 2.0 and mem <= 1.5
        print(
            f"{r['command']:>12} {r['row']:>11} {r['floor_s']:8.3f} {r['before_ratio']:9.2f} "
            f"{r['now_ratio']:7.2f} {r['now_min']:5.2f}-{r['now_max']:<5.2f} "
            f"{r['paired']:7.2f} {r['floor_mb']:8.0f} {r['before_mb']:7.0f} "
            f"{r['now_mb']:6.0f} {mem:6.2f} {r['load']:5.1f} {r['same']:>4} "
            f"{'yes' if met else 'no':>4}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--baseline", type=Path, required=True, help="a checkout of the code before"
    )
    parser.add_argument("--code", type=Path, help="the checkout measured as now (default: this)")
    parser.add_argument("--pairs", type=int, default=3, help="alternating triples per row")
    parser.add_argument("--bytecode", action="store_true", help="compiled modules, as installed")
    parser.add_argument(
        "--commands",
        nargs="+",
        choices=COMMANDS,
        default=list(COMMANDS),
        help="the commands measured (default: all four)",
    )
    parser.add_argument(
        "--rows",
        nargs="+",
        default=[f"{t}x{p}" for t, p in ROWS],
        help="sessions as TARGETSxPOINTS (default: 1000x400 10000x25)",
    )
    args = parser.parse_args()
    floor.BYTECODE = args.bytecode
    now = args.code or Path(__file__).resolve().parents[1]
    out_root = CACHE / f"commands-out-{os.getpid()}"
    rows = []
    try:
        for spec in args.rows:
            targets, per_ball = (int(v) for v in spec.lower().split("x"))
            for command in args.commands:
                rows.append(
                    measure(
                        command,
                        targets,
                        per_ball,
                        args.baseline,
                        now,
                        args.pairs,
                        out_root / f"{command}-{targets}x{per_ball}",
                    )
                )
                shutil.rmtree(out_root / f"{command}-{targets}x{per_ball}", ignore_errors=True)
        table(rows, args.pairs)
    finally:
        shutil.rmtree(out_root, ignore_errors=True)


if __name__ == "__main__":
    main()
