"""From a session folder to results: read, assemble, register, correct.

This is the glue between the I/O layer and the core. It reads the session's
files, gathers every step's ball centres (fitting spheres where the files hold
probed points), registers each step's frame, and runs the thermal method. It
writes nothing: :mod:`hexatherm.io.results` does.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from hexatherm.core.method import Correction, Interpolation, StepPoses, correct
from hexatherm.core.registration import Registration, register
from hexatherm.errors import InputError, PlanError
from hexatherm.io.config import Session, read_session
from hexatherm.io.csvfile import Temperatures, read_measurements, read_temperatures
from hexatherm.io.records import Records, TimeKind

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class StepCentres:
    """Ball centres of every plan step, in plan order and balls-file order.

    Attributes
    ----------
    centres_mm : ndarray, shape (N, k, 3)
        CMM frame.
    times_s : ndarray, shape (N,)
        Mean time of each step's records.
    time_kind : {"iso", "seconds"}
    """

    centres_mm: FloatArray
    times_s: FloatArray
    time_kind: TimeKind


@dataclass(frozen=True)
class ProcessResult:
    """Everything ``hexatherm process`` computed for a session."""

    session: Session
    centres: StepCentres
    registration: Registration
    steps: StepPoses
    correction: Correction
    temperatures: Temperatures | None
    interpolation: Interpolation


def assemble_centres(records: list[Records], session: Session) -> StepCentres:
    """Gather one centre per plan step and ball from the records of all files.

    Raises InputError (naming file and line) for records of unknown steps or balls
    and for mixed time kinds, and PlanError (naming the step) for a step or a
    ball that was not measured.
    """
    plan, balls = session.plan, session.balls
    step_index = {label: i for i, label in enumerate(plan.labels)}
    ball_index = {name: j for j, name in enumerate(balls.names)}
    n, k = len(plan.labels), len(balls.names)
    sums = np.zeros((n, k, 3))
    counts = np.zeros((n, k), dtype=int)
    time_sum, time_count = np.zeros(n), np.zeros(n)
    kinds = {r.time_kind for r in records}
    if len(kinds) > 1:
        iso = next(r for r in records if r.time_kind == "iso")
        sec = next(r for r in records if r.time_kind == "seconds")
        raise InputError(f"times are ISO 8601 here but seconds in {sec.path}: all the files "
                         "of a session must use one kind", path=iso.path, line=int(iso.line[0]),
                         field="time")
    for rec in records:
        if rec.kind != "centres":
            raise InputError("holds probed points: sphere fitting of points comes with the "
                             "points readers; give ball centres", path=rec.path,
                             line=int(rec.line[0]))
        si = np.array([step_index.get(s, -1) for s in rec.label])
        bi = np.array([ball_index.get(b, -1) for b in rec.ball])
        if np.any(si < 0):
            row = int(np.argmax(si < 0))
            raise InputError(f"step {str(rec.label[row])!r} is not in the plan", path=rec.path,
                             line=int(rec.line[row]), field="label")
        if np.any(bi < 0):
            row = int(np.argmax(bi < 0))
            raise InputError(f"ball {str(rec.ball[row])!r} is not in the balls file "
                             f"({', '.join(balls.names)})", path=rec.path,
                             line=int(rec.line[row]), field="ball")
        dup = counts[si, bi] > 0
        if np.any(dup):
            row = int(np.argmax(dup))
            raise InputError(f"step {rec.label[row]} ball {rec.ball[row]} is measured again "
                             "(already in an earlier file)", path=rec.path,
                             line=int(rec.line[row]), field="label")
        np.add.at(sums, (si, bi), rec.xyz_mm)
        np.add.at(counts, (si, bi), 1)
        np.add.at(time_sum, si, rec.time_s)
        np.add.at(time_count, si, 1)
    missing_step = time_count == 0
    if np.any(missing_step):
        i = int(np.argmax(missing_step))
        raise PlanError(f"step {plan.labels[i]}: not measured (no record in "
                        f"{', '.join(str(p.name) for p in session.measurements)})")
    missing_ball = counts == 0
    if np.any(missing_ball):
        i, j = np.argwhere(missing_ball)[0]
        raise PlanError(f"step {plan.labels[i]}: ball {balls.names[j]} not measured")
    return StepCentres(sums / counts[..., None], time_sum / time_count,
                       kinds.pop() if kinds else "seconds")


def process_session(
    path: str | Path, interpolation: Interpolation = "linear"
) -> ProcessResult:
    """Read a session and compute conventional and corrected poses of every target."""
    session = read_session(path)
    records: list[Records] = []
    for file in session.measurements:
        records.extend(read_measurements(file))
    centres = assemble_centres(records, session)
    temperatures = None
    if session.temperatures is not None:
        temperatures = read_temperatures(session.temperatures)
        if temperatures.time_kind != centres.time_kind:
            raise InputError(f"times are {temperatures.time_kind} here but "
                             f"{centres.time_kind} in the measurements: use one kind",
                             path=temperatures.path, line=2, field="time")
    registration = register(centres.centres_mm, session.balls.centres_mm)
    steps, correction = correct(session.hexapod, session.plan, centres.times_s,
                                registration.platform2cmm, interpolation)
    return ProcessResult(session, centres, registration, steps, correction, temperatures,
                         interpolation)
