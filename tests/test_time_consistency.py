"""Time consistency: trust is defined per second (DESIGN section 1, "time step outside
lock-step"; docs/MODEL.md, "Time consistency")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trust_monitor.trust_model import (
    TrustConfig,
    TrustEstimator,
    explicability_bound,
    performance,
    propagate_trust,
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
    bound = explicability_bound(trust, trust_min, CONFIG, 30, 0.1)
    for score in np.linspace(0.0, 0.999, 1500):
        propagated_ok = min(propagate_trust(trust, float(score), CONFIG, 30, 0.1)) >= trust_min
        bound_ok = bound is not None and score <= bound
        if abs(score - (bound or 0.0)) > 1e-9:
            assert propagated_ok == bound_ok, (trust, trust_min, score, bound)


def test_bound_over_the_same_seconds_agrees_when_trust_is_above_t_min() -> None:
    """Above T_min only the end of the horizon matters: 3 s is 3 s on either grid."""
    for trust in (0.2, 0.21, 0.25, 3.0):
        assert explicability_bound(trust, 0.2, CONFIG, 30, 0.1) == pytest.approx(
            explicability_bound(trust, 0.2, CONFIG, 3, 1.0), rel=1e-12)
