"""The human driver's MPC (eq. 13): features by hand, bounds, and following behaviour."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from human_driver_sim.driver_mpc import DriverMpc, features
from trust_monitor.common import kinematics


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
