"""Write a whole session folder from the hexapod twin.

The twin (:mod:`hexatherm.core.twin`) computes the true platform frames of every
step; this module adds the session's timing, the heating of the legs, the
thermocouple, CMM and positioning noise and the effects applied to the truth,
and writes the files a real session has (``session.yaml``, the configs, the
plan, the measurement file, ``temperatures.csv``) plus ``truth/``, which
``process`` never reads:

- ``truth/steps.csv``: per step, the true pose at measurement time
  (``*_true_*``) and in the thermal state of the first reference
  (``*_truecorr_*``), both relative to the measured origin step; each leg's
  effective temperature ``T_leg<i>_C`` and true thermal growth ``dq_leg<i>_um``;
- ``truth/legs.csv``: per step, commanded and true leg lengths, the growth in
  the reference thermal state and the variable segment's temperature;
- ``truth/temperatures.csv``: the true (noise-free) thermocouple and air
  temperatures at the logging times, and each leg's effective temperature;
- ``truth/effects.yaml``: the seed and the effects applied to the truth.

The truth's thermocouple history is the heating model sampled at the logging
times and at every step's time (joined by straight lines, as the spec's twin
reads thermocouples), so without effects the twin sees the heating model's
exact temperature at every step. ``t_0`` is the session start, the first
logged sample.

Random draws, in this order from ``default_rng(seed)``: the centre noise (N, k,
3), the probing noise of the points, the thermocouple noise of the legs and of
the air. The hexapod's positioning noise comes from its own stream,
``default_rng([seed, 1])``.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd
import yaml

from hexatherm.core.calibration.model import (
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    nominal_parameters,
)
from hexatherm.core.effects import Effect, ThermocoupleLog
from hexatherm.core.geometry import transform_from_pose
from hexatherm.core.heating import Heating, HeatingModel
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.core.spherefit import fit_spheres, probe_radius_mm
from hexatherm.core.twin import (
    TwinSteps,
    cmm_readings,
    effective_leg_temperatures,
    predict,
    probe_points,
)
from hexatherm.io.config import balls_to_yaml, plan_to_yaml, read_hexapod_text, session_to_yaml
from hexatherm.io.csvout import csv_text
from hexatherm.io.dmisout import dmis_output
from hexatherm.io.outputs import output_dir
from hexatherm.io.records import iso_to_seconds, seconds_to_iso
from hexatherm.session import Balls
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.outputs import pose_columns

OUTPUTS = ("centres", "points", "dmis", "serial")
#: the twin's clock is UTC: its naive times (from the scenario's ``start``) are declared so
#: in ``session.yaml``, and every time ``process`` writes carries ``+00:00``
TWIN_UTC_OFFSET = "+00:00"

__all__ = [
    "Heating",
    "TwinSessionSpec",
    "SimulatedSession",
    "simulate_session",
    "write_twin_session",
    "write_files",
    "step_timing",
    "OUTPUTS",
]


@dataclass(frozen=True)
class TwinSessionSpec:
    """What :func:`simulate_session` needs.

    Attributes
    ----------
    name : str
        Session name (``session.yaml``).
    hexapod_text : str
        The hexapod file, copied as is.
    balls : Balls
    plan : Plan
    heating : HeatingModel
        Leg and air temperatures (seconds from the start).
    origin_on_cmm : tuple of 6 floats
        The nominal frame O on the CMM (a pose in the hexapod's convention).
    start : str
        ISO 8601 time of the session start (``t_0``).
    seconds_per_ball, seconds_per_move : float
        Probing time of one ball, and the move after each step.
    pauses_s : tuple of float
        Extra seconds waited before each step (one per step of the plan; empty: none):
        references irregular in time, long gaps.
    sample_period_s : float
        Thermocouple logging period.
    thermocouple_noise_C : float
        Standard deviation of each logged temperature (rounded to 1 mK).
    centre_noise_mm : float
        Standard deviation (per axis) of noise added to the true ball centres.
    seed : int
    readme : str
        Written as ``README.md`` when not empty.
    extra : dict of str to str
        Further files (relative path -> text).
    output : {"centres", "points", "dmis"}
    points_per_ball, cap_half_angle_deg : int, float
        Probed points per ball, spread over the ball's upper cap.
    touch_polar_deg : (float, float), optional
        Probe with polar angles uniform over this range (another CMM program's pattern)
        instead of the equal-area spiral over ``cap_half_angle_deg``.
    point_noise_mm : float
        Standard deviation of each probed point along the surface normal.
    effects : tuple of Effect
        Applied to the truth (the data follows the truth; ``process`` knows nothing).
    repeatability_mm : float
        Standard deviation of the hexapod's positioning error, per leg and step.
    fit_centres : bool
        With ``output="centres"``: the centres are sphere fits (free radius) of
        probed points, as a CMM reports them, instead of true centres plus
        ``centre_noise_mm``.
    true_parameters : ndarray, shape (48,), optional
        The hexapod's true geometry where it differs from the hexapod file (see
        :func:`hexatherm.core.twin.predict`); written to ``truth/geometry.csv``.
    """

    name: str
    hexapod_text: str
    balls: Balls
    plan: Plan
    heating: HeatingModel
    origin_on_cmm: tuple[float, ...] = (450.0, 320.0, 210.0, 0.0, 0.0, 15.0)
    start: str = "2019-12-20T09:00:00"
    seconds_per_ball: float = 60.0
    seconds_per_move: float = 20.0
    pauses_s: tuple[float, ...] = ()
    sample_period_s: float = 30.0
    thermocouple_noise_C: float = 0.0
    centre_noise_mm: float = 0.0
    seed: int = 0
    readme: str = ""
    extra: dict[str, str] = field(default_factory=dict)
    output: str = "centres"  # centres | points | dmis
    points_per_ball: int = 25
    cap_half_angle_deg: float = 70.0
    touch_polar_deg: tuple[float, float] | None = None
    point_noise_mm: float = 0.0
    effects: tuple[Effect, ...] = ()
    repeatability_mm: float = 0.0
    fit_centres: bool = False
    true_parameters: FloatArray | None = None


@dataclass(frozen=True)
class SimulatedSession:
    """A simulated session: the files to write and the twin's truth.

    Attributes
    ----------
    files : dict of str to str
        Relative path -> text, in writing order.
    truth : TwinSteps
    step_times_s : ndarray, shape (N,)
        Seconds from the start.
    """

    files: dict[str, str]
    truth: TwinSteps
    step_times_s: FloatArray


def step_timing(
    n_steps: int,
    n_balls: int,
    seconds_per_ball: float,
    seconds_per_move: float,
    pauses_s: tuple[float, ...] = (),
) -> tuple[FloatArray, FloatArray]:
    """Times (seconds from start) of every ball (n_steps, n_balls) and every step (mean).

    The hexapod starts at the origin step's pose: each step probes its balls one
    after the other, then the hexapod moves to the next step's pose (after
    ``pauses_s[i]`` more seconds before step i, when given).
    """
    step_start = np.arange(n_steps) * (n_balls * seconds_per_ball + seconds_per_move)
    if len(pauses_s):
        if len(pauses_s) != n_steps or min(pauses_s) < 0:
            raise ValueError(f"need {n_steps} pauses of at least 0 s, got {pauses_s!r}")
        step_start = step_start + np.cumsum(pauses_s)
    ball_times = step_start[:, None] + (np.arange(n_balls) + 0.5) * seconds_per_ball
    return ball_times, ball_times.mean(axis=1)


def simulate_session(spec: TwinSessionSpec, truth_files: bool = True) -> SimulatedSession:
    """Simulate ``spec``: the session's files and the truth, nothing written.

    Without ``truth_files`` the files leave out ``truth/`` (the twin's truth is still
    returned as :attr:`SimulatedSession.truth`): for a caller that never reads those files
    (noise replicas, campaigns whose truth is the hidden effects), which are a third to a
    half of the simulation's time. The other files are the same, byte for byte, and so is
    every random draw."""
    if spec.output not in OUTPUTS:
        raise ValueError(f"output must be one of {', '.join(OUTPUTS)}, got {spec.output!r}")
    hexapod = _hexapod(spec.hexapod_text)
    legs = hexapod.legs
    if legs is None:  # the reader requires legs: a guard for the type checker
        raise ValueError("the twin needs the hexapod's leg model (legs:)")
    rng = np.random.default_rng(spec.seed)
    plan, balls = spec.plan, spec.balls
    n, k = len(plan.labels), len(balls.names)
    ball_t, step_t = step_timing(n, k, spec.seconds_per_ball, spec.seconds_per_move, spec.pauses_s)
    end = ball_t.max() + spec.seconds_per_ball
    sample_t = np.arange(0.0, end + spec.sample_period_s, spec.sample_period_s)
    truth_t = np.union1d(sample_t, step_t)
    log = ThermocoupleLog(truth_t, spec.heating.legs(truth_t), spec.heating.air(truth_t))
    error = None
    if spec.repeatability_mm > 0:
        error = np.random.default_rng([spec.seed, 1]).normal(
            scale=spec.repeatability_mm, size=(n, 6)
        )
    origin2cmm = transform_from_pose(spec.origin_on_cmm, hexapod.convention)
    truth = predict(
        hexapod,
        plan,
        step_t,
        log,
        balls.centres_mm,
        origin2cmm,
        spec.effects,
        ball_times_s=ball_t,
        positioning_error_mm=error,
        true_parameters=spec.true_parameters,
    )
    centres = truth.centres_cmm_mm + rng.normal(scale=spec.centre_noise_mm, size=(n, k, 3))

    t0 = iso_to_seconds(spec.start)
    measurement_name, measurement_text = _measurements(spec, centres, ball_t, t0, log, rng)
    true_legs = spec.heating.legs(sample_t)
    true_air = spec.heating.air(sample_t)
    logged = true_legs + rng.normal(scale=spec.thermocouple_noise_C, size=true_legs.shape)
    air = true_air + rng.normal(scale=spec.thermocouple_noise_C, size=sample_t.shape)
    stamps = [seconds_to_iso(t0 + t) for t in sample_t]
    temps_frame = pd.DataFrame({"time": stamps})
    for i in range(6):
        temps_frame[f"leg{i + 1}"] = logged[:, i].round(3)
    temps_frame["air"] = air.round(3)

    files = {
        "hexapod.yaml": spec.hexapod_text,
        "balls.yaml": balls_to_yaml(balls),
        "plan.yaml": plan_to_yaml(plan),
        "session.yaml": session_to_yaml(
            spec.name,
            "hexapod.yaml",
            "balls.yaml",
            "plan.yaml",
            [measurement_name],
            "temperatures.csv",
            utc_offset=TWIN_UTC_OFFSET,
        ),
        measurement_name: measurement_text,
        "temperatures.csv": csv_text(temps_frame, rounded=False),
        **(
            _truth_files(
                spec,
                truth,
                step_t,
                t0,
                log,
                sample_t,
                stamps,
                true_legs,
                true_air,
                legs.variable,
            )
            if truth_files
            else {}
        ),
        **spec.extra,
    }
    if not truth_files:  # the spec's own truth/ files too (a scenario's copy)
        files = {rel: text for rel, text in files.items() if not rel.startswith("truth/")}
    if spec.output == "serial":
        del files["session.yaml"]  # a capture, not a session yet: acquire --replay makes it one
    if spec.readme:
        files["README.md"] = spec.readme
    return SimulatedSession(files, truth, step_t)


@functools.lru_cache(maxsize=4)
def _hexapod(text: str) -> Hexapod:
    """The hexapod file's text read (once per text: noise replicas simulate the same
    hexapod hundreds of times, and reading it is some 2 ms; the twin only reads it)."""
    return read_hexapod_text(text, "hexapod.yaml")


def write_files(
    files: dict[str, str],
    out: str | os.PathLike[str],
    overwrite: bool = False,
    inputs: Sequence[Path] = (),
) -> list[Path]:
    """Write ``files`` (relative path -> text) as the folder ``out``, all or nothing,
    through the output guard (:func:`~hexatherm.io.outputs.output_dir`: never into or
    around ``inputs``; ``overwrite`` replaces only a folder hexatherm wrote)."""
    written = []
    with output_dir(out, inputs=inputs, overwrite=overwrite, sessions=True) as tmp:
        for rel, text in files.items():
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text, encoding="utf-8", newline="")
            written.append(Path(out) / rel)
    return written


def write_twin_session(
    spec: TwinSessionSpec, out: str | Path, overwrite: bool = False
) -> TwinSteps:
    """Simulate ``spec`` and write the session folder ``out``; returns the twin's truth."""
    simulated = simulate_session(spec)
    write_files(simulated.files, out, overwrite)
    return simulated.truth


