"""The human driver's MPC (eq. 13): features by hand, bounds, the hard gap bound with its
margin for an AV that brakes harder than expected, and following behaviour."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from human_driver_sim.driver_mpc import DriverConfig, DriverMpc, features
from trust_av_common import kinematics


def test_step_and_rollout_by_hand() -> None:
    assert kinematics.step(10.0, 5.0, 7.0, -1.0, 0.5) == (11.0, 4.5)
    gaps, speeds = kinematics.rollout(10.0, 5.0, [7.0, 7.0], [1.0, 1.0], 1.0)
    assert gaps == [12.0, 13.0] and speeds == [6.0, 7.0]
    assert kinematics.lead_speeds(4.0, [1.0, 2.0, 3.0], 1.0) == [4.0, 5.0, 7.0]


def test_features_by_hand() -> None:
    # Human: gap 10, speed 5; AV: speed 6, expected plan (0, 0); human plan (1, 0); dt 1.
    # AV speeds at steps 0, 1: (6, 6); AV speeds after each step: (6, 6).
    # Human speeds after each step: (6, 6); gaps: 10 + (6 - 5) = 11, 11 + (6 - 6) = 11.
    f_a, f_ds, f_rs, f_rd = features(10.0, 5.0, 6.0, [1.0, 0.0], [0.0, 0.0], dt_s=1.0,
                                     standstill_gap_m=5.0, time_headway_s=1.0,
                                     desired_speed_mps=8.0)
    assert f_a == 1.0
    assert f_ds == (6 - 8) ** 2 * 2
    assert f_rs == 0.0
    assert f_rd == (11 - 5 - 6) ** 2 * 2


def test_driver_respects_bounds_and_follows(run_config) -> None:
    cfg = dataclasses.replace(run_config.driver, speed_max_mps=30.0)
    mpc = DriverMpc(cfg)
    rng = np.random.default_rng(3)
    for _ in range(50):
        speed = rng.uniform(0, 28)
        gap = 5.0 + 1.5 * speed + rng.uniform(-2, 10)
        av_speed = max(0.0, speed + rng.uniform(-3, 3))
        expected = rng.uniform(-2, 2, 3)
        result = mpc.step(gap, speed, av_speed, expected)
        assert result.success, result.status
        plan = result.plan_mps2
        assert np.all(plan >= cfg.accel_min_mps2 - 1e-9)
        assert np.all(plan <= cfg.accel_max_mps2 + 1e-9)
        speeds = speed + np.cumsum(plan) * cfg.dt_s
        assert np.all(speeds >= -1e-6) and np.all(speeds <= cfg.speed_max_mps + 1e-6)
        cautious = mpc.cautious_av_speeds(av_speed, expected)
        gaps, _ = kinematics.rollout(gap, speed, list(cautious), list(plan), cfg.dt_s)
        assert min(gaps[1:]) >= cfg.standstill_gap_m - 1e-6


def test_driver_brakes_when_the_av_is_expected_to_brake(run_config) -> None:
    mpc = DriverMpc(dataclasses.replace(run_config.driver, speed_max_mps=30.0))
    steady = mpc.step(5.0 + 1.5 * 20.0, 20.0, 20.0, np.zeros(3)).plan_mps2[0]
    mpc.reset()
    braking = mpc.step(5.0 + 1.5 * 20.0, 20.0, 20.0, np.full(3, -3.0)).plan_mps2[0]
    assert abs(steady) < 0.5
    assert braking < steady - 0.5


def test_fallback_plan_keeps_bounds() -> None:
    plan = kinematics.hold_gap_plan(
        6.0, 15.0, [5.0, 5.0, 5.0], dt_s=1.0, standstill_gap_m=5.0, time_headway_s=1.2,
        gap_gain_per_s2=0.3, speed_gain_per_s=0.8, accel_min_mps2=-3.0, accel_max_mps2=3.0,
        speed_min_mps=0.0, speed_max_mps=30.0)
    assert plan == pytest.approx([-3.0, -3.0, -3.0])
    plan = kinematics.hold_gap_plan(
        50.0, 1.0, [0.0] * 3, dt_s=1.0, standstill_gap_m=5.0, time_headway_s=1.2,
        gap_gain_per_s2=0.3, speed_gain_per_s=0.8, accel_min_mps2=-3.0, accel_max_mps2=3.0,
        speed_min_mps=0.0, speed_max_mps=30.0)
    speeds = 1.0 + np.cumsum(plan)
    assert np.all(speeds >= 0.0)


ASSUMED_MPS2 = -3.0


def safety_config(run_config, **changes: float) -> DriverConfig:
    """The shipped driver with v_max 30 m/s, cautious (the AV assumed to brake at up to
    -3 m/s^2) unless ``changes`` say otherwise."""
    values = {'speed_max_mps': 30.0, 'assumed_av_accel_min_mps2': ASSUMED_MPS2,
              'cautious': True, **changes}
    return dataclasses.replace(run_config.driver, **values)


def test_shipped_assumption_is_the_avs_braking_bound(run_config) -> None:
    assert run_config.driver.assumed_av_accel_min_mps2 == run_config.planner.accel_min_mps2


def test_cautious_av_speeds_by_hand(run_config) -> None:
    mpc = DriverMpc(safety_config(run_config, dt_s=1.0))
    # Expected (1, -4, x): the AV at min(expected, -3) from 10 m/s: 10, 7, 3.
    assert mpc.cautious_av_speeds(10.0, np.array([1.0, -4.0, 0.5])) == pytest.approx([10, 7, 3])
    # The AV never reverses.
    assert mpc.cautious_av_speeds(2.0, np.zeros(3)) == pytest.approx([2, 0, 0])
    # Assuming no braking at all leaves the expected plan where it brakes.
    holding = DriverMpc(safety_config(run_config, assumed_av_accel_min_mps2=0.0))
    assert holding.cautious_av_speeds(10.0, np.array([1.0, -1.0, 0.5])) == pytest.approx(
        [10, 10, 9])


def test_fitted_caution_av_speeds_by_hand(run_config) -> None:
    # Not cautious: the AV at min(expected, 0) - a_extra, whatever assumed_av_accel_min says.
    mpc = DriverMpc(safety_config(run_config, cautious=False, av_extra_decel_mps2=0.5))
    # Expected (1, -4, x) from 10 m/s: accelerations (-0.5, -4.5): 10, 9.5, 5.
    assert mpc.cautious_av_speeds(10.0, np.array([1.0, -4.0, 0.5])) == pytest.approx(
        [10, 9.5, 5])
    # a_extra = 0: the expected plan's braking only (the ablation of docs/DRIVER_IRL.md).
    plain = DriverMpc(safety_config(run_config, cautious=False, av_extra_decel_mps2=0.0))
    assert plain.cautious_av_speeds(10.0, np.array([1.0, -1.0, 0.5])) == pytest.approx(
        [10, 10, 9])
    # The shipped driver plans against the expected braking; cautious ignores a_extra.
    assert not run_config.driver.cautious
    worst = DriverMpc(safety_config(run_config, av_extra_decel_mps2=2.0))
    assert worst.cautious_av_speeds(10.0, np.array([1.0, -4.0, 0.5])) == pytest.approx(
        [10, 7, 3])


def test_fitted_caution_sets_how_close_the_human_follows(run_config) -> None:
    # Both at 20 m/s, 7 m apart, the AV expected to hold its speed: d^2 = 7 + (20 - a_extra
    # - 20 - u_0) >= 5 needs u_0 <= 2 - a_extra. a_extra = 0 leaves the driver free; 2.5
    # makes it brake at least 0.5 m/s^2.
    free = DriverMpc(safety_config(run_config, cautious=False, av_extra_decel_mps2=0.0))
    careful = DriverMpc(safety_config(run_config, cautious=False, av_extra_decel_mps2=2.5))
    u_free = free.step(7.0, 20.0, 20.0, np.zeros(3)).plan_mps2[0]
    u_careful = careful.step(7.0, 20.0, 20.0, np.zeros(3))
    assert u_careful.success, u_careful.status
    assert u_careful.plan_mps2[0] <= -0.5 + 1e-6
    assert u_free > u_careful.plan_mps2[0] + 0.1


def test_gap_bound_holds_against_an_av_braking_harder_than_expected(run_config) -> None:
    # Both at 20 m/s, 7 m apart; the human expects the AV to hold its speed. If the AV brakes
    # at -3 m/s^2 instead, d^2 = 7 + (17 - 20 - u_0) >= d_s = 5 needs u_0 <= -1 m/s^2, while
    # against the expected plan alone u_0 <= 2 would do (and the driver's relative-speed
    # term wants u_0 near 0): a driver without the margin fails this.
    cfg = safety_config(run_config)
    plan = DriverMpc(cfg).step(7.0, 20.0, 20.0, np.zeros(3))
    assert plan.success, plan.status
    assert plan.plan_mps2[0] <= -1.0 + 1e-6
    # ... and the gaps the plan leads to, with the AV braking at -3 m/s^2, keep d_s.
    av_braking = kinematics.lead_speeds(20.0, [ASSUMED_MPS2] * 3, cfg.dt_s)
    gaps, _ = kinematics.rollout(7.0, 20.0, av_braking, list(plan.plan_mps2), cfg.dt_s)
    assert min(gaps[1:]) >= cfg.standstill_gap_m - 1e-6


def test_gap_bound_is_hard_where_the_cost_pulls_through_it(run_config) -> None:
    # A human 1 m/s faster than the AV, 6.5 m behind, who wants to go faster (a heavy
    # desired-speed weight): a soft bound (an L1 penalty of weight 1000) lets the cost trade
    # gap for speed, the hard one keeps every actionable gap at d_s or more, and is active.
    cfg = safety_config(run_config, weight_desired_speed=1000.0, weight_relative_speed=0.0)
    mpc = DriverMpc(cfg)
    plan = mpc.step(6.5, 21.0, 20.0, np.zeros(3))
    assert plan.success, plan.status
    cautious = mpc.cautious_av_speeds(20.0, np.zeros(3))
    gaps, _ = kinematics.rollout(6.5, 21.0, list(cautious), list(plan.plan_mps2), cfg.dt_s)
    assert min(gaps[1:]) == pytest.approx(cfg.standstill_gap_m, abs=1e-6)


def test_first_gap_is_not_constrained(run_config) -> None:
    # d^1 = 5.2 + (20 - 21) = 4.2 m < d_s whatever the human does; braking still restores
    # d^2, so the problem is feasible and solved (a bound on d^1 would make it infeasible).
    cfg = safety_config(run_config)
    mpc = DriverMpc(cfg)
    result = mpc.step(5.2, 21.0, 20.0, np.zeros(3))
    assert result.success, result.status
    cautious = mpc.cautious_av_speeds(20.0, np.zeros(3))
    gaps, _ = kinematics.rollout(5.2, 21.0, list(cautious), list(result.plan_mps2), cfg.dt_s)
    assert gaps[0] == pytest.approx(4.2)
    assert min(gaps[1:]) >= cfg.standstill_gap_m - 1e-6


@pytest.mark.parametrize('gap_m', (5.2, 5.5, 6.0))
def test_the_shipped_driver_solves_where_the_bound_binds(run_config, gap_m: float) -> None:
    # The shipped (not cautious) driver 1 m/s faster than an AV expected to hold 20 m/s:
    # d^2 = gap - 2 - u^0 >= 5 needs u^0 <= gap - 7, and the cost wants u^0 near 0, so the
    # bound binds. qrqp stopped here with Search_Direction_Becomes_Too_Small at d^2 = 4.64 m
    # (gap 5.2 m) and the human fell back to its hold-gap plan (-6 m/s^2).
    cfg = dataclasses.replace(run_config.driver, speed_max_mps=30.0)
    assert not cfg.cautious
    mpc = DriverMpc(cfg)
    result = mpc.step(gap_m, 21.0, 20.0, np.zeros(3))
    assert result.success, result.status
    assert result.plan_mps2[0] == pytest.approx(gap_m - 7.0, abs=1e-6)
    gaps, _ = kinematics.rollout(gap_m, 21.0, [20.0] * 3, list(result.plan_mps2), cfg.dt_s)
    assert min(gaps[1:]) >= cfg.standstill_gap_m - 1e-9


def test_infeasible_gap_bound_brakes_hardest_and_is_a_fallback(run_config) -> None:
    # 8 m behind an AV 6 m/s slower: d^1 = 2 m; even braking at -6 m/s^2, d^2 = 2 + (11 - 14)
    # = -1 m against the cautious AV (14, 11, 8 m/s): no plan meets d_s.
    cfg = safety_config(run_config)
    mpc = DriverMpc(cfg)
    result = mpc.step(8.0, 20.0, 14.0, np.zeros(3))
    assert not result.success
    assert result.status == 'fallback: gap_bound_infeasible'
    assert result.plan_mps2 == pytest.approx([cfg.accel_min_mps2] * 3)
    # Near standstill the braking plan stops at speed_min and never reverses.
    stopping = mpc.step(0.5, 7.0, 0.0, np.zeros(3))
    assert stopping.status == 'fallback: gap_bound_infeasible'
    assert stopping.plan_mps2 == pytest.approx([-6.0, -1.0, 0.0])
    # The same states with room to brake are solved normally.
    assert mpc.step(30.0, 20.0, 14.0, np.zeros(3)).success


def test_stopped_a_hair_below_d_s_is_solved_not_a_fallback(run_config) -> None:
    # Rounding may leave a stopped human a hair below d_s behind a stopped AV: the bound then
    # holds at what braking reaches (standing still), not a fallback at every standstill step.
    cfg = safety_config(run_config)
    mpc = DriverMpc(cfg)
    result = mpc.step(cfg.standstill_gap_m - 1.4e-7, 0.0, 0.0, np.zeros(3))
    assert result.success, result.status
    assert result.plan_mps2[:2] == pytest.approx([0.0, 0.0], abs=1e-12)  # it stays put
    # A real shortfall is still a fallback.
    assert mpc.step(cfg.standstill_gap_m - 1e-3, 0.0, 0.0, np.zeros(3)).status == (
        'fallback: gap_bound_infeasible')



def test_a_qp_failure_is_a_named_fallback_to_the_hold_gap_plan(run_config) -> None:
    # One DAQP iteration cannot solve the bound-active problem of the test above: the step
    # falls back to the hold-gap controller against the bound's AV speeds, named by DAQP's
    # exit flag.
    cfg = dataclasses.replace(run_config.driver, speed_max_mps=30.0, solver_max_iter=1)
    mpc = DriverMpc(cfg)
    result = mpc.step(5.2, 21.0, 20.0, np.zeros(3))
    assert not result.success
    assert result.status == 'fallback: DAQP iteration limit (exit flag -4)'
    expected = kinematics.hold_gap_plan(
        5.2, 21.0, list(mpc.cautious_av_speeds(20.0, np.zeros(3))), dt_s=cfg.dt_s,
        standstill_gap_m=cfg.standstill_gap_m, time_headway_s=cfg.time_headway_s,
        gap_gain_per_s2=cfg.fallback_gap_gain_per_s2,
        speed_gain_per_s=cfg.fallback_speed_gain_per_s, accel_min_mps2=cfg.accel_min_mps2,
        accel_max_mps2=cfg.accel_max_mps2, speed_min_mps=cfg.speed_min_mps,
        speed_max_mps=cfg.speed_max_mps)
    assert result.plan_mps2 == pytest.approx(expected)
