"""``hexatherm serve-twin`` from a request to its outcome: the command's steps, start to end.

:func:`serve_twin` reads the scenario, hexapod and balls files, builds the twin's world
(:class:`~hexatherm.workflows.serve.TwinWorld`) on an accelerated clock, starts the
simulated CMM, hexapod controller and thermocouple logger
(:class:`~hexatherm.workflows.serve.TwinMachines`), tells the caller where they listen
(:class:`Serving`) and serves until the caller's ``wait`` returns. The machines
themselves are :mod:`hexatherm.workflows.serve`'s; the command line
(``hexatherm.cli.serve_twin``) parses the options, prints the URLs and waits for Ctrl-C.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from hexatherm.core.effects import Effect
from hexatherm.core.heating import HeatingModel, MatHeating
from hexatherm.io.config import read_balls, read_hexapod
from hexatherm.io.scenario import read_scenario
from hexatherm.workflows.serve import (
    AcceleratedClock,
    ServeFaults,
    TwinMachines,
    TwinWorld,
    default_heating,
)

#: where frame O is on the CMM without a scenario or --origin-on-cmm (mm, deg)
DEFAULT_ORIGIN_ON_CMM = (450.0, 320.0, 210.0, 0.0, 0.0, 15.0)
#: the probing noise without a scenario or --point-noise-um (um)
DEFAULT_POINT_NOISE_UM = 0.5


def time_scale_warning(scale: float, heating: HeatingModel) -> str | None:
    """What ``--time-scale`` does to a rehearsal's thermal behaviour (None at 1).

    ``hexatherm run`` stamps its session with the wall clock, while the twin's legs heat
    on the accelerated one: in the session's times, the heating is ``scale`` times
    faster (its time constants ``scale`` times shorter), and the legs drift ``scale``
    times more while a ball is probed and between a target and its references.

    >>> print(time_scale_warning(60.0, default_heating()))
    --time-scale 60: the twin's legs heat 60 times faster than the wall clock that \
hexatherm run stamps its session with: the heating's 2400 s time constant lasts 40 s \
of the session's times, and the legs drift 60 times more while a ball is probed and \
between a target and its references than they would at the real pace. The rehearsal \
checks the campaign (moves, probing, logs, resume), not the thermal drift nor how well \
process corrects it (--time-scale 1 for those)
    """
    if scale == 1.0:
        return None
    taus = [m.tau_s for m in heating.mats] if isinstance(heating, MatHeating) else []
    tau_s = getattr(heating, "tau_s", None)
    if isinstance(tau_s, float):
        taus.append(tau_s)

    def three(value: float) -> str:  # 3 significant digits, no exponent below 1e6
        return f"{float(f'{value:.3g}'):g}"

    factor = three(scale if scale > 1 else 1.0 / scale)
    faster, more = ("faster", "more") if scale > 1 else ("slower", "less")
    constant = (
        f"the heating's {min(taus):g} s time constant lasts {three(min(taus) / scale)} s of the "
        "session's times, and "
        if taus
        else ""
    )
    return (
        f"--time-scale {scale:g}: the twin's legs heat {factor} times {faster} than the "
        f"wall clock that hexatherm run stamps its session with: {constant}the legs drift "
        f"{factor} times {more} while a ball is probed and between a target and its "
        "references than they would at the real pace. The rehearsal checks the campaign "
        "(moves, probing, logs, resume), not the thermal drift nor how well process corrects "
        "it (--time-scale 1 for those)"
    )


@dataclass(frozen=True)
class ServeRequest:
    """What ``hexatherm serve-twin`` was asked (see its ``--help``): None takes the
    scenario's value, else the default."""

    hexapod: Path | None = None
    balls: Path | None = None
    scenario: Path | None = None
    dialect: str = "symetrie"
    cmm_dialect: str = "dme-1.4.3"
    time_scale: float = 60.0
    faults: ServeFaults = field(default_factory=ServeFaults)
    origin_on_cmm: tuple[float, ...] | None = None
    point_noise_um: float | None = None
    seed: int | None = None
    tool: str = "Probe1"
    cmm_port: int = 0
    controller_port: int = 0
    speed_mm_s: float = 2.0
    settle_s: float = 2.0
    cmm_move_s: float = 1.0
    thermocouple_port: int = 0
    thermocouple_period_s: float = 10.0


@dataclass(frozen=True)
class Serving:
    """Where the twin's machines listen, and what they simulate."""

    cmm_url: str
    controller_url: str
    thermocouples_url: str
    origin_on_cmm: tuple[float, ...]
    point_noise_um: float
    n_ipp_faults: int
    #: why the time scale distorts the heating (None: it does not)
    time_scale_warning: str | None


def serve_twin(
    request: ServeRequest, ready: Callable[[Serving], None], wait: Callable[[], None]
) -> Serving:
    """Serve the twin of ``request``: ``ready`` is called once the machines listen, and
    they serve until ``wait`` returns; then they are stopped."""
    heating: HeatingModel = default_heating()
    origin: tuple[float, ...] = DEFAULT_ORIGIN_ON_CMM
    noise, seed = DEFAULT_POINT_NOISE_UM, 0
    effects: tuple[Effect, ...] = ()
    hexapod = balls = None
    if request.scenario is not None:
        read = read_scenario(request.scenario)
        heating, origin, hexapod, balls = read.heating, read.origin_on_cmm, read.hexapod, read.balls
        noise, seed = 1e3 * read.point_noise_mm, read.seed
        # the truth: the scenario's hexapod model and its hidden effects (another --hexapod
        # brings its own model: the hidden effects only)
        effects = read.effects if request.hexapod is None else read.hidden_effects
    if request.hexapod is not None:
        hexapod = read_hexapod(request.hexapod)
    if request.balls is not None:
        balls = read_balls(request.balls)
    if hexapod is None or balls is None:
        raise ValueError("the twin needs a hexapod and balls (or a scenario)")
    origin = request.origin_on_cmm or origin
    noise = noise if request.point_noise_um is None else request.point_noise_um
    seed = seed if request.seed is None else request.seed
    injected = request.faults
    clock = AcceleratedClock(request.time_scale)
    world = TwinWorld(
        hexapod,
        balls,
        heating=heating,
        origin_on_cmm=origin,
        effects=effects,
        clock=clock,
        sleep=clock.sleep,
        cmm_move_s=request.cmm_move_s,
        speed_mm_s=request.speed_mm_s,
        speed_deg_s=request.speed_mm_s / 2,
        settle_s=request.settle_s,
        seed=seed,
        faults=injected.controller,
    )
    with TwinMachines(
        world,
        dialect=request.dialect,
        tool=request.tool,
        point_noise_um=noise,
        seed=seed,
        ipp_faults=injected.ipp,
        cmm_port=request.cmm_port,
        controller_port=request.controller_port,
        thermocouple_port=request.thermocouple_port,
        thermocouple_period_s=request.thermocouple_period_s,
        pi_start=injected.pi,
        cmm_dialect=request.cmm_dialect,
    ) as machines:
        serving = Serving(
            machines.cmm_url,
            machines.controller_url,
            machines.thermocouples_url,
            tuple(origin),
            noise,
            len(injected.ipp),
            time_scale_warning(request.time_scale, heating),
        )
        ready(serving)
        wait()
    return serving
