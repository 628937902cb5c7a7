"""The state of an interrupted run, rebuilt from its session folder (``--resume``).

The I++ transcript is the primary record: every ball it accepted is kept, with its points
bit for bit, and ``points.csv`` is made to hold exactly those (a ball accepted in the
transcript whose lines did not reach ``points.csv`` before a crash is restored; nothing is
written twice). Balls begun and not accepted are probed again from their start. The other
logs (controller log, ``steps.csv``) lose at most an unfinished last line.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from hexatherm.core.plan import Plan
from hexatherm.errors import AcquisitionError
from hexatherm.io.atomic import atomic_write_text
from hexatherm.session import Balls
from hexatherm.workflows.run.files import (
    CONTROLLER_LOG_NAME,
    POINTS_NAME,
    RUN_NAME,
    STEPS_NAME,
    TRANSCRIPT_NAME,
    AcceptedBall,
    accepted_balls,
    points_lines,
    truncate_partial_line,
)

RUN_FORMAT = "hexatherm-run/1"


@dataclass(frozen=True)
class ProbeSettings:
    """How the CMM probes each ball (kept in ``run.yaml``: a resume probes the same way).

    Attributes
    ----------
    tool : str
        The I++ tool to use (``ChangeTool``).
    cap_angle_deg : float
        Half-angle of the probed upper cap, deg, in (0, 90].
    approach_mm : float
        Distance of the approach positions from the predicted surface, mm.
    clearance_mm : float
        Safe plane above each ball's top, mm (>= approach).
    travel_mm : float
        Travel height above the highest ball top of the whole plan, mm: where the probe
        waits while the hexapod moves and travels between balls.
    """

    tool: str = "Probe1"
    cap_angle_deg: float = 70.0
    approach_mm: float = 2.0
    clearance_mm: float = 5.0
    travel_mm: float = 30.0

    def __post_init__(self) -> None:
        if not (0 < self.cap_angle_deg <= 90):
            raise AcquisitionError(f"cap angle must be in (0, 90] deg, got {self.cap_angle_deg}")
        if not (self.approach_mm > 0 and self.clearance_mm >= self.approach_mm):
            raise AcquisitionError("need approach > 0 and clearance >= approach (mm)")
        if not (math.isfinite(self.travel_mm) and self.travel_mm >= 0):
            raise AcquisitionError(f"travel height must be >= 0 mm, got {self.travel_mm}")


@dataclass(frozen=True)
class RunSettings:
    """What ``run.yaml`` keeps: the nominal placement of O on the CMM and the probing."""

    origin_on_cmm: tuple[float, ...]
    probe: ProbeSettings


def write_run_settings(folder: Path, settings: RunSettings) -> None:
    """Write ``run.yaml`` (atomically)."""
    doc = {
        "format": RUN_FORMAT,
        "origin_on_cmm": [float(v) for v in settings.origin_on_cmm],
        "probe": {k: v for k, v in asdict(settings.probe).items()},
    }
    atomic_write_text(folder / RUN_NAME, yaml.safe_dump(doc, sort_keys=False))


def record_cmm_facts(folder: Path, facts: dict[str, object]) -> None:
    """Keep what the CMM said of itself in ``run.yaml`` under ``cmm`` (the last connection's):
    ``dme_version``, ``tool_avr_radius_mm`` (``unknown`` when not asked or refused) and
    ``unknown`` (why). The settings a resume reads are left as they are."""
    path = folder / RUN_NAME
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    doc["cmm"] = facts
    atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False))


def read_run_settings(folder: Path) -> RunSettings:
    """Read ``run.yaml`` of a session started by ``hexatherm run``."""
    path = folder / RUN_NAME
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != RUN_FORMAT:
            raise ValueError(f"format must be {RUN_FORMAT}")
        origin = tuple(float(v) for v in doc["origin_on_cmm"])
        if len(origin) != 6:
            raise ValueError("origin_on_cmm needs 6 numbers")
        probe = ProbeSettings(**doc["probe"])
    except (OSError, ValueError, KeyError, TypeError, yaml.YAMLError) as exc:
        raise AcquisitionError(f"cannot read the run's settings {path}: {exc}") from None
    return RunSettings(origin, probe)


@dataclass
class RunState:
    """What a run has done so far.

    Attributes
    ----------
    accepted : dict of (str, str) to AcceptedBall
        The accepted balls by (step label, ball name), in order of acceptance.
    positionings : Counter of str
        How often the hexapod was brought in position for each step.
    """

    accepted: dict[tuple[str, str], AcceptedBall]
    positionings: collections.Counter[str]


def rebuild_state(
    folder: Path, plan: Plan, balls: Balls, notify: Callable[[str, str], None]
) -> RunState:
    """Rebuild a run's state from its folder and make ``points.csv`` match the transcript.

    Unfinished last lines of the logs (a writer killed mid-line) are cut first.
    """
    for name in (TRANSCRIPT_NAME, CONTROLLER_LOG_NAME, STEPS_NAME, POINTS_NAME):
        cut = truncate_partial_line(folder / name)
        if cut:
            notify("warn", f"{name}: an unfinished last line ({cut} bytes) cut")
    text = (folder / TRANSCRIPT_NAME).read_text(encoding="ascii", errors="replace")
    accepted = accepted_balls(text)
    unknown = [k for k in accepted if k[0] not in plan.labels or k[1] not in balls.names]
    if unknown:
        raise AcquisitionError(
            f"the transcript has balls the plan or balls file does not know: {unknown[:3]}"
        )
    expected = "".join(line + "\n" for line in points_lines(plan, balls, accepted))
    points = folder / POINTS_NAME
    current = points.read_text(encoding="utf-8") if points.is_file() else ""
    if current != expected:
        if expected.startswith(current):
            missing = expected.count("\n") - current.count("\n")
            notify("info", f"{POINTS_NAME}: {missing} line(s) restored from the transcript")
        else:
            notify("warn", f"{POINTS_NAME} did not match the transcript: rewritten from it")
        atomic_write_text(points, expected)
    positionings: collections.Counter[str] = collections.Counter()
    steps = folder / STEPS_NAME
    if steps.is_file():
        for line in steps.read_text(encoding="utf-8").splitlines()[1:]:
            if line:
                positionings[line.split(",", 1)[0]] += 1
    return RunState(accepted, positionings)
