"""Does a fitted trust model describe a participant's ratings at all? Model checking, beside
the model choice of :mod:`trust_monitor.trust_fit`.

A model choice ranks the registered models; it names one even when none describes the
ratings. These checks are absolute: each compares a statistic of the participant's ratings
with its distribution under the fitted model (a posterior-predictive check, Gelman, Meng &
Stern 1996, with the fitted (MAP) parameters plugged in: replicated ratings are drawn from
the fitted observation model, rounded to whole ratings and kept in [0, 100] as real ones
are):

- ``residual_lag1``: the lag-1 autocorrelation of the rating residuals of the participant's
  own fit (pairs of consecutive ratings within a drive). The fitted model says the residuals
  are independent rating noise; trust that wanders in ways the model does not follow (a
  process the model lacks, another model's dynamics) leaves runs of residuals of one sign.
  One-sided: p is the share of replicates whose autocorrelation is at least the observed.
- ``interval_90``: the share of held-out ratings (leave one drive out) inside the fitted
  model's central 90 % predictive interval (of the censored rating: the latent interval cut
  to 0-100); about 0.9, more where ratings sit at an end. Two-sided: p is twice the
  smaller tail of the replicates' shares.

A model is ``adequate`` for a participant when no check's p is below :data:`ALPHA`.
:func:`stacking_weights` combines the held-out predictive densities of the adequate models
(Yao, Vehtari, Simpson & Gelman 2018). :func:`parameter_count` is the size of a fit the
parsimony rule of :func:`~trust_monitor.trust_fit.preferred` compares.

What the checks cannot tell (docs/concepts/trust-models.md): a model that passes is not
shown true (another model, in the zoo or not, may pass as well; few ratings pass almost
anything); the parameters are plugged in, not drawn from a posterior, so a statistic the fit
adapts to (the residuals of the own fit) is checked conservatively; they see only the
misfits their statistics measure.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trust_monitor.rating_observation import LOWER, UPPER
from trust_monitor.trust_fit import Fit, ModelSpec, RatedDrive, Score, model_trust

__all__ = ['ALPHA', 'INTERVAL', 'OBSERVATION_PARAMETERS', 'REPLICATES', 'STATISTICS', 'Check',
           'adequate', 'check_model', 'lag1', 'misfit_text', 'parameter_count',
           'stacking_weights']

ALPHA = 0.01
"""A check with a p-value below this rejects the model. Two checks per model at 1 % each:
a participant whose ratings a registered model generated is flagged as fitted by none in at
most about 2 % of cases by chance (benchmarks/bench_model_checking.py measures it)."""
INTERVAL = 0.9
"""The central predictive interval ``interval_90`` checks."""
REPLICATES = 2000
"""Replicated rating sets per check (a p-value's resolution is 1 / (1 + this))."""
STATISTICS = ('residual_lag1', 'interval_90')
_Z = 1.6448536269514722
"""The standard normal's 95 % quantile: the half-width of the central 90 % interval."""


OBSERVATION_PARAMETERS = {'linear': 3, 'direct': 1}
"""Parameters an observation model fits: ``linear`` a, b, s; ``direct`` s."""


def parameter_count(spec: ModelSpec) -> int:
    """Every parameter a fit of ``spec`` estimates: the model's identifiable parameters and
    its observation model's (:data:`OBSERVATION_PARAMETERS`): the size the parsimony rule of
    :func:`~trust_monitor.trust_fit.preferred` compares, counted here beside the checks."""
    return len(spec.parameters) + OBSERVATION_PARAMETERS[spec.observation]


@dataclass(frozen=True)
class Check:
    """One check of one model for one participant (a row of ``adequacy.csv``)."""

    participant: str
    model: str
    statistic: str
    value: float
    p_value: float
    ratings: int

    @property
    def adequate(self) -> bool:
        """False when the check rejects the model (p below :data:`ALPHA`); NaN (too few
        ratings) rejects nothing."""
        return not self.p_value < ALPHA


def lag1(residuals: np.ndarray, drive: np.ndarray) -> np.ndarray:
    """The lag-1 autocorrelation of ``residuals`` (last axis; replicates on the first),
    over pairs of consecutive ratings of one drive (``drive``: each rating's drive index),
    about the mean of all: NaN with fewer than three pairs."""
    r = np.asarray(residuals, float)
    same = np.asarray(drive)[1:] == np.asarray(drive)[:-1]
    if int(same.sum()) < 3:
        return np.full(r.shape[:-1], math.nan)
    centred = r - r.mean(axis=-1, keepdims=True)
    num = (centred[..., 1:] * centred[..., :-1])[..., same].sum(axis=-1)
    den = (centred ** 2).sum(axis=-1)
    with np.errstate(divide='ignore', invalid='ignore'):
        out: np.ndarray = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    return out


def _replicate(mean: np.ndarray, sd: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """:data:`REPLICATES` rating sets drawn from N(mean, sd), rounded, kept in [0, 100]."""
    draws = mean + sd * rng.standard_normal((REPLICATES, len(mean)))
    out: np.ndarray = np.clip(np.round(draws), LOWER, UPPER)
    return out


def _inside(ratings: np.ndarray, mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Which ratings lie in the central 90 % predictive interval: the latent interval
    ``mean +- 1.645 sd`` cut to the scale, the interval of the censored rating (a mean far
    above 100 puts most of the rating's probability on 100 itself)."""
    low = np.clip(mean - _Z * sd, LOWER, UPPER)
    high = np.clip(mean + _Z * sd, LOWER, UPPER)
    out: np.ndarray = (ratings >= low - 1e-9) & (ratings <= high + 1e-9)
    return out


def _upper_p(observed: float, replicated: np.ndarray) -> float:
    return float((1 + np.sum(replicated >= observed - 1e-12)) / (1 + len(replicated)))


def check_model(participant: str, spec: ModelSpec, own: Fit, drives: Sequence[RatedDrive],
                lodo: Score | None, seed: int = 0) -> list[Check]:
    """The checks of one model for one participant: ``own`` is the model fitted to all of
    ``drives``, ``lodo`` its leave-one-drive-out score over the same drives (None: one drive,
    no ``interval_90``)."""
    rng = np.random.Generator(np.random.PCG64(seed))
    model = spec.build(own.theta)
    index = np.concatenate([np.full(len(d.ratings), k) for k, d in enumerate(drives)])
    ratings = np.concatenate([np.asarray(d.ratings, float) for d in drives])
    trust = np.concatenate([model_trust(model, d)[1] for d in drives])
    mean = 100.0 * own.observation.mean(trust)
    sd = np.full(len(mean), 100.0 * own.observation.s)
    observed = float(lag1(ratings - mean, index))
    replicated = lag1(_replicate(mean, sd, rng) - mean, index)
    p = _upper_p(observed, replicated) if math.isfinite(observed) else math.nan
    out = [Check(participant, spec.name, 'residual_lag1', observed, p, len(ratings))]
    if lodo is not None and len(lodo.sd) == len(lodo.errors) and len(lodo.errors):
        # the held-out rating is mean + error: replicate around the held-out mean
        held_mean = ratings - lodo.errors if len(ratings) == len(lodo.errors) else None
        if held_mean is not None:
            inside = float(np.mean(_inside(ratings, held_mean, lodo.sd)))
            rep = _replicate(held_mean, lodo.sd, rng)
            shares = np.mean(_inside(rep, held_mean, lodo.sd), axis=1)
            low = float((1 + np.sum(shares <= inside + 1e-12)) / (1 + len(shares)))
            high = float((1 + np.sum(shares >= inside - 1e-12)) / (1 + len(shares)))
            out.append(Check(participant, spec.name, 'interval_90', inside,
                             min(1.0, 2.0 * min(low, high)), len(ratings)))
    return out


def adequate(checks: Sequence[Check]) -> dict[str, bool]:
    """Per model: True when none of its checks rejects it."""
    out: dict[str, bool] = {}
    for c in checks:
        out[c.model] = out.get(c.model, True) and c.adequate
    return out


def _p_text(p: float) -> str:
    return 'p < 0.001' if p < 0.001 else f'p = {p:.3f}'


def misfit_text(checks: Sequence[Check]) -> str:
    """What rejects the models, in words: the rejections shared by most models first
    (``residuals correlated, lag-1 0.48, p < 0.001``), each with its strongest case."""
    rejected = [c for c in checks if not c.adequate]
    parts = []
    for statistic in STATISTICS:
        these = [c for c in rejected if c.statistic == statistic]
        if not these:
            continue
        worst = min(these, key=lambda c: c.p_value)
        what = ('residuals correlated, lag-1' if statistic == 'residual_lag1'
                else 'held-out 90 % intervals hold')
        value = (f'{worst.value:.2f}' if statistic == 'residual_lag1'
                 else f'{100.0 * worst.value:.0f} %')
        parts.append((len(these), f'{what} {value} ({worst.model}), {_p_text(worst.p_value)}'
                      f' in {len(these)} model{"s" if len(these) > 1 else ""}'))
    return '; '.join(text for _, text in sorted(parts, key=lambda item: -item[0]))


def stacking_weights(scores: Mapping[str, Score]) -> dict[str, float]:
    """Stacking weights of the models (Yao et al. 2018): the weights on the simplex that
    maximise the summed log of the weighted held-out predictive densities
    (``scipy.optimize``, SLSQP).

    Raises:
        ValueError: scores not over the same ratings.
    """
    names = list(scores)
    if len(names) == 1:
        return {names[0]: 1.0}
    lpd = np.array([scores[m].pointwise for m in names])
    if len({len(row) for row in lpd}) != 1:
        raise ValueError('stacking needs scores over the same ratings')
    from scipy import optimize  # lazy: importing scipy costs every trust-av start
    from scipy.special import logsumexp

    def loss(w: np.ndarray) -> float:
        w = np.clip(w, 1e-300, None)
        return -float(np.sum(logsumexp(lpd + np.log(w)[:, None], axis=0)))

    k = len(names)
    result = optimize.minimize(loss, np.full(k, 1.0 / k), method='SLSQP',
                               bounds=[(0.0, 1.0)] * k,
                               constraints=({'type': 'eq', 'fun': lambda w: np.sum(w) - 1.0},))
    w = np.clip(np.asarray(result.x, float), 0.0, None)
    w = w / w.sum()
    return {m: float(v) for m, v in zip(names, w, strict=True)}
