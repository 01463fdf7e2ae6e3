"""Small statistics for driver populations: mean and 95 % confidence interval (Student t).

numpy only (no scipy in the project): the t quantile is found by bisection on the t CDF,
which is integrated numerically from the density (Simpson's rule); accurate to about 1e-6
for every degree of freedom >= 1.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

_SIMPSON_INTERVALS = 4000
_BISECTION_STEPS = 60


def _t_cdf_upper_half(x: float, dof: int) -> float:
    """P(0 <= T <= x) for Student's t with ``dof`` degrees of freedom, x >= 0."""
    log_norm = (math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2)
                - 0.5 * math.log(dof * math.pi))
    grid = np.linspace(0.0, x, _SIMPSON_INTERVALS + 1)
    density = np.exp(log_norm - (dof + 1) / 2 * np.log1p(grid ** 2 / dof))
    weights = np.ones_like(grid)
    weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0
    return float(x / (3 * _SIMPSON_INTERVALS) * np.dot(weights, density))


def t_quantile_975(dof: int) -> float:
    """The 0.975 quantile of Student's t (two-sided 95 %), e.g. 12.706 for 1, 2.093 for 19.

    Raises:
        ValueError: ``dof`` < 1.
    """
    if dof < 1:
        raise ValueError(f'degrees of freedom must be >= 1, got {dof}')
    low, high = 0.0, 64.0  # t(1) quantile is 12.7
    for _ in range(_BISECTION_STEPS):
        mid = 0.5 * (low + high)
        if _t_cdf_upper_half(mid, dof) < 0.475:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)


def mean_ci95(values: Sequence[float]) -> tuple[float, float]:
    """Sample mean and the half-width of its 95 % confidence interval (t, n - 1 dof).

    One value gives a half-width of 0 (no spread can be estimated).

    Raises:
        ValueError: no values, or a value that is not finite.
    """
    data = np.asarray(values, dtype=float)
    if data.size == 0:
        raise ValueError('mean_ci95 needs at least one value')
    if not np.all(np.isfinite(data)):
        raise ValueError(f'mean_ci95 got a value that is not finite: {data.tolist()}')
    if data.size == 1:
        return float(data[0]), 0.0
    sem = float(np.std(data, ddof=1)) / math.sqrt(data.size)
    return float(np.mean(data)), t_quantile_975(data.size - 1) * sem
