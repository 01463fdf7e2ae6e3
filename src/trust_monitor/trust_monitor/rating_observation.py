"""The observation model from a trust model's trust to the rating scale, fitted with it
(:mod:`trust_monitor.trust_fit`): ``linear`` (default), ``rating / 100 = a + b T + e``,
``b >= 0``; ``direct`` (a model whose trust is itself a probability of trusting),
``rating / 100 = T + e``; ``e ~ N(0, s^2)`` in both, censored at the scale's ends (a Tobit
model, Tobin 1958): the scale stops at 0 and 100, so a rating of 0 says only that the
latent rating is at or below 0 (probability ``Phi(-mean / s)``) and a rating of 100 that
it is at or above 100 (``Phi((mean - 1) / s)``); every other rating has the Gaussian
density.

Fitting a, b and s for given trust:

- no rating at an end: the censored likelihood is the Gaussian one, whose maximum is in
  closed form (least squares), so a fit profiles them out exactly and at no cost;
- ratings at an end: the log-likelihood is concave in Olsen's (1978) parameters
  ``(a / s, b / s, 1 / s)``, so Newton's method (from the least-squares values, or from a
  given nearby solution) finds its unique maximum (two or three iterations, each vectorised
  over the ratings); ``b >= 0`` and
  ``s >= MIN_RATING_STD`` are kept by refitting on the bound when the free maximum lies
  beyond it (a concave function's maximum under one violated bound lies on that bound).
  With fewer uncensored ratings than parameters the maximum may not exist (all ratings at
  100: the mean runs off to infinity); the least-squares values are kept then.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ['LOWER', 'MIN_RATING_STD', 'OBSERVATIONS', 'UPPER', 'Observation', 'censored',
           'fit_observation', 'log_density']

OBSERVATIONS = ('linear', 'direct')
MIN_RATING_STD = 0.5 / 100.0
"""The observation noise s is at least half a rating point (ratings are whole numbers)."""
LOWER, UPPER = 0.0, 100.0
"""The rating scale's ends, where ratings are censored."""
_NEWTON_STEPS = 50
_TOL = 1e-8
"""Newton stops when the Newton decrement squared (twice the log-likelihood the next step
expects to gain) is below this, in nats: far below what a fit's search can tell apart
(its values are hundreds of nats, compared to 1e-4 relative)."""


@dataclass(frozen=True)
class Observation:
    """Fitted observation model: rating / 100 = a + b T + N(0, s^2), censored at 0 and 1."""

    a: float
    b: float
    s: float

    def mean(self, trust: np.ndarray) -> np.ndarray:
        """The latent rating / 100 (before the scale's ends cut it)."""
        return self.a + self.b * np.asarray(trust)


