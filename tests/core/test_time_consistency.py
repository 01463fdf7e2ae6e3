"""Time consistency: trust is defined per second (docs/concepts/time-consistency.md;
docs/concepts/reading-the-paper.md, "The time step outside lock-step")."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import numpy as np
import pytest
from support.closed_loop import shipped_trace
from support.trust_reference import propagate_trust

from preceding_traffic.traces import truncate
from trust_av.system.closed_loop import SimResult, control_trace, simulate
from trust_av.system.config import load_run_config
from trust_av.system.metrics import (
    compute_metrics,
    expectation_errors,
    explicability_by_age,
    step_change_rms_mps2,
    ticks_per_model_step,
)
from trust_av_common.grids import hold_at, interp_at
from trust_av_common.kinematics import rollout
from trust_av_planner.nmpc import TrustAwareNmpc, prediction_grid
from trust_av_planner.predictors import Observation
from trust_av_planner.predictors.ca import ConstantAccelerationPredictor
from trust_av_planner.predictors.sampling import ModelGridPredictor
from trust_av_planner.preview import LeadPreview, hold_on_grid
from trust_monitor.paper_trust import (
    TrustConfig,
    TrustEstimator,
    paper_explicability_bound,
    performance,
    trust_input,
    trust_step,
)

CONFIG = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                     trust_initial=0.0)


@pytest.mark.parametrize('score', [0.0, 0.01, 0.1, math.atanh(0.2) + 1e-6, 0.6])
def test_one_second_step_is_exactly_eq_10(score: float) -> None:
    """T + delta * 1 s * u_T is bit for bit the paper's T + delta * u_T."""
    paper = 2.5 + 0.1 * trust_input(performance(score), 0.8)
    assert trust_step(2.5, score, CONFIG, 1.0) == paper
    assert trust_step(2.5, score, CONFIG) == paper


@pytest.mark.parametrize('rate_hz', [2, 10, 50])
def test_trust_per_second_does_not_depend_on_the_rate(rate_hz: int) -> None:
    """The same E held for 1 s gives the same trust whether updated once or rate_hz times."""
    estimator = TrustEstimator(CONFIG)
    for _ in range(rate_hz):
        estimator.step([0.3, 0.2, 0.1], [0.0, 0.0, 0.0], dt_s=1.0 / rate_hz)
    once = TrustEstimator(CONFIG)
    once.step([0.3, 0.2, 0.1], [0.0, 0.0, 0.0], dt_s=1.0)
    assert estimator.trust == pytest.approx(once.trust, rel=1e-12)
    assert once.trust > 0.0


def test_estimator_refuses_negative_time() -> None:
    with pytest.raises(ValueError, match='dt_s'):
        TrustEstimator(CONFIG).step([0.0], [0.0], dt_s=-0.1)


@pytest.mark.parametrize('trust', [-0.02, -0.005, 0.0, 0.003, 0.05, 3.0])
@pytest.mark.parametrize('trust_min', [0.0, 0.2])
def test_bound_on_a_fine_grid_is_the_propagated_per_second_rule(trust: float,
                                                                trust_min: float) -> None:
    """E <= E_max exactly when every T^k >= T_min on a 0.1 s grid of 30 steps."""
    bound = paper_explicability_bound(trust, trust_min, CONFIG, 30, 0.1)
    for score in np.linspace(0.0, 0.999, 1500):
        propagated_ok = min(propagate_trust(trust, float(score), CONFIG, 30, 0.1)) >= trust_min
        bound_ok = bound is not None and score <= bound
        if abs(score - (bound or 0.0)) > 1e-9:
            assert propagated_ok == bound_ok, (trust, trust_min, score, bound)


def test_bound_over_the_same_seconds_agrees_when_trust_is_above_t_min() -> None:
    """Above T_min only the end of the horizon matters: 3 s is 3 s on either grid."""
    for trust in (0.2, 0.21, 0.25, 3.0):
        assert paper_explicability_bound(trust, 0.2, CONFIG, 30, 0.1) == pytest.approx(
            paper_explicability_bound(trust, 0.2, CONFIG, 3, 1.0), rel=1e-12)


