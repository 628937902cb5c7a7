"""The diagnosis's fast paths against a second method (issue 26): the stacked twin runs
(:class:`TwinRuns`) against ``predict`` one set at a time, the FGM from a kept first
iteration against the FGM from the start poses, the rows' registration against
``register`` row by row, the batched placements against one by one, the lag from the
log's kept grid against ``first_order_lag``, the held-out folds refitted side by side
against one by one. The same operations on the same numbers, so the same results to
rounding: numpy's matmul, einsum and LAPACK pick their kernels (and the order in which
they add) by the arrays' shapes and the CPU's SIMD, so a stack and one set alone may
differ in the last bits on some CPUs (:func:`same_to_rounding`); the log's kept grid
is the same shapes, to the bit."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

import hexatherm.core.diagnosis.fitting as fitting
from hexatherm.core.diagnosis import place, twin_centres, twins
from hexatherm.core.diagnosis.model import place_many
from hexatherm.core.diagnosis.twins import TwinRuns
from hexatherm.core.effects import EFFECTS, Effect, first_order_lag, make_effect
from hexatherm.core.hexapod import Hexapod
from hexatherm.core.registration import register, rigid_rows
from hexatherm.core.residuals import time_blocks
from hexatherm.errors import ConvergenceError
from hexatherm.workflows.diagnose.run import SessionData, read_for_diagnosis
from hexatherm.workflows.simulate.campaigns import NOMINAL_HIDDEN, diagnosis_campaign
from hexatherm.workflows.simulate.twinsession import write_twin_session

#: centres, poses and transforms from a stack against one by one: coordinates up to
#: about 1000 mm (spacing 1.1e-13 mm), through a few Newton steps and registrations;
#: 1e-10 (mm, deg, or a rotation's entries) keeps a factor of 1000 over that rounding
#: and is a million times below a CMM's 0.1 um
ROUNDING = 1e-10


def same_to_rounding(a: np.ndarray, b: np.ndarray, atol: float = ROUNDING) -> None:
    """``a`` and ``b`` equal but for rounding (see the module's docstring)."""
    np.testing.assert_allclose(a, b, rtol=0, atol=atol)


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> SessionData:
    folder = tmp_path_factory.mktemp("twins") / "lag"
    hidden = (make_effect("leg_thermal_lag", NOMINAL_HIDDEN["leg_thermal_lag"]),)
    write_twin_session(diagnosis_campaign(hidden, 5, n_targets=4), folder)
    return read_for_diagnosis(folder)


def _runs(data: SessionData) -> TwinRuns:
    obs = data.observations
    return TwinRuns(data.hexapod, obs.plan, obs.times_s, obs.log, obs.balls_mm)


def _count_stacks(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The size of each stack of parameter sets TwinRuns runs from now on (a list that
    fills as they run)."""
    stacks: list[int] = []
    real = TwinRuns.centres

    def counted(self: TwinRuns, sets: list[tuple[Effect, ...]]) -> list[np.ndarray]:
        stacks.append(len(sets))
        return real(self, sets)

    monkeypatch.setattr(TwinRuns, "centres", counted)
    return stacks


def _every_effect() -> list[tuple[Effect, ...]]:
    """No effect, each registered effect away from its start values, and a pair."""
    sets: list[tuple[Effect, ...]] = [()]
    for cls in EFFECTS.values():
        values = cls.start_values()[0] + 0.3 * cls.scales()
        sets.append((cls.from_vector(values.tolist()),))
    sets.append((sets[1][0], sets[-1][0]))
    return sets


def test_stacked_twin_runs_are_predict_one_set_at_a_time(data: SessionData) -> None:
    sets = _every_effect()
    assert any(type(s[0]).base_joints_mm is not Effect.base_joints_mm for s in sets if s)
    stacked = _runs(data).centres(sets)
    for effects, centres in zip(sets, stacked, strict=True):
        alone = twin_centres(data.hexapod, data.observations, effects)  # predict
        same_to_rounding(centres, alone)
    one = twin_centres(data.hexapod, data.observations, sets[1], _runs(data))
    same_to_rounding(one, stacked[1])
    # without an effect that moves the balls per step, the frames apply in one stack
    still = [
        s for s in sets if all(type(e).ball_positions_mm is Effect.ball_positions_mm for e in s)
    ]
    assert len(still) < len(sets)
    for effects, centres in zip(still, _runs(data).centres(still), strict=True):
        same_to_rounding(centres, twin_centres(data.hexapod, data.observations, effects))


def test_the_fgm_from_a_kept_first_iteration_is_the_fgm_from_the_start(
    data: SessionData,
) -> None:
    hexapod, poses = data.hexapod, data.observations.plan.poses
    rng = np.random.default_rng(4)
    legs = [hexapod.igm(poses) + rng.normal(scale=0.05, size=(len(poses), 6)) for _ in range(3)]
    start = hexapod.fgm_start(poses)
    stacked = hexapod.fgm(np.concatenate(legs), start=start)
    for k, q in enumerate(legs):
        cold = hexapod.fgm(q, initial_poses=poses)
        same_to_rounding(stacked[k * len(poses) : (k + 1) * len(poses)], cold)
        assert np.abs(hexapod.igm(cold) - q).max() <= 1e-10
    with pytest.raises(ValueError, match="start"):
        hexapod.fgm(legs[0][:-1], start=start)


def test_rows_registered_together_are_register_row_by_row() -> None:
    rng = np.random.default_rng(5)
    measured = rng.normal(scale=100.0, size=(1, 60, 3))
    twins = measured[0] + rng.normal(scale=0.01, size=(4, 60, 3)) + [0.5, -0.2, 0.1]
    weights = rng.uniform(0.2, 3.0, size=60)
    rows = rigid_rows(measured, twins, weights)
    for k in range(4):
        alone = register(measured, twins[k], weights[None]).platform2cmm[0]
        same_to_rounding(rows[k], alone)


def test_batched_placements_are_one_by_one(data: SessionData) -> None:
    obs = data.observations
    drift = EFFECTS["cmm_drift"]
    sets = [(), (drift.from_vector((np.ones(len(drift.parameters)) * 3.0).tolist()),)]
    ys = [twin_centres(data.hexapod, obs, s) for s in sets]
    mask = np.arange(obs.n_steps) % 3 != 0
    together = place_many(ys, obs, sets, mask)
    for y, effects, (origin2cmm, predicted) in zip(ys, sets, together, strict=True):
        c_alone, p_alone = place(y, obs, effects, mask)
        same_to_rounding(origin2cmm, c_alone)
        same_to_rounding(predicted, p_alone)


def test_a_jacobian_runs_its_columns_twins_together_and_equals_one_by_one(
    data: SessionData, monkeypatch: pytest.MonkeyPatch
) -> None:
    obs, cls = data.observations, EFFECTS["leg_thermal_lag"]
    every = np.ones(obs.n_steps, dtype=bool)
    theta = cls.start_values()[0]
    runs = _runs(data)
    stacks = _count_stacks(monkeypatch)
    jac = fitting._Problem(data.hexapod, obs, (), [cls], runs).jacobian(theta, every)
    assert stacks == [1 + theta.size]  # theta and every column: one stacked run

    # one by one with predict's twin: the same Jacobian, to rounding: forward differences
    # divide the residuals' rounding (ROUNDING mm over sigma's micrometres) by their step
    # (1e-3 of a scale), hence the bound relative to the Jacobian's largest entry
    class OneByOne(fitting._Problem):
        def prepare(self, thetas: Sequence[np.ndarray], mask: np.ndarray) -> None:
            for t in thetas:
                key = (np.asarray(t, dtype=float).tobytes(), np.asarray(mask).tobytes())
                effects = self.effects(t)
                centres = twin_centres(self.hexapod, self.obs, effects)
                origin2cmm, predicted = place(centres, self.obs, effects, mask)
                self._placed[key] = (origin2cmm, predicted, self.obs.centres_mm - predicted)

    slow = OneByOne(data.hexapod, obs, (), [cls], runs).jacobian(theta, every)
    same_to_rounding(jac, slow, atol=1e-6 * np.abs(jac).max())
    assert np.all(np.linalg.norm(jac, axis=0) > 0)


def test_the_lag_from_the_logs_kept_grid_is_first_order_lag(data: SessionData) -> None:
    log = data.observations.log
    times = np.concatenate([[log.t0_s], data.observations.times_s])
    grid = log.lag_grid(times)
    assert log.lag_grid(times) is grid  # kept for these times
    for tau in (5.0, 600.0, 86400.0):
        effect = EFFECTS["leg_thermal_lag"].from_vector([tau])
        lagged = effect.leg_temperature_C(log.legs_at(times), times, log)
        assert np.array_equal(lagged, first_order_lag(log.times_s, log.legs_C, tau, times))
    assert log.lag_grid(times[:-1]) is not grid
    with pytest.raises(ValueError, match="time constant"):
        grid.at(0.0)


def test_the_folds_refitted_side_by_side_are_refitted_one_by_one(data: SessionData) -> None:
    obs, cls = data.observations, EFFECTS["leg_thermal_lag"]
    blocks = time_blocks(obs.times_s, 6)
    trains = [blocks % 2 == parity for parity in (0, 1)]
    theta = np.array([NOMINAL_HIDDEN["leg_thermal_lag"]["tau_s"] * 1.3])
    together = fitting._Problem(data.hexapod, obs, (), [cls], _runs(data)).refit(theta, trains)
    for train, refitted in zip(trains, together, strict=True):
        alone = fitting._Problem(data.hexapod, obs, (), [cls]).refit(theta, [train])[0]
        same_to_rounding(refitted, alone, atol=1e-6 * np.abs(theta).max())
        assert abs(refitted[0] - theta[0]) > 1.0  # the chord iterations moved it


def test_stacked_runs_refuse_and_accept_what_predict_does(data: SessionData) -> None:
    """Legs beyond the stroke: predict starts from the commanded poses and so does not
    refuse them, nor does a stack; a twin that cannot be solved raises predict's error,
    naming the step (not its place in the stack)."""
    obs, cls = data.observations, EFFECTS["leg_offset"]
    beyond = (cls.from_vector([50.0, 0, 0, 0, 0, 0]),)  # leg 1 beyond the stroke
    assert data.hexapod.stroke_mm is not None
    stacked = _runs(data).centres([(), beyond])
    same_to_rounding(stacked[1], twin_centres(data.hexapod, obs, beyond))
    lost = (cls.from_vector([150.0, 0, 0, 0, 0, 0]),)  # no pose has these legs
    with pytest.raises(ConvergenceError) as alone:
        twin_centres(data.hexapod, obs, lost)
    with pytest.raises(ConvergenceError) as together:
        _runs(data).centres([(), lost])
    assert str(together.value) == str(alone.value)


def test_candidates_held_out_side_by_side_are_held_out_one_by_one(
    data: SessionData, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A round's held-out refits run every candidate together: four stacked twin runs
    whatever the number of candidates (one by one: four each); the RMS the same, to
    rounding, as each candidate alone."""
    obs = data.observations
    blocks = time_blocks(obs.times_s, 6)
    names = ["leg_thermal_lag", "leg_offset", "leg_cte_error"]
    thetas = [EFFECTS[name].start_values()[0] + 0.2 * EFFECTS[name].scales() for name in names]
    alone = [
        fitting.heldout_rms_um(fitting._Problem(data.hexapod, obs, (), [EFFECTS[n]]), t, blocks)
        for n, t in zip(names, thetas, strict=True)
    ]
    runs = _runs(data)
    problems = [fitting._Problem(data.hexapod, obs, (), [EFFECTS[n]], runs) for n in names]
    stacks = _count_stacks(monkeypatch)
    together = fitting.heldout_rms_many(list(zip(problems, thetas, strict=True)), blocks)
    np.testing.assert_allclose(together, alone, rtol=1e-9)
    # the Jacobians; the second and third chord iterations and the refitted values (the
    # first starts where the Jacobians are): each both folds of every candidate
    assert stacks == [sum(1 + t.size for t in thetas)] + [2 * len(names)] * 3


def test_stacks_split_at_their_size_limit_are_the_same(
    data: SessionData, monkeypatch: pytest.MonkeyPatch
) -> None:
    sets = _every_effect()
    whole = _runs(data).centres(sets)
    monkeypatch.setattr(twins, "MAX_STACKED_POSES", 2 * data.observations.n_steps)
    calls: list[int] = []
    real = Hexapod.fgm

    def counted(self: Hexapod, q: np.ndarray, *args: object, **kwargs: object) -> np.ndarray:
        calls.append(len(q))
        return real(self, q, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Hexapod, "fgm", counted)
    split = _runs(data).centres(sets)
    assert max(calls) == 2 * data.observations.n_steps < len(sets) * data.observations.n_steps
    for a, b in zip(whole, split, strict=True):
        same_to_rounding(a, b)
