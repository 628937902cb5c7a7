"""``hexatherm process`` done the straightforward way: the reference of ``bench/speed.py``.

Run with ``.venv/bin/python bench/straightforward.py SESSION -o OUT``. It does the job of
``hexatherm process`` (free-radius sphere fits of the probed points, weighted rigid
registration, conventional and corrected poses, linear interpolation of the
references, O carried to R0's thermal state) one item at a time, the way one would write it first:

- the measurements are read line by line with the standard library (``csv`` for a
  points CSV, a plain line loop for a DMIS file of ``FA(<step>_<ball>_<n>)=FEAT/POINT``
  features), the session's YAML files with hexatherm's readers;
- one :func:`scipy.optimize.least_squares` per sphere (Levenberg-Marquardt with
  the analytic Jacobian, from the algebraic fit, default tolerances);
- one registration per step (:meth:`scipy.spatial.transform.Rotation.align_vectors`,
  weights ``1/u^2`` from each fit's centre uncertainty);
- one pose and leg-length computation per step, and per target the references,
  the scaling of the growth and one :func:`scipy.optimize.root` for the FGM;
- O's legs' growth since R0 (the thermocouple log read row by row and the leg model's
  sensitivity, or without a log the references' growth on the Lagrange polynomial
  through the first two or three of them), O's frame moved by it with one more FGM, and
  every corrected pose expressed in that frame.

It writes ``OUT/poses.csv`` (label, conventional and corrected pose). Only the
formats and options ``bench/speed.py`` simulates are supported. The functions
are the reference that ``tests/io/test_speed_paths.py`` checks the vectorized code
against.
"""

from __future__ import annotations

import csv
import math
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, root
from scipy.spatial.transform import Rotation

from hexatherm.core.hexapod import Hexapod
from hexatherm.io.config import read_session
from hexatherm.session import Session

#: as in hexatherm.workflows.process.measured.registration_weights
U_FLOOR_UM = 1e-3

Groups = dict[tuple[str, str], tuple[list[list[float]], list[float]]]


# ----------------------------------------------------------------------------- reading
def _seconds(stamp: str) -> float:
    moment = datetime.fromisoformat(stamp.strip())
    if moment.tzinfo is None:
        moment = moment.replace(tzinfo=UTC)
    return moment.timestamp()


def read_points_csv(path: str | Path) -> Groups:
    """Points of a points CSV grouped by (step, ball), in file order, with their times."""
    groups: Groups = {}
    with open(path, newline="", encoding="utf-8-sig") as handle:
        for row in csv.DictReader(handle):
            key = (row["label"].strip(), row["ball"].strip())
            points, times = groups.setdefault(key, ([], []))
            points.append([float(row["x"]), float(row["y"]), float(row["z"])])
            times.append(_seconds(row["time"]))
    return groups


def read_points_dmis(path: str | Path) -> Groups:
    """Points of a DMIS file (``DATE=``, ``TIME=``, ``FA(step_ball_n)=FEAT/POINT,CART,...``)."""
    groups: Groups = {}
    day = clock = ""
    with open(path, encoding="utf-8-sig") as handle:
        for raw in handle:
            line = raw.strip()
            if line.startswith("DATE="):
                day = line[5:].replace("/", "-")
            elif line.startswith("TIME="):
                clock = line[5:]
            elif line.startswith("FA(") and "=FEAT/POINT," in line:
                label, _, rest = line[3:].partition(")=FEAT/POINT,")
                step, ball, _ = label.split("_")
                fields = rest.split(",")
                if fields[0].upper() != "CART":
                    raise ValueError(f"only CART points are supported: {line}")
                points, times = groups.setdefault((step, ball), ([], []))
                points.append([float(v) for v in fields[1:4]])
                times.append(_seconds(f"{day}T{clock}"))
    return groups


