"""The observation model from a trust model's trust to the rating scale, fitted with it
(:mod:`trust_monitor.trust_fit`): ``linear`` (default), ``rating / 100 = a + b T + e``,
``b >= 0``; ``direct`` (a model whose trust is itself a probability of trusting),
``rating / 100 = T + e``; ``e ~ N(0, s^2)`` in both. For given trust a, b and s have
closed-form maximum-likelihood values (least squares), so a fit profiles them out exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ['MIN_RATING_STD', 'OBSERVATIONS', 'Observation', 'fit_observation', 'log_density']

OBSERVATIONS = ('linear', 'direct')
MIN_RATING_STD = 0.5 / 100.0
"""The observation noise s is at least half a rating point (ratings are whole numbers)."""


@dataclass(frozen=True)
class Observation:
    """Fitted observation model: rating / 100 = a + b T + N(0, s^2)."""

    a: float
    b: float
    s: float

    def mean(self, trust: np.ndarray) -> np.ndarray:
        """Predicted rating / 100."""
        return self.a + self.b * np.asarray(trust)


def fit_observation(kind: str, trust: np.ndarray, y: np.ndarray) -> Observation:
    """Least-squares (= maximum likelihood) a, b >= 0 and s for ratings / 100 ``y``."""
    if kind == 'direct':
        a, b = 0.0, 1.0
    else:
        spread = float(np.var(trust))
        b = (float(np.mean((trust - trust.mean()) * (y - y.mean()))) / spread
             if spread > 1e-12 else 0.0)
        b = max(b, 0.0)
        a = float(y.mean() - b * trust.mean())
    s = math.sqrt(float(np.mean((y - a - b * trust) ** 2)))
    return Observation(a, b, max(s, MIN_RATING_STD))


def log_density(obs: Observation, trust: np.ndarray, ratings: np.ndarray) -> np.ndarray:
    """Pointwise log density of ratings (0-100 scale) under the observation model."""
    sd = 100.0 * obs.s
    z = (np.asarray(ratings) - 100.0 * obs.mean(trust)) / sd
    result: np.ndarray = -0.5 * z * z - math.log(sd * math.sqrt(2.0 * math.pi))
    return result
