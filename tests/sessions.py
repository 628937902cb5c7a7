"""Small twin sessions written to a temporary folder, for the I/O and CLI tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from hexatherm.core.plan import Plan
from hexatherm.session import Balls
from hexatherm.workflows.simulate.twinsession import Heating, TwinSessionSpec, write_twin_session

ROOT = Path(__file__).resolve().parent.parent
REFERENCE = [0.0, 0.0, -40.0, 0.0, 0.0, 0.0]
BALLS = Balls(
    ("B1", "B2", "B3"),
    np.array([[0.0, 90.0, 30.0], [-73.6, -42.5, 30.0], [82.3, -47.5, 30.0]]),
    np.full(3, 25.4),
    True,
    2.0,
)


#: the legs' heating gains (K at the end of the heating) of the twin sessions the
#: workflow tests simulate: six unequal legs, so that the heating tilts the platform
LEG_GAIN_C = (3.0, 7.0, 2.0, 3.0, 9.0, 3.5)


def small_plan(n_targets: int = 3, seed: int = 1) -> Plan:
    rng = np.random.default_rng(seed)
    steps = [("O", "origin", [0.0] * 6), ("R0", "reference", REFERENCE)]
    for i in range(1, n_targets + 1):
        pose = rng.uniform(-1, 1, 6) * [10, 10, 5, 1, 1, 2]
        steps += [(f"S{i}", "target", pose.tolist()), (f"R{i}", "reference", REFERENCE)]
    return Plan.from_steps(steps, reference_pose=REFERENCE)


def make_session(
    folder: Path,
    *,
    n_targets: int = 3,
    noise_mm: float = 0.0,
    gain=LEG_GAIN_C,
    tau_s: float = 2400.0,
    seed: int = 1,
    output: str = "centres",
    point_noise_mm: float = 0.0,
    balls: Balls = BALLS,
):
    """Write a twin session to ``folder`` and return the twin's truth."""
    spec = TwinSessionSpec(
        name=folder.name,
        hexapod_text=(ROOT / "configs" / "symetrie-like.yaml").read_text(),
        balls=balls,
        plan=small_plan(n_targets, seed),
        heating=Heating(on_s=0.0, tau_s=tau_s, gain_C=gain),
        centre_noise_mm=noise_mm,
        seed=seed,
        output=output,
        point_noise_mm=point_noise_mm,
    )
    return write_twin_session(spec, folder)


#: the calibration campaigns' workspace: +-20/+-20/+-15 mm, +-4/+-4/+-8 deg (issue 15)
CALIBRATION_SPAN = np.array([20.0, 20.0, 15.0, 4.0, 4.0, 8.0])


def calibration_targets(seed: int, n: int = 30, decimals: int = 4) -> np.ndarray:
    """``n`` targets drawn uniformly in :data:`CALIBRATION_SPAN`, rounded as a plan writes
    them."""
    targets = np.random.default_rng(seed).uniform(-1, 1, (n, 6)) * CALIBRATION_SPAN
    return targets.round(decimals)


def calibration_scenario(
    targets: np.ndarray,
    *,
    geometry_seed: int,
    extra: str = "",
    **sections: object,
) -> str:
    """A ``simulate`` scenario of the Symetrie-like hexapod whose true geometry differs
    from its file (joints sigma 50 um, leg offsets sigma 30 um, ``geometry_errors:``
    drawn with ``geometry_seed``), measuring ``targets`` with R = [0, 0, -40, 0, 0, 0]
    around each.

    ``sections`` are further top-level keys (``seed``, ``name``, ``cmm``, ``timing``,
    ``thermocouples``, ...) and ``points_per_ball`` (in the plan); ``extra`` is YAML text
    appended as it is (heating, hidden effects).
    """
    plan: dict[str, object] = {"reference_pose": REFERENCE}
    if "points_per_ball" in sections:
        plan["points_per_ball"] = sections.pop("points_per_ball")
    plan["targets"] = np.asarray(targets, dtype=float).tolist()
    doc: dict[str, object] = {
        "format": "hexatherm-scenario/1",
        "hexapod": str(ROOT / "configs" / "symetrie-like.yaml"),
        "balls": str(ROOT / "configs" / "balls-3.yaml"),
        "plan": plan,
        **sections,
        "geometry_errors": {"seed": geometry_seed, "joint_sigma_um": 50, "offset_sigma_um": 30},
    }
    return yaml.safe_dump(doc, sort_keys=False) + extra
