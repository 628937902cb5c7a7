"""Quality checks of every step of a processed session (``OUT/quality.csv``).

One row per plan step; each check has a measured value (units in the column
name) and a pass/fail column ``ok_<check>``: ``True``, ``False``, or :data:`NA`
(``"na"``) where the check could not run (no sphere fit, not a target, no
temperature log); its value is then NaN (empty in ``quality.csv``). A check that
could not run does not fail, and it never reads "ok": the screen says ``n/a``.

==============  =========================  ===============================================
check           value                      fails when
==============  =========================  ===============================================
form            ``form_um``                largest sphere form error (max - min residual)
                                           of the step's balls > ``form_um``
diameter        ``diameter_dev_um``        fitted diameter - nominal (the ball of largest
                                           deviation, signed), ``|.|`` > ``diameter_dev_um``
distance        ``distance_dev_um``        measured - nominal inter-ball distance (the
                                           worst pair, signed), ``|.|`` > ``distance_dev_um``
registration    ``registration_rms_um``    registration RMS residual > ``registration_rms_um``
time_gap        ``time_gap_s``             a target's largest time to a reference it uses
                                           > ``time_gap_s``
temperature     ``temperature_change_C``   a target's largest leg temperature change to a
                                           reference it uses > ``temperature_change_C``
conditioning    ``jacobian_rcond``         reciprocal condition number of the Jacobian at a
                                           target's corrected pose (the FGM) < ``min_rcond``
growth          ``growth_excess_C``        with a temperature log, at a reference after R0:
                                           the largest temperature change a leg's growth
                                           since R0 needs beyond the span of the leg's
                                           logged temperatures (0 within it) >
                                           ``growth_margin_C``
warming         ``growth_warming_C``       at a reference after R0: the largest
                                           temperature change a leg's growth since R0
                                           needs > ``max_warming_C``
==============  =========================  ===============================================

The growth and warming checks name the leg in ``growth_leg`` and ``warming_leg`` (1 to
6): thermal growth is micrometres per kelvin
(:func:`hexatherm.core.plausibility.implied_warming_K`), so a reference measured a
millimetre away from its commanded pose reads as tens of kelvin.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from hexatherm.core.plan import known_indices
from hexatherm.core.plausibility import implied_warming_K, temperature_span_K
from hexatherm.core.registration import check_distances
from hexatherm.errors import HexathermError, InputWarning
from hexatherm.session import QUALITY_ALIASES, QualityLimits, Session
from hexatherm.typing import FloatArray
from hexatherm.workflows.process.measured import check_log_span, nominal_fit_diameter_mm
from hexatherm.workflows.process.pipeline import ProcessResult

__all__ = ["CHECKS", "NA", "QualityReport", "parse_threshold", "quality_checks"]

#: the ``ok_<check>`` entry of a check that could not run on a step
NA = "na"
#: the types of an ``ok_<check>`` entry where the check ran (its pass or fail)
_RAN = (bool, np.bool_)


#: check name -> (value column, threshold field, value must be at least the threshold)
CHECKS: dict[str, tuple[str, str, bool]] = {
    "form": ("form_um", "form_um", False),
    "diameter": ("diameter_dev_um", "diameter_dev_um", False),
    "distance": ("distance_dev_um", "distance_dev_um", False),
    "registration": ("registration_rms_um", "registration_rms_um", False),
    "time_gap": ("time_gap_s", "time_gap_s", False),
    "temperature": ("temperature_change_C", "temperature_change_C", False),
    "conditioning": ("jacobian_rcond", "min_rcond", True),
    "growth": ("growth_excess_C", "growth_margin_C", False),
    "warming": ("growth_warming_C", "max_warming_C", False),
}

#: check name -> the column that names where on the step it failed, and how
DETAILS: dict[str, tuple[str, str]] = {
    "growth": ("growth_leg", "leg {}"),
    "warming": ("warming_leg", "leg {}"),
}


@dataclass(frozen=True)
class QualityReport:
    """The quality checks of a session.

    Attributes
    ----------
    frame : pandas.DataFrame
        One row per step: ``label``, ``kind``, the values of :data:`CHECKS`,
        ``ok_<check>`` for each check (True, False or :data:`NA`), ``failed`` (the
        failed checks, ``;``-separated).
    thresholds : QualityLimits
    """

    frame: pd.DataFrame
    thresholds: QualityLimits

    def failing(self, check: str) -> pd.Series:
        """Whether ``check`` (a key of :data:`CHECKS`) failed at each step (boolean)."""
        # over the column's objects as a list (Series.map infers types per call: 20x slower)
        column = self.frame[f"ok_{check}"]
        failed = [ok is False for ok in column.tolist()]
        return pd.Series(failed, index=column.index, dtype=bool, name=column.name)

    def ran(self, check: str) -> pd.Series:
        """Whether ``check`` could run at each step (boolean)."""
        column = self.frame[f"ok_{check}"]
        return pd.Series(
            [type(ok) in _RAN for ok in column.tolist()],
            index=column.index,
            dtype=bool,
            name=column.name,
        )

    def ran_anywhere(self, check: str) -> bool:
        """Whether ``check`` could run at any step (asked up to the first step it ran at,
        not a flag per step)."""
        return any(type(ok) in _RAN for ok in self.frame[f"ok_{check}"].tolist())

    @property
    def failed_steps(self) -> list[str]:
        """Labels of the steps with a failed check."""
        return self.frame.loc[self.frame["failed"] != "", "label"].tolist()

    @property
    def any_failed(self) -> bool:
        """Whether any check failed on any step."""
        return bool((self.frame["failed"] != "").any())

    def failing_texts(self, check: str) -> list[str]:
        """Labels of the steps that failed ``check``, with where on the step
        (:data:`DETAILS`: ``R3 (leg 2)``)."""
        # the two columns it names, not the whole frame's rows (the screen asks each check)
        failing = self.failing(check)
        if not failing.any():
            return []
        labels = self.frame["label"][failing].astype(str).tolist()
        if check not in DETAILS:
            return labels
        column, text = DETAILS[check]
        return [
            f"{label} ({text.format(where)})" if where != "" else label
            for label, where in zip(labels, self.frame[column][failing].tolist(), strict=True)
        ]

    def summary(self) -> list[str]:
        """Screen lines: per check the worst value, its limit and the failing steps."""
        lines = []
        for check, (column, field, at_least) in CHECKS.items():
            values = self.frame[column].to_numpy(dtype=float)
            limit = getattr(self.thresholds, field)
            shown = values if at_least else np.abs(values)
            if np.all(np.isnan(shown)):
                worst_text = "n/a"
            else:
                worst = np.nanmin(shown) if at_least else np.nanmax(shown)
                worst_text = f"{worst:.4g}"
            failing = self.failing_texts(check)
            status = (
                "n/a (could not run: " + _why_not(check, self.frame) + ")"
                if not self.ran_anywhere(check)
                else "ok"
                if not failing
                else (
                    f"FAILED at {len(failing)} step(s): "
                    + ", ".join(failing[:5])
                    + (" ..." if len(failing) > 5 else "")
                )
            )
            sign = ">=" if at_least else "<="
            lines.append(
                f"  {check:<13} {column:<22} worst {worst_text:>9}  "
                f"(limit {sign} {limit:g})  {status}"
            )
        return lines


def _why_not(check: str, frame: pd.DataFrame) -> str:
    """Why a check ran on no step, in a few words."""
    if (
        check in ("time_gap", "temperature", "conditioning")
        and not (frame["kind"] == "target").any()
    ):
        return "no target"
    if check in ("growth", "warming") and (frame["kind"] == "reference").sum() < 2:
        return "no reference after R0"
    reasons = {
        "form": "no probed points, centres given as such",
        "diameter": "no fitted diameters, centres given as such",
        "temperature": "no thermocouple log in the session",
        "growth": "no thermocouple log in the session",
    }
    return reasons.get(check, "no value")


def parse_threshold(text: str) -> tuple[str, float]:
    """``NAME=VALUE`` -> ``(name, value)``, checked against :class:`QualityLimits`.

    >>> parse_threshold("form_um=5")
    ('form_um', 5.0)
    >>> parse_threshold("form=5")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    hexatherm.errors.HexathermError: --quality-threshold 'form=5': unknown name 'form'; ...
    """
    names = [f.name for f in dataclasses.fields(QualityLimits)]
    name, sep, value = text.partition("=")
    name = name.strip()
    factor = 1.0
    if name in QUALITY_ALIASES:
        name, factor = QUALITY_ALIASES[name]
    if not sep:
        raise HexathermError(
            f"--quality-threshold {text!r}: expected NAME=VALUE, NAME one of {', '.join(names)}"
        )
    if name not in names:
        raise HexathermError(
            f"--quality-threshold {text!r}: unknown name {name!r}; expected one "
            f"of {', '.join(names)}"
        )
    try:
        number = float(value)
    except ValueError:
        raise HexathermError(
            f"--quality-threshold {text!r}: {value.strip()!r} is not a number"
        ) from None
    if not number >= 0:
        raise HexathermError(
            f"--quality-threshold {text!r}: must be a number >= 0 (inf disables a limit)"
        )
    if name == "min_rcond" and number > 1:
        raise HexathermError(
            f"--quality-threshold {text!r}: a reciprocal condition number is at most 1, and "
            "a min_rcond above it fails every target (0 turns the check off)"
        )
    if factor != 1.0:
        warnings.warn(
            InputWarning(
                f"--quality-threshold {text!r}: a radius limit; read as {name}="
                f"{number * factor:g} (the check compares diameters now)"
            ),
            stacklevel=2,
        )
    return name, number * factor


def _signed_worst(values: FloatArray) -> FloatArray:
    """Per row the entry of largest magnitude, with its sign (NaN when all are NaN)."""
    mag = np.where(np.isnan(values), -1.0, np.abs(values))
    pick = np.take_along_axis(values, np.argmax(mag, axis=1)[:, None], axis=1)[:, 0]
    return np.where(np.isnan(values).all(axis=1), np.nan, pick)


def _row_max(values: FloatArray) -> FloatArray:
    """Per row the largest entry ignoring NaN (NaN when all are NaN)."""
    filled = np.where(np.isnan(values), -np.inf, values)
    return np.where(np.isnan(values).all(axis=1), np.nan, filled.max(axis=1))


def _ball_values(result: ProcessResult) -> tuple[FloatArray, FloatArray]:
    """Form error (um) and diameter deviation (um) of every step and ball (NaN: unknown)."""
    plan, balls = result.session.plan, result.session.balls
    # a repeated O or R0 (averaged into one step): the worst of its measurements
    step_names = [*plan.labels, *result.repeat_of]
    step_of = np.arange(len(step_names), dtype=np.intp)
    step_of[len(plan.labels) :] = known_indices(plan.labels, list(result.repeat_of.values()))
    nominal_mm = nominal_fit_diameter_mm(balls)
    shape = (len(plan.labels), len(balls.names))
    form, diameter = np.full(shape, np.nan), np.full(shape, np.nan)
    for rec in result.records:
        si = step_of[known_indices(step_names, rec.label)]
        bi = known_indices(balls.names, rec.ball)
        if "form_um" in rec.extra:
            values = pd.to_numeric(pd.Series(rec.extra["form_um"]), errors="coerce").to_numpy()
            np.fmax.at(form, (si, bi), values)
        if rec.diameter_mm is not None:
            dev = (rec.diameter_mm - nominal_mm[bi]) * 1e3
            cells = si * shape[1] + bi
            if np.isnan(diameter.ravel()[cells]).all() and np.unique(cells).size == cells.size:
                # each cell once and none set yet (one file, no repeats): the loop below
                # would set each to its value
                diameter[si, bi] = dev
                continue
            for i, j, value in zip(si, bi, dev, strict=True):
                if not abs(diameter[i, j]) >= abs(value):  # NaN or smaller: the worse one
                    diameter[i, j] = value
    return form, diameter


def _leg_temperatures(result: ProcessResult) -> FloatArray | None:
    """Thermocouple temperatures of the legs at every step's time, (N, 6), or None."""
    temps = result.temperatures
    if temps is None:
        return None
    t = result.centres.times_s
    check_log_span(t, result.session.plan.labels, temps)  # np.interp would hold the ends
    return np.column_stack([np.interp(t, temps.time_s, temps.legs_C[:, i]) for i in range(6)])