def _truth_files(
    spec: TwinSessionSpec,
    truth: TwinSteps,
    step_t: FloatArray,
    t0: float,
    log: ThermocoupleLog,
    sample_t: FloatArray,
    stamps: list[str],
    true_legs: FloatArray,
    true_air: FloatArray,
    variable: npt.NDArray[np.bool_],
) -> dict[str, str]:
    """The files of ``truth/`` (``variable`` marks each leg's variable segment)."""
    plan = spec.plan
    step_stamps = [seconds_to_iso(t0 + t) for t in step_t]
    steps: dict[str, object] = {
        "label": list(plan.labels),
        "kind": list(plan.kinds),
        "time": step_stamps,
    }
    for cols, values in (
        (pose_columns("true"), truth.pose),
        (pose_columns("truecorr"), truth.corrected_pose),
    ):
        for j, col in enumerate(cols):
            steps[col] = values[:, j]
    for i in range(6):
        steps[f"T_leg{i + 1}_C"] = truth.leg_temperature_C[:, i]
    for i in range(6):
        steps[f"dq_leg{i + 1}_um"] = truth.growth_mm[:, i] * 1e3

    t_var = (truth.segment_temperature_C * variable).sum(axis=-1)
    legs: dict[str, object] = {"label": list(plan.labels), "time": step_stamps}
    for name, values, scale in (
        ("q_cmd_leg{}_mm", truth.q_cmd_mm, 1.0),
        ("q_leg{}_mm", truth.q_mm, 1.0),
        ("dq_ref_leg{}_um", truth.reference_growth_mm, 1e3),
        ("T_var_leg{}_C", t_var, 1.0),
    ):
        for i in range(6):
            legs[name.format(i + 1)] = values[:, i] * scale

    effective = effective_leg_temperatures(log, sample_t, spec.effects)
    temps: dict[str, object] = {"time": stamps}
    for i in range(6):
        temps[f"leg{i + 1}"] = true_legs[:, i]
    temps["air"] = true_air
    for i in range(6):
        temps[f"T_leg{i + 1}_C"] = effective[:, i]

    effects_doc = {
        "seed": int(spec.seed),
        "reference_step": plan.labels[truth.reference_index],
        "effects": [e.as_dict() for e in spec.effects],
    }
    files = {
        "truth/steps.csv": csv_text(pd.DataFrame(steps), rounded=False),
        "truth/legs.csv": csv_text(pd.DataFrame(legs), rounded=False),
        "truth/temperatures.csv": csv_text(pd.DataFrame(temps), rounded=False),
        "truth/effects.yaml": yaml.safe_dump(
            effects_doc, sort_keys=False, default_flow_style=None, width=100
        ),
    }
    if spec.true_parameters is not None:
        files["truth/geometry.csv"] = _geometry_csv(spec)
    return files


