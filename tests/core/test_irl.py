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
                      fallback_gap_gain_per_s2=0.3, fallback_speed_gain_per_s=0.8,
                      desired_standstill_gap_m=2.0)
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


def test_fitted_caution_file_picked_on_validation_and_its_test_target() -> None:
    """driver_fit_caution.yaml (the shipped driver's source): the model with the lowest validation
    loss is the one picked, and its evaluation's test target (docs/DRIVER_IRL.md, Summary)
    is what the docs report: at most 0.9 x the best IDM on both test sets, no collision."""
    import json

    import yaml

    from human_driver_sim.population import DRIVER_FIT_FILE
    fit = yaml.safe_load(DRIVER_FIT_FILE.read_text())
    losses = {m: v['mean'] for m, v in fit['validation_loss'].items() if m.startswith('MPC')}
    assert fit['selected'] == min(losses, key=losses.__getitem__)
    evaluation = json.loads(DRIVER_FIT_FILE.with_name(
        DRIVER_FIT_FILE.stem + '_eval.json').read_text())
    assert set(evaluation['target']) == {'openacc test', 'ngsim test'}
    for by_protocol in evaluation['target'].values():
        for target in by_protocol.values():
            assert target['model'] == fit['selected']
            assert target['met'] and target['ratio'] <= 0.9
            assert target['mpc_collisions'] == 0 and target['mpc_steps_below_2m'] == 0
    ngsim = evaluation['target']['ngsim test']['window']
    assert round(ngsim['ratio'], 2) == 0.82
    assert ngsim['paired_difference']['mean'] + ngsim['paired_difference']['ci95'] < 0.0
