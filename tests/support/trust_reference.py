"""Independent references the tests check the trust model and its final-trust bound
against (not production code: nothing in src/ needs them).

* :func:`propagate_trust`: trust propagated step by step with eq. (10), against which the
  closed form :func:`trust_monitor.paper_trust.paper_explicability_bound` is checked.
* :func:`extremal_scores`: a score sequence whose final trust comes within delta of
  :func:`trust_monitor.final_trust_bound.trust_lower_bound` (the bound is tight).
* :func:`lenient_row_bound`: the most lenient bound over the readings of a printed paper
  row (step counts, rounding, warm-up), to check the paper's tables.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from trust_monitor.final_trust_bound import score_threshold, warmup_bounds
from trust_monitor.paper_trust import TrustConfig, trust_step


def propagate_trust(trust: float, score: float, config: TrustConfig, steps: int,
                    dt_s: float = 1.0) -> list[float]:
    """Trust over a horizon of ``steps`` steps of ``dt_s`` if the plan with score E were
    kept: T^1..T^steps."""
    out = []
    for _ in range(steps):
        trust = trust_step(trust, score, config, dt_s)
        out.append(trust)
    return out


def extremal_scores(mean_score: float, steps: int, performance_threshold: float,
                    above: float = 1e-9) -> list[float]:
    """A sequence of E with the given mean whose final trust comes within delta of the bound.

    For a mean m <= E*: ``k = floor(M m / (E* + above))`` steps at ``E* + above`` (each
    loses ``1 + tanh E*`` = c E*, the most per unit of E), the remaining mass r < E* + above
    spread evenly over the other ``M - k`` steps (each loses about its E, ``tanh x ~ x``).
    Against the bound this gives away at most ``(c - 1) r``, below
    ``1 + tanh E* - E*`` <= 1 shortfall unit: delta in trust. For m > E*: every step at m,
    which is exactly the envelope.

    Args:
        mean_score: target mean E, >= 0.
        steps: M >= 1.
        performance_threshold: P_thre of eq. (11).
        above: how far above E* the failing steps sit (must fail in floating point).

    Returns:
        M scores whose mean is ``mean_score`` up to rounding.

    Raises:
        ValueError: a step count below 1 or a bad mean E or P_thre.
    """
    if steps < 1:
        raise ValueError(f'steps must be >= 1, got {steps}')
    if not (math.isfinite(mean_score) and mean_score >= 0.0):
        raise ValueError(f'mean explicability score must be finite and >= 0, got {mean_score}')
    e_star = score_threshold(performance_threshold)
    if mean_score > e_star:
        return [mean_score] * steps
    total = mean_score * steps
    fail = e_star + above
    k = int(total // fail)  # < M, since total <= M E* < M fail
    rest = steps - k
    remainder = total - k * fail
    return [fail] * k + [remainder / rest] * rest


@dataclass(frozen=True)
class LenientBound:
    """The most lenient bound over the readings of a row that the paper leaves open.

    Attributes:
        bound: the smallest bound over every variant, trust units.
        steps: M of that variant.
        mean_score: the (rounded-up) mean E of that variant.
        variant: which warm-up reading gave it (see :func:`lenient_row_bound`).
        attainable: printed final trust >= bound.
    """

    bound: float
    steps: int
    mean_score: float
    variant: str
    attainable: bool


def lenient_row_bound(final_trust: float, mean_score: float, steps_options: Iterable[int],
                      trust_growth_rate: float, performance_threshold: float, *,
                      round_up: float = 0.0, warmup_steps: int = 0,
                      trust_initial: float = 0.0,
                      warmup_score_max: float = math.inf) -> LenientBound:
    """The smallest bound for a row over step counts, rounding and warm-up readings.

    Args:
        final_trust: printed final trust.
        mean_score: printed mean E.
        steps_options: candidate M (e.g. 596..600 for US06).
        trust_growth_rate: delta.
        performance_threshold: P_thre.
        round_up: added to the printed mean E (0.0005 for a value printed to 3 decimals).
        warmup_steps: W; 0 for no warm-up.
        trust_initial: T_0.
        warmup_score_max: the largest E of a warm-up step left out of the printed mean.

    Returns:
        The :class:`LenientBound` of the most lenient combination.
    """
    best: LenientBound | None = None
    score = mean_score + round_up
    for steps in steps_options:
        bounds = warmup_bounds(score, steps, warmup_steps, trust_growth_rate,
                               performance_threshold, trust_initial, warmup_score_max)
        for variant, bound in bounds.items():
            if best is None or bound < best.bound:
                best = LenientBound(bound, steps, score, variant, final_trust >= bound)
    if best is None:
        raise ValueError('steps_options is empty')
    return best
