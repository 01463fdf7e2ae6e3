"""Means with 95 % confidence intervals (Student's t), one rule for every table.

The quantile is scipy's (``scipy.stats.t.ppf``). One value has no spread to estimate: its
half-width is nan, and tables print such a cell as the mean alone with ``n = 1``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ['mean_ci95', 't_quantile_975']


def t_quantile_975(dof: int) -> float:
    """The 0.975 quantile of Student's t (two-sided 95 %): 12.706 for 1 degree of freedom,
    2.093 for 19, 1.960 as ``dof`` grows.

    Raises:
        ValueError: ``dof`` < 1.
    """
    if dof < 1:
        raise ValueError(f'degrees of freedom must be >= 1, got {dof}')
    # imported here: scipy.stats takes ~0.6 CPU-s to import, and every start of trust-av
    # imports this module (through the reproduce command's parser)
    from scipy import stats

    return float(stats.t.ppf(0.975, dof))


def mean_ci95(values: Sequence[float]) -> tuple[float, float]:
    """Sample mean and the half-width of its 95 % confidence interval (t, n - 1 dof).

    One value gives a half-width of nan: no spread can be estimated from it.

    Raises:
        ValueError: no values, or a value that is not finite.
    """
    data = np.asarray(values, dtype=float)
    if data.size == 0:
        raise ValueError('mean_ci95 needs at least one value')
    if not np.all(np.isfinite(data)):
        raise ValueError(f'mean_ci95 got a value that is not finite: {data.tolist()}')
    if data.size == 1:
        return float(data[0]), math.nan
    sem = float(np.std(data, ddof=1)) / math.sqrt(data.size)
    return float(np.mean(data)), t_quantile_975(data.size - 1) * sem
