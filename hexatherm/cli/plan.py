"""``hexatherm plan``: a measuring plan, its DMIS program and the operator's checklist."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import click

from hexatherm.cli.options import (
    MAX_SEED,
    CheckedFloat,
    clean_errors,
    echo_err,
    imports_done,
    max_gap_option,
    overwrite_option,
)

AXES = ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")


def parse_pose(text: str, what: str) -> list[float]:
    """A pose ``Tx,Ty,Tz,Rx,Ry,Rz`` from an option value (click.BadParameter when bad)."""
    cells = [c.strip() for c in text.replace(";", ",").split(",")]
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise click.BadParameter(
            f"{text!r}: expected six numbers Tx,Ty,Tz,Rx,Ry,Rz", param_hint=what
        ) from None
    if len(values) != 6 or not all(abs(v) < float("inf") for v in values):
        raise click.BadParameter(
            f"{text!r}: expected six finite numbers Tx,Ty,Tz,Rx,Ry,Rz", param_hint=what
        )
    return values


def parse_box(specs: Sequence[str]) -> tuple[list[float], list[float]]:
    """The workspace box from ``AXIS=MIN:MAX`` items; axes not given are fixed at 0."""
    lower, upper = [0.0] * 6, [0.0] * 6
    seen: set[str] = set()
    for spec in specs:
        name, _, bounds = spec.partition("=")
        axis = next((a for a in AXES if a.lower() == name.strip().lower()), None)
        lo_text, sep, hi_text = bounds.partition(":")
        try:
            lo, hi = float(lo_text), float(hi_text)
        except ValueError:
            lo = hi = float("nan")
        if axis is None or not sep or not lo <= hi:
            raise click.BadParameter(
                f"{spec!r}: expected AXIS=MIN:MAX with AXIS one of "
                f"{', '.join(AXES)} and MIN <= MAX",
                param_hint="--box",
            )
        if axis in seen:
            raise click.BadParameter(f"{axis} given twice", param_hint="--box")
        seen.add(axis)
        lower[AXES.index(axis)], upper[AXES.index(axis)] = lo, hi
    return lower, upper


#: the most targets a plan takes (--random, --grid): a campaign of a thousand targets
#: is a week of measuring
MAX_TARGETS = 100_000
#: the most cycles over the targets
MAX_CYCLES = 1_000
#: the most points probed on one ball
MAX_POINTS_PER_BALL = 10_000
#: the most repeats of O or R0
MAX_REPEATS = 100


def parse_levels(text: str) -> list[int]:
    """Grid levels: one count for every axis, or six counts."""
    try:
        counts = [int(c) for c in text.split(",")]
    except ValueError:
        counts = []
    if len(counts) not in (1, 6) or min(counts, default=0) < 1:
        raise click.BadParameter(
            f"{text!r}: expected a count >= 1, or six counts Tx,Ty,Tz,Rx,Ry,Rz", param_hint="--grid"
        )
    return counts * 6 if len(counts) == 1 else counts


@click.command("plan")
@click.option(
    "--hexapod",
    "hexapod_path",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Hexapod file.",
)
@click.option(
    "--balls",
    "balls_path",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Balls file.",
)
@click.option(
    "--targets",
    "targets_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="CSV of target poses Tx,Ty,Tz,Rx,Ry,Rz (mm, deg), one per line.",
)
@click.option(
    "--grid",
    "grid",
    metavar="N|N1,..,N6",
    help="Targets on a grid over the --box: N values per axis (or one count per axis).",
)
@click.option(
    "--random",
    "n_random",
    type=click.IntRange(min=1, max=MAX_TARGETS),
    metavar="N",
    help="N targets drawn uniformly in the --box (poses out of reach are drawn again).",
)
@click.option(
    "--seed", type=click.IntRange(min=0, max=MAX_SEED), default=None, help="Seed of --random."
)
@click.option(
    "--box",
    "box",
    multiple=True,
    metavar="AXIS=MIN:MAX",
    help="Workspace box of --grid/--random, one axis per option, relative to O (Tx, Ty, "
    "Tz in mm; Rx, Ry, Rz in deg; e.g. --box Tx=-10:10 --box Rz=-2:2); axes not given "
    "stay at 0.",
)
@click.option(
    "--reference",
    default="0,0,-40,0,0,0",
    show_default=True,
    metavar="Tx,Ty,Tz,Rx,Ry,Rz",
    help="The reference pose R, relative to O (mm and deg, the hexapod file's convention).",
)
@click.option(
    "--cycles",
    type=click.IntRange(min=1, max=MAX_CYCLES),
    default=1,
    show_default=True,
    help="Measure the targets this many times.",
)
@click.option(
    "--reference-every",
    type=click.Choice(["both", "before", "after"]),
    default="both",
    show_default=True,
    help="both/after: one R between consecutive targets and one after the last, so "
    "each target has R on both sides; before: no R after the last target.",
)
@click.option(
    "--origin-repeats",
    type=click.IntRange(min=1, max=MAX_REPEATS),
    default=1,
    show_default=True,
    metavar="N",
    help="Measure O N times (O, R0, O-2, R0-2, ...: a repeat of O is a target at the "
    "zero pose labelled O-n, with R0 measured again beside it); process averages them.",
)
@click.option(
    "--reference0-repeats",
    type=click.IntRange(min=1, max=MAX_REPEATS),
    default=1,
    show_default=True,
    metavar="N",
    help="Measure R0 N times (references labelled R0-n, before the first target; at "
    "least as often as O); process averages them.",
)
@click.option(
    "--points-per-ball",
    type=click.IntRange(min=1, max=MAX_POINTS_PER_BALL),
    default=25,
    show_default=True,
    help="Points probed on each ball (the DMIS program's and the checklist's count, and the "
    "time estimate's; 4 fit a sphere, 25 check its form: docs/planning.md).",
)
@click.option(
    "--seconds-per-point",
    type=CheckedFloat(min=0),
    default=2.4,  # core.planning.DEFAULT_SECONDS_PER_POINT (imports numpy)
    show_default=True,
    help="Estimated probing time per point (s).",
)
@click.option(
    "--seconds-per-move",
    type=CheckedFloat(min=0),
    default=20.0,  # core.planning.DEFAULT_SECONDS_PER_MOVE, as simulate's
    show_default=True,
    help="Estimated time to command a pose and settle (s).",
)
@max_gap_option
@click.option(
    "--min-rcond",
    type=CheckedFloat(min=0),
    default=None,
    help="Refuse poses whose Jacobian's reciprocal condition number is below this [default: 1e-2].",
)
@click.option(
    "--dmis",
    "dmis_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write a DMIS measurement program for the CMM.",
)
@click.option(
    "--qif",
    "qif_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the plan as a QIF 3 document (the balls of every step as sphere "
    "features named <step>_<ball> at their nominal centres on the CMM).",
)
@click.option(
    "--origin-on-cmm",
    metavar="Tx,Ty,Tz,Rx,Ry,Rz",
    help="Nominal placement of frame O on the CMM: X,Y,Z in mm, A,B,C in deg, the hexapod "
    "file's convention (needed by --dmis and --qif).",
)
@click.option(
    "--cap-angle",
    type=CheckedFloat(min=1, max=180),
    default=70.0,  # core.planning.DEFAULT_CAP_ANGLE_DEG, as the session's cmm:
    show_default=True,
    help="Half-angle of the ball cap the touch points cover (deg).",
)
@click.option(
    "--clearance",
    type=CheckedFloat(min=0),
    default=30.0,
    show_default=True,
    help="Probe clearance above the balls between balls (mm).",
)
@click.option(
    "--calibration",
    "calibration_poses",
    type=click.IntRange(min=1, max=MAX_TARGETS),
    default=None,
    metavar="N",
    help="Plan a calibration campaign: of the targets, grid or random poses given "
    "(candidates), keep the N that best identify the geometry (--calibration-criterion); "
    "refused when they cannot identify it, naming why.",
)
@click.option(
    "--calibration-criterion",
    type=click.Choice(["d-optimal", "g-optimal", "i-optimal"]),
    default="d-optimal",
    show_default=True,
    help="How --calibration chooses: d-optimal (the parameters' joint uncertainty), "
    "g-optimal (the worst predicted uncertainty of a calibrated pose over the candidates) "
    "or i-optimal (its mean over them).",
)
@click.option(
    "--calibration-level",
    type=click.Choice(["offsets", "joints", "joints+gains"]),
    default="joints",
    show_default=True,
    help="The calibration model --calibration designs for.",
)
@click.option(
    "--checklist",
    "checklist_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write the operator's checklist (Markdown).",
)
@click.option(
    "-o",
    "--out",
    "out",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Plan file to write [default: standard output].",
)
@overwrite_option
@clean_errors
def command(
    hexapod_path: Path,
    balls_path: Path,
    targets_path: Path | None,
    grid: str | None,
    n_random: int | None,
    seed: int | None,
    box: tuple[str, ...],
    reference: str,
    cycles: int,
    reference_every: str,
    origin_repeats: int,
    reference0_repeats: int,
    points_per_ball: int,
    seconds_per_point: float,
    seconds_per_move: float,
    max_gap: float,
    min_rcond: float | None,
    dmis_path: Path | None,
    qif_path: Path | None,
    origin_on_cmm: str | None,
    cap_angle: float,
    clearance: float,
    calibration_poses: int | None,
    calibration_level: str,
    calibration_criterion: str,
    checklist_path: Path | None,
    out: Path | None,
    overwrite: bool,
) -> None:
    """Write a measuring plan in the paper's order: O, R0, then S_i with R around them.

    Targets come from --targets (a CSV file), --grid or --random over a --box.
    Every commanded pose is checked against the legs' stroke and for a
    near-singular Jacobian; nothing is written when one fails. The plan goes to
    OUT (or standard output); --dmis, --checklist and --qif add the CMM program, the
    operator's sheet and the plan as QIF 3 sphere features.
    """
    from hexatherm.workflows.plan import PlanFiles, PlanRequest, write_plan

    imports_done()

    sources_given = sum(x is not None for x in (targets_path, grid, n_random))
    if sources_given != 1:
        raise click.UsageError("give exactly one of --targets, --grid and --random")
    if box and targets_path is not None:
        raise click.UsageError("--box goes with --grid or --random, not with --targets")
    if (grid is not None or n_random is not None) and not box:
        raise click.UsageError("--grid and --random need the workspace: --box AXIS=MIN:MAX")
    if seed is not None and n_random is None:
        raise click.UsageError("--seed goes with --random")
    if dmis_path is not None and origin_on_cmm is None:
        raise click.UsageError(
            "--dmis needs --origin-on-cmm: where frame O nominally is on "
            "the CMM (the probe would otherwise go to made-up positions)"
        )
    if qif_path is not None and origin_on_cmm is None:
        raise click.UsageError(
            "--qif needs --origin-on-cmm: where frame O nominally is on the CMM (the "
            "spheres' nominal centres)"
        )
    named = [(out, "-o"), (dmis_path, "--dmis"), (checklist_path, "--checklist")]
    named.append((qif_path, "--qif"))
    outputs = [p for p, _ in named if p is not None]
    if len({os.path.realpath(p) for p in outputs}) != len(outputs):
        raise click.UsageError("-o, --dmis, --checklist and --qif must be different files")
    lower, upper = parse_box(box) if box else (None, None)
    if grid is not None and lower is not None and upper is not None:
        varied = [n for n, lo, hi in zip(parse_levels(grid), lower, upper, strict=True) if hi > lo]
        if math.prod(varied) > MAX_TARGETS:
            raise click.BadParameter(
                f"{grid!r} over the --box gives {math.prod(varied):,} targets (at most "
                f"{MAX_TARGETS:,})",
                param_hint="--grid",
            )
    origin = None if origin_on_cmm is None else parse_pose(origin_on_cmm, "--origin-on-cmm")
    if origin is not None:
        from hexatherm.workflows.plan import COORDINATE_MAX_MM

        if max(abs(v) for v in origin[:3]) > COORDINATE_MAX_MM:
            raise click.BadParameter(
                f"{origin_on_cmm!r}: frame O farther than {COORDINATE_MAX_MM / 1e3:g} m from "
                "the CMM's origin (a value in um?)",
                param_hint="--origin-on-cmm",
            )
    request = PlanRequest(
        hexapod_path=hexapod_path,
        balls_path=balls_path,
        reference_pose=parse_pose(reference, "--reference"),
        targets_path=targets_path,
        grid_levels=None if grid is None else parse_levels(grid),
        n_random=n_random,
        seed=seed,
        box_lower=lower,
        box_upper=upper,
        cycles=cycles,
        reference_every=reference_every,
        origin_repeats=origin_repeats,
        reference0_repeats=reference0_repeats,
        points_per_ball=points_per_ball,
        seconds_per_point=seconds_per_point,
        seconds_per_move=seconds_per_move,
        max_gap_s=max_gap,
        min_rcond=min_rcond,
        origin_on_cmm=origin,
        cap_angle_deg=cap_angle,
        clearance_mm=clearance,
        dmis_name=None if dmis_path is None else Path(dmis_path).stem,
        checklist=checklist_path is not None,
        qif=qif_path is not None,
        calibration_poses=calibration_poses,
        calibration_level=calibration_level,
        calibration_criterion=calibration_criterion,
    )
    done = write_plan(request, PlanFiles(out, dmis_path, checklist_path, qif_path, overwrite))
    made = done.made
    if made.redrawn:
        echo_err(f"drew {made.redrawn} random pose(s) again: out of the stroke or near-singular")
    if made.selection is not None:
        chosen = made.selection
        refused = ", ".join(f"{n} {why}" for why, n in chosen.refused.items() if n)
        echo_err(
            f"calibration ({calibration_level}): kept {len(chosen.indices)} of the candidates "
            f"({', '.join(str(int(k) + 1) for k in chosen.indices)}"
            f"{'; refused: ' + refused if refused else ''}); predicted standard "
            f"uncertainty of a calibrated pose at most {chosen.worst_sigma_um:.2f} um, "
            f"{chosen.worst_sigma_urad:.2f} urad (1 um / 5 urad per measured pose)"
        )
        random_worst, random_rms = chosen.random_sigma_um
        echo_err(
            f"design ({chosen.criterion}): over the candidates a calibrated pose's Tx, Ty, "
            f"Tz uncertainty is at most {chosen.worst_sigma_um:.2f} um, "
            f"{chosen.mean_sigma_um:.2f} um RMS; {len(chosen.indices)} random candidates "
            f"(median of 20 draws): {random_worst:.2f} um, {random_rms:.2f} um RMS "
            f"({random_worst / chosen.worst_sigma_um:.2f}x, "
            f"{random_rms / chosen.mean_sigma_um:.2f}x; predicted, before measuring)"
        )
        if origin_repeats == 1 or reference0_repeats == 1:
            echo_err(
                "note: O and R0 are measured once: their error is common to every corrected "
                "pose, so it does not average out in the calibration; --origin-repeats 4 "
                "--reference0-repeats 4, measured before the legs warm, remove most of it "
                "(docs/calibrate.md, 'The paper's claim, measured')"
            )
    for gap in made.gaps:
        echo_err(
            f"warning: {gap.target} and its reference {gap.reference} are expected "
            f"{gap.gap_s / 60:.1f} min apart (--max-gap {max_gap / 60:.1f} min): fewer "
            "points per ball or a faster CMM program keep the thermal state comparable"
        )
    if done.stdout is not None:
        click.echo(done.stdout, nl=False)
    for target in done.written:
        echo_err(f"wrote {target}")
    echo_err(
        f"plan: {len(made.plan.labels)} steps ({done.n_targets} targets x "
        f"{len(made.ball_names)} balls x {points_per_ball} points), estimated "
        f"{made.timing.total_s / 3600:.2f} h"
    )
    if done.repeat_labels:
        echo_err(
            f"O measured {done.n_origin} time(s), R0 {done.n_reference0} time(s) "
            f"({', '.join(done.repeat_labels)}): process averages each"
        )