def growth_values(result: ProcessResult) -> dict[str, FloatArray | list[str]]:
    """The growth and warming checks' values of every step, and the legs they name.

    At every reference after R0 the growth of each leg since R0, ``q_R - q_R0`` (the
    correction's step 2), needs a temperature change of at least
    :func:`~hexatherm.core.plausibility.implied_warming_K`; ``growth_warming_C`` is the
    largest over the legs. With a thermocouple log the leg's temperature can have changed
    by at most the span of its logged temperatures from the log's start to the reference
    (:func:`~hexatherm.core.plausibility.temperature_span_K`: a leg lags its
    thermocouple but stays within what it went through): ``growth_excess_C`` is the
    largest need beyond that span (0 within it; NaN without a log). ``growth_leg`` and
    ``warming_leg`` name the leg (1 to 6) of each, ``""`` where a check does not apply
    (O, R0, targets, no log).
    """
    session = result.session
    plan, legs = session.plan, session.hexapod.legs
    n = len(plan.labels)
    excess, warming = np.full(n, np.nan), np.full(n, np.nan)
    growth_leg, warming_leg = [""] * n, [""] * n
    out: dict[str, FloatArray | list[str]] = {
        "growth_excess_C": excess,
        "growth_warming_C": warming,
        "growth_leg": growth_leg,
        "warming_leg": warming_leg,
    }
    refs = plan.reference_indices
    if legs is None or refs.size < 2:
        return out
    q = result.steps.q_mm
    later = refs[1:]
    needed = implied_warming_K(legs, q[later], q[later] - q[refs[0]])  # (n_refs - 1, 6)
    warming[later] = needed.max(axis=1)
    for i, j in zip(later, np.argmax(needed, axis=1), strict=True):
        warming_leg[i] = str(int(j) + 1)
    temps = result.temperatures
    if temps is not None:
        t = result.centres.times_s[later]
        check_log_span(t, [plan.labels[i] for i in later], temps)
        beyond = needed - temperature_span_K(temps.time_s, temps.legs_C, t)
        excess[later] = np.maximum(beyond.max(axis=1), 0.0)
        for i, j in zip(later, np.argmax(beyond, axis=1), strict=True):
            growth_leg[i] = str(int(j) + 1)
    return out


