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
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from hexatherm.core.plan import Plan
from hexatherm.errors import AcquisitionError, InputError
from hexatherm.io.atomic import atomic_write_text
from hexatherm.io.files import read_bytes, refusal
from hexatherm.io.yamlfile import YamlDoc
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
    step_header,
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
    _update_run_yaml(folder, lambda doc: doc.update(cmm=facts))


def _update_run_yaml(folder: Path, change: Callable[[dict[str, Any]], None]) -> None:
    """``change`` the document of ``run.yaml`` (read by the strict reader a resume uses,
    written atomically); what it leaves is kept as it was."""
    path = folder / RUN_NAME
    doc = dict(YamlDoc.load(path).data)
    change(doc)
    atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False))


def read_run_settings(folder: Path) -> RunSettings:
    """Read ``run.yaml`` of a session started by ``hexatherm run``.

    Through the strict YAML reader of every other input (:class:`~hexatherm.io.yamlfile.YamlDoc`):
    a FIFO, a device, an oversized or deeply nested file, a non-finite number are each one
    :class:`~hexatherm.errors.InputError` naming the file, the line and the field.
    """
    doc = YamlDoc.load(folder / RUN_NAME)
    doc.check_keys(["format", "origin_on_cmm", "probe", "controller", "cmm"])
    doc.check_format(RUN_FORMAT)
    origin = tuple(doc.vector("origin_on_cmm", size=6))
    doc.check_keys([f.name for f in fields(ProbeSettings)], "probe")
    values: dict[str, str | float] = {}
    for f in fields(ProbeSettings):
        if f.name == "tool":
            values[f.name] = doc.string("probe", f.name, default=f.default)
        else:
            values[f.name] = doc.number("probe", f.name, default=f.default)
    try:
        probe = ProbeSettings(**values)  # type: ignore[arg-type]
    except AcquisitionError as exc:
        raise doc.error(str(exc), "probe") from None
    return RunSettings(origin, probe)


def record_controller(
    folder: Path, at: str, url: str, info: dict[str, str], checks: dict[str, str]
) -> None:
    """Append one connection's controller record to ``run.yaml`` (atomically).

    ``run.yaml``'s ``controller`` list gets ``{at, url, identification..., checks}`` at
    every connection (start, resume, reconnection): what the controller said it was and
    what :meth:`~hexatherm.devices.controller.SocketController.check_ready` found before
    the run moved it. The settings above it are kept as they were.
    """
    entry: dict[str, object] = {"at": at, "url": url}
    entry.update({k: v for k, v in info.items() if k != "error_at_stop"})
    entry["checks"] = dict(checks)

    def append(doc: dict[str, Any]) -> None:
        records = doc.get("controller")
        doc["controller"] = [*(records if isinstance(records, list) else []), entry]

    _update_run_yaml(folder, append)


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
    names = (TRANSCRIPT_NAME, CONTROLLER_LOG_NAME, STEPS_NAME, POINTS_NAME)
    for name in names:  # what is there must be a regular file: a FIFO would block the run
        path = folder / name
        refused = refusal(path) if path.exists() or path.is_symlink() else None
        if refused is not None:
            raise refused
    for name in names:
        cut = truncate_partial_line(folder / name)
        if cut:
            notify("warn", f"{name}: an unfinished last line ({cut} bytes) cut")
    text = _text(folder / TRANSCRIPT_NAME, "ascii", "replace")
    accepted = accepted_balls(text)
    unknown = [k for k in accepted if k[0] not in plan.labels or k[1] not in balls.names]
    if unknown:
        raise AcquisitionError(
            f"the transcript has balls the plan or balls file does not know: {unknown[:3]}"
        )
    expected = "".join(line + "\n" for line in points_lines(plan, balls, accepted))
    points = folder / POINTS_NAME
    current = _text(points) if points.exists() or points.is_symlink() else ""
    if current != expected:
        if expected.startswith(current):
            missing = expected.count("\n") - current.count("\n")
            notify("info", f"{POINTS_NAME}: {missing} line(s) restored from the transcript")
        else:
            notify("warn", f"{POINTS_NAME} did not match the transcript: rewritten from it")
        atomic_write_text(points, expected)
    return RunState(accepted, _positionings(folder / STEPS_NAME, plan))


def _text(path: Path, encoding: str = "utf-8", errors: str = "strict") -> str:
    """A file of the session as text, through the strict reader (a FIFO, a device, an
    oversized file: one InputError naming it, never a hang)."""
    raw = read_bytes(path)
    try:
        return raw.decode(encoding, errors)
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(f"not {encoding} text ({exc.reason})", path=path, line=line) from None


def _positionings(path: Path, plan: Plan) -> collections.Counter[str]:
    """How often each step was brought in position, by ``steps.csv``'s rows."""
    out: collections.Counter[str] = collections.Counter()
    if not (path.exists() or path.is_symlink()):
        return out
    lines = _text(path).splitlines()
    if not lines or lines[0] != step_header():
        raise InputError("not the run's steps.csv (its header differs)", path=path, line=1)
    for number, line in enumerate(lines[1:], start=2):
        if not line:
            continue
        label = line.split(",", 1)[0]
        if label not in plan.labels:
            raise InputError(
                f"step {label[:40]!r} is not in the plan", path=path, line=number, field="label"
            )
        out[label] += 1
    return out
