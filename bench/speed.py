"""Speed benchmark of ``hexatherm process`` (a plain script, not a test).

Run with ``.venv/bin/python bench/speed.py [--targets 1000] [--repeat 3]``. It simulates
a campaign of N targets on the Symetrie-like hexapod (O, R0, then every target
followed by a reference: 2N + 2 steps; 3 balls, 25 points per ball on a 70 deg cap,
0.5 um point noise), written once as a points CSV and once as DMIS (cached in
``bench/.cache/``), and prints, as the best of ``--repeat`` wall times:

1. end to end, as subprocesses (interpreter start, imports, reading, sphere fits,
   registration, correction, writing): ``hexatherm process DIR -o OUT --overwrite``
   against ``python bench/straightforward.py DIR -o OUT``, the same job done the
   straightforward way (one ``scipy.optimize.least_squares`` per sphere, one
   ``Rotation.align_vectors`` per step, one ``scipy.optimize.root`` per pose, the
   files read line by line). ``process`` also propagates the centres' uncertainties
   to the poses and runs the quality checks, which the straightforward script does
   not: both figures are shown, with and without that work;
2. in process, imports excluded: :func:`hexatherm.workflows.process.pipeline.process_session`
   against ``straightforward.process`` (reading and computation);
3. the computation alone, the points in memory: sphere fits, centres, registration
   and correction against ``straightforward.compute``;
4. how far the two ways agree (they must, to 1e-6 mm);
5. rates: sphere fits, registrations and FGM poses per second, vectorized and one
   at a time; and the measurement readers against their general (slow) paths;
6. the time of ``hexatherm --help`` (best of 5).

The machine's load matters: timings are the best of several runs, and the
straightforward figures are best of fewer runs where they take long.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CACHE = Path(__file__).resolve().parent / ".cache"
sys.path.insert(0, str(Path(__file__).resolve().parent))

import straightforward  # noqa: E402

from hexatherm.core.registration import register  # noqa: E402
from hexatherm.core.spherefit import fit_spheres  # noqa: E402
from hexatherm.io import csvfile, dmis, temperatures  # noqa: E402
from hexatherm.io.config import read_hexapod, read_session  # noqa: E402
from hexatherm.io.measurements import read_measurements  # noqa: E402
from hexatherm.workflows.process.measured import (  # noqa: E402
    assemble_centres,
    fit_points,
    registration_weights,
)
from hexatherm.workflows.process.pipeline import process_session  # noqa: E402

HALF_RANGE = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])  # target box: +-mm, +-deg
URAD_PER_DEG = np.pi / 180 * 1e6


# ----------------------------------------------------------------------------- sessions
def scenario_text(
    n_targets: int, output: str, points_per_ball: int = 25, seconds_per_point: float = 2.0
) -> str:
    rng = np.random.default_rng(20240607)
    targets = np.round(rng.uniform(-1, 1, (n_targets, 6)) * HALF_RANGE, 3)
    rows = "\n".join(f"    - [{', '.join(f'{v:g}' for v in t)}]" for t in targets)
    mats = "\n".join(
        f"    - {{gain_C: {g}, tau_s: 2400, power: [[600, 12600]]}}"
        for g in (3.0, 7.0, 2.0, 3.0, 9.0, 3.5)
    )
    return f"""format: hexatherm-scenario/1
