"""Trust model (eqs. 8-11) against hand-computed values, and the NMPC's trust constraint."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from support.trust_reference import propagate_trust

from trust_monitor.paper_trust import (
    TrustConfig,
    TrustEstimator,
    explicability,
    paper_explicability_bound,
    performance,
    trust_input,
    trust_step,
)

CONFIG = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=0.8,
                     trust_initial=0.0)


def test_equal_plans_score_zero() -> None:
    assert explicability([0.3, -1.0, 2.0], [0.3, -1.0, 2.0], 6.0) == 0.0
    assert explicability([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 6.0) == 0.0


def test_known_pair_by_hand() -> None:
    # a = (7, 6, 6), b = (6, 6, 6): sum ab = 114, sum(a^2 + b^2 - ab) = 43 + 36 + 36 = 115.
    assert explicability([1.0, 0.0, 0.0], [0.0, 0.0, 0.0], 6.0) == pytest.approx(1.0 / 115.0,
                                                                              abs=1e-15)
    # a = (3, 9), b = (9, 3): sum ab = 54, sum(...) = 2 * (9 + 81 - 27) = 126 -> E = 72/126.
    assert explicability([-3.0, 3.0], [3.0, -3.0], 6.0) == pytest.approx(72.0 / 126.0, abs=1e-15)


def test_score_is_symmetric_and_grows_with_distance() -> None:
    base = [0.5, 0.5, 0.5]
    scores = [explicability(base, [0.5 + d] * 3, 6.0) for d in (0.0, 0.5, 1.0, 2.0)]
    assert scores == sorted(scores) and scores[0] == 0.0 and scores[-1] > scores[1]
    swapped = explicability([1.5] * 3, base, 6.0)
    assert explicability(base, [1.5] * 3, 6.0) == pytest.approx(swapped)


def test_casadi_expression_equals_float() -> None:
    u, e = ca.SX.sym('u', 3), ca.SX.sym('e', 3)
    fn = ca.Function('E', [u, e], [explicability([u[k] for k in range(3)],
                                                 [e[k] for k in range(3)], 6.0)])
    plan, expected = [1.2, -0.4, 2.5], [0.1, 0.1, -2.0]
    assert float(fn(plan, expected)) == pytest.approx(explicability(plan, expected, 6.0),
                                                      abs=1e-15)


def test_plans_of_different_length_are_rejected() -> None:
    with pytest.raises(ValueError, match='same non-zero length'):
        explicability([1.0, 2.0], [1.0], 6.0)


def test_performance_and_trust_input_around_threshold() -> None:
    assert performance(0.0) == 1.0
    assert performance(0.5) == pytest.approx(1.0 - math.tanh(0.5))
    assert trust_input(0.8, 0.8) == 0.8          # P >= P_thre: u_T = P
    assert trust_input(0.95, 0.8) == 0.95
    assert trust_input(0.79, 0.8) == pytest.approx(-0.21)   # else u_T = -(1 - P)
    at_threshold = math.atanh(0.2)               # E where P = 0.8
    assert trust_step(1.0, at_threshold - 1e-9, CONFIG) == pytest.approx(1.0 + 0.1 * 0.8)
    assert trust_step(1.0, at_threshold + 1e-9, CONFIG) == pytest.approx(1.0 - 0.1 * 0.2)
    assert trust_step(2.0, 0.0, CONFIG) == pytest.approx(2.1)


def test_estimator_accumulates_updates() -> None:
    est = TrustEstimator(CONFIG)
    first = est.step([1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    assert first.explicability == pytest.approx(1 / 115)
    assert first.performance == pytest.approx(1 - math.tanh(1 / 115))
    assert first.trust == pytest.approx(0.1 * first.performance)
    second = est.step([0.0] * 3, [0.0] * 3)
    assert second.trust == pytest.approx(first.trust + 0.1)


@pytest.mark.parametrize('trust', [-1.0, -0.15, -0.05, 0.0, 0.01, 0.05, 0.1, 0.5, 3.0])
@pytest.mark.parametrize('trust_min', [0.0, 0.2])
def test_explicability_bound_is_the_propagated_constraint(trust: float, trust_min: float) -> None:
    """E <= E_max holds exactly when every propagated T^k >= T_min (k = 1..N)."""
    bound = paper_explicability_bound(trust, trust_min, CONFIG, 3)
    for score in np.linspace(0.0, 0.999, 2000):
        propagated_ok = min(propagate_trust(trust, float(score), CONFIG, 3)) >= trust_min
        bound_ok = bound is not None and score <= bound
        if abs(score - (bound or 0.0)) > 1e-9:  # exclude the boundary point itself
            assert propagated_ok == bound_ok, (trust, trust_min, score, bound)


def test_bound_is_none_when_trust_cannot_recover() -> None:
    assert paper_explicability_bound(-0.2, 0.0, CONFIG, 3) is None   # needs u_T >= 2 > 1
    assert paper_explicability_bound(10.0, 0.0, CONFIG, 3) == math.inf


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match='performance_threshold'):
        TrustConfig(epsilon_mps2=6.0, trust_growth_rate=0.1, performance_threshold=1.5,
                    trust_initial=0.0)
    with pytest.raises(ValueError, match='epsilon_mps2'):
        TrustConfig(epsilon_mps2=0.0, trust_growth_rate=0.1, performance_threshold=0.8,
                    trust_initial=0.0)
