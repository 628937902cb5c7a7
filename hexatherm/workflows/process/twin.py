"""``process --method twin``: poses corrected by the twin from the thermocouples alone.

The twin's model is a hexapod file (geometry, leg model and ``thermal_model``
effects), typically the ``hexapod.yaml`` that ``hexatherm diagnose`` writes. No
reference measurement is used: the measured pose of each target is corrected by
the thermal deflection the twin predicts from the thermocouple log
(:func:`hexatherm.core.twin.twin_corrected`), referred to the thermal state of
the first reference step, like the references' correction.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from hexatherm.core.effects import Effect, ThermocoupleLog, effects_from_dicts
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.twin import twin_corrected
from hexatherm.errors import InputError
from hexatherm.io.temperatures import Temperatures
from hexatherm.workflows.process.frames import model_in_origin
from hexatherm.workflows.process.measured import check_log_span

if TYPE_CHECKING:  # diagnose reads the twin's model here, without process's pipeline
    from hexatherm.workflows.process.pipeline import ProcessResult


def twin_poses(
    result: ProcessResult, hexapod: Hexapod, source: str = ""
) -> npt.NDArray[np.float64]:
    """Twin-corrected pose (M, 6) of every target of ``result``, mm and deg.

    ``source`` names the hexapod file in error messages. ``hexapod`` is the model as its
    file gives it (the machine frame): with the controller's frames set during the
    session, it is moved into frame O as the session is
    (:func:`~hexatherm.workflows.process.frames.model_in_origin`).
    """
    session = result.session
    hexapod = model_in_origin(hexapod, result.frames)
    if result.temperatures is None:
        raise InputError(
            "the twin corrects from the thermocouple log: add 'temperatures: "
            "temperatures.csv' to the session",
            path=str(session.path),
            field="temperatures",
        )
    # a step outside the log would get the log's end values (np.interp holds them)
    check_log_span(result.centres.times_s, session.plan.labels, result.temperatures)
    effects = model_effects(hexapod, source or None)
    log = thermocouple_log(result.temperatures)
    if log.air_C is None and any(type(e).needs_air for e in effects):
        raise InputError(
            "the thermal model's effects need the air temperature: the "
            "temperatures have no 'air' column",
            path=result.temperatures.path,
            line=1,
            field="air",
        )
    poses = twin_corrected(
        hexapod,
        session.plan,
        result.centres.times_s,
        log,
        session.balls.centres_mm,
        result.registration.platform2cmm,
        effects,
    )
    return poses[result.correction.target_index]


def model_effects(hexapod: Hexapod, source: str | None) -> tuple[Effect, ...]:
    """The twin's effects of ``hexapod`` (its ``thermal_model``), checked.

    InputError naming ``source`` (the hexapod file) when the leg model is missing
    or an effect is invalid.
    """
    if hexapod.legs is None:
        raise InputError(
            "the twin needs the hexapod's leg model ('legs:')", path=source, field="legs"
        )
    try:
        return effects_from_dicts(hexapod.effects)
    except ValueError as exc:
        raise InputError(str(exc), path=source, field="thermal_model") from None


def thermocouple_log(temperatures: Temperatures) -> ThermocoupleLog:
    """The twin's thermocouple log of ``temperatures.csv`` (with its ``air`` column if any)."""
    return ThermocoupleLog(
        temperatures.time_s, temperatures.legs_C, temperatures.others_C.get("air")
    )