def session_thresholds(
    session: Session, overrides: Mapping[str, float] | None = None
) -> QualityLimits:
    """The limits for ``session``: the defaults, changed by the session file's
    ``quality:`` mapping, then by ``overrides`` (``--quality-threshold``)."""
    return QualityLimits(**{**session.quality, **(overrides or {})})


def ok_cells(bad: npt.NDArray[np.bool_], missing: npt.NDArray[np.bool_]) -> list[Any]:
    """A check's ``ok_`` cells: :data:`NA` where its value is missing, else whether it
    passed (Python bools), made by numpy (20,000 steps times nine checks)."""
    cells = np.array((~bad).tolist(), dtype=object)
    cells[missing] = NA
    return cells.tolist()


def quality_checks(result: ProcessResult, thresholds: QualityLimits | None = None) -> QualityReport:
    """Run every check of :data:`CHECKS` on every step of ``result``.

    ``thresholds`` defaults to the session's (:func:`session_thresholds`).
    """
    thresholds = thresholds or session_thresholds(result.session)
    session = result.session
    plan, balls, corr = session.plan, session.balls, result.correction
    n = len(plan.labels)
    targets = corr.target_index
    form, diameter = _ball_values(result)
    distances = check_distances(result.centres.centres_mm, balls.centres_mm, balls.names)
    values: dict[str, FloatArray] = {
        "form_um": _row_max(form),
        "diameter_dev_um": _signed_worst(diameter),
        "distance_dev_um": _signed_worst(distances.deviation_mm * 1e3),
        "registration_rms_um": np.asarray(result.registration.rms_um, dtype=float),
    }
    gap = np.full(n, np.nan)
    gap[targets] = _row_max(np.column_stack([corr.dt_before_s, corr.dt_after_s]))
    values["time_gap_s"] = gap
    change = np.full(n, np.nan)
    legs_c = _leg_temperatures(result)
    if legs_c is not None and targets.size:
        per_ref = []
        for ref in (corr.before_index, corr.after_index):
            diff = np.abs(legs_c[targets] - legs_c[np.maximum(ref, 0)]).max(axis=1)
            per_ref.append(np.where(ref >= 0, diff, np.nan))
        change[targets] = _row_max(np.column_stack(per_ref))
    values["temperature_change_C"] = change
    rcond = np.full(n, np.nan)
    if targets.size:
        sv = np.linalg.svd(session.hexapod.jacobian(corr.corrected), compute_uv=False)
        rcond[targets] = sv[:, -1] / sv[:, 0]
    values["jacobian_rcond"] = rcond
    growth = growth_values(result)
    values["growth_excess_C"] = np.asarray(growth["growth_excess_C"])
    values["growth_warming_C"] = np.asarray(growth["growth_warming_C"])

    legs = {name: growth[name] for name in ("growth_leg", "warming_leg")}
    frame = pd.DataFrame({"label": list(plan.labels), "kind": list(plan.kinds), **values, **legs})
    failed = [[] for _ in range(n)]  # type: list[list[str]]
    for check, (column, field, at_least) in CHECKS.items():
        value, limit = values[column], getattr(thresholds, field)
        missing = np.isnan(value)
        bad = ((value < limit) if at_least else (np.abs(value) > limit)) & ~missing
        frame[f"ok_{check}"] = ok_cells(bad, missing)
        for i in np.flatnonzero(bad):
            failed[i].append(check)
    frame["failed"] = [";".join(f) for f in failed]
    return QualityReport(frame, thresholds)
