"""``process --method twin``: poses corrected by the twin from the thermocouples alone.

The twin's model is a hexapod file (geometry, leg model and ``thermal_model``
effects), typically the ``hexapod.yaml`` that ``hexatherm diagnose`` writes. No
reference measurement is used: the measured pose of each target is corrected by
the thermal deflection the twin predicts from the thermocouple log
(:func:`hexatherm.core.twin.twin_corrected`), referred to the thermal state of
the first reference step, like the references' correction.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from hexatherm.core.effects import ThermocoupleLog, effects_from_dicts
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.twin import twin_corrected
from hexatherm.errors import InputError
from hexatherm.pipeline import ProcessResult


def twin_poses(result: ProcessResult, hexapod: Hexapod, source: str = ""
               ) -> npt.NDArray[np.float64]:
    """Twin-corrected pose (M, 6) of every target of ``result``, mm and deg.

    ``source`` names the hexapod file in error messages.
    """
    session = result.session
    if result.temperatures is None:
        raise InputError("the twin corrects from the thermocouple log: add 'temperatures: "
                         "temperatures.csv' to the session", path=str(session.path),
                         field="temperatures")
    if hexapod.legs is None:
        raise InputError("the twin needs the hexapod's leg model ('legs:')",
                         path=source or None, field="legs")
    try:
        effects = effects_from_dicts(hexapod.effects)
    except ValueError as exc:
        raise InputError(str(exc), path=source or None, field="thermal_model") from None
    temps = result.temperatures
    air = temps.others_C.get("air")
    if air is None and any(type(e).needs_air for e in effects):
        raise InputError("the thermal model's effects need the air temperature: the "
                         "temperatures have no 'air' column", path=temps.path, line=1,
                         field="air")
    log = ThermocoupleLog(temps.time_s, temps.legs_C, air)
    poses = twin_corrected(hexapod, session.plan, result.centres.times_s, log,
                           session.balls.centres_mm, result.registration.platform2cmm, effects)
    return poses[result.correction.target_index]