def censored(ratings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the ratings (0-100 scale) at the lower and at the upper end."""
    r = np.asarray(ratings, float)
    return r <= LOWER, r >= UPPER


def _least_squares(kind: str, trust: np.ndarray, y: np.ndarray) -> Observation:
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


_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def _evaluate(theta: np.ndarray, d_mid: np.ndarray,
              d_cut: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """The log-likelihood at ``theta`` (-inf for tau <= 0) and what its derivatives reuse:
    the uncensored ratings' residuals r, the censored ones' forms w and log Phi(w)."""
    from scipy.special import log_ndtr

    r = d_mid @ theta
    w = d_cut @ theta
    log_cdf = log_ndtr(w)
    tau = theta[-1]
    value = (float(len(r) * math.log(tau) - 0.5 * r @ r + log_cdf.sum()) if tau > 0.0
             else -math.inf)
    return value, r, w, log_cdf


def _newton(theta: np.ndarray, free: np.ndarray, d_mid: np.ndarray,
            d_cut: np.ndarray) -> np.ndarray:
    """Maximise the censored log-likelihood over the coordinates ``free`` of ``theta``.

    In Olsen's parameters every rating's term is a function of one linear form of theta:
    an uncensored rating contributes ``log tau - (d . theta)^2 / 2``, a censored one
    ``log Phi(d . theta)`` (the rows of ``d_mid`` and ``d_cut``); theta's last coordinate is
    tau = 1 / s. Damped Newton (backtracking to a sufficient increase), which converges
    from any start on a strictly concave function.
    """
    n_mid = len(d_mid)
    mid_curvature = d_mid.T @ d_mid                   # the same at every theta
    every = bool(free.all())
    value, r, w, log_cdf = _evaluate(theta, d_mid, d_cut)
    for _ in range(_NEWTON_STEPS):
        tau = theta[-1]
        lam = np.exp(-0.5 * w * w - _HALF_LOG_2PI - log_cdf)          # phi(w) / Phi(w)
        grad = d_cut.T @ lam - d_mid.T @ r
        grad[-1] += n_mid / tau
        hess = -mid_curvature - (d_cut.T * (lam * (w + lam))) @ d_cut
        hess[-1, -1] -= n_mid / tau ** 2
        g = grad if every else grad[free]
        step = np.linalg.solve(hess if every else hess[np.ix_(free, free)], -g)
        decrement = float(g @ step)
        if not decrement > _TOL:
            break
        if every:
            full = step
        else:
            full = np.zeros_like(theta)
            full[free] = step
        t = 1.0
        while t > 1e-8:
            trial = theta + t * full
            trial_value, trial_r, trial_w, trial_log_cdf = _evaluate(trial, d_mid, d_cut)
            if trial_value >= value + 0.25 * t * decrement:
                break
            t *= 0.5
        else:
            break
        theta, value, r, w, log_cdf = trial, trial_value, trial_r, trial_w, trial_log_cdf
    return theta


def fit_observation(kind: str, trust: np.ndarray, y: np.ndarray,
                    near: Observation | None = None) -> Observation:
    """Maximum-likelihood a, b >= 0 and s for ratings / 100 ``y``, censored at 0 and 1.

    ``near``: where Newton's method starts when ratings sit at an end (the maximum is
    unique, so the start changes only the iterations: a fit over a model's parameters
    passes the solution for the previous trust, which is close); default the least-squares
    values.
    """
    trust, y = np.asarray(trust, float), np.asarray(y, float)
    low, high = censored(100.0 * y)
    cut = low | high
    width = 1 if kind == 'direct' else 3
    if not cut.any() or int((~cut).sum()) < width:
        return _least_squares(kind, trust, y)
    start = (near if near is not None and near.s > 0.0
             and math.isfinite(near.a + near.b + near.s) else _least_squares(kind, trust, y))
    # the linear forms (module docstring): columns (a/s, b/s, 1/s) for 'linear', (1/s) for
    # 'direct' whose mean is T itself; lower end Phi((0 - m) / s), upper Phi((m - 1) / s)
    if kind == 'direct':
        d_mid = (y - trust)[~cut, None]
        d_cut = np.where(low, -trust, trust - 1.0)[cut, None]
        theta = np.array([1.0 / start.s])
    else:
        ones = np.ones_like(trust)
        d_mid = np.column_stack([-ones, -trust, y])[~cut]
        sign = np.where(low, -1.0, 1.0)
        d_cut = np.column_stack([sign * ones, sign * trust, np.where(low, 0.0, -1.0)])[cut]
        theta = np.array([start.a, max(start.b, 0.0), 1.0]) / start.s
    free = np.ones(len(theta), bool)
    theta = _newton(theta, free, d_mid, d_cut)
    while True:                      # a violated bound: the maximum on it (each fixed once)
        if kind == 'linear' and free[1] and theta[1] < 0.0:               # b >= 0
            theta[1], free[1] = 0.0, False
        elif free[-1] and theta[-1] > 1.0 / MIN_RATING_STD:              # s >= its least
            theta = theta / theta[-1] * (1.0 / MIN_RATING_STD)
            free[-1] = False
        else:
            break
        theta = _newton(theta, free, d_mid, d_cut)
    tau = float(theta[-1])
    if kind == 'direct':
        return Observation(0.0, 1.0, 1.0 / tau)
    return Observation(float(theta[0]) / tau, float(theta[1]) / tau, 1.0 / tau)


def log_density(obs: Observation, trust: np.ndarray, ratings: np.ndarray) -> np.ndarray:
    """Pointwise log likelihood of ratings (0-100 scale) under the observation model: the
    log density for a rating inside the scale, the log probability of the end for a rating
    at 0 or 100."""
    from scipy.special import log_ndtr

    r = np.asarray(ratings, float)
    sd = 100.0 * obs.s
    z = (r - 100.0 * obs.mean(trust)) / sd
    result: np.ndarray = -0.5 * z * z - math.log(sd * math.sqrt(2.0 * math.pi))
    low, high = censored(r)
    if low.any() or high.any():
        result = np.where(low, log_ndtr(np.where(low, z, 0.0)), result)
        result = np.where(high, log_ndtr(-np.where(high, z, 0.0)), result)
    return result
