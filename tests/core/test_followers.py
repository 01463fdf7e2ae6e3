"""The registered follower models and the constant-velocity estimator (pure, no rclpy):
the IDM follower's physics, the choice by name and its refusal, the registry's parameters."""

from __future__ import annotations

import numpy as np
import pytest

from human_driver_sim.driver_mpc import DriverMpc
from human_driver_sim.followers import FollowerConfig, make_follower
from human_driver_sim.idm import TEXTBOOK_MOTORWAY, IdmConfig, IdmFollower, idm_accel
from trust_av.system.config import load_run_config
from trust_av_common import registry
from trust_av_common.params import ParamsError
from trust_av_planner.planner import make_predictor
from trust_av_planner.predictors import Observation


@pytest.fixture(scope='module')
def driver():  # type: ignore[no-untyped-def]
    return load_run_config().driver


def test_idm_follower_applies_the_idm_within_the_humans_bounds(driver) -> None:  # type: ignore[no-untyped-def]
    follower = IdmFollower(driver, IdmConfig())
    steady = np.zeros(driver.horizon_steps)
    # free road: the IDM's own acceleration, a (1 - (v / v0)^4) minus a tiny gap term
    free = follower.step(500.0, 10.0, 10.0, steady).plan_mps2
    assert free[0] == pytest.approx(idm_accel(TEXTBOOK_MOTORWAY, 500.0, 10.0, 10.0))
    assert 0.9 < free[0] <= TEXTBOOK_MOTORWAY.max_accel_mps2
    # closing fast on a near AV: the IDM asks for more than the human can brake
    close = follower.step(3.0, 20.0, 5.0, steady).plan_mps2
    assert close[0] == driver.accel_min_mps2
    # stopped behind a stopped AV: it brakes no further than to standstill
    stopped = follower.step(1.5, 0.0, 0.0, steady).plan_mps2
    assert np.all(stopped == 0.0)


def test_idm_plan_follows_the_expected_av_plan(driver) -> None:  # type: ignore[no-untyped-def]
    follower = IdmFollower(driver, IdmConfig())
    braking = follower.step(25.0, 15.0, 15.0, np.full(driver.horizon_steps, -3.0)).plan_mps2
    steady = follower.step(25.0, 15.0, 15.0, np.zeros(driver.horizon_steps)).plan_mps2
    assert braking[0] == steady[0]            # now: the same state
    assert braking[-1] < steady[-1]           # later: the AV it expects has slowed


def test_followers_are_chosen_by_name(driver) -> None:  # type: ignore[no-untyped-def]
    # the model the registry built, inside the checks of its every step (CheckedFollower)
    assert isinstance(make_follower(driver).model, DriverMpc)  # the default, mpc
    idm = make_follower(driver, FollowerConfig('idm'), IdmConfig(idm_time_headway_s=2.0)).model
    assert isinstance(idm, IdmFollower) and idm.params.time_headway_s == 2.0
    with pytest.raises(ParamsError, match=r"driver_model must be one of \[.*'idm'.*\], got 'x'"):
        FollowerConfig('x')
    with pytest.raises(registry.RegistryError, match="'idm': parameters must be a IdmConfig"):
        make_follower(driver, FollowerConfig('idm'), object())
    with pytest.raises(registry.RegistryError, match="'mpc' has no parameters"):
        make_follower(driver, FollowerConfig('mpc'), IdmConfig())
    with pytest.raises(ParamsError, match=r'idm_min_gap_m must be in \[1, 8\], got 0.5'):
        IdmConfig(idm_min_gap_m=0.5)


def test_constant_velocity_expects_no_acceleration() -> None:
    planner = load_run_config(overrides={'planner': {'predictor': 'cv'}}).planner
    predictor = make_predictor(planner)
    for accel in (2.5, -3.0, 1.0):
        predictor.observe(Observation(20.0, 1.0, 2.0, accel))
        assert np.array_equal(predictor.predict(), np.zeros(planner.horizon_steps))
