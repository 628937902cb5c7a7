"""``hexatherm simulate``: a session folder (and its truth) from a scenario file."""

from __future__ import annotations

from pathlib import Path

import click

from hexatherm.cli.options import MAX_SEED, clean_errors, echo_err, imports_done, overwrite_option


@click.command("simulate")
@click.argument(
    "scenario", required=False, type=click.Path(exists=True, dir_okay=False, path_type=Path)
)
@click.option(
    "--plan",
    "plan_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Simulate this plan file (as 'hexatherm plan' writes it) as a typical session, "
    "instead of a SCENARIO: legs warmed 3 K by mats from 5 min on, 0.5 um CMM noise, "
    "0.02 K thermocouple noise (OUT/truth/scenario.yaml holds it, to edit and rerun). "
    "Needs --hexapod and --balls.",
)
@click.option(
    "--hexapod",
    "hexapod_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Hexapod file of --plan.",
)
@click.option(
    "--balls",
    "balls_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Balls file of --plan.",
)
@click.option(
    "-o",
    "--out",
    "out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="The session folder to write.",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0, max=MAX_SEED),
    default=None,
    help="Seed of the random draws [default: the scenario's seed].",
)
@overwrite_option
@clean_errors
def command(
    scenario: Path | None,
    plan_path: Path | None,
    hexapod_path: Path | None,
    balls_path: Path | None,
    out: Path,
    seed: int | None,
    overwrite: bool,
) -> None:
    """Simulate SCENARIO (or --plan) with the hexapod twin and write a session folder OUT.

    OUT holds the files a real session has (session.yaml, hexapod, balls and
    plan files, the CMM's measurements, temperatures.csv), ready for
    'hexatherm process', plus OUT/truth/ (true poses at measurement time and in
    the reference thermal state, true leg growth and temperatures, the effects
    and seed), which process never reads. The same scenario and seed always
    give the same files, byte for byte. Prints, per target, the true thermal
    error of its conventional pose (um, urad).
    """
    from hexatherm.workflows.simulate.run import SimulateRequest, simulate_folder

    imports_done()
    if (scenario is None) == (plan_path is None):
        raise click.UsageError("give a SCENARIO file or --plan PLAN, one of them")
    if plan_path is None:
        if hexapod_path is not None or balls_path is not None:
            raise click.UsageError("--hexapod and --balls go with --plan (a scenario names them)")
    elif hexapod_path is None or balls_path is None:
        raise click.UsageError("--plan needs --hexapod and --balls")
    done = simulate_folder(
        SimulateRequest(out, scenario, plan_path, hexapod_path, balls_path, seed, overwrite)
    )
    read = done.scenario
    effects = ", ".join(e.name for e in read.effects) or "none"
    echo_err(
        f"scenario {read.name}: {done.n_steps} steps ({done.n_targets} "
        f"targets) over {done.duration_h:.2f} h, output {read.output}, effects: {effects}"
    )
    echo_err("true thermal error of each target's conventional pose (vs. R0's thermal state):")
    click.echo(f"{'label':8} {'|dT| um':>10} {'|dR| urad':>10}")
    for target in done.targets:
        click.echo(f"{target.label:8} {target.translation_um:10.3f} {target.rotation_urad:10.3f}")
    echo_err(f"wrote {len(done.written)} files to {out}")