name: speed-{n_targets}-{output}
hexapod: {ROOT / "configs" / "symetrie-like.yaml"}
balls: {ROOT / "configs" / "balls-3.yaml"}
plan:
  reference_pose: [0, 0, -40, 0, 0, 0]
  references: both
  points_per_ball: {points_per_ball}
  targets:
{rows}
origin_on_cmm: [450, 320, 210, 0, 0, 15]
start: "2024-03-05T07:30:00"
seed: 7
timing: {{seconds_per_point: {seconds_per_point:g}, seconds_per_move: 20}}
heating:
  air_C: 20.0
  mats:
{mats}
thermocouples: {{period_s: 30, noise_C: 0.02}}
cmm: {{point_noise_um: 0.5, points_per_ball: {points_per_ball}, cap_angle_deg: 70}}
hexapod_repeatability_um: 0.1
output: {output}
"""


def session(
    n_targets: int, output: str, points_per_ball: int = 25, seconds_per_point: float = 2.0
) -> Path:
    """The simulated session folder (made once, then taken from the cache)."""
    from hexatherm.workflows.simulate.run import simulate_file

    text = scenario_text(n_targets, output, points_per_ball, seconds_per_point)
    key = hashlib.sha256(text.encode()).hexdigest()[:12]
    folder = CACHE / f"speed-{n_targets}-{output}-{key}"
    if not (folder / "session" / "session.yaml").exists():
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "scenario.yaml").write_text(text)
        note(f"simulating {n_targets} targets as {output} into {folder} ...")
        simulate_file(folder / "scenario.yaml", folder / "session", overwrite=True)
    return folder / "session"


def scanning_session(n_targets: int, points_per_ball: int = 400) -> Path:
    """A scanning probe's session (issue 37): ``points_per_ball`` points per ball taken at
    100 points a second, written as a CMM exports them: ``label,ball,x,y,z,time`` with the
    coordinates at 4 decimals (0.1 um), no normals. Made once from the twin's points
    session, then taken from the cache."""
    import pandas as pd

    source = session(n_targets, "points", points_per_ball, seconds_per_point=0.01)
    folder = source.parent / f"scan-{points_per_ball}"
    if (folder / "session.yaml").exists():
        return folder
    folder.mkdir(exist_ok=True)
    for name in ("session.yaml", "hexapod.yaml", "balls.yaml", "plan.yaml", "temperatures.csv"):
        (folder / name).write_bytes((source / name).read_bytes())
    points = pd.read_csv(source / "points.csv", usecols=["label", "ball", "x", "y", "z", "time"])
    points.to_csv(folder / "points.csv", index=False, float_format="%.4f")
    return folder


# ----------------------------------------------------------------------------- timing
def note(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def best(fn: Callable[[], Any], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def run(*command: str | Path) -> None:
    done = subprocess.run(
        [str(c) for c in command],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, command))} failed:\n{done.stderr}")


def import_time(repeat: int) -> float:
    """Interpreter start and the imports of ``hexatherm process`` (a subprocess)."""
    code = (
        "import hexatherm.cli.process, hexatherm.workflows.process.pipeline, "
        "hexatherm.workflows.process.outputs, "
        "hexatherm.workflows.process.uncertainty, hexatherm.workflows.process.quality"
    )
    return best(lambda: run(sys.executable, "-c", code), repeat)


def hexatherm_script() -> list[str]:
    script = Path(sys.executable).parent / "hexatherm"
    return [str(script)] if script.exists() else [sys.executable, "-m", "hexatherm"]


def computation(records: list[Any], sess: Any) -> Any:
    """The computation of ``process_session`` on records already read (no uncertainty)."""
    from hexatherm.core.correction import correct

    centres = assemble_centres(
        [fit_points(r, sess.balls) if r.kind == "points" else r for r in records], sess
    )
    reg = register(centres.centres_mm, sess.balls.centres_mm, registration_weights(centres.u_um))
    return correct(sess.hexapod, sess.plan, centres.times_s, reg.platform2cmm)


def phase_times(folder: Path, repeat: int) -> dict[str, float]:
    """Best times of the parts of ``hexatherm process`` (in process, imports excluded)."""
    from hexatherm.core.correction import correct
    from hexatherm.core.registration import check_distances
    from hexatherm.session import QualityLimits
    from hexatherm.workflows.process.outputs import write_results
    from hexatherm.workflows.process.quality import quality_checks
    from hexatherm.workflows.process.uncertainty import pose_uncertainty

    sess = read_session(folder)
    state: dict[str, Any] = {}

    def measurements() -> None:
        state["records"] = [r for f in sess.measurements for r in read_measurements(f)]

    def fits() -> None:
        state["centres"] = assemble_centres(
            [fit_points(r, sess.balls) if r.kind == "points" else r for r in state["records"]], sess
        )

    def method() -> None:
        centres = state["centres"]
        check_distances(centres.centres_mm, sess.balls.centres_mm, sess.balls.names)
        reg = register(
            centres.centres_mm, sess.balls.centres_mm, registration_weights(centres.u_um)
        )
        sess.hexapod.igm(sess.plan.poses)
        correct(sess.hexapod, sess.plan, centres.times_s, reg.platform2cmm)

    result = process_session(folder)
    out = CACHE / "out" / "phases"
    uncertainty = pose_uncertainty(result)
    quality = quality_checks(result, QualityLimits())
    return {
        "session, hexapod, balls, plan (YAML)": best(lambda: read_session(folder), repeat),
        "measurements": best(measurements, repeat),
        "temperatures": best(lambda: temperatures.read_temperatures(sess.temperatures), repeat)
        if sess.temperatures is not None
        else 0.0,
        "sphere fits and centres": best(fits, repeat),
        "registration, poses, correction (FGM)": best(method, repeat),
        "uncertainty propagation": best(lambda: pose_uncertainty(result), repeat),
        "quality checks": best(lambda: quality_checks(result, QualityLimits()), repeat),
        "writing the results": best(
            lambda: write_results(
                result, out, overwrite=True, uncertainty=uncertainty, quality=quality
            ),
            repeat,
        ),
    }


def general(reader: str) -> Callable[[Path], Any]:
    """The measurement reader with its fast path switched off."""

    def read(path: Path) -> Any:
        if reader == "dmis":
            return dmis.records_from_features(
                dmis.features_from_text(dmis._read_text(path), path), path
            )
        fast = csvfile._fast_measurement_csv
        csvfile._fast_measurement_csv = lambda *args: None
        try:
            return csvfile.read_measurement_csv(path)
        finally:
            csvfile._fast_measurement_csv = fast

    return read


# ----------------------------------------------------------------------------- report
def table(title: str, header: list[str], rows: list[list[str]]) -> None:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    print(f"\n{title}")
    line = "  ".join(
        h.ljust(w) if i == 0 else h.rjust(w)
        for i, (h, w) in enumerate(zip(header, widths, strict=True))
    )
    print("  " + line)
    for row in rows:
        print(
            "  "
            + "  ".join(
                c.ljust(w) if i == 0 else c.rjust(w)
                for i, (c, w) in enumerate(zip(row, widths, strict=True))
            )
        )


def seconds(t: float) -> str:
    return f"{t:.2f} s" if t >= 0.1 else f"{t * 1e3:.1f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=1000)
    parser.add_argument("--repeat", type=int, default=3, help="runs per timing (best of)")
    parser.add_argument(
        "--slow-repeat",
        type=int,
        default=2,
        help="runs per timing of the straightforward way and general readers",
    )
    args = parser.parse_args()
    rep, slow = args.repeat, args.slow_repeat
    import numpy
    import pandas

    print(
        f"hexatherm speed benchmark: {args.targets} targets; {os.cpu_count()} cores, load "
        f"{os.getloadavg()[0]:.2f}; Python {sys.version.split()[0]}, numpy "
        f"{numpy.__version__}, pandas {pandas.__version__}; best of {rep} "
        f"(straightforward: best of {slow})"
    )
    sessions = {"CSV": session(args.targets, "points"), "DMIS": session(args.targets, "dmis")}
    work = CACHE / "out"
    hexatherm = hexatherm_script()
    end_to_end, in_process, agree = [], [], []
    compute_rows: list[list[str]] = []
    first = read_first = None
    for name, folder in sessions.items():
        sess = read_session(folder)
        n_steps, n_points = len(sess.plan.labels), 0
        note(f"{name}: hexatherm process ...")
        t_ours = best(
            lambda f=folder: run(*hexatherm, "process", f, "-o", work / "ours", "--overwrite"), rep
        )
        note(f"{name}: straightforward.py ...")
        t_plain = best(
            lambda f=folder: run(
                sys.executable, ROOT / "bench" / "straightforward.py", f, "-o", work / "plain"
            ),
            slow,
        )
        note(f"{name}: in process ...")
        result = process_session(folder)
        t_ours_in = best(lambda f=folder: process_session(f), rep)
        plain: dict[str, Any] = {}
        t_plain_in = best(lambda f=folder, p=plain: p.update(straightforward.process(f)), slow)
        from hexatherm.workflows.process.uncertainty import pose_uncertainty

        t_unc = best(lambda r=result: pose_uncertainty(r), rep)
        records = [r for file in sess.measurements for r in read_measurements(file)]
        n_points = sum(len(r) for r in records)
        end_to_end.append(
            [
                name,
                f"{n_steps} steps, {n_points:,} points",
                seconds(t_ours),
                seconds(t_ours - t_unc),
                seconds(t_plain),
                f"{t_plain / t_ours:.1f}x",
                f"{t_plain / (t_ours - t_unc):.1f}x",
            ]
        )
        in_process.append(
            [name, seconds(t_ours_in), seconds(t_plain_in), f"{t_plain_in / t_ours_in:.1f}x"]
        )
        corr = result.correction
        agree.append(
            [
                name,
                f"{np.abs(plain['centres_mm'] - result.centres.centres_mm).max():.1e}",
                f"{np.abs(plain['conventional'][:, :3] - corr.conventional[:, :3]).max():.1e}",
                f"{np.abs(plain['corrected'][:, :3] - corr.corrected[:, :3]).max():.1e}",
                f"{np.abs(plain['corrected'][:, 3:] - corr.corrected[:, 3:]).max():.1e}",
            ]
        )
        if first is None:
            first, read_first = folder, (sess, records)
    # where the time of process goes, in process, for both sessions
    note("phases ...")
    phases = {name: phase_times(folder, rep) for name, folder in sessions.items()}
    # the computation alone, on the CSV session's points in memory
    note("computation alone ...")
    sess, records = read_first
    groups = straightforward.read(first)[1]
    t_comp = best(lambda: computation(records, sess), rep)
    t_comp_plain = best(lambda: straightforward.compute(sess, groups), slow)
    compute_rows.append(
        [
            "fits, registration, correction",
            seconds(t_comp),
            seconds(t_comp_plain),
            f"{t_comp_plain / t_comp:.0f}x",
        ]
    )

    # rates
    note("rates ...")
    points = records[0]
    keys = np.char.add(np.char.add(points.label.astype(str), "/"), points.ball.astype(str))
    _, first_row, groups_idx = np.unique(keys, return_index=True, return_inverse=True)
    n_spheres = first_row.size
    t_fit = best(lambda: fit_spheres(points.xyz_mm, groups_idx), rep)
    some = [points.xyz_mm[groups_idx == k] for k in range(200)]
    t_fit_plain = best(lambda: [straightforward.fit_sphere(p) for p in some], slow) / len(some)
    hexapod = read_hexapod(ROOT / "configs" / "symetrie-like.yaml")
    rng = np.random.default_rng(1)
    poses = rng.uniform(-1, 1, (100_000, 6)) * HALF_RANGE
    q = hexapod.igm(poses)
    near = poses + rng.normal(scale=[0.01] * 3 + [0.001] * 3, size=poses.shape)
    t_fgm0 = best(lambda: hexapod.fgm(q), rep)
    t_fgm1 = best(lambda: hexapod.fgm(q, initial_poses=near), rep)
    t_fgm_plain = (
        best(lambda: [straightforward.fgm_pose(hexapod, q[i], near[i]) for i in range(300)], slow)
        / 300
    )
    centres = result.centres.centres_mm
    many = np.repeat(centres, 50, axis=0)  # ~100k steps
    w = np.ones(many.shape[:2])
    t_reg = best(lambda: register(many, sess.balls.centres_mm, w), rep)
    t_reg_plain = (
        best(
            lambda: [
                straightforward.register_step(c, sess.balls.centres_mm, np.ones(3))
                for c in centres[:500]
            ],
            slow,
        )
        / 500
    )
    rates = [
        [
            "sphere fits (free radius, 25 points)",
            f"{n_spheres / t_fit:,.0f}",
            f"{1 / t_fit_plain:,.0f}",
            f"{t_fit_plain * n_spheres / t_fit:.0f}x",
        ],
        [
            "registrations (3 balls)",
            f"{len(many) / t_reg:,.0f}",
            f"{1 / t_reg_plain:,.0f}",
            f"{t_reg_plain * len(many) / t_reg:.0f}x",
        ],
        ["FGM poses, from the zero pose", f"{len(q) / t_fgm0:,.0f}", "", ""],
        [
            "FGM poses, from 10 um / 1 mdeg away",
            f"{len(q) / t_fgm1:,.0f}",
            f"{1 / t_fgm_plain:,.0f}",
            f"{t_fgm_plain * len(q) / t_fgm1:.0f}x",
        ],
    ]

    # readers: fast path against the general one
    note("readers ...")
    readers = []
    for name, folder, kind in (
        ("points CSV", sessions["CSV"], "csv"),
        ("DMIS", sessions["DMIS"], "dmis"),
    ):
        file = read_session(folder).measurements[0]
        t_fast = best(lambda f=file: read_measurements(f), rep)
        t_general = best(lambda f=file, k=kind: general(k)(f), slow)
        readers.append(
            [
                f"{name} ({file.stat().st_size / 1e6:.0f} MB)",
                seconds(t_fast),
                seconds(t_general),
                f"{t_general / t_fast:.0f}x",
            ]
        )

    note("hexatherm --help ...")
    t_help = best(lambda: run(*hexatherm, "--help"), 5)
    shutil.rmtree(work, ignore_errors=True)

    table(
        "1. End to end, subprocess wall time (imports included)",
        [
            "session",
            "size",
            "process",
            "w/o uncertainty",
            "straightforward",
            "ratio",
            "ratio w/o unc.",
        ],
        end_to_end,
    )
    print(
        "   'w/o uncertainty': minus the time of the uncertainty propagation, measured in "
        "process\n   (the straightforward script does not propagate uncertainties)."
    )
    names = list(phases["CSV"])
    imports = import_time(rep)
    rows = [["interpreter start and imports", seconds(imports), seconds(imports)]]
    rows += [[part, *(seconds(phases[s][part]) for s in ("CSV", "DMIS"))] for part in names]
    rows.append(["sum", *(seconds(imports + sum(phases[s].values())) for s in ("CSV", "DMIS"))])
    table(
        "   Where the time of hexatherm process goes (in process, best of each part)",
        ["part", "CSV", "DMIS"],
        rows,
    )
    table(
        "2. In process, imports excluded (reading + computation, no uncertainty)",
        ["session", "process_session", "straightforward", "ratio"],
        in_process,
    )
    table(
        "3. The computation alone (points in memory)",
        ["work", "vectorized", "straightforward", "ratio"],
        compute_rows,
    )
    table(
        "4. Agreement, max |ours - straightforward|",
        ["session", "centres mm", "conv. T mm", "corr. T mm", "corr. R deg"],
        agree,
    )
    table("5. Rates per second", ["what", "vectorized", "one at a time", "ratio"], rates)
    table("   Measurement readers", ["file", "fast path", "general path", "ratio"], readers)
    print(f"\n6. hexatherm --help: {seconds(t_help)} (best of 5)")


if __name__ == "__main__":
    main()
