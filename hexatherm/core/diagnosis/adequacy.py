"""Does the final model explain the data.

The noise floor, chi-square per degree of freedom, structure tests, where the residual shows.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hexatherm.core.diagnosis.model import Fit, Observations, rms_um
from hexatherm.core.effects import Effect
from hexatherm.core.geometry import invert_transform, pose_from_transform
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.ranktests import kruskal_wallis
from hexatherm.core.registration import register
from hexatherm.core.residuals import (
    LEG_NAMES,
    POSE_COMPONENTS,
    TIME_PARTS,
    PoseResiduals,
    spearman,
    summarize,
    time_blocks,
)
from hexatherm.typing import FloatArray


# ------------------------------------------------------------------ pose space
def pose_residuals(hexapod: Hexapod, obs: Observations, fit: Fit) -> PoseResiduals:
    """Residuals of ``fit`` in pose space (6 components) and leg space (through the IGM).

    Both the measured and the predicted centres of a step are registered to the
    balls, and the frames are expressed relative to the fitted frame O.
    """
    cmm2origin = invert_transform(fit.origin2cmm)
    measured = cmm2origin @ register(obs.centres_mm, obs.balls_mm).platform2cmm
    predicted = cmm2origin @ register(fit.predicted_mm, obs.balls_mm).platform2cmm
    pm = pose_from_transform(measured, hexapod.convention)
    pp = pose_from_transform(predicted, hexapod.convention)
    pose = pm - pp
    pose[:, 3:] = (pose[:, 3:] + 180.0) % 360.0 - 180.0
    pose = pose * np.array([1e3] * 3 + [np.pi / 180 * 1e6] * 3)
    legs = (hexapod.igm(pm) - hexapod.igm(pp)) * 1e3
    step_rms = np.sqrt(np.mean(fit.residual_mm**2, axis=(1, 2))) * 1e3
    return PoseResiduals(pose, legs, step_rms)


# ------------------------------------------------------------------ adequacy
#: the final RMS may exceed the noise floor by this factor before the model is inadequate
RMS_RATIO_LIMIT = 1.3


#: chi2/dof must exceed 1 by this many of its spreads (and by the RMS limit) to fail
CHI2_SIGMAS = 5.0


#: family-wise level of the structure tests (Bonferroni over all of them); strict because
#: their p-values assume independent residuals and the series overlap (pose and legs are
#: one residual seen twice): at 0.01, 1 of 20 null campaigns of 8 targets failed
STRUCTURE_ALPHA = 0.001


@dataclass(frozen=True)
class Finding:
    """A structure test of the residuals that fails (Bonferroni, family level 0.001).

    Attributes
    ----------
    series : str
        What was tested: a pose component (``"Rx"``), a leg (``"leg3"``), or
        ``"steps"`` (every step's mean square centre residual).
    test : str
        ``"autocorrelated"`` (Ljung-Box), ``"trend with time"`` (slope),
        ``"correlates with time"``, ``"correlates with temperature"`` (Spearman),
        ``"differs by step kind"`` (Kruskal-Wallis).
    statistic : float
        Q, t, rho or H.
    p_value : float
    """

    series: str
    test: str
    statistic: float
    p_value: float

    def text(self) -> str:
        symbol = {"autocorrelated": "Q", "trend with time": "t", "differs by step kind": "H"}
        name = symbol.get(self.test, "rho")
        return f"{self.series} {self.test} ({name} = {self.statistic:.3g}, p = {self.p_value:.1e})"


@dataclass(frozen=True)
class Adequacy:
    """Whether a fitted model explains the measurements down to their noise.

    Attributes
    ----------
    adequate : bool
        False when ``chi2_per_dof`` is beyond its limit, or ``final_rms_um`` above
        ``RMS_RATIO_LIMIT`` times the floor, or a structure test fails.
    chi2_per_dof, chi2_spread : float
        ``sum(r^2 / sigma^2) / dof`` over every centre residual value and its
        spread ``sqrt(2 / dof)`` (``sqrt(2/dof + 2/m)`` when sigma is estimated
        from ``m`` reference differences); ``dof = n - p``.
    chi2_limit : float
        ``max(RMS_RATIO_LIMIT^2, 1 + CHI2_SIGMAS chi2_spread)``.
    dof : int
    noise_floor_um : float
        RMS expected from noise alone (per centre and axis, um), the definition of
        the reported RMS: ``sqrt(mean(u^2))`` of the centre uncertainties when
        given, else estimated from consecutive references (:func:`noise_floor`).
    noise_floor_source : str
        ``"centre uncertainties"`` or ``"references"``.
    reference_floor_um : float
        The estimate from consecutive references (a cross-check; nan without two).
    final_rms_um : float
    unexplained_rms_um : float
        ``sqrt(max(0, final_rms^2 - floor^2))``.
    reasons : tuple of str
        Why inadequate, in words (empty when adequate).
    findings : tuple of Finding
        The failed structure tests, smallest p first.
    n_tests : int
        How many structure tests were made (the Bonferroni divisor).
    component_rms : ndarray, shape (6,)
        RMS of the pose residuals Tx, Ty, Tz (um), Rx, Ry, Rz (urad).
    kind_rms_um, kind_floor_um : dict of str to float
        RMS of the centre residuals, and its noise floor, by step kind.
    kind_count : dict of str to int
        Steps of each kind.
    part_rms_um, part_floor_um : ndarray, shape (TIME_PARTS,)
        The same by quarter of the session in time order.
    part_span_s : ndarray, shape (TIME_PARTS, 2)
    temperature_rho : float
        Spearman's rho of each step's mean square residual with the mean leg
        temperature.
    notes : tuple of str
        What the verdict rests on, when it is weaker than usual (no floor; centre
        uncertainties smaller than the references' scatter).
    """

    adequate: bool
    chi2_per_dof: float
    chi2_spread: float
    chi2_limit: float
    dof: int
    noise_floor_um: float
    noise_floor_source: str
    reference_floor_um: float
    final_rms_um: float
    unexplained_rms_um: float
    reasons: tuple[str, ...]
    findings: tuple[Finding, ...]
    n_tests: int
    component_rms: FloatArray
    kind_rms_um: dict[str, float]
    kind_floor_um: dict[str, float]
    kind_count: dict[str, int]
    part_rms_um: FloatArray
    part_floor_um: FloatArray
    part_span_s: FloatArray
    temperature_rho: float
    notes: tuple[str, ...] = ()

    def where(self) -> list[str]:
        """Where the unexplained part shows, in words: components, step kinds, time,
        temperature (the failed tests first)."""
        out = []
        comps = sorted({f.series for f in self.findings if f.series in POSE_COMPONENTS})
        legs = sorted({f.series for f in self.findings if f.series in LEG_NAMES})
        if comps:
            out.append(f"components {', '.join(comps)}")
        if legs:
            out.append(f"legs {', '.join(legs)}")
        # a kind of one or two steps (the origin) is too noisy to point at
        ratio = {
            k: v / self.kind_floor_um[k]
            for k, v in self.kind_rms_um.items()
            if self.kind_floor_um.get(k, 0) > 0 and self.kind_count.get(k, 0) >= 3
        }
        if ratio:
            kind = max(ratio, key=lambda k: ratio[k])
            out.append(
                f"{kind} steps ({self.kind_rms_um[kind]:.2f} um vs floor "
                f"{self.kind_floor_um[kind]:.2f} um)"
            )
        with np.errstate(invalid="ignore", divide="ignore"):
            part_ratio = self.part_rms_um / self.part_floor_um
        if np.any(np.isfinite(part_ratio)):
            q = int(np.nanargmax(part_ratio))
            t0 = float(np.nanmin(self.part_span_s))
            a, b = (self.part_span_s[q] - t0) / 3600.0
            out.append(
                f"quarter {q + 1} of the session ({a:.1f}-{b:.1f} h: "
                f"{self.part_rms_um[q]:.2f} um vs floor {self.part_floor_um[q]:.2f} um)"
            )
        temp = [f for f in self.findings if "temperature" in f.test]
        if temp:
            out.append("with temperature: " + ", ".join(f.series for f in temp))
        elif np.isfinite(self.temperature_rho):
            out.append(f"vs temperature rho = {self.temperature_rho:.2f} (steps' mean square)")
        return out

    def summary(self) -> str:
        """One line: the verdict with its numbers (and where, when inadequate)."""
        numbers = (
            f"final RMS {self.final_rms_um:.3f} um, noise floor {self.noise_floor_um:.3f} um "
            f"({self.noise_floor_source}), chi2/dof {self.chi2_per_dof:.2f} "
            f"(1 ± {self.chi2_spread:.2f}, limit {self.chi2_limit:.2f})"
        )
        notes = "".join(f"; note: {n}" for n in self.notes)
        if self.adequate:
            return f"ADEQUATE: the residual left is noise: {numbers}{notes}"
        size = (
            f"{self.unexplained_rms_um:.3f} um RMS is left unexplained"
            if np.isfinite(self.unexplained_rms_um)
            else "the residual is structured"
        )
        return (
            f"NOT ADEQUATE: {size} ({numbers}); because {'; '.join(self.reasons)}; "
            f"it shows in: {'; '.join(self.where())}{notes}"
        )


def noise_floor(obs: Observations, fit: Fit) -> tuple[float, int]:
    """Noise per centre and axis (um) from consecutive references, and the values used.

    The references are measured at one commanded pose a few minutes apart: the
    difference of the residuals of two consecutive ones (in time order) is noise
    (the CMM's and the hexapod's positioning) times sqrt(2), plus what an
    unexplained effect changes between them (little for slow thermal effects,
    nothing for pose-dependent ones; an approach-direction effect adds). Returns
    ``(sqrt(mean(d^2) / 2) * 1e3, d.size)``, nan and 0 with fewer than two
    references.
    """
    refs = np.flatnonzero(np.array([k == "reference" for k in obs.plan.kinds], dtype=bool))
    if refs.size < 2:
        return float("nan"), 0
    refs = refs[np.argsort(obs.times_s[refs], kind="stable")]
    d = np.diff(fit.residual_mm[refs], axis=0)
    return float(np.sqrt(np.mean(d**2) / 2.0) * 1e3), int(d.size)


def adequacy(hexapod: Hexapod, obs: Observations, fit: Fit) -> Adequacy:
    """The verdict on a fitted model: is what it leaves the measurements' noise?

    Three checks, each of which can fail it:

    1. **chi-square**: ``chi2/dof`` of the weighted centre residuals, expected
       ``1 ± sqrt(2/dof)``. It fails above ``max(1.3^2, 1 + 5 sqrt(2/dof))``: the
       centres' uncertainties of sphere fits leave out the hexapod's positioning
       noise and part of a cap fit's out-of-plane noise (issue 14, part 1), so an
       adequate model on simulated campaigns reads 1.3-1.4, far beyond the
       spread; the limit is the RMS limit below in weighted form.
    2. **RMS**: the final RMS above ``RMS_RATIO_LIMIT`` (1.3) times the noise floor.
    3. **structure**: any of the tests of the pose and leg residuals (whiteness,
       trend, correlation with time and with temperature, per series), of every
       step's mean square residual against time and temperature, and across
       step kinds (Kruskal-Wallis) below ``STRUCTURE_ALPHA / n_tests``.

    Without the centres' uncertainties (``obs.u_given`` False) sigma is the
    floor estimated from consecutive references (:func:`noise_floor`).
    """
    if fit.residual_mm.shape != obs.centres_mm.shape:
        raise ValueError("the fit's residuals must have the observations' shape")
    residual = fit.residual_mm
    dof = max(fit.n - fit.p, 1)
    ref_floor, m = noise_floor(obs, fit)
    final = rms_um(residual)
    if obs.u_given:
        floor, source = float(np.sqrt(np.mean(obs.u_mm**2)) * 1e3), "centre uncertainties"
        sigma_mm = obs.u_mm
        chi2 = float(np.sum((residual / sigma_mm[..., None]) ** 2)) / dof
        spread = float(np.sqrt(2.0 / dof))
    else:
        floor, source = ref_floor, "references"
        sigma_mm = np.full(obs.u_mm.shape, floor * 1e-3)
        chi2 = float(np.sum(residual**2) / (floor * 1e-3) ** 2) / dof if m else float("nan")
        spread = float(np.sqrt(2.0 / dof + 2.0 / m)) if m else float("nan")
    limit = max(RMS_RATIO_LIMIT**2, 1.0 + CHI2_SIGMAS * spread)
    unexplained = (
        float(np.sqrt(max(0.0, final**2 - floor**2))) if np.isfinite(floor) else float("nan")
    )
    notes = []
    if not np.isfinite(floor):
        notes.append(
            "the noise floor is unknown (no centre uncertainties and fewer than two "
            "references): only the structure tests are made"
        )
    elif obs.u_given and np.isfinite(ref_floor) and ref_floor > RMS_RATIO_LIMIT * floor:
        notes.append(
            f"consecutive references scatter by {ref_floor:.3f} um, more than the centres' "
            f"uncertainties ({floor:.3f} um): they may leave out noise (the hexapod's "
            "positioning, form errors), which the verdict then counts as unexplained"
        )

    res = pose_residuals(hexapod, obs, fit)
    kinds = list(obs.plan.kinds)
    temperature = obs.log.legs_at(obs.times_s)
    summary = summarize(res, obs.plan.labels, kinds, obs.times_s, temperature, n_worst=0)
    tests: list[Finding] = []
    for st in summary.tests:
        tests += [
            Finding(st.name, "autocorrelated", st.whiteness.q, st.whiteness.p_value),
            Finding(st.name, "trend with time", st.trend.t, st.trend.p_value),
            Finding(st.name, "correlates with time", st.vs_time.rho, st.vs_time.p_value),
            Finding(
                st.name,
                "correlates with temperature",
                st.vs_temperature.rho,
                st.vs_temperature.p_value,
            ),
        ]
    step_ms = np.mean((residual / sigma_mm[..., None]) ** 2, axis=(1, 2))
    vs_time = spearman(obs.times_s, step_ms)
    vs_temp = spearman(temperature.mean(axis=1), step_ms)
    tests += [
        Finding("steps", "correlates with time", vs_time.rho, vs_time.p_value),
        Finding("steps", "correlates with temperature", vs_temp.rho, vs_temp.p_value),
    ]
    groups = [step_ms[[k == kind for k in kinds]] for kind in sorted(set(kinds))]
    groups = [g for g in groups if g.size >= 2]
    if len(groups) >= 2 and np.ptp(step_ms) > 0:
        h, p = kruskal_wallis(groups)
        tests.append(Finding("steps", "differs by step kind", h, p))
    n_tests = len(tests)
    cut = STRUCTURE_ALPHA / max(n_tests, 1)
    findings = tuple(
        sorted(
            (f for f in tests if np.isfinite(f.p_value) and f.p_value < cut),
            key=lambda f: f.p_value,
        )
    )

    reasons = []
    if np.isfinite(chi2) and chi2 > limit:
        reasons.append(f"chi2/dof {chi2:.2f} is above {limit:.2f}")
    if np.isfinite(floor) and final > RMS_RATIO_LIMIT * floor:
        reasons.append(
            f"the final RMS is {final / floor:.2f}x the noise floor (limit {RMS_RATIO_LIMIT:g}x)"
        )
    if findings:
        reasons.append(f"{len(findings)} of {n_tests} structure tests fail")

    u2 = np.mean(sigma_mm**2, axis=1) * 1e6  # per step, um^2
    step_ms_um2 = np.mean(residual**2, axis=(1, 2)) * 1e6
    kind_floor = {}
    for kind in summary.kind_rms_um:
        sel = np.array([k == kind for k in kinds], dtype=bool)
        kind_floor[kind] = float(np.sqrt(np.mean(u2[sel])))
    blocks = time_blocks(obs.times_s, TIME_PARTS)
    part_rms = np.full(TIME_PARTS, np.nan)
    part_floor = np.full(TIME_PARTS, np.nan)
    for b in range(TIME_PARTS):
        sel = blocks == b
        if sel.any():
            part_rms[b] = np.sqrt(np.mean(step_ms_um2[sel]))
            part_floor[b] = np.sqrt(np.mean(u2[sel]))
    return Adequacy(
        adequate=not reasons,
        chi2_per_dof=chi2,
        chi2_spread=spread,
        chi2_limit=limit,
        dof=dof,
        noise_floor_um=floor,
        noise_floor_source=source,
        reference_floor_um=ref_floor,
        final_rms_um=final,
        unexplained_rms_um=unexplained,
        reasons=tuple(reasons),
        findings=findings,
        n_tests=n_tests,
        component_rms=summary.component_rms,
        kind_rms_um=dict(summary.kind_rms_um),
        kind_floor_um=kind_floor,
        kind_count=dict(summary.kind_count),
        part_rms_um=part_rms,
        part_floor_um=part_floor,
        part_span_s=summary.part_span_s,
        temperature_rho=vs_temp.rho,
        notes=tuple(notes),
    )


def bound_flags(effect: Effect, unseen: Sequence[str] = ()) -> tuple[str, ...]:
    """Parameters of a fitted effect at a bound of their range, or outside it.

    ``unseen`` (a :class:`Fit`'s ``unseen`` of the effect) are the parameters the data
    do not see: they kept their start value, wherever that lies, and are not flagged.
    """
    flags = [f"{p}: {why}" for p, why in effect.out_of_range().items() if p not in unseen]
    note = _bound_note(effect, unseen, blind_note=False)
    return tuple(flags + ([note] if note else []))


def _bound_note(effect: Effect, unseen: Sequence[str] = (), blind_note: bool = True) -> str:
    """What is noteworthy of a fitted effect's parameters: those at a bound of their
    range, and (with ``blind_note``) the ``unseen`` ones, which have no effect on these
    data and kept their start value (not identifiable: not a bound)."""
    notes = []
    for p, (lo, hi) in zip(effect.parameters, effect.ranges, strict=True):
        value = effect.values[p]
        if p in unseen:
            if blind_note:
                notes.append(
                    f"{p} has no effect on these data (not identifiable: kept at its start "
                    f"value {value:g})"
                )
        elif effect.at_bound(p):
            notes.append(f"{p} at the bound of its range [{lo:g}, {hi:g}]")
    return "; ".join(notes)