def read_points(path: str | Path) -> Groups:
    """A points CSV or a DMIS file, by its suffix."""
    if Path(path).suffix.lower() in (".dmo", ".dms", ".dmi"):
        return read_points_dmis(path)
    return read_points_csv(path)


# ----------------------------------------------------------------------------- sphere fit
def fit_sphere(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """One free-radius geometric sphere fit: centre (3,), radius, centre uncertainty (um).

    ``u = sqrt(trace(cov_centre) / 3)`` with ``cov = s^2 (J^T J)^-1``, ``s^2 = SSR/(n-4)``.
    """
    mean = points.mean(axis=0)
    q = points - mean
    a = np.c_[2.0 * q, np.ones(len(q))]
    sol = np.linalg.lstsq(a, np.einsum("ij,ij->i", q, q), rcond=None)[0]
    start = np.r_[sol[:3], math.sqrt(sol[3] + sol[:3] @ sol[:3])]

    def fun(x: np.ndarray) -> np.ndarray:
        return np.linalg.norm(q - x[:3], axis=1) - x[3]

    def jac(x: np.ndarray) -> np.ndarray:
        d = q - x[:3]
        return np.c_[-d / np.linalg.norm(d, axis=1)[:, None], -np.ones(len(q))]

    res = least_squares(fun, start, jac=jac, method="lm")
    j = jac(res.x)
    s2 = float(res.fun @ res.fun) / (len(q) - 4)
    cov = s2 * np.linalg.inv(j.T @ j)
    return mean + res.x[:3], float(res.x[3]), math.sqrt(np.trace(cov[:3, :3]) / 3) * 1e3


# ----------------------------------------------------------------------------- registration
def register_step(centres: np.ndarray, balls: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``platform2cmm`` (4, 4) of one step: weighted rigid fit of the balls to the centres."""
    w = weights / weights.sum()
    c_mean = w @ centres
    b_mean = w @ balls
    rotation, _ = Rotation.align_vectors(centres - c_mean, balls - b_mean, weights=w)
    out = np.eye(4)
    out[:3, :3] = rotation.as_matrix()
    out[:3, 3] = c_mean - out[:3, :3] @ b_mean
    return out


# ----------------------------------------------------------------------------- poses
def _seq(hexapod: Hexapod) -> str:
    return "xyz" if hexapod.convention == "symetrie" else "XYZ"


def pose_of(transform: np.ndarray, hexapod: Hexapod) -> np.ndarray:
    """``[Tx, Ty, Tz, Rx, Ry, Rz]`` (mm, deg) of one 4x4 transform."""
    angles = Rotation.from_matrix(transform[:3, :3]).as_euler(_seq(hexapod), degrees=True)
    return np.r_[transform[:3, 3], angles]


def leg_lengths(pose: np.ndarray, hexapod: Hexapod) -> np.ndarray:
    """IGM of one pose: ``|t + R p_i - b_i|``, shape (6,)."""
    rot = Rotation.from_euler(_seq(hexapod), pose[3:], degrees=True).as_matrix()
    legs = pose[:3] + hexapod.platform_joints_mm @ rot.T - hexapod.base_joints_mm
    return np.linalg.norm(legs, axis=1)


def fgm_pose(hexapod: Hexapod, q: np.ndarray, start: np.ndarray) -> np.ndarray:
    """FGM of one set of leg lengths: one :func:`scipy.optimize.root` with the Jacobian."""
    sol = root(
        lambda x: hexapod.igm(x)[0] - q, start, jac=lambda x: hexapod.jacobian(x)[0], method="hybr"
    )
    if not sol.success and np.abs(hexapod.igm(sol.x)[0] - q).max() > 1e-9:
        raise RuntimeError(f"FGM did not converge: {sol.message}")
    return sol.x


def transform_of(pose: np.ndarray, hexapod: Hexapod) -> np.ndarray:
    """The 4x4 transform of one pose ``[Tx, Ty, Tz, Rx, Ry, Rz]`` (mm, deg)."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler(_seq(hexapod), pose[3:], degrees=True).as_matrix()
    out[:3, 3] = pose[:3]
    return out


# ----------------------------------------------------------------------------- O's carry
def read_leg_log(path: str | Path) -> tuple[list[float], list[list[float]]]:
    """Times and leg temperatures of a thermocouple log, row by row."""
    times, temps = [], []
    with open(path, newline="", encoding="utf-8-sig") as handle:
        for row in csv.DictReader(handle):
            stamp = row["time"].strip()
            try:
                times.append(float(stamp))
            except ValueError:
                times.append(_seconds(stamp))
            temps.append([float(row[f"leg{i}"]) for i in range(1, 7)])
    return times, temps


def leg_temperatures_at(times: list[float], temps: list[list[float]], t: float) -> np.ndarray:
    """Each leg's temperature at ``t``, the samples joined by straight lines."""
    return np.array([np.interp(t, times, [row[i] for row in temps]) for i in range(6)])


def lagrange_at(ref_times: list[float], t: float) -> list[float]:
    """Weights of the polynomial through the references' values at time ``t``."""
    weights = []
    for j, tj in enumerate(ref_times):
        w = 1.0
        for m, tm in enumerate(ref_times):
            if m != j:
                w *= (t - tm) / (tj - tm)
        weights.append(w)
    return weights


def polynomial_degree(ref_times: list[float], growth: list[np.ndarray]) -> int:
    """1 (a line) or 2 (a parabola): with two references a line, three a parabola; with
    more, the one whose backward predictions of each reference from the next two (three)
    miss less (root of the mean square over references and legs)."""
    n = len(ref_times)
    if n < 4:
        return n - 1
    squares = {1: 0.0, 2: 0.0}
    for j in range(n - 3):
        for degree in (1, 2):
            later = list(range(j + 1, j + 2 + degree))
            weights = lagrange_at([ref_times[i] for i in later], ref_times[j])
            predicted = sum(w * growth[i] for w, i in zip(weights, later, strict=True))
            squares[degree] += float(np.sum((predicted - growth[j]) ** 2))
    return 2 if squares[2] < squares[1] else 1


def origin_growth(
    session: Session, times: np.ndarray, q: np.ndarray, q_origin_cmd: np.ndarray
) -> np.ndarray | None:
    """Growth of O's legs since R0's thermal state (negative: O's legs were shorter): the
    leg model and the thermocouple log when the session has one, otherwise the
    references' growth since R0 on the line or parabola through the first two or three
    of them (:func:`polynomial_degree`) back to O's time, scaled to O's legs; None when
    neither is there."""
    plan, legs = session.plan, session.hexapod.legs
    assert legs is not None
    o, refs = plan.origin_index, list(plan.reference_indices)
    if not refs:
        return None
    r0 = refs[0]
    if session.temperatures is not None:
        log_t, log_c = read_leg_log(session.temperatures)
        warming = leg_temperatures_at(log_t, log_c, times[o]) - leg_temperatures_at(
            log_t, log_c, times[r0]
        )
        return np.asarray(legs.sensitivity_mm_per_K(q_origin_cmd) * warming, dtype=float)
    if len(refs) < 2:
        return None
    used = refs[
        : 1 + polynomial_degree([float(times[r]) for r in refs], [q[r] - q[r0] for r in refs])
    ]
    weights = lagrange_at([float(times[r]) for r in used], float(times[o]))
    growth_r = sum(w * (q[r] - q[r0]) for w, r in zip(weights, used, strict=True))
    return np.asarray(legs.scale_growth(growth_r, q[r0], q_origin_cmd), dtype=float)


# ----------------------------------------------------------------------------- the job
def read(session_path: str | Path) -> tuple[Session, Groups]:
    """The session and its probed points, grouped by (step, ball)."""
    session = read_session(session_path)
    groups: Groups = {}
    for file in session.measurements:
        groups.update(read_points(file))
    return session, groups


def process(session_path: str | Path) -> dict[str, np.ndarray]:
    """The job of ``hexatherm process`` (linear interpolation, free-radius fits)."""
    return compute(*read(session_path))


def compute(session: Session, groups: Groups) -> dict[str, np.ndarray]:
    """Fits, registration, poses and correction, one sphere, step and target at a time."""
    hexapod, balls, plan = session.hexapod, session.balls, session.plan
    legs = hexapod.legs
    if legs is None:
        raise ValueError("the hexapod file has no leg model")
    n, k = len(plan.labels), len(balls.names)
    centres = np.zeros((n, k, 3))
    u_um = np.zeros((n, k))
    times = np.zeros(n)
    for i, label in enumerate(plan.labels):
        ball_times = []
        for j, name in enumerate(balls.names):
            points, point_times = groups[(label, name)]
            centres[i, j], _, u_um[i, j] = fit_sphere(np.array(points))
            ball_times.append(sum(point_times) / len(point_times))
        times[i] = sum(ball_times) / len(ball_times)
    frames = np.zeros((n, 4, 4))
    for i in range(n):
        weights = 1.0 / np.maximum(u_um[i], U_FLOOR_UM) ** 2
        frames[i] = register_step(centres[i], balls.centres_mm, weights)
    origin_inv = np.linalg.inv(frames[plan.origin_index])
    poses = np.zeros((n, 6))
    q = np.zeros((n, 6))
    for i in range(n):
        poses[i] = pose_of(origin_inv @ frames[i], hexapod)
        q[i] = leg_lengths(poses[i], hexapod)
    q_r0 = q[plan.reference_indices[0]]
    targets = plan.target_indices
    corrected = np.zeros((len(targets), 6))
    for m, (s, (before, after)) in enumerate(zip(targets, plan.adjacent_references(), strict=True)):
        if before >= 0 and after >= 0:
            w_after = (times[s] - times[before]) / (times[after] - times[before])
            growth_r = (1 - w_after) * (q[before] - q_r0) + w_after * (q[after] - q_r0)
        else:
            growth_r = q[before if before >= 0 else after] - q_r0
        growth_s = legs.scale_growth(growth_r, q_r0, q[s])
        growth_s = legs.scale_growth(growth_r, q_r0, q[s] - growth_s)
        corrected[m] = fgm_pose(hexapod, q[s] - growth_s, poses[s])
    # the corrected poses relative to O in R0's thermal state: O's frame moved by its
    # legs' growth taken off, at its commanded pose
    pose_o = plan.poses[plan.origin_index]
    q_o = leg_lengths(pose_o, hexapod)
    g_o = origin_growth(session, times, q, q_o)
    if g_o is not None:
        shift = np.linalg.inv(transform_of(pose_o, hexapod)) @ transform_of(
            fgm_pose(hexapod, q_o - g_o, pose_o), hexapod
        )
        for m in range(len(targets)):
            corrected[m] = pose_of(
                np.linalg.inv(shift) @ transform_of(corrected[m], hexapod), hexapod
            )
    return {
        "centres_mm": centres,
        "u_um": u_um,
        "times_s": times,
        "platform2cmm": frames,
        "poses": poses,
        "q_mm": q,
        "conventional": poses[targets],
        "corrected": corrected,
        "target_labels": np.array([plan.labels[s] for s in targets]),
    }


def main(argv: list[str]) -> None:
    if len(argv) != 3 or argv[1] != "-o":
        raise SystemExit("usage: straightforward.py SESSION -o OUT")
    result = process(argv[0])
    out = Path(argv[2])
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "poses.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        names = [
            f"{a}_{tag}" for tag in ("conv", "corr") for a in ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")
        ]
        writer.writerow(["label", *names])
        for m, label in enumerate(result["target_labels"]):
            writer.writerow([label, *result["conventional"][m], *result["corrected"][m]])


if __name__ == "__main__":
    main(sys.argv[1:])
