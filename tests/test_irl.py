"""Inverse KKT recovers known driver weights from synthetic demonstrations of our MPC."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from human_driver_sim.driver_mpc import DriverConfig, DriverMpc
from human_driver_sim.irl import Demonstration, fit_inverse_kkt

CONFIG = DriverConfig(dt_s=1.0, horizon_steps=3, standstill_gap_m=2.0, speed_min_mps=0.0,
                      speed_max_mps=33.0, weight_acceleration=1.0, weight_desired_speed=0.02,
                      weight_relative_speed=0.4, weight_relative_distance=0.15,
                      time_headway_s=1.5, accel_min_mps2=-6.0, accel_max_mps2=3.0,
                      solver_max_iter=50,
                      fallback_gap_gain_per_s2=0.3, fallback_speed_gain_per_s=0.8)
TOLERANCE = 0.10  # relative error on each normalised weight


def test_inverse_kkt_recovers_weights() -> None:
    rng = np.random.default_rng(3)
    mpc = DriverMpc(CONFIG)
    demos = []
    for _ in range(40):
        speed = rng.uniform(10.0, 28.0)
        state = (speed * 1.5 + rng.uniform(-8.0, 8.0) + 5.0, speed, speed + rng.uniform(-3, 3))
        expected = np.full(3, rng.uniform(-1.0, 1.0))
        result = mpc.step(*state, expected)
        mpc.reset()
        if result.success and np.all(np.abs(result.plan_mps2) < 2.9):
            demos.append(Demonstration(*state, expected, result.plan_mps2))
    assert len(demos) >= 20
    fitted = fit_inverse_kkt(CONFIG, demos)
    truth = CONFIG.weights / CONFIG.weight_acceleration
    assert np.all(np.abs(fitted - truth) <= TOLERANCE * truth), (fitted, truth)
    assert dataclasses.replace(CONFIG, weight_relative_speed=float(fitted[2]))


def test_shipped_driver_fit_has_per_pair_weights(tmp_path: Path) -> None:
    from human_driver_sim.population import DriverFitError, per_pair_weights
    weights = per_pair_weights()
    assert weights.shape == (4, 4) and (weights[:, 0] == 1.0).all() and (weights >= 0).all()
    bad = tmp_path / 'fit.yaml'
    bad.write_text('per_pair_inverse_kkt:\n  a: [1.0, -2.0, 0.1, 0.1]\n')
    with pytest.raises(DriverFitError, match=r"fit\.yaml: per_pair_inverse_kkt\['a'\] must be 4"):
        per_pair_weights(bad)
    with pytest.raises(DriverFitError, match='cannot read the driver fit'):
        per_pair_weights(tmp_path / 'missing.yaml')


def test_bilevel_refinement_recovers_the_time_headway() -> None:
    """Demonstrations replayed by our MPC with tau_H = 1.0 s; the refinement starts at the
    config's 1.5 s (and at the true W) and must find tau_H within 5 % and a tiny gap error."""
    from human_driver_sim.car_following import FollowingPair
    from human_driver_sim.irl import refine_bilevel, replay_mpc
    truth = dataclasses.replace(CONFIG, time_headway_s=1.0)
    t = np.arange(120.0)
    leader = 20.0 + 4.0 * np.sin(t / 9.0) + 2.0 * np.sin(t / 4.0)
    seed = FollowingPair('synthetic', 1.0, leader, np.full(t.size, 20.0), np.full(t.size, 25.0))
    gap, speed = replay_mpc(truth, seed)
    demo = FollowingPair('synthetic', 1.0, leader, speed, gap)
    weights, tau, loss = refine_bilevel(CONFIG, [demo], CONFIG.weights, iterations=30)
    assert abs(tau - 1.0) <= 0.05, (tau, weights)
    assert loss < 0.5   # m, mean replay gap RMSE (starting point: several metres)
    start_loss = float(np.sqrt(np.mean((replay_mpc(CONFIG, demo)[0] - gap) ** 2)))
    assert start_loss > 5 * loss


def test_params_file_driver_is_the_pooled_fit() -> None:
    """The default config's human driver is the shipped IRL fit (W and tau_H)."""
    import yaml

    from human_driver_sim.population import DRIVER_FIT_FILE, WEIGHT_NAMES
    from trust_av_planner.system.config import load_run_config
    pooled = yaml.safe_load(DRIVER_FIT_FILE.read_text())['pooled']
    driver = load_run_config().driver
    for name in (*WEIGHT_NAMES, 'time_headway_s'):
        assert getattr(driver, name) == pooled[name], name
