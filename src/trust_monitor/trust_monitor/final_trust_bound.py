"""A lower bound on the final trust that eqs. (9)-(11) allow for a given mean E.

Pure (no ROS, no wall clock). Everything here follows from the trust update alone, so it
holds for any epsilon and any definition of the explicability score E >= 0.

Derivation (Ozkan & Ma, eqs. 9-11; docs/MODEL.md, "What eqs. (9)-(11) allow"):

* Per-step shortfall. With ``P = 1 - tanh E`` and ``u_T = P`` if ``P >= P_thre`` else
  ``-(1 - P)``, a step adds ``delta * u_T = delta * (1 - s(E))`` to the trust, where
  ``s(E) = 1 - u_T`` is ``tanh E`` for ``E <= E*`` and ``1 + tanh E`` for ``E > E*``,
  with ``E* = atanh(1 - P_thre)`` (0.2027 at P_thre = 0.8).
* The constant. ``tanh E / E < 1`` for E > 0, and ``(1 + tanh E) / E`` decreases on
  E > 0 (its derivative has the sign of ``E sech^2 E - 1 - tanh E`` < 0, since
  ``E sech^2 E <= 0.45``). So ``c = sup_{E>0} s(E)/E = max(1, (2 - P_thre) / E*)``,
  approached just above E* (c = 1.2 / 0.2027 = 5.919 at P_thre = 0.8) and never
  attained.
* The bound. ``s(E) <= c E``; summing M steps,
  ``T_M = T_0 + delta (M - sum s(E_t)) >= T_0 + delta M (1 - c mean(E))``.
  The sharp form replaces ``c mean(E)`` by the concave envelope of s, ``s_hat(m) = c m``
  for ``m <= E*`` and ``1 + tanh m`` beyond (where ``c m`` would be loose); for every
  row of the paper's Tables II-III (mean E <= 0.065 < E*) the two are the same.
* Tightness. ``k = floor(M mean(E) / E*)`` steps just above E* and the rest of the E mass
  spread thinly over the other steps end within ``delta (1 + tanh E* - E*) <= delta`` of
  the bound (``tests/support/trust_reference.py`` builds that sequence).
* T_0 enters additively. M matters through ``delta M (1 - c mean(E))``: for
  ``mean(E) < 1/c`` the bound grows with M, so the fewest plausible steps give the most
  lenient bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from trust_monitor.paper_trust import performance, trust_input

__all__ = ['row_bound', 'score_threshold', 'shortfall',
           'shortfall_constant', 'trust_lower_bound', 'warmup_bounds']

# Largest shortfall of one step for any E >= 0: 1 + tanh E < 2.
SHORTFALL_SUP = 2.0


def _check_threshold(performance_threshold: float) -> None:
    if not 0.0 < performance_threshold < 1.0:
        raise ValueError(f'performance_threshold must be in (0, 1), got {performance_threshold}')


def score_threshold(performance_threshold: float) -> float:
    """E* = atanh(1 - P_thre): the largest E whose step still raises trust.

    Args:
        performance_threshold: P_thre of eq. (11), dimensionless in (0, 1).

    Returns:
        E*, dimensionless (0.2027 at P_thre = 0.8).

    Raises:
        ValueError: P_thre outside (0, 1).
    """
    _check_threshold(performance_threshold)
    return math.atanh(1.0 - performance_threshold)


def shortfall(score: float, performance_threshold: float) -> float:
    """Per-step shortfall s(E) = 1 - u_T(E) of eqs. (9)-(11), from the trust model itself.

    Args:
        score: explicability score E >= 0, dimensionless.
        performance_threshold: P_thre of eq. (11).

    Returns:
        s(E) in [0, 2): the step adds delta * (1 - s(E)) to the trust.

    Raises:
        ValueError: E negative or not finite, or P_thre outside (0, 1).
    """
    _check_threshold(performance_threshold)
    if not (math.isfinite(score) and score >= 0.0):
        raise ValueError(f'explicability score must be finite and >= 0, got {score}')
    return 1.0 - trust_input(performance(score), performance_threshold)


def max_shortfall(score_max: float, performance_threshold: float) -> float:
    """sup of s(E) over 0 <= E <= score_max (s is increasing on each branch).

    Args:
        score_max: the largest E allowed, > 0 (``math.inf`` for none).
        performance_threshold: P_thre.

    Returns:
        ``1 + tanh(score_max)`` above E* (2 for no limit), ``tanh(score_max)`` otherwise.
    """
    if math.isinf(score_max):
        return SHORTFALL_SUP
    return shortfall(score_max, performance_threshold)


def shortfall_constant(performance_threshold: float) -> float:
    """c(P_thre) = sup_{E>0} s(E)/E = max(1, (2 - P_thre) / atanh(1 - P_thre)).

    Below E*, ``s(E)/E = tanh(E)/E`` rises to 1 as E -> 0; above it ``(1 + tanh E)/E``
    decreases, so its supremum is the limit ``(1 + tanh E*)/E* = (2 - P_thre)/E*`` from
    above E*. The supremum is not attained.

    Args:
        performance_threshold: P_thre of eq. (11).

    Returns:
        c, dimensionless (5.919 at P_thre = 0.8).
    """
    e_star = score_threshold(performance_threshold)
    return max(1.0, (2.0 - performance_threshold) / e_star)


def shortfall_envelope(mean_score: float, performance_threshold: float) -> float:
    """Largest mean shortfall of any sequence of E >= 0 with the given mean.

    The concave envelope of s: ``c m`` up to E* and ``1 + tanh m`` beyond (the line from
    the origin touches ``1 + tanh E`` at E*, and ``1 + tanh`` is concave there). For
    ``m <= E*`` this is the ``c m`` of the bound; above it is sharper.

    Args:
        mean_score: mean E over the steps, >= 0.
        performance_threshold: P_thre of eq. (11).

    Returns:
        sup over sequences of mean(s(E_t)), dimensionless.
    """
    if not (math.isfinite(mean_score) and mean_score >= 0.0):
        raise ValueError(f'mean explicability score must be finite and >= 0, got {mean_score}')
    e_star = score_threshold(performance_threshold)
    c = shortfall_constant(performance_threshold)
    if mean_score <= e_star:
        return c * mean_score
    return 1.0 + math.tanh(mean_score)


def trust_lower_bound(mean_score: float, steps: int, trust_growth_rate: float,
                      performance_threshold: float, trust_initial: float = 0.0) -> float:
    """Lowest final trust eqs. (9)-(11) allow after ``steps`` updates with mean E.

    ``T_M >= T_0 + delta M (1 - s_hat(mean E))``, which is
    ``T_0 + delta M (1 - c mean E)`` for mean E <= E*. The infimum over all sequences: no
    sequence goes below it, and one (module docstring, "Tightness") comes within delta of it.

    Args:
        mean_score: mean E over the M steps, >= 0.
        steps: M, the number of trust updates, >= 1.
        trust_growth_rate: delta of eq. (10), trust units per step, > 0.
        performance_threshold: P_thre of eq. (11).
        trust_initial: T_0, trust units.

    Returns:
        The bound on T_M, trust units.

    Raises:
        ValueError: a non-positive step count or growth rate, or a bad E or P_thre.
    """
    if steps < 1:
        raise ValueError(f'steps must be >= 1, got {steps}')
    if not trust_growth_rate > 0.0:
        raise ValueError(f'trust_growth_rate must be > 0, got {trust_growth_rate}')
    envelope = shortfall_envelope(mean_score, performance_threshold)
    return trust_initial + trust_growth_rate * steps * (1.0 - envelope)


@dataclass(frozen=True)
class RowBound:
    """The bound applied to one printed table row.

    Attributes:
        final_trust: the printed final trust, trust units.
        mean_score: the mean E used (printed value, possibly rounded up).
        steps: M, trust updates.
        bound: lowest attainable final trust, trust units.
        attainable: whether the printed final trust is >= the bound.
        trust_initial_needed: the largest T_0 with which the printed trust would be
            attainable (printed minus the bound's gain), trust units.
        failing_mass_fraction: for an attainable row, the smallest fraction of the total
            E mass that must sit on steps with E > E* (NaN if unattainable).
        failing_steps: the number of steps just above E* that carry that mass.
    """

    final_trust: float
    mean_score: float
    steps: int
    bound: float
    attainable: bool
    trust_initial_needed: float
    failing_mass_fraction: float
    failing_steps: float


def row_bound(final_trust: float, mean_score: float, steps: int, trust_growth_rate: float,
              performance_threshold: float, trust_initial: float = 0.0) -> RowBound:
    """Apply the bound to a printed row (final trust, mean E) after M steps.

    The needed E mass above E*: the trust lost against ``T_0 + delta M`` is
    ``D = (T_0 + delta M - T) / delta`` shortfall units; steps at or below E* lose at most
    their E and steps above it at most c times their E, so a mass ``S_A`` above E* out of
    ``S = M mean(E)`` gives at most ``c S_A + (S - S_A)``, and ``S_A >= (D - S)/(c - 1)``.
    In the extremal sequence that mass sits on ``S_A / E*`` steps just above E*.

    Args:
        final_trust: printed final trust, trust units.
        mean_score: printed mean E (round it up yourself to be lenient), >= 0.
        steps: M >= 1.
        trust_growth_rate: delta, trust units per step.
        performance_threshold: P_thre.
        trust_initial: T_0, trust units.

    Returns:
        The :class:`RowBound`.
    """
    bound = trust_lower_bound(mean_score, steps, trust_growth_rate, performance_threshold,
                              trust_initial)
    attainable = final_trust >= bound
    needed = final_trust - (bound - trust_initial)
    fraction = math.nan
    failing = math.nan
    if attainable:
        c = shortfall_constant(performance_threshold)
        lost = (trust_initial + trust_growth_rate * steps - final_trust) / trust_growth_rate
        total = steps * mean_score
        mass_above = max(0.0, (lost - total) / (c - 1.0)) if c > 1.0 else 0.0
        fraction = mass_above / total if total > 0.0 else 0.0
        failing = mass_above / score_threshold(performance_threshold)
    return RowBound(final_trust, mean_score, steps, bound, attainable, needed, fraction,
                    failing)


def warmup_bounds(mean_score: float, steps: int, warmup_steps: int, trust_growth_rate: float,
                  performance_threshold: float, trust_initial: float = 0.0,
                  warmup_score_max: float = math.inf) -> dict[str, float]:
    """The bound under each reading of a W-step warm-up (the GRU's first 10 s).

    * ``none``: trust and mean E both over all M steps.
    * ``outside``: neither trust nor mean E counts the W warm-up steps (M - W updates).
    * ``trust_only``: trust over M steps, mean E printed over the last M - W; the E of a
      warm-up step is then unknown: it loses at most ``max_shortfall(warmup_score_max)``
      (< 2 for any E; 1 + tanh 1 = 1.76 if E <= 1, as for the Tanimoto distance).
    * ``score_only``: mean E over all M steps, trust over the last M - W only; the E mass
      of those M - W steps is at most M mean E.

    Args:
        mean_score: printed mean E, >= 0.
        steps: M, steps of the cycle.
        warmup_steps: W, 0 <= W < M.
        trust_growth_rate: delta.
        performance_threshold: P_thre.
        trust_initial: T_0.
        warmup_score_max: the largest E a warm-up step may have (``trust_only`` only).

    Returns:
        Variant name to its bound, trust units.
    """
    if not 0 <= warmup_steps < steps:
        raise ValueError(f'warmup_steps must be in [0, {steps}), got {warmup_steps}')
    delta = trust_growth_rate
    after = steps - warmup_steps
    bounds = {'none': trust_lower_bound(mean_score, steps, delta, performance_threshold,
                                        trust_initial)}
    if warmup_steps == 0:
        return bounds
    bounds['outside'] = trust_lower_bound(mean_score, after, delta, performance_threshold,
                                          trust_initial)
    bounds['trust_only'] = (bounds['outside'] + delta * warmup_steps
                            * (1.0 - max_shortfall(warmup_score_max, performance_threshold)))
    # The last M - W steps hold E mass <= M m, i.e. a mean <= M m / (M - W) over them.
    bounds['score_only'] = trust_lower_bound(mean_score * steps / after, after, delta,
                                             performance_threshold, trust_initial)
    return bounds
