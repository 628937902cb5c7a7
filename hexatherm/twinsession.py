"""Write a whole session folder from the hexapod twin (no hidden effects yet).

The twin computes the true ball centres of every step; this module adds the
session's timing, heating-mat leg temperatures, thermocouple and CMM noise, and
writes the files a real session has (``session.yaml``, the configs, the plan,
``centres.csv``, ``temperatures.csv``) plus ``truth/`` that ``process`` never
reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.plan import Plan
from hexatherm.core.spherefit import probe_radius_mm
from hexatherm.core.twin import TwinSteps, predict_steps, probe_points
from hexatherm.io.atomic import atomic_output_dir
from hexatherm.io.config import (
    Balls,
    balls_to_yaml,
    plan_to_yaml,
    read_hexapod_text,
    session_to_yaml,
)
from hexatherm.io.dmisout import dmis_output
from hexatherm.io.records import iso_to_seconds, seconds_to_iso
from hexatherm.io.results import pose_columns, to_csv_text

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Heating:
    """Leg temperatures from heating mats with a first-order response.

    ``T_i(t) = T_air(t) + gain_i * (1 - exp(-(t - on_s) / tau_s))`` while the mat
    is on (after ``on_s``), ``T_air(t) = air_C + air_drift_C_per_h * t / 3600``.
    """

    air_C: float = 20.0
    air_drift_C_per_h: float = 0.0
    on_s: float = 0.0
    tau_s: float = 2400.0
    gain_C: tuple[float, ...] = (0.0,) * 6

    def air(self, t_s: npt.ArrayLike) -> FloatArray:
        """Air temperature at times ``t_s`` (seconds from the session start)."""
        return self.air_C + self.air_drift_C_per_h * np.asarray(t_s, dtype=float) / 3600.0

    def legs(self, t_s: npt.ArrayLike) -> FloatArray:
        """Leg temperatures (n, 6) at times ``t_s`` (seconds from the session start)."""
        t = np.asarray(t_s, dtype=float)
        rise = 1.0 - np.exp(-np.clip(t - self.on_s, 0.0, None) / self.tau_s)
        return self.air(t)[:, None] + rise[:, None] * np.asarray(self.gain_C)


@dataclass(frozen=True)
class TwinSessionSpec:
    """What :func:`write_twin_session` needs."""

    name: str
    hexapod_text: str
    balls: Balls
    plan: Plan
    heating: Heating
    origin_on_cmm: tuple[float, ...] = (450.0, 320.0, 210.0, 0.0, 0.0, 15.0)
    start: str = "2019-12-20T09:00:00"
    seconds_per_ball: float = 60.0
    seconds_per_move: float = 20.0
    sample_period_s: float = 30.0
    thermocouple_noise_C: float = 0.0
    centre_noise_mm: float = 0.0
    seed: int = 0
    readme: str = ""
    extra: dict[str, str] = field(default_factory=dict)
    output: str = "centres"  # centres | points | dmis
    points_per_ball: int = 25
    cap_half_angle_deg: float = 70.0
    point_noise_mm: float = 0.0


def step_timing(n_steps: int, n_balls: int, seconds_per_ball: float, seconds_per_move: float
                ) -> tuple[FloatArray, FloatArray]:
    """Times (seconds from start) of every ball (n_steps, n_balls) and every step (mean)."""
    step_start = np.arange(n_steps) * (n_balls * seconds_per_ball + seconds_per_move)
    ball_times = step_start[:, None] + (np.arange(n_balls) + 0.5) * seconds_per_ball
    return ball_times, ball_times.mean(axis=1)


def write_twin_session(spec: TwinSessionSpec, out: str | Path, overwrite: bool = False
                       ) -> TwinSteps:
    """Simulate ``spec`` and write the session folder ``out``; returns the twin's truth."""
    hexapod = read_hexapod_text(spec.hexapod_text, "hexapod.yaml")
    rng = np.random.default_rng(spec.seed)
    plan, balls = spec.plan, spec.balls
    n, k = len(plan.labels), len(balls.names)
    ball_t, step_t = step_timing(n, k, spec.seconds_per_ball, spec.seconds_per_move)
    temps = spec.heating.legs(step_t)
    origin2cmm = transform_from_pose(spec.origin_on_cmm, hexapod.convention)
    truth = predict_steps(hexapod, plan, temps, balls.centres_mm, origin2cmm)
    centres = truth.centres_cmm_mm + rng.normal(scale=spec.centre_noise_mm, size=(n, k, 3))

    t0 = iso_to_seconds(spec.start)
    measurement_name, measurement_text = _measurements(spec, centres, ball_t + t0, rng)
    end = ball_t.max() + spec.seconds_per_ball
    sample_t = np.arange(0.0, end + spec.sample_period_s, spec.sample_period_s)
    true_legs = spec.heating.legs(sample_t)
    logged = true_legs + rng.normal(scale=spec.thermocouple_noise_C, size=true_legs.shape)
    air = spec.heating.air(sample_t) + rng.normal(scale=spec.thermocouple_noise_C,
                                                  size=sample_t.shape)
    temps_frame = pd.DataFrame({"time": [seconds_to_iso(t0 + t) for t in sample_t]})
    for i in range(6):
        temps_frame[f"leg{i + 1}"] = logged[:, i].round(3)
    temps_frame["air"] = air.round(3)

    truth_data: dict[str, object] = {"label": list(plan.labels), "kind": list(plan.kinds),
                                     "time": [seconds_to_iso(t0 + t) for t in step_t]}
    for cols, values in ((pose_columns("true"), truth.pose),
                         (pose_columns("truecorr"), truth.corrected_pose)):
        for j, col in enumerate(cols):
            truth_data[col] = values[:, j]
    for i in range(6):
        truth_data[f"T_leg{i + 1}_C"] = temps[:, i]
    for i in range(6):
        truth_data[f"dq_leg{i + 1}_um"] = truth.growth_mm[:, i] * 1e3

    files = {
        "hexapod.yaml": spec.hexapod_text,
        "balls.yaml": balls_to_yaml(balls),
        "plan.yaml": plan_to_yaml(plan),
        "session.yaml": session_to_yaml(spec.name, "hexapod.yaml", "balls.yaml", "plan.yaml",
                                        [measurement_name], "temperatures.csv"),
        measurement_name: measurement_text,
        "temperatures.csv": to_csv_text(temps_frame),
        "truth/steps.csv": to_csv_text(pd.DataFrame(truth_data)),
        **spec.extra,
    }
    if spec.readme:
        files["README.md"] = spec.readme
    with atomic_output_dir(out, overwrite=overwrite) as tmp:
        for rel, text in files.items():
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text, encoding="utf-8", newline="")
    return truth


