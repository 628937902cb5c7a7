"""``hexatherm serve-twin``: a simulated CMM and hexapod controller, backed by the twin."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import click

from hexatherm.cli.options import CheckedFloat, clean_errors, echo_err, imports_done


@click.command("serve-twin")
@click.option(
    "--hexapod",
    "hexapod_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Hexapod file (with its leg model) [default: the scenario's].",
)
@click.option(
    "--balls",
    "balls_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Balls file [default: the scenario's].",
)
@click.option(
    "--scenario",
    type=click.Path(dir_okay=False, path_type=Path),
    help="A simulate scenario: heating, origin_on_cmm, noise, seed, hidden effects.",
)
@click.option(
    "--dialect",
    type=click.Choice(["symetrie", "pi", "symetrie-pmac"]),
    default="symetrie",
    show_default=True,
    help="The controller's dialect (symetrie-pmac: Symetrie's Power PMAC gpascii over "
    "telnet, as ZONDA/JORAN/PUNA+ controllers).",
)
@click.option(
    "--cmm-dialect",
    type=click.Choice(["dme-1.4.3", "dme-1.4"]),
    default="dme-1.4.3",
    show_default=True,
    help="How the CMM speaks I++: dme-1.4 is a plain DME 1.4 server as the NIST I++ DME "
    "Test Suite's (no Tool.AvrRadius, PtMeas fields in its own order ER, IJK, X, Y, Z, a "
    "lax FindTool) that also keeps its session across connections.",
)
@click.option(
    "--time-scale",
    type=CheckedFloat(min=1e-3, max=1e6),
    default=60.0,
    show_default=True,
    help="Simulated seconds per wall-clock second (thermal drift, moves, settle).",
)
@click.option(
    "--fault",
    "faults",
    multiple=True,
    metavar="KIND[:key=value,...]",
    help="Inject a fault (repeatable): ipp-error:severity=2,method=PtMeas,nth=3; "
    "ipp-event:method=PtMeas,nth=2; ipp-drop:method=PtMeas,nth=5; "
    "ipp-split:method=PtMeas,nth=1; late-in-position:seconds=30; controller-drop; "
    "controller-split; controller-error:command=MOVE#ABS,code=-104; "
    "refuse:axis=Tz,max=5; pi-servo-off; pi-unreferenced; pi-busy; "
    "pi-coordinate-system:name=SAMPLE; pi-pivot:t=100.",
)
@click.option(
    "--origin-on-cmm",
    metavar="Tx,Ty,Tz,Rx,Ry,Rz",
    help="True placement of frame O on the CMM [default: the scenario's, or 450,320,210,0,0,15].",
)
@click.option(
    "--point-noise-um",
    type=CheckedFloat(min=0, max=1000),
    default=None,
    help="Probing noise along the normal (um) [default: the scenario's, or 0.5].",
)
@click.option(
    "--seed",
    type=click.IntRange(min=0, max=2**32 - 1),
    default=None,
    help="Noise seed [default: the scenario's, or 0].",
)
@click.option("--tool", default="Probe1", show_default=True, help="Name of the CMM's tool.")
@click.option(
    "--cmm-port",
    type=click.IntRange(0, 65535),
    default=0,
    show_default=True,
    help="I++ port on 127.0.0.1 (0: a free one).",
)
@click.option(
    "--controller-port",
    type=click.IntRange(0, 65535),
    default=0,
    show_default=True,
    help="Controller port on 127.0.0.1 (0: a free one).",
)
@click.option(
    "--speed-mm-s",
    type=CheckedFloat(min=1e-3, max=1000),
    default=2.0,
    show_default=True,
    help="The hexapod's speed (simulated mm/s; deg/s half of it).",
)
@click.option(
    "--settle",
    type=CheckedFloat(min=0, max=3600),
    default=2.0,
    show_default=True,
    help="In-position flag after the motion ends (simulated s).",
)
@click.option(
    "--cmm-move-s",
    type=CheckedFloat(min=0, max=3600),
    default=1.0,
    show_default=True,
    help="Duration of each CMM motion (simulated s).",
)
@click.option(
    "--thermocouple-port",
    type=click.IntRange(0, 65535),
    default=0,
    show_default=True,
    help="Thermocouple logger port on 127.0.0.1 (0: a free one).",
)
@click.option(
    "--thermocouple-period",
    type=CheckedFloat(min=0.01, max=3600),
    default=10.0,
    show_default=True,
    help="The logger's sampling period (simulated s).",
)
@clean_errors
def command(
    hexapod_path: Path | None,
    balls_path: Path | None,
    scenario: Path | None,
    dialect: str,
    cmm_dialect: str,
    time_scale: float,
    faults: tuple[str, ...],
    origin_on_cmm: str | None,
    point_noise_um: float | None,
    seed: int | None,
    tool: str,
    cmm_port: int,
    controller_port: int,
    speed_mm_s: float,
    settle: float,
    cmm_move_s: float,
    thermocouple_port: int,
    thermocouple_period: float,
) -> None:
    """Serve a simulated CMM (I++ DME), hexapod controller and thermocouple logger on
    127.0.0.1, until Ctrl-C.

    All are backed by the hexapod twin: the balls are where the commanded pose and the
    legs' thermal growth put them, in accelerated time (--time-scale); the hexapod moves
    at a finite speed and reports in position after a settle time, with read-back noise,
    actuator lengths and the legs' temperatures; the logger sends the six legs' and the
    air's temperatures every --thermocouple-period (lines as acquire and run read them).
    Prints the three URLs for hexatherm run (standard output: cmm, controller,
    thermocouples), then serves; --fault injects failures. The rehearsal of an overnight
    campaign.
    """
    from hexatherm.cli.run import _numbers
    from hexatherm.errors import HexathermError
    from hexatherm.workflows.serve import ServeFaults, parse_fault
    from hexatherm.workflows.serve_twin import ServeRequest, Serving, serve_twin

    imports_done()

    if scenario is None and (hexapod_path is None or balls_path is None):
        raise click.UsageError("give --hexapod and --balls (or a --scenario)")
    origin = _numbers(origin_on_cmm, 6, "--origin-on-cmm")
    injected = ServeFaults()
    for text in faults:
        try:
            parse_fault(text, injected)
        except HexathermError as exc:  # an option's value: a usage error
            raise click.BadParameter(f"{text!r}: {exc}", param_hint="--fault") from None
    request = ServeRequest(
        hexapod=hexapod_path,
        balls=balls_path,
        scenario=scenario,
        dialect=dialect,
        cmm_dialect=cmm_dialect,
        time_scale=time_scale,
        faults=injected,
        origin_on_cmm=origin,
        point_noise_um=point_noise_um,
        seed=seed,
        tool=tool,
        cmm_port=cmm_port,
        controller_port=controller_port,
        speed_mm_s=speed_mm_s,
        settle_s=settle,
        cmm_move_s=cmm_move_s,
        thermocouple_port=thermocouple_port,
        thermocouple_period_s=thermocouple_period,
    )
    stop = threading.Event()

    def ready(serving: Serving) -> None:
        # from the moment the URLs are out, Ctrl-C (or SIGTERM) stops the serving: a
        # KeyboardInterrupt raised before wait() began would end it as interrupted (130)
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        signal.signal(signal.SIGINT, lambda *_: stop.set())
        click.echo(f"cmm: {serving.cmm_url}")
        click.echo(f"controller: {serving.controller_url}")
        click.echo(f"thermocouples: {serving.thermocouples_url}")
        sys_stdout_flush()
        if serving.time_scale_warning is not None:
            echo_err(f"warning: {serving.time_scale_warning}")
        echo_err(
            f"serving the twin ({dialect}, x{time_scale:g} time, {serving.point_noise_um:g} um "
            f"probing noise, {serving.n_ipp_faults} I++ fault(s)); Ctrl-C to stop. Rehearse "
            f"with:\n  hexatherm run PLAN --cmm {serving.cmm_url} --controller "
            f"{serving.controller_url} --temperature-port {serving.thermocouples_url} "
            f"--hexapod H --balls B --origin-on-cmm "
            f"{','.join(f'{v:g}' for v in serving.origin_on_cmm)} --session DIR"
        )

    def wait() -> None:
        try:
            while not stop.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass

    serve_twin(request, ready, wait)
    echo_err("stopped")


def sys_stdout_flush() -> None:
    """Flush standard output (the URLs are read by scripts while the servers run)."""
    import sys

    sys.stdout.flush()
