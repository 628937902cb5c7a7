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

**The controller's frames** (user frame ``U`` in the machine frame, object frame ``O``
in the platform frame). With each driver the script then sets two frame settings with
CGSE's own ``configure_coordinates_systems`` (``C_CFG_CS``; those of
``tests/workflows/test_run_frames.py``, and one with rotations of 8 to 35 deg), reads
them back (``get_coordinates_systems``), and, after frames set with the platform away
from zero, three absolute moves, a move relative to the object frame and one relative to
the user frame, reads the object pose in the user frame (``s_uto_tx``), the platform's
in the machine frame (``get_machine_positions``: ``s_mtp_tx``) and the legs; and
validates a pose the struts reach without the frames but not with them, and lets
hexatherm's own driver read the frames CGSE set (what ``run.yaml`` records). Compared with
hexatherm's maths: :func:`hexatherm.core.frames.platform_in_machine` (``M = U X O^-1``)
and the IGM of the hexapod file for the absolute moves (1 nm, 1 nrad), the twin's own
rules for the relative ones (``move_target``: CGSE's, below).

CGSE also has a simulator of its own, ``egse.hexapod.symetrie.hexapod.HexapodSimulator``
(base of its ``PunaSimulator``, ``ZondaSimulator``, ``JoranSimulator``): no geometry and
no legs (``get_actuator_length`` is six NaN), but its frames are its own maths, a chain
of ``egse.coordinates.ReferenceFrame`` (user linked to machine, object to platform, a
move setting the object in the user frame; rotations ``sxyz`` through ``transforms3d``).
The same calls go through it (``ZondaSimulator``) and its poses are compared with the
twin's and hexatherm's: the independent check, the relative moves included (the twin
takes CGSE's rule for a move relative to the user frame: docs/formats.md, section 9.7).
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

from hexatherm.core.frames import campaign_transforms, platform_in_machine
from hexatherm.core.geometry import invert_transform, pose_from_transform, transform_from_pose
from hexatherm.core.hexapod import Hexapod
from hexatherm.devices.sim.symetrie import SimulatedHexapod
from hexatherm.devices.sim.symetriepmac import SymetriePmacSimulator, move_target
from hexatherm.devices.symetriepmac import SymetriePmacController
from hexatherm.io.config import read_hexapod

ROOT = Path(__file__).resolve().parents[1]
POSE = [1.2, -2.5, 3.0, 0.4, -0.3, 1.5]
UNREACHABLE = [0.0, 0.0, 80.0, 0.0, 0.0, 0.0]
TOLERANCE = 1e-6  # mm and deg: 1 nm
#: the frames set (user frame in the machine frame, object frame in the platform frame;
#: mm, deg): tests/workflows/test_run_frames.py's, and rotations of 8 to 35 deg
FRAMES = {
    "run's test frames": [0.8, -1.5, 122.0, 0.4, -0.3, 21.2, 0.5, -0.3, 120.0, 0.1, -0.2, 20.3],
    "large angles": [3.0, -4.0, 110.0, 12.0, -9.0, 35.0, 2.5, -3.5, 112.0, 11.5, -8.0, 33.0],
}
START = [1.0, 2.0, -1.0, 0.5, -0.5, 1.0]  # where the platform is when the frames are set
MOVES = ([0.0] * 6, POSE, [-2.0, 1.5, -3.0, -2.5, 2.0, -4.0])  # absolute, in the frames
STEP = [0.5, 1.0, -0.7, 2.0, -1.0, 3.0]  # the relative moves, from MOVES[1]
#: reachable without the frames (longest leg 307.9 mm), not with them (312.9, 310.9 mm;
#: stroke 220 to 310 mm)
REFUSED = [0.0, 0.0, 27.0, 0.0, 9.0, 0.0]
NM, NRAD = 1e-6, float(np.degrees(1e-9))  # mm, deg


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
    twins: dict[str, dict[str, Record]] = {}
    for name, kind in (
        ("PunaPlusController", PunaPlusController),
        ("ZondaController", ZondaController),
    ):
        model = SimulatedHexapod(hexapod, speed_mm_s=20.0, speed_deg_s=20.0, settle_s=0.05)
        with SymetriePmacSimulator(model) as sim:
            problems += drive(name, kind("127.0.0.1", sim.port), model)
            controller = kind("127.0.0.1", sim.port)
            controller.connect()
            try:
                for label, frames in FRAMES.items():
                    wait = lambda c=controller: in_position(c)  # noqa: E731
                    twin = sequence(controller, frames, wait)
                    twins[f"{name}, {label}"] = twin
                    problems += against_hexatherm(f"{name}, {label}", twin, frames, hexapod)
                    problems += validation(f"{name}, {label}", controller, frames, hexapod)
                    problems += hexatherm_reads(f"{name}, {label}", controller, sim.port, frames)
            finally:
                controller.disconnect()
            print(
                f"{name}: {len(sim.received)} lines received by the twin, first {sim.received[2:6]}"
            )
    problems += cgse_simulator(twins, hexapod)
    print("\n".join(problems) if problems else "every CGSE read-back equals the twin's truth")
    return 1 if problems else 0


#: one read-back: the object pose in the user frame, the platform's in the machine frame
#: (mm, deg) and the legs (mm)
Record = tuple[np.ndarray, np.ndarray, np.ndarray]


def in_position(controller: Any) -> bool:
    """Wait (30 s at most) for a CGSE driver's in-position flag."""
    deadline = time.monotonic() + 30.0
    while not controller.is_in_position():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def sequence(device: Any, frames: list[float], wait: Any) -> dict[str, Record]:
    """CGSE's calls on ``device`` (a driver on the twin, or CGSE's simulator): the frames
    set with the platform at ``START``, the moves; what it read after each."""

    def read() -> Record:
        user = np.array(device.get_user_positions(), dtype=float)
        machine = np.array(device.get_machine_positions(), dtype=float)
        return user, machine, np.array(device.get_actuator_length(), dtype=float)

    out: dict[str, Record] = {}
    device.configure_coordinates_systems(*[0.0] * 12)
    device.move_absolute(*START)
    wait()
    device.configure_coordinates_systems(*frames)
    got = np.array(device.get_coordinates_systems(), dtype=float)
    out["frames read back"] = (got, got, np.zeros(6))
    out["frames set at START"] = read()
    for k, pose in enumerate(MOVES):
        device.move_absolute(*pose)
        wait()
        out[f"move_absolute {k}"] = read()
    for kind in ("object", "user"):
        device.move_absolute(*MOVES[1])
        wait()
        getattr(device, f"move_relative_{kind}")(*STEP)
        wait()
        out[f"move_relative_{kind}"] = read()
    device.configure_coordinates_systems(*[0.0] * 12)
    return out


def differs(got: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Largest differences of two poses (mm, deg)."""
    d = np.abs(np.asarray(got, float) - np.asarray(truth, float))
    return float(d[:3].max()), float(d[3:].max())


def truths(frames: list[float]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """hexatherm's object and platform poses (wire: mm, deg) for each step of
    :func:`sequence`: the machine pose ``U X O^-1`` of each object pose ``X``."""
    user, obj = campaign_transforms(frames)
    at_start = invert_transform(user) @ transform_from_pose(START, "symetrie") @ obj
    out = {"frames set at START": (pose_from_transform(at_start, "symetrie"), np.array(START))}
    for k, pose in enumerate(MOVES):
        out[f"move_absolute {k}"] = (np.array(pose), platform_in_machine(frames, pose, "symetrie"))
    for kind in ("object", "user"):
        x = move_target(1 if kind == "object" else 2, np.array(MOVES[1]), np.array(STEP))
        out[f"move_relative_{kind}"] = (x, platform_in_machine(frames, x, "symetrie"))
    return out


def frames_back(name: str, back: np.ndarray, frames: list[float]) -> list[str]:
    """The 12 values read back against those set (1 nm, 1 nrad)."""
    (dt, dr), (dt2, dr2) = differs(back[:6], frames[:6]), differs(back[6:], frames[6:])
    print(f"{name}: frames read back, max |diff| {max(dt, dt2):.1e} mm, {max(dr, dr2):.1e} deg")
    if max(dt, dt2) < NM and max(dr, dr2) < NRAD:
        return []
    return [f"{name}: frames read back {back.tolist()}"]


def against_hexatherm(
    name: str, got: dict[str, Record], frames: list[float], hexapod: Hexapod
) -> list[str]:
    """A driver's read-backs on the twin against hexatherm's maths (1 nm, 1 nrad)."""
    problems = frames_back(name, got["frames read back"][0], frames)
    for step, (user, machine) in truths(frames).items():
        u, m, legs = got[step]
        igm = hexapod.igm(machine)[0]
        du, dm = differs(u, user), differs(m, machine)
        dq = float(np.abs(legs - igm).max())
        print(
            f"{name}: {step}: s_uto {np.round(u, 6).tolist()}, s_mtp {np.round(m, 6).tolist()};"
            f" max |diff| from hexatherm: object {du[0]:.1e} mm {du[1]:.1e} deg, platform"
            f" {dm[0]:.1e} mm {dm[1]:.1e} deg, legs {dq:.1e} mm"
        )
        if not (max(du[0], dm[0], dq) < NM and max(du[1], dm[1]) < NRAD):
            problems.append(f"{name}: {step}: read-back differs from hexatherm's")
    return problems


def validation(name: str, controller: Any, frames: list[float], hexapod: Hexapod) -> list[str]:
    """``REFUSED`` validated without the frames and with them, against the struts' stroke
    at ``U X O^-1``."""
    controller.configure_coordinates_systems(*[0.0] * 12)
    bare = controller.check_absolute_movement(*REFUSED)
    controller.configure_coordinates_systems(*frames)
    framed = controller.check_absolute_movement(*REFUSED)
    controller.configure_coordinates_systems(*[0.0] * 12)
    legs = hexapod.igm(platform_in_machine(frames, REFUSED, "symetrie"))[0]
    print(
        f"{name}: validation of {REFUSED}: {bare} without the frames, {framed} with them"
        f" (longest leg {legs.max():.2f} mm, stroke {hexapod.stroke_mm})"
    )
    if bare[0] != 0 or framed[0] <= 0 or not hexapod.check_stroke(legs).any():
        return [f"{name}: validation of {REFUSED} {bare}, {framed}"]
    return []


def hexatherm_reads(name: str, controller: Any, port: int, frames: list[float]) -> list[str]:
    """The frames CGSE set, as hexatherm's own driver reads them at its connection (what
    ``run.yaml`` records: ``frames_mm_deg``)."""
    controller.configure_coordinates_systems(*frames)
    with SymetriePmacController("127.0.0.1", port) as driver:
        read = np.asarray(driver.frames_mm_deg, dtype=float)
        recorded = driver.info["frames_mm_deg"]
    controller.configure_coordinates_systems(*[0.0] * 12)
    print(f"{name}: hexatherm's driver reads the frames CGSE set: frames_mm_deg {recorded}")
    return frames_back(f"{name}: hexatherm's driver", read, frames)


def cgse_simulator(twins: dict[str, dict[str, Record]], hexapod: Hexapod) -> list[str]:
    """The same calls through CGSE's own simulator (its frames, its maths): its poses
    against hexatherm's and the twin's (as ZondaController read them)."""
    from egse.hexapod.symetrie.zonda import ZondaSimulator

    problems: list[str] = []
    for label, frames in FRAMES.items():
        simulator = ZondaSimulator("peers")
        simulator.homing()
        got = sequence(simulator, frames, lambda: None)
        name = f"CGSE's ZondaSimulator, {label}"
        twin = twins[f"ZondaController, {label}"]
        expected = truths(frames)
        for step, record in got.items():
            if step == "frames read back":
                problems += frames_back(name, record[0], frames)
                continue
            u, m = record[0], record[1]
            du, dm = differs(u, expected[step][0]), differs(m, expected[step][1])
            tu, tm = differs(u, twin[step][0]), differs(m, twin[step][1])
            print(
                f"{name}: {step}: object {np.round(u, 6).tolist()}, platform"
                f" {np.round(m, 6).tolist()}; max |diff| from hexatherm: object {du[0]:.1e} mm"
                f" {du[1]:.1e} deg, platform {dm[0]:.1e} mm {dm[1]:.1e} deg; from the twin:"
                f" object {tu[0]:.1e} mm {tu[1]:.1e} deg, platform {tm[0]:.1e} mm {tm[1]:.1e} deg"
            )
            close = max(du[0], dm[0], tu[0], tm[0]) < NM and max(du[1], dm[1], tu[1], tm[1]) < NRAD
            if not close:
                problems.append(f"{name}: {step}: differs from hexatherm's or the twin's")
            legs = record[2]
            if step == "move_absolute 1":
                print(f"{name}: {step}: its legs {legs.tolist()} (no geometry)")
    return problems


if __name__ == "__main__":
    sys.exit(main())
