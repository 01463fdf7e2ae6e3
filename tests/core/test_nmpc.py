"""The AV's NMPC (eq. 12): bounds, optimality against the independent IPOPT formulation,
the trust constraint, and the fallback path."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest
from support.closed_loop import closed_loop, shipped_trace, with_alpha
from support.nmpc_bounds import bound_violation
from support.paths import REPO

from trust_av_planner.nmpc import TrustAwareNmpc
from trust_monitor.paper_trust import explicability

sys.path.insert(0, str(REPO / 'benchmarks'))
from nmpc_reference import ReferenceNmpc, compare_on_records  # the benchmark's baseline


@pytest.mark.parametrize('alpha', [0.0, 0.5, 1.0])
def test_matches_independent_ipopt_and_respects_bounds(run_config, alpha) -> None:
    cfg = dataclasses.replace(run_config.planner, alpha=alpha, speed_max_mps=36.0)
    nmpc = TrustAwareNmpc(cfg, run_config.trust)
    reference = ReferenceNmpc(cfg, run_config.trust, {'tol': 1e-12})
    rng = np.random.default_rng(7)
    solved = 0
    for _ in range(40):
        speed = rng.uniform(0.0, 30.0)
        gap = 5.0 + 1.2 * speed + rng.uniform(-3.0, 8.0)
        lead = np.clip(speed + rng.uniform(-4, 4) + np.cumsum(rng.uniform(-2, 2, 3)), 0, 36)
        expected = rng.uniform(-2.0, 2.0, 3)
        nmpc.reset()
        result = nmpc.step(gap, speed, lead, expected, trust=5.0)
        if not result.success:
            continue
        solved += 1
        assert bound_violation(nmpc, result.plan_mps2, gap, speed, lead, expected,
                               result.explicability_max) <= 1e-6
        ref = reference.step(gap, speed, lead, expected, result.explicability_max)
        np.testing.assert_allclose(result.plan_mps2, ref, atol=1e-4)
    assert solved >= 30


def test_trust_constraint_limits_explicability(run_config) -> None:
    """At T = T_min = 0 the plan must keep u_T >= 0, i.e. E <= atanh(0.2), even at alpha = 0."""
    cfg = dataclasses.replace(run_config.planner, alpha=0.0, speed_max_mps=36.0)
    nmpc = TrustAwareNmpc(cfg, run_config.trust)
    # The tracking optimum brakes hard while the human expects strong acceleration.
    gap, speed, lead, expected = 8.0, 15.0, np.array([10.0, 8.0, 6.0]), np.full(3, 3.0)
    free = TrustAwareNmpc(dataclasses.replace(cfg, trust_min=-1e6), run_config.trust)
    unconstrained = free.step(gap, speed, lead, expected, trust=0.0)
    result = nmpc.step(gap, speed, lead, expected, trust=0.0)
    assert explicability(list(unconstrained.plan_mps2), list(expected), 6.0) > np.arctanh(0.2)
    if result.success:
        assert explicability(list(result.plan_mps2), list(expected), 6.0) <= np.arctanh(0.2) + 1e-6
    else:
        assert result.status.startswith('fallback')


def test_start_inside_the_minimum_gap_brakes_as_hard_as_allowed(run_config) -> None:
    """Start inside the minimum gap, closing fast: no plan satisfies (12), so the gap bounds
    are what the hardest braking reaches; the plan is that braking, flagged as such."""
    cfg = dataclasses.replace(run_config.planner, speed_max_mps=36.0)
    nmpc = TrustAwareNmpc(cfg, run_config.trust)
    result = nmpc.step(3.0, 20.0, np.zeros(3), np.zeros(3), trust=5.0)
    assert result.success and result.gap_bounds_relaxed
    assert 'gap bounds relaxed' in result.status
    plan = result.plan_mps2
    assert plan.shape == (3,)
    assert np.all(plan >= cfg.accel_min_mps2 - 1e-9) and np.all(plan <= cfg.accel_max_mps2)
    assert plan[0] == pytest.approx(cfg.accel_min_mps2, abs=1e-6)  # brakes as hard as allowed
    speeds = 20.0 + np.cumsum(plan)
    assert np.all(speeds >= -1e-9)                 # never reverses


def test_fallback_when_trust_cannot_recover(run_config) -> None:
    cfg = dataclasses.replace(run_config.planner, speed_max_mps=36.0)
    nmpc = TrustAwareNmpc(cfg, run_config.trust)
    result = nmpc.step(20.0, 10.0, np.full(3, 10.0), np.zeros(3), trust=-5.0)
    assert result.status == 'fallback: trust below T_min'


def test_solver_failure_is_reported_not_raised(run_config) -> None:
    cfg = dataclasses.replace(run_config.planner, speed_max_mps=36.0, solver_max_iter=1)
    nmpc = TrustAwareNmpc(cfg, run_config.trust)
    statuses = {nmpc.step(g, 12.0, np.array([14.0, 9.0, 16.0]), np.array([2.0, -2.0, 1.0]),
                           trust=5.0).status for g in (12.0, 25.0, 40.0)}
    assert any(s.startswith('fallback: Maximum_Iterations') for s in statuses)


def test_standstill_at_minimum_gap_is_solved_not_fallen_back(run_config) -> None:
    """Stopped at d_min behind a stopped leader, the only feasible plan is to stay stopped."""
    cfg = dataclasses.replace(run_config.planner, alpha=1.0, speed_max_mps=36.0)
    nmpc = TrustAwareNmpc(cfg, run_config.trust)
    result = nmpc.step(5.0, 0.0, np.zeros(3), np.full(3, -0.03), trust=10.0)
    assert result.success, result.status
    np.testing.assert_allclose(result.plan_mps2, 0.0, atol=1e-6)


def test_cpu_budget_exceeded_falls_back(run_config) -> None:
    """A tiny CPU budget against the wall clock: every solve overruns, every step is a
    documented fallback. Without the wall clock (lock-step, in-process) the budget does not
    apply: the same solve is planned, so timing never changes those results."""
    cfg = dataclasses.replace(run_config.planner, speed_max_mps=36.0, solver_cpu_budget_s=1e-9)
    nmpc = TrustAwareNmpc(cfg, run_config.trust, cpu_budget=True)
    result = nmpc.step(20.0, 12.0, np.full(3, 12.0), np.zeros(3), trust=5.0)
    assert result.status.startswith('fallback: CPU budget exceeded')
    assert np.all(np.abs(result.plan_mps2) <= 3.0)
    untimed = TrustAwareNmpc(cfg, run_config.trust).step(20.0, 12.0, np.full(3, 12.0),
                                                         np.zeros(3), trust=5.0)
    assert untimed.success, untimed.status


def test_loop_plans_agree_with_the_baseline_solver(run_config) -> None:
    """Our SQP's plans equal the Opti + IPOPT baseline's within 1e-4 m/s^2 (US06)."""
    result = closed_loop('us06', 0.5)
    comparison = compare_on_records(with_alpha(run_config, 0.5), shipped_trace('us06'),
                                    result.records[:150])
    assert comparison.reference_failures == 0
    assert len(comparison.plan_differences_mps2) >= 145
    assert comparison.max_plan_difference_mps2 < 1e-4