# --- the prediction grid and the NMPC at 10 Hz ---------------------------------------------

def _planner(run_config, **changes):  # type: ignore[no-untyped-def]
    return dataclasses.replace(run_config.planner, speed_max_mps=30.0, **changes)


def test_prediction_grid_is_the_paper_at_1_hz_and_the_period_at_10_hz(run_config) -> None:  # type: ignore[no-untyped-def]
    planner = _planner(run_config)
    assert prediction_grid(planner) == (1.0, 3)
    assert prediction_grid(planner, 1.0) == (1.0, 3)
    assert prediction_grid(planner, 0.1) == (0.1, 30)
    assert prediction_grid(_planner(run_config, prediction_grid='model_step'), 0.1) == (1.0, 3)
    with pytest.raises(ValueError, match='steps'):
        prediction_grid(planner, 0.001)


def test_near_standstill_the_1_s_prediction_loses_the_gap_the_period_grid_does_not(
        run_config) -> None:  # type: ignore[no-untyped-def]
    """Creeping at 0.1 m/s 2 cm beyond d_s behind a stopped lead: the 1 s grid predicts
    4.92 m at k = 1 whatever the plan (so its gap bound is relaxed to that, and it says so);
    the 0.1 s grid brakes in time and keeps d_s."""
    planner = _planner(run_config)
    coarse = TrustAwareNmpc(planner, run_config.trust)
    result = coarse.step(5.02, 0.1, np.zeros(3), np.zeros(3), 5.0)
    assert result.success and 'relaxed' in result.status, result.status
    assert min(rollout(5.02, 0.1, [0.0] * 3, result.plan_mps2.tolist(), 1.0)[0]) < 4.93
    fine = TrustAwareNmpc(planner, run_config.trust, 0.1)
    result = fine.step(5.02, 0.1, np.zeros(30), np.zeros(30), 5.0)
    assert result.success and 'relaxed' not in result.status, result.status
    gaps, speeds = rollout(5.02, 0.1, [0.0] * 30, result.plan_mps2.tolist(), 0.1)
    assert min(gaps) >= 5.0 - 1e-6 and min(speeds) >= -1e-9


def test_standstill_corner_on_the_fine_grid_is_solved(run_config) -> None:  # type: ignore[no-untyped-def]
    """Stopped at d_s behind a stopped lead that starts to move after 1 s: every gap and speed
    bound of the first second pins u = 0 from both sides (the case qrqp stalled on for
    20-300 ms at N = 30)."""
    nmpc = TrustAwareNmpc(_planner(run_config), run_config.trust, 0.1)
    lead = np.concatenate([np.zeros(10), np.linspace(0.1, 2.0, 20)])
    for expected in (np.zeros(30), np.full(30, 1e-18)):
        result = nmpc.step(5.0, 0.0, lead, expected, 0.4)
        assert result.success, result.status
        assert np.allclose(result.plan_mps2[:9], 0.0, atol=1e-6)


@pytest.mark.parametrize('period_s', [0.1, None])
@pytest.mark.parametrize('short_m', [1.9e-7, 0.06])
def test_stopped_short_of_d_s_is_planned_not_a_fallback(run_config, period_s: float | None,  # type: ignore[no-untyped-def]
                                                        short_m: float) -> None:
    """Stopped short of d_s behind a stopped lead that moves off after 2.5 s: by a rounding
    error (a 10 Hz NYCC run crept 1e-7 m/s), or by 6 cm (US06 with a constant-speed preview).
    No plan can restore d_s at once, so the gap bound is what the hardest braking keeps (the
    gap now) and the NMPC plans on; the strict bound made every solve of the stop fail (28 and
    127 fallbacks)."""
    nmpc = TrustAwareNmpc(_planner(run_config), run_config.trust, period_s)
    n = nmpc.steps
    lead = np.clip(0.45 * (np.arange(n) * nmpc.grid_step_s - 2.5), 0.0, None)
    start = 5.0 - short_m
    result = nmpc.step(start, 0.0, lead, np.full(n, -1.6e-8), 49.0)
    assert result.success, result.status
    assert result.gap_bounds_relaxed == (short_m > 1e-6)  # a rounding error is not reported
    gaps, speeds = rollout(start, 0.0, lead.tolist(), result.plan_mps2.tolist(), nmpc.grid_step_s)
    assert min(gaps) >= start - 1e-6 and min(speeds) >= -1e-6  # the bound check's tolerance