def _measurements(spec: TwinSessionSpec, centres: FloatArray, ball_t: FloatArray,
                  rng: np.random.Generator) -> tuple[str, str]:
    """The measurement file (name, text) in the spec's output format."""
    plan, balls = spec.plan, spec.balls
    n, k = centres.shape[:2]
    labels, names = np.repeat(plan.labels, k), np.tile(balls.names, n)
    if spec.output == "centres":
        frame = pd.DataFrame({"label": labels, "ball": names, "x": centres[..., 0].ravel(),
                              "y": centres[..., 1].ravel(), "z": centres[..., 2].ravel(),
                              "time": [seconds_to_iso(t) for t in ball_t.ravel()]})
        return "centres.csv", to_csv_text(frame)
    if spec.output not in ("points", "dmis"):
        raise ValueError(f"output must be centres, points or dmis, got {spec.output!r}")
    m = spec.points_per_ball
    radius = np.array([probe_radius_mm(d, balls.tip_diameter_mm, balls.probe_compensated)
                       for d in balls.diameters_mm])
    points, dirs = probe_points(centres, radius[None, :], m, spec.cap_half_angle_deg,
                                spec.point_noise_mm, rng)
    dt = spec.seconds_per_ball / m
    times = ball_t[..., None] + (np.arange(m) - (m - 1) / 2) * dt  # mean = the ball's time
    xyz = points.reshape(-1, 3)
    ijk = np.broadcast_to(-dirs, points.shape).reshape(-1, 3)
    point_labels = np.repeat(labels, m)
    point_balls = np.repeat(names, m)
    if spec.output == "points":
        frame = pd.DataFrame({"label": point_labels, "ball": point_balls, "x": xyz[:, 0],
                              "y": xyz[:, 1], "z": xyz[:, 2],
                              "time": [seconds_to_iso(t) for t in times.ravel()],
                              "i": ijk[:, 0], "j": ijk[:, 1], "k": ijk[:, 2]})
        return "points.csv", to_csv_text(frame)
    numbers = np.tile(np.arange(1, m + 1), n * k).astype(str)
    feature = np.char.add(np.char.add(np.char.add(np.char.add(point_labels, "_"), point_balls),
                                      "_"), numbers)
    return "points.dmo", dmis_output(feature, xyz, times.ravel(), "POINT", ijk=ijk,
                                     name=spec.name)