def _geometry_csv(spec: TwinSessionSpec) -> str:
    """``truth/geometry.csv``: every parameter of the geometry, nominal and true."""
    hexapod = read_hexapod_text(spec.hexapod_text, "hexapod.yaml")
    nominal = nominal_parameters(hexapod)
    true = np.asarray(spec.true_parameters, dtype=float)
    gain = np.array(PARAMETER_UNITS) != "mm"
    error = true - nominal
    frame = pd.DataFrame(
        {
            "parameter": PARAMETER_NAMES,
            "unit": PARAMETER_UNITS,
            "nominal": nominal,
            "true": true,
            "error_um": np.where(gain, np.nan, error * 1e3),
            "error_ppm": np.where(gain, error * 1e6, np.nan),
        }
    )
    return csv_text(frame, rounded=False)


def _measurements(
    spec: TwinSessionSpec,
    centres: FloatArray,
    ball_t: FloatArray,
    t0: float,
    log: ThermocoupleLog,
    rng: np.random.Generator,
) -> tuple[str, str]:
    """The measurement file (name, text) in the spec's output format.

    ``centres`` (N, k, 3) are the centres the points are probed around (true
    centres plus centre noise); ``ball_t`` (N, k) is seconds from the start.
    """
    plan, balls = spec.plan, spec.balls
    n, k = centres.shape[:2]
    labels, names = np.repeat(plan.labels, k), np.tile(balls.names, n)
    if spec.output == "centres" and not spec.fit_centres:
        reported = cmm_readings(centres, ball_t, log, spec.effects)
        frame = pd.DataFrame(
            {
                "label": labels,
                "ball": names,
                "x": reported[..., 0].ravel(),
                "y": reported[..., 1].ravel(),
                "z": reported[..., 2].ravel(),
                "time": [seconds_to_iso(t0 + t) for t in ball_t.ravel()],
            }
        )
        return "centres.csv", csv_text(frame, rounded=False)
    m = spec.points_per_ball
    radius = np.array(
        [
            probe_radius_mm(d, balls.tip_diameter_mm, balls.probe_compensated)
            for d in balls.diameters_mm
        ]
    )
    true_points, dirs = probe_points(
        centres,
        radius[None, :],
        m,
        spec.cap_half_angle_deg,
        spec.point_noise_mm,
        rng,
        polar_range_deg=spec.touch_polar_deg,
    )
    offsets = (np.arange(m) - (m - 1) / 2) * (spec.seconds_per_ball / m)  # mean: the ball's time
    points = cmm_readings(true_points, ball_t[..., None] + offsets, log, spec.effects)
    xyz = points.reshape(-1, 3)
    if spec.output == "centres":
        fits = fit_spheres(xyz, np.repeat(np.arange(n * k), m))
        frame = pd.DataFrame(
            {
                "label": labels,
                "ball": names,
                "x": fits.centre_mm[:, 0],
                "y": fits.centre_mm[:, 1],
                "z": fits.centre_mm[:, 2],
                "time": [seconds_to_iso(t0 + t) for t in ball_t.ravel()],
            }
        )
        return "centres.csv", csv_text(frame, rounded=False)
    ijk = np.broadcast_to(-dirs, points.shape).reshape(-1, 3)
    point_labels = np.repeat(labels, m)
    point_balls = np.repeat(names, m)
    abs_times = ((ball_t + t0)[..., None] + offsets).ravel()
    if spec.output == "serial":
        return "serial.log", _serial_capture(xyz, abs_times)
    if spec.output == "points":
        frame = pd.DataFrame(
            {
                "label": point_labels,
                "ball": point_balls,
                "x": xyz[:, 0],
                "y": xyz[:, 1],
                "z": xyz[:, 2],
                "time": [seconds_to_iso(t) for t in abs_times],
                "i": ijk[:, 0],
                "j": ijk[:, 1],
                "k": ijk[:, 2],
            }
        )
        return "points.csv", csv_text(frame, rounded=False)
    numbers = np.tile(np.arange(1, m + 1), n * k).astype(str)
    feature = np.char.add(
        np.char.add(np.char.add(np.char.add(point_labels, "_"), point_balls), "_"), numbers
    )
    return "points.dmo", dmis_output(feature, xyz, abs_times, "POINT", ijk=ijk, name=spec.name)


def _serial_capture(xyz: FloatArray, times_s: FloatArray) -> str:
    """A ``serial.log`` as ``hexatherm acquire --auto`` records a probe sending the points.

    One ``rx`` entry per point, at the point's time, as the line
    ``X+427.451688 Y+408.847293 Z+252.532346`` (1 nm resolution) with CRLF.
    """
    from hexatherm.io.seriallog import LOG_MAGIC, entry

    start = seconds_to_iso(float(times_s[0]) - 1.0)
    lines = [
        f"{LOG_MAGIC}\n",
        entry("config", "-", "units=mm", start).format(),
        entry("mode", "-", "auto", start).format(),
        entry("open", "probe", "twin", start).format(),
    ]
    for (x, y, z), t in zip(xyz, times_s, strict=True):
        lines.append(
            entry(
                "rx", "probe", f"X{x:+.6f} Y{y:+.6f} Z{z:+.6f}\r\n", seconds_to_iso(float(t))
            ).format()
        )
    return "".join(lines)
