"""Print the final-trust bound for every row of the paper's Tables II and III (Markdown).

Usage: python scripts/paper_bound_table.py
The numbers of docs/RESULTS.md, "What the paper's equations allow", come from this script.
The bound and its readings are in ``trust_monitor.final_trust_bound``; the paper's rows in
``trust_av.study.paper_results``.
"""

from __future__ import annotations

import math

from trust_av.study.paper_results import TABLE_II_TAC_GRU_US06, TABLE_III_TAC_CA_US06
from trust_monitor.final_trust_bound import (
    row_bound,
    score_threshold,
    shortfall_constant,
    warmup_bounds,
)

DELTA = 0.1  # Section III-C
P_THRE = 0.8  # Section III-C
STEPS = 600  # our US06 trace: 601 samples at 1 Hz
STEPS_LENIENT = 596  # EPA's US06 is 596 s long; fewer steps lower the bound
ROUND_UP = 0.0005  # the paper prints mean E to 3 decimals
WARMUP = 10  # the GRU's H = 10 s of history (Section III-B)


def verdict(trust: float, bound: float) -> str:
    return 'attainable' if trust >= bound else '**unattainable**'


def corner(trust: float, mean_score: float, steps: int) -> str:
    """How an attainable row has to look: share of E mass just above E*, on how many steps."""
    row = row_bound(trust, mean_score, steps, DELTA, P_THRE)
    if not row.attainable:
        return ''
    return f'{100 * row.failing_mass_fraction:.1f} % on {row.failing_steps:.0f} steps'


def threshold_needed(trust: float, mean_score: float) -> float:
    """Smallest P_thre (bisection, >= the paper's) at which the row becomes attainable."""
    low, high = P_THRE, 0.999
    if trust >= row_bound(trust, mean_score, STEPS, DELTA, low).bound:
        return low
    for _ in range(60):
        middle = 0.5 * (low + high)
        if trust >= row_bound(trust, mean_score, STEPS, DELTA, middle).bound:
            high = middle
        else:
            low = middle
    return high


def main() -> None:
    e_star = score_threshold(P_THRE)
    c = shortfall_constant(P_THRE)
    print(f'E* = atanh(1 - {P_THRE}) = {e_star:.4f}, c = (2 - {P_THRE}) / E* = {c:.4f}, '
          f'delta = {DELTA}\n')
    print('| table | alpha | paper T | paper mean E | bound, M = 600 | verdict | T_0 needed '
          '| bound, M = 596, mean E + 0.0005 | verdict '
          '| E mass just above E* needed (M = 600; lenient) |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for name, table in (('II (GRU)', TABLE_II_TAC_GRU_US06), ('III (CA)', TABLE_III_TAC_CA_US06)):
        for alpha, (trust, mean_score, _) in table.items():
            exact = row_bound(trust, mean_score, STEPS, DELTA, P_THRE)
            lenient = row_bound(trust, mean_score + ROUND_UP, STEPS_LENIENT, DELTA, P_THRE)
            needed = '; '.join(filter(None, (
                corner(trust, mean_score, STEPS),
                corner(trust, mean_score + ROUND_UP, STEPS_LENIENT))))
            print(f'| {name} | {alpha:g} | {trust:.3f} | {mean_score:.3f} | {exact.bound:.3f} '
                  f'| {verdict(trust, exact.bound)} | {exact.trust_initial_needed:+.2f} '
                  f'| {lenient.bound:.3f} | {verdict(trust, lenient.bound)} '
                  f'| {needed} |')
    rows = TABLE_II_TAC_GRU_US06.values()
    print('\nTable II at M = 600 would need P_thre >= '
          + ', '.join(f'{threshold_needed(t, e):.4f}' for t, e, _ in rows)
          + ' or at most M = '
          + ', '.join(f'{math.floor(t / (DELTA * (1.0 - c * e)))}' for t, e, _ in rows)
          + ' steps (alpha = 0 ... 1)')
    print('\nTable II with the GRU warm-up of 10 steps (M = 596, mean E + 0.0005):\n')
    print('| alpha | paper T | warm-up outside trust and mean E | in mean E, not in trust '
          '| in trust, not in mean E, E <= 1 | in trust, not in mean E, any E '
          '| mean shortfall each warm-up step needs (in trust, not in mean E) |')
    print('|---|---|---|---|---|---|---|')
    for alpha, (trust, mean_score, _) in TABLE_II_TAC_GRU_US06.items():
        score = mean_score + ROUND_UP
        any_e = warmup_bounds(score, STEPS_LENIENT, WARMUP, DELTA, P_THRE)
        e_le_1 = warmup_bounds(score, STEPS_LENIENT, WARMUP, DELTA, P_THRE,
                               warmup_score_max=1.0)
        # Trust-only reading: the W warm-up steps must lose this much each on average.
        per_step = 1.0 + (any_e['outside'] - trust) / (DELTA * WARMUP)
        cells = [f'{b:.3f} ({verdict(trust, b)})' for b in
                 (any_e['outside'], any_e['score_only'], e_le_1['trust_only'],
                  any_e['trust_only'])]
        print(f'| {alpha:g} | {trust:.3f} | ' + ' | '.join(cells)
              + f' | {max(per_step, 0.0):.2f} |')
    outside = [row_bound(t, e + ROUND_UP, STEPS_LENIENT - WARMUP, DELTA, P_THRE)
               for t, e, _ in TABLE_II_TAC_GRU_US06.values()]
    print('\nOutside-warm-up reading, attainable rows need (E mass above E*, steps): '
          + ', '.join(f'{100 * r.failing_mass_fraction:.1f} % on {r.failing_steps:.0f}'
                      for r in outside if r.attainable and not math.isnan(r.failing_steps)))


if __name__ == '__main__':
    main()