@pytest.mark.parametrize('period_s', [0.1, None])
def test_outside_the_gap_bounds_the_nmpc_takes_the_hardest_way_back(  # type: ignore[no-untyped-def]
        run_config, period_s: float | None) -> None:
    """A cut-in 3 m ahead closing at 5 m/s: the plan brakes as hard as it may first (anything
    else ends closer than braking does); a lead 80 m ahead (beyond d_max = 60 m): it
    accelerates as hard as it may. Both planned, not fallbacks; within d_min..d_max the
    bounds are untouched."""
    config = _planner(run_config)
    nmpc = TrustAwareNmpc(config, run_config.trust, period_s)
    n = nmpc.steps
    cut_in = nmpc.step(3.0, 15.0, np.full(n, 10.0), np.zeros(n), 49.0)
    assert cut_in.success and cut_in.gap_bounds_relaxed, cut_in.status
    assert cut_in.plan_mps2[0] == pytest.approx(config.accel_min_mps2, abs=1e-6)
    far = nmpc.step(80.0, 10.0, np.full(n, 10.0), np.zeros(n), 49.0)
    assert far.success and far.gap_bounds_relaxed and 'relaxed' in far.status, far.status
    assert far.plan_mps2[0] == pytest.approx(config.accel_max_mps2, abs=1e-6)
    normal = nmpc.step(30.0, 10.0, np.full(n, 10.0), np.zeros(n), 49.0)
    assert normal.success and not normal.gap_bounds_relaxed, normal.status


# --- grids, samples and previews ------------------------------------------------------------

def test_hold_and_interp_on_another_grid() -> None:
    plan = np.array([1.0, 2.0, 3.0])
    assert hold_at(np.array([0.0, 1.0, 2.0]), plan, 1.0, 3).tolist() == plan.tolist()
    held = hold_at(np.array([0.0, 1.0, 2.0]), plan, 0.1, 30)
    assert held[:10].tolist() == [1.0] * 10 and held[10:20].tolist() == [2.0] * 10
    assert held[29] == 3.0
    assert hold_on_grid(plan, 1.0, 0.5, 4, offset_s=0.5).tolist() == [1.0, 2.0, 2.0, 3.0]
    assert interp_at(np.array([0.0, 1.0]), np.array([0.0, 2.0]), 0.25, 5).tolist() == [
        0.0, 0.5, 1.0, 1.5, 2.0]
    with pytest.raises(ValueError, match='increase'):
        hold_at(np.array([1.0, 0.0]), np.array([1.0, 2.0]), 0.1, 3)


def test_estimator_sees_aligned_1_s_samples_at_10_hz() -> None:
    """Ticks of 0.1 s: the CA estimator gets the mean acceleration of the last whole second."""
    sampler = ModelGridPredictor(ConstantAccelerationPredictor(3, -3.0, 3.0), 1.0, 1)
    assert sampler.predict(0.0)[0].tolist() == [0.0, 0.0, 0.0]
    for k in range(1, 26):
        accel = 1.0 if k <= 10 else (0.0 if k <= 15 else 2.0)  # applied over ((k-1)/10, k/10]
        seen = Observation(gap_m=10.0, relative_speed_mps=0.0, time_headway_s=1.0,
                           av_accel_mps2=accel)
        sampler.observe(seen, k / 10, 0.1)
        if k == 9:  # not a whole second of history yet
            assert sampler.predict(0.9)[0].tolist() == [0.0, 0.0, 0.0]
        if k == 13:  # the second (0, 1]: all 1.0, held until t = 2
            plan, age = sampler.predict(1.3)
            assert plan.tolist() == pytest.approx([1.0] * 3) and age == pytest.approx(0.3)
    plan, age = sampler.predict(2.5)
    assert age == pytest.approx(0.5)
    assert plan.tolist() == pytest.approx([1.0] * 3)  # mean over (1, 2]: 5 x 0 + 5 x 2 = 1


