"""The paper's reported numbers (Ozkan & Ma, Tables II-IV), for side-by-side comparison.

Transcribed from ``shared/paper/trust_aware_control_ozkan_ma.md``. "Experiment 1/2" are the
paper's unpublished commute trips; our stand-ins are the traces ``commute_am``/``commute_pm``.
"""

from __future__ import annotations

__all__ = ['MAX_IMPROVEMENT_PERCENT', 'TABLE_III_TAC_CA_US06', 'TABLE_II_TAC_GRU_US06',
           'TRACE_LABELS']

# (final trust, average explicability score, RMSE m/s^2) per alpha, US06.
TABLE_II_TAC_GRU_US06 = {
    0.0: (44.360, 0.038, 0.518), 0.25: (49.160, 0.024, 0.435), 0.5: (51.707, 0.019, 0.393),
    0.75: (52.500, 0.016, 0.367), 1.0: (53.402, 0.015, 0.353),
}
TABLE_III_TAC_CA_US06 = {
    0.0: (38.141, 0.065, 0.724), 0.25: (44.991, 0.041, 0.616), 0.5: (47.611, 0.034, 0.570),
    0.75: (48.762, 0.031, 0.537), 1.0: (49.539, 0.028, 0.513),
}
# Maximum improvement (%) of (final trust, mean E, RMSE) per (predictor, trace).
MAX_IMPROVEMENT_PERCENT = {
    ('gru', 'us06'): (20.38, 59.27, 31.87),
    ('ca', 'us06'): (29.88, 56.37, 29.22),
    ('gru', 'nycc'): (20.12, 66.55, 39.33),
    ('gru', 'commute_am'): (9.72, 72.78, 45.25),
    ('gru', 'commute_pm'): (9.89, 73.81, 45.16),
    ('ca', 'nycc'): (24.01, 48.87, 48.87),
    ('ca', 'commute_am'): (7.59, 36.36, 57.48),
    ('ca', 'commute_pm'): (8.78, 36.68, 60.52),
}
TRACE_LABELS = {'us06': 'US06', 'nycc': 'NYCC', 'commute_am': 'Commute am (Experiment 1)',
                'commute_pm': 'Commute pm (Experiment 2)'}
