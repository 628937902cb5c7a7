"""Session-level types: what a session is made of, below the files that describe it.

``io`` turns bytes into these types and back; the workflows and the ``core`` maths use
them. No file access here.

- :class:`Balls`: the precision balls on the platform (balls file).
- :class:`CmmNoise`: the CMM's probing noise (the session's optional ``cmm:`` mapping).
- :class:`QualityLimits`: limits of the quality checks (the session's ``quality:``
  mapping, ``--quality-threshold NAME=VALUE``).
- :class:`Session`: a session folder as its ``session.yaml`` describes it.
- :class:`Datums`: how ``hexatherm register`` finds the platform frame.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from hexatherm.core.hexapod import Hexapod
from hexatherm.core.plan import Plan
from hexatherm.limits import (
    DISTANCE_REFUSAL_UM,
    QUALITY_ALIASES,
    QualityLimits,
    limits_text,
)

__all__ = [
    "DISTANCE_REFUSAL_UM",
    "QUALITY_ALIASES",
    "Balls",
    "CmmNoise",
    "Datums",
    "Identification",
    "MeasurementFormat",
    "QualityLimits",
    "Session",
    "limits_text",
]


@dataclass(frozen=True)
class Balls:
    """The precision balls on the platform (balls file).

    Attributes
    ----------
    names : tuple of str
    centres_mm : ndarray, shape (k, 3)
        Centres in the platform frame.
    diameters_mm : ndarray, shape (k,)
    probe_compensated : bool
        True when probed points are surface points (probe radius compensated).
    tip_diameter_mm : float
    """

    names: tuple[str, ...]
    centres_mm: npt.NDArray[np.float64]
    diameters_mm: npt.NDArray[np.float64]
    probe_compensated: bool = True
    tip_diameter_mm: float = 0.0


@dataclass(frozen=True)
class CmmNoise:
    """The CMM's probing noise, from the session's optional ``cmm:`` mapping (an extension).

    Used for the uncertainty of ball centres that come without fit residuals
    (centres files): the centre covariance of a free-radius sphere fit to
    ``points_per_ball`` points spread over a cap of ``cap_angle_deg``.

    Attributes
    ----------
    point_noise_um : float
        Standard deviation of a probed point along the surface normal
        (``point_noise_um``, or ``mpe_um / 2`` as for an ISO 10360 MPE).
    points_per_ball : int or None
        Points probed per ball (None: the plan's ``points_per_ball``).
    cap_angle_deg : float
        Half-angle of the probed cap (default 70).
    cap_stated : bool
        Whether the session stated ``cap_angle_deg`` (False: the default is assumed, and
        ``process`` checks it against the data).
    """

    point_noise_um: float
    points_per_ball: int | None = None
    cap_angle_deg: float = 70.0
    cap_stated: bool = True


#: length units a mapped table or a Calypso run may be written in -> mm per unit
LENGTH_UNITS: dict[str, float] = {"mm": 1.0, "um": 1e-3, "inch": 25.4}


@dataclass(frozen=True)
class MeasurementFormat:
    """How one ``measurements:`` entry of ``session.yaml`` is read when it is not
    hexatherm's own CSV or DMIS (an extension, :mod:`hexatherm.io.config.tablemap`).

    Attributes
    ----------
    kind : {"table", "calypso"}
        A delimited table through a column map, or a folder of Zeiss Calypso runs
        (``<name>_chr.txt`` beside ``<name>_hdr.txt``), one run per step.
    columns : dict of str to tuple of str
        Table: role (``label``, ``ball``, ``feature``, ``x``, ``y``, ``z``, ``time``,
        ``diameter``, ``u``) -> the file's column names (``time`` may join two: a date
        and a time column).
    feature_pattern : str or None
        A regular expression with the named groups ``step`` and ``ball`` that splits
        the ``feature`` column (table), or names the ball in a Calypso feature name.
    delimiter, decimal : str
        Table: the field delimiter and the decimal mark.
    unit : {"mm", "um", "inch"}
        The length unit of the coordinates, diameters and ``u`` (Calypso: the file's
        ``unit`` column wins, this is for runs without one).
    time_format : str
        ``iso``, ``seconds``, or a :func:`time.strptime` format (``%d.%m.%Y %H:%M:%S``).
    utc_offset_s : float or None
        Seconds east of UTC of the file's times that carry no offset (None: the
        session's ``utc_offset``, else naive).
    encoding : str
        The text encoding when the file has no byte order mark.
    balls : dict of str to str
        Ball name or feature name in the file -> ball of the balls file.
    step_field : str or None
        Calypso: the header field naming each run's step (None: runs in time order
        against the plan's order, with a warning).
    where : str
        ``session.yaml:LINE`` of the entry, for messages.
    column_lines : dict of str to int
        Table: the line of ``session.yaml`` that maps each role, for messages.
    key : str
        The entry's field in ``session.yaml`` (``measurements[2]``), for messages.
    """

    kind: str
    columns: dict[str, tuple[str, ...]] = dataclasses.field(default_factory=dict)
    feature_pattern: str | None = None
    delimiter: str = ","
    decimal: str = "."
    unit: str = "mm"
    time_format: str = "iso"
    utc_offset_s: float | None = None
    encoding: str = "utf-8"
    balls: dict[str, str] = dataclasses.field(default_factory=dict)
    step_field: str | None = None
    where: str = ""
    column_lines: dict[str, int] = dataclasses.field(default_factory=dict)
    key: str = "measurements"


@dataclass(frozen=True)
class Session:
    """A session folder as described by its ``session.yaml``.

    Attributes
    ----------
    path : Path
        The session file.
    name : str
    hexapod : Hexapod
    balls : Balls
    plan : Plan
    measurements : tuple of Path
    temperatures : Path or None
    cmm : CmmNoise or None
        The optional ``cmm:`` mapping (``point_noise_um`` or ``mpe_um``,
        ``points_per_ball``, ``cap_angle_deg``).
    quality : dict of str to float
        The optional ``quality:`` mapping: limits of the quality checks kept with
        the session (names of :class:`hexatherm.workflows.process.quality.QualityLimits`).
    config_files : tuple of Path
        The hexapod, balls and plan files the session file names.
    utc_offset_s : float or None
        The optional ``utc_offset:`` (seconds east of UTC) of the times that the
        measurement and temperature files give without an offset (a CMM's local clock).
    identification : dict
        The optional ``identification:`` mapping (an extension), flat: ``"lab"``,
        ``"cmm.serial"``, ... -> text (``ambient.*`` numbers), ``"signatures"`` -> list of
        ``(role, name)`` (:func:`hexatherm.io.config.identity.read_identification`).
    tolerances : dict of str to Tolerance
        The optional ``tolerances:`` mapping: ``Tx_um`` .. ``Rz_urad`` -> half-width of
        the tolerance zone of that deviation from the commanded pose, or its
        ``(lower, upper)`` limits.
    formats : dict of Path to MeasurementFormat
        The measurement entries given as a mapping (a column map, Calypso runs): how
        each is read; the others are hexatherm's CSV or DMIS.
    measurement_files : tuple of Path
        The files inside measurement folders (a Calypso folder's runs), read too.
    feature_names : dict of str to str or None
        The optional ``feature_names:`` mapping (an extension): a CMM's feature name in a
        QIF results file -> ``<step>_<ball>``, or None for a feature read past.
    """

    path: Path
    name: str
    hexapod: Hexapod
    balls: Balls
    plan: Plan
    measurements: tuple[Path, ...]
    temperatures: Path | None
    cmm: CmmNoise | None = None
    quality: dict[str, float] = dataclasses.field(default_factory=dict)
    config_files: tuple[Path, ...] = ()
    utc_offset_s: float | None = None
    identification: dict[str, object] = dataclasses.field(default_factory=dict)
    tolerances: dict[str, Tolerance] = dataclasses.field(default_factory=dict)
    formats: dict[Path, MeasurementFormat] = dataclasses.field(default_factory=dict)
    measurement_files: tuple[Path, ...] = ()
    feature_names: dict[str, str | None] = dataclasses.field(default_factory=dict)

    def input_files(self) -> list[Path]:
        """Every file a run on this session reads: the session file, the hexapod, balls
        and plan files, the measurements and the temperatures (an output may never be,
        contain or sit inside any of them)."""
        files = [self.path, *self.config_files, *self.measurements, *self.measurement_files]
        if self.temperatures is not None:
            files.append(self.temperatures)
        return files


@dataclass(frozen=True)
class Datums:
    """How ``hexatherm register`` finds the platform frame (an extension file).

    Attributes
    ----------
    step : str or None
        Label of the records to use (None: the file's only label).
    plane : str
        Feature name of the points on the top face.
    bores : (str, str)
        Feature names of the points in the two bores (origin, X direction).
    origin_offset_mm : ndarray, shape (3,)
        The platform origin in the datum frame.
    balls : dict of str to float
        Ball names and diameters, mm.
    probe_compensated : bool
    tip_diameter_mm : float
    """

    step: str | None
    plane: str
    bores: tuple[str, str]
    origin_offset_mm: npt.NDArray[np.float64]
    balls: dict[str, float]
    probe_compensated: bool
    tip_diameter_mm: float


#: a tolerance: a half-width ``T`` (the interval ``[-T, T]``) or ``(lower, upper)`` limits
Tolerance = float | tuple[float, float]
#: tolerance keys -> unit of the deviation they bound (``tolerances:``, ``--tolerance``)
TOLERANCE_UNITS: dict[str, str] = {
    **{f"T{a}_um": "um" for a in "xyz"},
    **{f"R{a}_urad": "urad" for a in "xyz"},
}

#: identification keys -> how a report names them, in the order it prints them
IDENTIFICATION_NAMES: dict[str, str] = {
    "lab": "Laboratory",
    "address": "Address",
    "report_number": "Report number",
    "customer": "Customer",
    "operator": "Operator",
    "hexapod.model": "Hexapod model",
    "hexapod.serial": "Hexapod serial",
    "cmm.make": "CMM make",
    "cmm.model": "CMM model",
    "cmm.serial": "CMM serial",
    "cmm.certificate": "CMM calibration certificate",
    "cmm.mpe": "CMM MPE",
    "ambient.temperature_C": "Ambient temperature (\u00b0C)",
    "ambient.humidity_percent": "Relative humidity (%)",
    "ambient.note": "Ambient conditions",
}


@dataclass(frozen=True)
class Identification:
    """Who and what a report is about: the lab file's and the session's fields merged.

    Attributes
    ----------
    fields : tuple of (str, str or float)
        ``(key, value)``: keys of :data:`IDENTIFICATION_NAMES`.
    signatures : tuple of (str, str)
        ``(role, name)`` of each signatory (the signature block), in order.
    """

    fields: tuple[tuple[str, object], ...] = ()
    signatures: tuple[tuple[str, str], ...] = ()

    def rows(self) -> list[tuple[str, str]]:
        """``(name, text)`` of every field given, in :data:`IDENTIFICATION_NAMES`'s order."""
        given = dict(self.fields)
        rows = []
        for key, name in IDENTIFICATION_NAMES.items():
            if key in given:
                value = given[key]
                rows.append((name, f"{value:g}" if isinstance(value, float) else str(value)))
        return rows
