"""Property-based tests (hypothesis) of the trust model and the NMPC on random inputs."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.nmpc_bounds import bound_violation

from trust_av.system.config import load_run_config
from trust_av_planner.nmpc import BOUND_TOLERANCE, TrustAwareNmpc
from trust_monitor.paper_trust import TrustEstimator, explicability, performance

CONFIG = load_run_config()
ACCEL = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False)
PLAN = st.lists(ACCEL, min_size=3, max_size=3)
NMPC = TrustAwareNmpc(dataclasses.replace(CONFIG.planner, speed_max_mps=36.0), CONFIG.trust)


@given(PLAN, PLAN)
def test_explicability_and_performance_in_unit_interval(plan: list[float],
                                                       expected: list[float]) -> None:
    score = explicability(plan, expected, CONFIG.trust.epsilon_mps2)
    assert 0.0 <= score <= 1.0
    assert 0.0 <= performance(score) <= 1.0
    assert (score == 0.0) == (plan == expected) or score < 1e-15


@given(st.lists(st.tuples(PLAN, PLAN), min_size=1, max_size=40))
def test_trust_moves_at_most_delta_per_step(steps: list[tuple[list[float], list[float]]]) -> None:
    estimator = TrustEstimator(CONFIG.trust)
    delta = CONFIG.trust.trust_growth_rate
    previous = estimator.trust
    for plan, expected in steps:
        trust = estimator.step(plan, expected).trust
        assert abs(trust - previous) <= delta + 1e-12
        previous = trust
    assert abs(previous - CONFIG.trust.trust_initial) <= delta * len(steps) + 1e-9


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(speed=st.floats(0.0, 35.0), gap_offset=st.floats(-10.0, 40.0),
       lead=st.lists(st.floats(0.0, 36.0), min_size=3, max_size=3), expected=PLAN,
       trust=st.floats(-1.0, 60.0))
def test_every_plan_is_inside_the_bounds_or_flagged(speed: float, gap_offset: float,
                                                    lead: list[float], expected: list[float],
                                                    trust: float) -> None:
    gap = max(0.5, 5.0 + 1.2 * speed + gap_offset)
    NMPC.reset()
    result = NMPC.step(gap, speed, np.array(lead), np.array(expected), trust)
    plan = result.plan_mps2
    assert plan.shape == (3,) and np.all(np.isfinite(plan))
    cfg = NMPC.config
    # Every plan, fallback or not, keeps the acceleration bounds and never reverses.
    assert np.all(plan >= cfg.accel_min_mps2 - BOUND_TOLERANCE)
    assert np.all(plan <= cfg.accel_max_mps2 + BOUND_TOLERANCE)
    assert np.all(speed + np.cumsum(plan) * cfg.dt_s >= -BOUND_TOLERANCE)
    if result.success:
        # Inside the bounds of (12), or flagged: the gap bounds were what the vehicle can
        # reach (it already stood outside [d_min, d_max] as far as it can act), and it keeps
        # those.
        inputs = (plan, gap, speed, np.array(lead), np.array(expected), result.explicability_max)
        assert bound_violation(NMPC, *inputs, reachable=True) <= BOUND_TOLERANCE
        if not result.gap_bounds_relaxed:
            assert bound_violation(NMPC, *inputs) <= 2 * BOUND_TOLERANCE
        else:
            assert 'gap bounds relaxed' in result.status
    else:
        assert result.status.startswith('fallback: ')
