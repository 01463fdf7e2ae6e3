"""The final-trust bound of eqs. (9)-(11): no sequence of E beats it, one comes within 1 %.

Sequences are run through the real :func:`trust_monitor.paper_trust.trust_step`, not
through the bound module's own shortfall, so the bound is checked against the model.
The paper's rows (Tables II and III) are taken from ``paper_results``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.trust_reference import extremal_scores, lenient_row_bound

from trust_av.study.paper_results import TABLE_II_TAC_GRU_US06, TABLE_III_TAC_CA_US06
from trust_monitor.final_trust_bound import (
    row_bound,
    score_threshold,
    shortfall,
    shortfall_constant,
    trust_lower_bound,
    warmup_bounds,
)
from trust_monitor.paper_trust import TrustConfig, trust_step

DELTA = 0.1  # paper, Section III-C
P_THRE = 0.8  # paper, Section III-C
US06_STEPS = range(596, 601)  # EPA's 596 s to our trace's 600 steps
GRU_WARMUP_STEPS = 10  # H = 10 s of history before the GRU predicts (Section III-B)


def run_trust(scores: list[float], delta: float, p_thre: float, trust_initial: float) -> float:
    config = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=delta,
                         performance_threshold=p_thre, trust_initial=trust_initial)
    trust = trust_initial
    for score in scores:
        trust = trust_step(trust, score, config)
    return trust


def test_constant_is_the_supremum_of_shortfall_over_score() -> None:
    for p_thre in (0.3, 0.5, 0.8, 0.9):
        c = shortfall_constant(p_thre)
        grid = np.concatenate([np.linspace(1e-6, 3.0, 30001),
                               score_threshold(p_thre) + np.geomspace(1e-12, 1e-3, 200)])
        ratios = [shortfall(float(e), p_thre) / float(e) for e in grid]
        assert max(ratios) <= c  # never attained ...
        assert max(ratios) >= c * (1.0 - 1e-9)  # ... but approached just above E*


def test_constant_at_the_papers_threshold() -> None:
    # E* = atanh(0.2), c = (1 + 0.2) / E*: the two numbers the issue quotes, recomputed.
    assert score_threshold(P_THRE) == pytest.approx(0.2027, abs=5e-5)
    assert shortfall_constant(P_THRE) == pytest.approx(5.919, abs=5e-4)


def test_shortfall_is_the_models_step() -> None:
    config = TrustConfig(epsilon_mps2=6.0, trust_growth_rate=DELTA,
                         performance_threshold=P_THRE, trust_initial=0.0)
    e_star = score_threshold(P_THRE)
    for score in (0.0, 0.05, e_star, e_star + 1e-9, 0.5, 3.0):
        step = trust_step(10.0, score, config) - 10.0
        assert step == pytest.approx(DELTA * (1.0 - shortfall(score, P_THRE)), abs=1e-15)
    assert shortfall(e_star, P_THRE) == pytest.approx(0.2)  # P = P_thre still gains
    assert shortfall(e_star + 1e-9, P_THRE) == pytest.approx(1.2)


def test_bad_input_is_refused() -> None:
    with pytest.raises(ValueError, match='explicability score'):
        shortfall(-0.1, P_THRE)
    with pytest.raises(ValueError, match='performance_threshold'):
        shortfall_constant(1.0)
    with pytest.raises(ValueError, match='steps'):
        trust_lower_bound(0.01, 0, DELTA, P_THRE)
    with pytest.raises(ValueError, match='warmup_steps'):
        warmup_bounds(0.01, 10, 10, DELTA, P_THRE)


def _scores() -> st.SearchStrategy[float]:
    # Plain E in [0, 3], plus E just either side of the threshold where the bound is tight.
    near = st.floats(-1e-6, 1e-6).map(lambda x: max(0.0, score_threshold(P_THRE) + x))
    return st.one_of(st.floats(0.0, 3.0), st.floats(0.0, 0.3), near)


@settings(max_examples=300, deadline=None)
@given(scores=st.lists(_scores(), min_size=1, max_size=400),
       delta=st.floats(0.01, 1.0), trust_initial=st.floats(-10.0, 10.0))
def test_no_sequence_ends_below_the_bound(scores: list[float], delta: float,
                                          trust_initial: float) -> None:
    final = run_trust(scores, delta, P_THRE, trust_initial)
    bound = trust_lower_bound(math.fsum(scores) / len(scores), len(scores), delta, P_THRE,
                              trust_initial)
    assert final >= bound - 1e-9 * len(scores)


@settings(max_examples=200, deadline=None)
@given(scores=st.lists(st.floats(0.0, 2.0), min_size=1, max_size=200),
       p_thre=st.floats(0.05, 0.95))
def test_no_sequence_ends_below_the_bound_for_any_threshold(scores: list[float],
                                                            p_thre: float) -> None:
    final = run_trust(scores, DELTA, p_thre, 0.0)
    bound = trust_lower_bound(math.fsum(scores) / len(scores), len(scores), DELTA, p_thre)
    assert final >= bound - 1e-9 * len(scores)


@settings(max_examples=200, deadline=None)
@given(steps=st.integers(100, 2000), mean_score=st.floats(0.0, 1.0),
       p_thre=st.floats(0.5, 0.95), delta=st.floats(0.01, 1.0))
def test_the_bound_is_tight(steps: int, mean_score: float, p_thre: float,
                            delta: float) -> None:
    scores = extremal_scores(mean_score, steps, p_thre)
    assert len(scores) == steps
    assert math.fsum(scores) / steps == pytest.approx(mean_score, rel=1e-9, abs=1e-12)
    final = run_trust(scores, delta, p_thre, 0.0)
    bound = trust_lower_bound(mean_score, steps, delta, p_thre)
    gap = final - bound
    assert -1e-9 * steps <= gap <= delta * (1.0 + 1e-6)  # within one step's delta
    if bound >= 100.0 * delta:
        assert gap <= 0.01 * bound  # within 1 % of the bound


def test_tight_on_every_paper_row() -> None:
    rows = list(TABLE_II_TAC_GRU_US06.values()) + list(TABLE_III_TAC_CA_US06.values())
    for _, mean_score, _ in rows:
        scores = extremal_scores(mean_score, 600, P_THRE)
        final = run_trust(scores, DELTA, P_THRE, 0.0)
        bound = trust_lower_bound(mean_score, 600, DELTA, P_THRE)
        assert bound <= final <= bound * 1.01


def test_bound_for_the_issues_example_row() -> None:
    # Table II, alpha = 0: mean E 0.038 after 600 steps -> T >= 60 (1 - 5.919 * 0.038).
    assert trust_lower_bound(0.038, 600, DELTA, P_THRE) == pytest.approx(46.50, abs=5e-3)


def test_table_ii_is_unattainable_for_every_step_count_and_rounding() -> None:
    for alpha, (trust, mean_score, _) in TABLE_II_TAC_GRU_US06.items():
        assert not row_bound(trust, mean_score, 600, DELTA, P_THRE).attainable, alpha
        lenient = lenient_row_bound(trust, mean_score, US06_STEPS, DELTA, P_THRE,
                                    round_up=0.0005)
        assert (lenient.steps, lenient.variant) == (596, 'none')
        assert not lenient.attainable, alpha


def _warmup_verdicts(steps: int, round_up: float, **kwargs: float) -> dict[str, list[bool]]:
    verdicts: dict[str, list[bool]] = {}
    for trust, mean_score, _ in TABLE_II_TAC_GRU_US06.values():
        bounds = warmup_bounds(mean_score + round_up, steps, GRU_WARMUP_STEPS, DELTA, P_THRE,
                               **kwargs)
        for variant, bound in bounds.items():
            verdicts.setdefault(variant, []).append(trust >= bound)
    return verdicts


def test_table_ii_with_the_gru_warmup() -> None:
    # alpha = 0, 0.25, 0.5, 0.75, 1. At 600 steps and the printed mean E, a warm-up left out
    # of trust, of mean E or of both leaves every row unattainable.
    exact = _warmup_verdicts(600, 0.0, warmup_score_max=1.0)
    assert exact == {'none': [False] * 5, 'outside': [False] * 5, 'score_only': [False] * 5,
                     'trust_only': [False, False, True, False, True]}
    # With 596 steps and mean E rounded up, alpha = 1 becomes attainable without the warm-up
    # in trust, and alpha >= 0.5 when the warm-up is in trust but not in mean E (E <= 1).
    lenient = _warmup_verdicts(596, 0.0005, warmup_score_max=1.0)
    assert lenient == {'none': [False] * 5, 'outside': [False] * 4 + [True],
                       'score_only': [False] * 4 + [True],
                       'trust_only': [False, False, True, True, True]}
    # E without limit on the 10 warm-up steps (each loses almost 2 delta): all attainable.
    assert _warmup_verdicts(596, 0.0005)['trust_only'] == [True] * 5


def test_table_iii_verdicts() -> None:
    exact = {a: row_bound(t, e, 600, DELTA, P_THRE) for a, (t, e, _) in
             TABLE_III_TAC_CA_US06.items()}
    assert {a: r.attainable for a, r in exact.items()} == {
        0.0: True, 0.25: False, 0.5: False, 0.75: False, 1.0: False}
    # alpha = 0 needs ~94 % of all E mass on ~180 steps just above E*.
    assert exact[0.0].failing_mass_fraction == pytest.approx(0.936, abs=1e-3)
    assert exact[0.0].failing_steps == pytest.approx(180.1, abs=0.1)
    lenient = {a: lenient_row_bound(t, e, US06_STEPS, DELTA, P_THRE, round_up=0.0005)
               for a, (t, e, _) in TABLE_III_TAC_CA_US06.items()}
    assert {a: r.attainable for a, r in lenient.items()} == {
        0.0: True, 0.25: True, 0.5: True, 0.75: True, 1.0: False}
