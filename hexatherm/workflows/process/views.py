"""What ``report``'s page reads of a processed session, whether processed now (a
:class:`~hexatherm.workflows.process.pipeline.ProcessResult` and its
:class:`~hexatherm.workflows.process.uncertainty.PoseUncertainty`) or read back from the
results folder ``process`` wrote (:mod:`hexatherm.workflows.process.written`): the
types of the second, and :data:`Processed` and :data:`Uncertain`, either."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
import numpy.typing as npt

from hexatherm.io.temperatures import Temperatures
from hexatherm.session import Session
from hexatherm.typing import FloatArray

if TYPE_CHECKING:
    from hexatherm.workflows.process.pipeline import ProcessResult
    from hexatherm.workflows.process.uncertainty import PoseUncertainty


@dataclass(frozen=True)
class WrittenCentres:
    """The steps' times as ``legs.csv`` gives them (POSIX seconds for ISO times)."""

    times_s: FloatArray
    time_kind: str
    time_aware: bool | None


@dataclass(frozen=True)
class WrittenCorrection:
    """The targets' poses of ``poses.csv`` (mm, deg), in the plan's order."""

    target_index: npt.NDArray[np.intp]
    conventional: FloatArray
    corrected: FloatArray


@dataclass(frozen=True)
class WrittenSteps:
    """Every step's IGM leg lengths of ``legs.csv`` (mm)."""

    q_mm: FloatArray


@dataclass(frozen=True)
class WrittenRegistration:
    """Every step's registration RMS residual of ``legs.csv`` (um)."""

    rms_um: FloatArray


@dataclass(frozen=True)
class WrittenResult:
    """A processed session as its results folder holds it (see the module)."""

    session: Session
    centres: WrittenCentres
    correction: WrittenCorrection
    steps: WrittenSteps
    registration: WrittenRegistration
    temperatures: Temperatures | None
    interpolation: str
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True)
class CentresNote:
    """Where the ball centres' uncertainty came from, as ``process`` said it."""

    description: str


@dataclass(frozen=True)
class WrittenUncertainty:
    """The poses' standard uncertainties of ``poses.csv`` (mm, deg) and their parts common
    to all targets and of their own (12 columns: conventional, then corrected)."""

    conventional_u: FloatArray
    corrected_u: FloatArray
    common_u: FloatArray | None
    own_u: FloatArray | None
    method: str
    draws: int
    seed: int | None
    centres: CentresNote


#: what the page reads: a session processed now, or one read back from its results
Processed: TypeAlias = "ProcessResult | WrittenResult"
Uncertain: TypeAlias = "PoseUncertainty | WrittenUncertainty"
