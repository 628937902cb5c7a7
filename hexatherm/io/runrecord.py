"""What ``run.yaml`` recorded of the controller's coordinate frames, for ``run`` (its
predictions of the balls), ``process`` and ``calibrate``.

``hexatherm run`` appends a record to ``run.yaml``'s ``controller:`` list at every
connection (docs/formats.md, ``run.yaml``). A Symétrie controller's record holds its user
frame in the machine frame and its object frame in the platform frame as it reported
them (``CFG#CS?3`` on API v2, ``C_CFG_CS`` on gpascii): ``frames_mm_deg`` (12 numbers,
15 significant digits, Symétrie convention) and, rounded for the eye,
``user_frame_in_machine`` and ``object_frame_in_platform`` (0.1 um and 1e-5 deg; read
when ``frames_mm_deg`` is missing, from runs before it was recorded). A PI controller's
record says which coordinate system was enabled (``checks: coordinate_system``): ``run``
moves a PI hexapod only in ``ZERO`` with its pivot at zero, so its frames were zero.

Every record of one session must give the same frames (a controller whose frames
changed between two connections: refused, naming the record). A session without
``run.yaml`` (``acquire``, CSV files) or whose records say nothing of frames: the
frames are not known and ``calibrate`` assumes them zero, which it says.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hexatherm.io.yamlfile import YamlDoc
from hexatherm.typing import FloatArray

RUN_YAML = "run.yaml"
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_THREE = rf"\[({_NUMBER}), ({_NUMBER}), ({_NUMBER})\]"
_ROUNDED = re.compile(rf"^{_THREE} mm, {_THREE} deg$")


@dataclass(frozen=True)
class RecordedFrames:
    """The controller frames of one session during its measurement.

    Attributes
    ----------
    values_mm_deg : ndarray, shape (12,), or None
        The user (work) frame in the machine frame (ZERO), then the object (tool) frame in
        the platform frame, mm and deg, Symétrie convention (``R = Rz Ry Rx``, fixed
        axes); None when no record says (assumed zero).
    source : str
        Where they come from, in words, for the screen and ``calibration.json``.
    path : str
        The ``run.yaml`` (or the session folder when there is none).
    """

    values_mm_deg: FloatArray | None
    source: str
    path: str

    @property
    def values(self) -> FloatArray:
        """The 12 values, zero when not recorded."""
        return np.zeros(12) if self.values_mm_deg is None else self.values_mm_deg


def read_recorded_frames(folder: str | Path) -> RecordedFrames:
    """The controller frames ``run.yaml`` in ``folder`` recorded (see the module text);
    InputError naming the file, the record and the field when they cannot be read or
    when two records of the session differ."""
    path = Path(folder) / RUN_YAML
    if not path.is_file():
        return RecordedFrames(
            None, f"no {RUN_YAML} (not measured by hexatherm run): frames assumed zero", str(path)
        )
    doc = YamlDoc.load(path)
    records = doc.get("controller", default=None)
    if not isinstance(records, list) or not records:
        return RecordedFrames(
            None, f"{RUN_YAML} has no controller record: frames assumed zero", str(path)
        )
    found: list[tuple[int, FloatArray, str]] = []
    for k, record in enumerate(records):
        if not isinstance(record, dict):
            raise doc.error("expected a mapping (a controller record)", "controller", k)
        read = _record_frames(doc, k, record)
        if read is not None:
            found.append((k, *read))
    if not found:
        return RecordedFrames(
            None,
            f"{RUN_YAML}'s controller records say nothing of frames: frames assumed zero",
            str(path),
        )
    first_k, first, how = found[0]
    for k, values, _ in found[1:]:
        if np.abs(values - first).max() > 1e-9:
            raise doc.error(
                f"the controller's frames changed between its connections: record "
                f"{first_k + 1} gives {_shown(first)}, record {k + 1} {_shown(values)} (mm, "
                "deg): one session, one frame setting",
                "controller",
                k,
            )
    return RecordedFrames(first, how, str(path))


def _record_frames(doc: YamlDoc, k: int, record: dict) -> tuple[FloatArray, str] | None:
    if "frames_mm_deg" in record:
        text = doc.string("controller", k, "frames_mm_deg")
        try:
            values = np.array([float(v) for v in text.split()], dtype=float)
        except ValueError:
            values = np.array([])
        if values.shape != (12,) or not np.isfinite(values).all():
            raise doc.error(
                f"expected 12 finite numbers separated by blanks, got {text!r}",
                "controller",
                k,
                "frames_mm_deg",
            )
        return values, f"{RUN_YAML}: the Symetrie controller's user and object frames"
    keys = ("user_frame_in_machine", "object_frame_in_platform")
    if all(key in record for key in keys):
        parts = []
        for key in keys:
            text = doc.string("controller", k, key)
            match = _ROUNDED.match(text.strip())
            if match is None:
                raise doc.error(
                    f"expected '[Tx, Ty, Tz] mm, [Rx, Ry, Rz] deg', got {text!r}",
                    "controller",
                    k,
                    key,
                )
            parts += [float(v) for v in match.groups()]
        return np.array(parts), (
            f"{RUN_YAML}: the Symetrie controller's user and object frames, as rounded there "
            "(0.1 um, 1e-5 deg: no frames_mm_deg recorded)"
        )
    checks = record.get("checks")
    if isinstance(checks, dict) and "coordinate_system" in checks:
        system = doc.string("controller", k, "checks", "coordinate_system")
        return np.zeros(12), (
            f"{RUN_YAML}: the PI controller's coordinate system {system} (run moves a PI "
            "hexapod only in ZERO, its pivot at zero): frames zero"
        )
    return None


def _shown(values: FloatArray) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"
