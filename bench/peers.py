"""CGSE's ``symetrie-hexapod`` drives the twin's Symétrie gpascii server (a script, not a
test; issue 23).

CGSE (KU Leuven, MIT) is the Python software Symétrie ZONDA / JORAN / PUNA+ users drive
their controllers with. Its package pulls about 70 distributions (PyQt5, pyarrow, duckdb,
influxdb, psycopg, ...; about 1 GB installed), so it is no test dependency of hexatherm:
run this in an environment of its own::

    python3 -m venv /tmp/venv-cgse
    /tmp/venv-cgse/bin/pip install symetrie-hexapod -e .
    /tmp/venv-cgse/bin/python bench/peers.py

It serves the twin's gpascii controller (:mod:`hexatherm.devices.sim.symetriepmac`) on
127.0.0.1 around the hexapod of ``configs/symetrie-like.yaml`` (wall clock, 20 mm/s), then
with each CGSE driver (``PunaPlusController``: the ``AlphaPlusTelnetInterface`` of
PUNA+ and JORAN; ``ZondaController``: ``ZondaTelnetInterface``) reads the version and the
state, validates a reachable and an unreachable pose, moves, waits for in position, reads
the object pose and the leg lengths, and stops. It prints what CGSE read next to the
twin's truth (its true pose, its IGM) and exits 1 on any difference over 1 nm.

CGSE 0.25.11's ``AlphaPlusTelnetInterface`` reads its login from
``Settings("Hexapod Controller")["PUNA_PLUS"].user_name``, a plain dict there, so
attribute access fails whatever the local settings: the script hands it the login as an
object with those attributes (the login only; the protocol is CGSE's own).
"""

from __future__ import annotations

import logging
import sys
import time
import types
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from hexatherm.devices.sim.symetrie import SimulatedHexapod
from hexatherm.devices.sim.symetriepmac import SymetriePmacSimulator
from hexatherm.io.config import read_hexapod

ROOT = Path(__file__).resolve().parents[1]
POSE = [1.2, -2.5, 3.0, 0.4, -0.3, 1.5]
UNREACHABLE = [0.0, 0.0, 80.0, 0.0, 0.0, 0.0]
TOLERANCE = 1e-6  # mm and deg: 1 nm


def drive(name: str, controller: Any, model: SimulatedHexapod) -> list[str]:
    """One CGSE driver through a move; the differences found (empty: none)."""
    problems: list[str] = []
    controller.connect()
    try:
        state = controller.get_general_state()
        print(f"{name}: general state {state[1]}")
        homed, there = controller.is_homing_done(), controller.is_in_position()
        print(f"{name}: homed {homed}, in position {there}")
        ok = controller.check_absolute_movement(*POSE)
        refused = controller.check_absolute_movement(*UNREACHABLE)
        print(f"{name}: validation {ok} / unreachable {refused}")
        if ok[0] != 0 or refused[0] <= 0:
            problems.append(f"{name}: validation {ok}, {refused}")
        print(f"{name}: move_absolute {controller.move_absolute(*POSE)}")
        deadline = time.monotonic() + 30.0
        while not controller.is_in_position():
            if time.monotonic() > deadline:
                problems.append(f"{name}: never in position")
                break
            time.sleep(0.05)
        pose = np.array(controller.get_user_positions(), dtype=float)
        legs = np.array(controller.get_actuator_length(), dtype=float)
        truth, igm = model.true_pose(), model.hexapod.igm(np.array(POSE))[0]
        dp, dq = np.abs(pose - truth).max(), np.abs(legs - igm).max()
        print(f"{name}: pose {pose.tolist()}, twin's truth {truth.tolist()}: max |diff| {dp:.2e}")
        print(f"{name}: legs {legs.tolist()}, twin's IGM: max |diff| {dq:.2e} mm")
        if not (dp < TOLERANCE and dq < TOLERANCE):
            problems.append(f"{name}: read-back differs from the twin's truth")
        print(f"{name}: stop {controller.stop()}")
    finally:
        controller.disconnect()
    return problems


def main() -> int:
    warnings.simplefilter("ignore")
    logging.disable(logging.WARNING)
    try:
        from egse.hexapod.symetrie import dynalpha
        from egse.hexapod.symetrie.punaplus import PunaPlusController
        from egse.hexapod.symetrie.zonda import ZondaController
    except ImportError as exc:
        print(f"CGSE's symetrie-hexapod is not installed here ({exc}); see the docstring")
        return 2
    from importlib.metadata import version

    print(f"symetrie-hexapod {version('symetrie-hexapod')}")
    dynalpha.PUNA_PLUS = types.SimpleNamespace(user_name="root", password="deltatau")
    hexapod = read_hexapod(ROOT / "configs" / "symetrie-like.yaml")
    problems: list[str] = []
    for name, kind in (
        ("PunaPlusController", PunaPlusController),
        ("ZondaController", ZondaController),
    ):
        model = SimulatedHexapod(hexapod, speed_mm_s=20.0, speed_deg_s=20.0, settle_s=0.05)
        with SymetriePmacSimulator(model) as sim:
            problems += drive(name, kind("127.0.0.1", sim.port), model)
            print(
                f"{name}: {len(sim.received)} lines received by the twin, first {sim.received[2:6]}"
            )
    print("\n".join(problems) if problems else "every CGSE read-back equals the twin's truth")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
