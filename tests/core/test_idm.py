"""IDM: physical behaviour behind a braking leader, the textbook set, the fit bounds."""

from __future__ import annotations

import numpy as np
import pytest

from human_driver_sim.car_following import FollowingPair
from human_driver_sim.evaluation import IdmFollower, make_runs, simulate
from human_driver_sim.idm import FIT_BOUNDS, TEXTBOOK_MOTORWAY, IdmParams, idm_accel


def test_idm_no_collision_behind_braking_leader() -> None:
    leader = np.concatenate([np.full(20, 25.0), np.linspace(25.0, 0.0, 9), np.zeros(40)])
    pair = FollowingPair('brake', 1.0, leader, np.full(leader.size, 25.0),
                         np.full(leader.size, 40.0))
    for params in (IdmParams(), TEXTBOOK_MOTORWAY):
        gap, speed = simulate(IdmFollower(params), make_runs([pair], 'full'))[0]
        assert gap.min() > 0.0
        assert speed[-1] < 0.5


def test_textbook_and_bounds() -> None:
    # Treiber & Kesting, Traffic Flow Dynamics (2013), Table 11.2, motorway.
    assert TEXTBOOK_MOTORWAY.desired_speed_mps == pytest.approx(33.33, abs=0.01)
    assert (TEXTBOOK_MOTORWAY.time_headway_s, TEXTBOOK_MOTORWAY.min_gap_m) == (1.0, 2.0)
    assert FIT_BOUNDS['comfort_decel_mps2'][1] <= 4.0 and FIT_BOUNDS['min_gap_m'][0] >= 1.0
    assert FIT_BOUNDS['time_headway_s'][0] >= 0.5
    # In equilibrium (same speed, gap s0 + v T) IDM's acceleration is a (1 - (v/v0)^4) - a.
    v = 20.0
    accel = idm_accel(TEXTBOOK_MOTORWAY, 2.0 + v * 1.0, v, v)
    assert accel == pytest.approx(-(v / TEXTBOOK_MOTORWAY.desired_speed_mps) ** 4, abs=1e-12)
    with pytest.raises(ValueError, match='time_headway_s'):
        IdmParams(time_headway_s=0.0)