def test_lead_preview_from_odometry() -> None:
    speed = LeadPreview('constant_speed', 1.0)
    speed.observe(0.0, 10.0)
    assert speed.preview(0.1, 3).tolist() == [10.0, 10.0, 10.0]
    accel = LeadPreview('constant_acceleration', 1.0)
    for k in range(21):
        accel.observe(k / 10, 10.0 - 2.0 * k / 10)  # braking at 2 m/s^2
    assert accel.acceleration_mps2() == pytest.approx(-2.0)
    preview = accel.preview(1.0, 6)
    assert preview.tolist() == pytest.approx([6.0, 4.0, 2.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match='no lead'):
        LeadPreview('constant_speed', 1.0).preview(0.1, 3)


def test_rate_diagnostics_on_known_records(run_config) -> None:  # type: ignore[no-untyped-def]
    """1 s means of the executed acceleration and E by the expectation's age, by hand."""
    config = load_run_config(overrides={'preceding_traffic': {'trace': 'us06'}})
    base = simulate(config, truncate(control_trace(config, 10.0), 2)).records[0]
    accels = [1.0] * 10 + [0.0] * 5 + [2.0] * 5 + [4.0] * 10 + [9.0] * 3  # 3 whole seconds
    records = [dataclasses.replace(base, av_accel_mps2=a, explicability=0.1 * (k % 10) + k)
               for k, a in enumerate(accels)]
    assert step_change_rms_mps2(records, 10) == pytest.approx(math.sqrt((0.0 + 9.0) / 2))
    assert step_change_rms_mps2(records[9:12], 1) == pytest.approx(math.sqrt(1.0 / 2))
    by_age = explicability_by_age(records[:30], 10)
    assert by_age.tolist() == pytest.approx([0.1 * j + 10 + j for j in range(10)])
    assert ticks_per_model_step(0.1, 1.0) == 10 and ticks_per_model_step(1.0, 1.0) == 1
    with pytest.raises(ValueError, match='whole number'):
        ticks_per_model_step(0.3, 1.0)
    with pytest.raises(ValueError, match='two model steps'):
        step_change_rms_mps2(records[:15], 10)


def test_rmse_compares_each_expected_value_at_its_own_time() -> None:
    """At 10 Hz a plan on the 1 s grid (``prediction_grid: model_step``) is compared with the
    command executed 1 s, 2 s later, not 0.1 s, 0.2 s later: an expectation that is exactly
    what the AV then did scores 0, and the loop's RMSE uses the plans' own grid."""
    config = load_run_config(overrides={'preceding_traffic': {'trace': 'us06'}})
    base = simulate(config, truncate(control_trace(config, 10.0), 2)).records[0]
    accel = [math.sin(0.37 * k) for k in range(60)]
    records = [dataclasses.replace(
        base, t_s=0.1 * k, av_accel_mps2=a,
        expected_plan_mps2=tuple(accel[min(k + 10 * j, 59)] for j in range(3)))
        for k, a in enumerate(accel)]
    assert compute_metrics(records, 4.0, plan_step_s=1.0).rmse_mps2 == 0.0
    assert compute_metrics(records, 4.0).rmse_mps2 > 0.3  # read on the 0.1 s grid: wrong
    assert expectation_errors(records, 1.0).size == sum(min(3, (59 - k) // 10 + 1)
                                                        for k in range(60))
    with pytest.raises(ValueError, match='whole number'):
        expectation_errors(records, 0.25)
    stepped = simulate(load_run_config(overrides={
        'planner': {'prediction_grid': 'model_step'}, 'preceding_traffic': {'trace': 'us06'}}),
        truncate(control_trace(config, 10.0), 50))
    assert stepped.plan_step_s == 1.0
    assert stepped.metrics.rmse_mps2 == pytest.approx(math.sqrt(np.mean(np.square(
        expectation_errors(stepped.records, 1.0)))))
    assert simulate(config, truncate(control_trace(config, 10.0), 5)).plan_step_s is None


# --- the closed loop at 1 Hz and 10 Hz ------------------------------------------------------

WINDOW_S = 60
"""The test compares the first 60 s of each trace (a standstill start, the first
accelerations and, on US06, a stop): 8 loops at 10 Hz stay within seconds. The whole traces:
``python scripts/rate_table.py`` (docs/RESULTS.md, "Control rate")."""
CASES = [(trace, predictor, alpha) for trace in ('us06', 'commute_am')
         for predictor in ('ca', 'gru') for alpha in (0.0, 1.0)]
SMOOTHER = ('the 10 Hz AV changes its 1 s mean acceleration less from second to second than '
            'the 1 Hz AV (each command held for 1 s, behind a lead whose speed steps once per '
            'second); at alpha = 0 the plan ignores E, so E and the RMSE of the GRU fall with it')
AGED = ('the 1 s expectation is refreshed once per second and ages up to 0.9 s before the next '
        'refresh; alpha = 1 keeps E small at the refresh, so its growth with age dominates')
SMOOTHER_AT_ONE = ('at alpha = 1 too the first cause outweighs the second on US06 with the GRU: '
                   'the 10 Hz AV changes its 1 s mean acceleration less (RMS 0.34 against 0.41 '
                   'm/s^2), E with a fresh expectation is 39 % below 1 Hz and grows with its '
                   'age only to 8 % above it before the next refresh (net -17 %)')
OUTSIDE_15_PERCENT = {('us06', 'ca', 0.0, 'mean_explicability'): SMOOTHER,
                      ('us06', 'gru', 0.0, 'mean_explicability'): SMOOTHER,
                      ('us06', 'gru', 1.0, 'mean_explicability'): SMOOTHER_AT_ONE,
                      ('commute_am', 'ca', 1.0, 'mean_explicability'): AGED,
                      ('commute_am', 'gru', 1.0, 'mean_explicability'): AGED}
"""Where the 10 Hz loop's mean E or RMSE differs from 1 Hz by more than 15 %, and the measured
reason (docs/MODEL.md, "Time consistency", with the definitions of E and RMSE tried; the two
reasons are asserted below for every case)."""


RatePair = Callable[[str, str, float], tuple[SimResult, SimResult]]


def _rate_pair(trace: str, predictor: str, alpha: float) -> tuple[SimResult, SimResult]:
    """The same window at 1 Hz and at 10 Hz."""
    config = load_run_config(overrides={'planner': {'alpha': alpha, 'predictor': predictor},
                                        'preceding_traffic': {'trace': trace}})
    return tuple(simulate(config, truncate(control_trace(config, rate), round(WINDOW_S * rate)))
                 for rate in (1.0, 10.0))  # type: ignore[return-value]


@pytest.fixture(scope='module')
def rate_pair() -> RatePair:
    """:func:`_rate_pair`, each case simulated once for the module's four tests that read it.
    A module-scoped fixture, so that the suite's xdist grouping (tests/conftest.py) runs
    these tests on one worker: a plain cache was filled again by every worker."""
    return functools.cache(_rate_pair)


def test_one_hz_is_the_paper_loop(run_config) -> None:  # type: ignore[no-untyped-def]
    """--control-rate-hz 1 is the default loop, record for record."""
    config = load_run_config(overrides={'preceding_traffic': {'trace': 'us06'}})
    default = simulate(config, truncate(shipped_trace('us06'), 40))
    at_one = simulate(config, truncate(control_trace(config, 1.0), 40))
    def untimed(result: SimResult) -> list[object]:
        return [dataclasses.replace(r, solve_time_s=0.0, driver_solve_time_s=0.0)
                for r in result.records]

    assert untimed(default) == untimed(at_one)


@pytest.mark.parametrize(('trace', 'predictor', 'alpha'), CASES)
def test_ten_hz_keeps_trust_and_safety(rate_pair: RatePair, trace: str, predictor: str,
                                       alpha: float) -> None:
    one, ten = rate_pair(trace, predictor, alpha)
    assert len(ten.records) == 10 * len(one.records)
    m1, m10 = one.metrics, ten.metrics
    assert m10.final_trust == pytest.approx(m1.final_trust, rel=0.03)
    assert m10.unsafe_steps == 0
    assert m10.fallback_steps == 0  # none at all, so none at a standstill
    stopped = [r for r in ten.records if r.av_speed_mps < 0.05 and r.traffic_speed_mps < 0.05]
    assert len(stopped) >= 10, 'the window holds a standstill'
    assert min(r.av_gap_m for r in ten.records) >= 5.0 - 1e-6


@pytest.mark.slow
def test_ten_hz_on_a_whole_held_out_trace_never_falls_back() -> None:
    """NYCC at 10 Hz, TAC-CA, alpha 1, the whole trace (not one of the 8 cases): the run that
    once crept 1e-7 m/s at a stop and then failed every solve of it (28 fallbacks). Now no
    fallback, no unsafe step, trust within 3 % of 1 Hz."""
    config = load_run_config(overrides={'planner': {'alpha': 1.0, 'predictor': 'ca'},
                                        'preceding_traffic': {'trace': 'nycc'}})
    ten = simulate(config, control_trace(config, 10.0)).metrics
    one = simulate(config, control_trace(config, 1.0)).metrics
    assert ten.fallback_steps == 0 and ten.unsafe_steps == 0
    assert ten.final_trust == pytest.approx(one.final_trust, rel=0.03)


@pytest.mark.parametrize('metric', ['mean_explicability', 'rmse_mps2'])
@pytest.mark.parametrize(('trace', 'predictor', 'alpha'), CASES)
def test_ten_hz_mean_e_and_rmse_within_15_percent(rate_pair: RatePair, trace: str,
                                                 predictor: str, alpha: float,
                                                 metric: str, request) -> None:  # type: ignore[no-untyped-def]
    if (trace, predictor, alpha, metric) in OUTSIDE_15_PERCENT:
        request.applymarker(pytest.mark.xfail(
            strict=True, reason=OUTSIDE_15_PERCENT[trace, predictor, alpha, metric]))
    one, ten = rate_pair(trace, predictor, alpha)
    assert getattr(ten.metrics, metric) == pytest.approx(getattr(one.metrics, metric), rel=0.15)


@pytest.mark.parametrize(('trace', 'predictor', 'alpha'), CASES)
def test_ten_hz_av_changes_its_one_second_acceleration_less(rate_pair: RatePair, trace: str,
                                                            predictor: str,
                                                            alpha: float) -> None:
    """The first reason E differs: the same drive is a different closed loop at 10 Hz, whose
    AV moves its 1 s mean acceleration less between seconds (what a held expectation
    misses)."""
    one, ten = rate_pair(trace, predictor, alpha)
    assert step_change_rms_mps2(ten.records, 10) < 0.95 * step_change_rms_mps2(one.records, 1)


@pytest.mark.parametrize(('trace', 'predictor', 'alpha'), CASES)
def test_ten_hz_e_grows_with_the_expectations_age(rate_pair: RatePair, trace: str,
                                                  predictor: str, alpha: float) -> None:
    """The second reason: the expectation is refreshed on the 1 s grid, and E 0.9 s after a
    refresh is well above E at the refresh."""
    _, ten = rate_pair(trace, predictor, alpha)
    by_age = explicability_by_age(ten.records, 10)
    assert by_age[-1] > 1.4 * by_age[0]
    assert np.all(np.diff(by_age) > 0.0)
