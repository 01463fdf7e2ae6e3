"""Fit trust models to trust ratings, and score them on ratings they were not fitted to.

Pure numerics (no ROS, no files): :mod:`trust_av.drive.trust_fit_data` reads drives,
``trust-av fit-trust`` writes the tables and figures. The method
(docs/tutorials/fit-trust-models.md):

- **Data.** A :class:`RatedDrive` is one drive of one participant: the explicability E of
  each applied plan (step ``i`` applies E_i from ``times_s[i]`` to ``times_s[i+1]``) and the
  trust ratings given during it (0-100, at their times).
- **Model trust.** A registered trust model runs over the drive's E with each update scaled
  by its step, and its trust is read on the common scale [0, 1]
  (:func:`~trust_monitor.model_interface.common_trust`) after every step completed by the
  rating's time; a whole drive at once through the model's fast path when it gives one
  (:func:`~trust_monitor.model_interface.trust_trajectory`), else step by step.
- **Observation model** (its parameters are fitted too). ``linear`` (default):
  ``rating / 100 = a + b T + e``, ``b >= 0``; ``direct`` (a model that declares
  ``rating_observation = 'direct'``: ``optimo``, ``beta_bernoulli``, whose trust is itself a
  probability of trusting): ``rating / 100 = T + e``; ``e ~ N(0, s^2)`` in both, censored
  at the scale's ends (a rating of 0 or 100 counts as the probability of the latent rating
  being there or beyond: :mod:`trust_monitor.rating_observation`). For given model
  parameters the maximum-likelihood a, b and s are found exactly (least squares in closed
  form when no rating sits at an end, Newton's method on the concave censored likelihood
  when some do), so they are profiled out and the optimiser searches the model's parameters
  only.
- **Parameters** come from the model's own declaration
  (:func:`~trust_monitor.model_interface.fit_parameters`): the identifiable ones are fitted
  by maximising the profile likelihood times the declared normal prior (on the log scale
  for ``log_scale`` parameters: a MAP estimate) with ``scipy.optimize.minimize`` (Powell,
  within the bounds: a threshold parameter makes the likelihood piecewise constant, so the
  search is derivative-free), in units of prior standard deviations (one tolerance, 0.01
  SD, for every parameter), one search from each of the :data:`SEARCHES` best of the prior
  mean, :data:`STARTS` draws from the prior and :data:`SPREAD_STARTS` points spread over
  the bounds; the best end wins. Each search may evaluate the objective
  :data:`MAX_EVALUATIONS` times per parameter.
- **Scores.** Held-out log predictive density of each rating under the fitted model and
  observation (nats, ratings on the 0-100 scale) and rating RMSE, from fits that did not see
  it: leave one drive out (per participant) and leave one participant out (pooled). Standard
  errors from the pointwise values (sqrt(n) x their standard deviation for a sum).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trust_monitor.errors import TrustMonitorError
from trust_monitor.model_interface import (
    COMMON_SCALE,
    FitParameter,
    TrustModel,
    common_trust,
    fit_parameters,
    make_trust_model,
    trust_trajectory,
)
from trust_monitor.paper_trust import TrustConfig
from trust_monitor.rating_observation import (
    OBSERVATIONS,
    Observation,
    fit_observation,
    log_density,
)

__all__ = ['Fit', 'FitError', 'ModelSpec', 'Observation', 'RatedDrive', 'Score', 'by_participant',
           'compare', 'fit', 'held_out', 'model_spec', 'model_trust']

STARTS = 8
"""Random starts drawn from the prior besides its mean."""
SPREAD_STARTS = 64
"""Starts spread over the whole box (a scrambled Sobol sequence): a true value far out in
the prior's tail is searched for too."""
SEARCHES = 3
"""Searches per fit, from the best starts (a threshold parameter makes the likelihood
piecewise constant, so one search can stop on a step far from the optimum)."""
MAX_EVALUATIONS = 250
"""Objective evaluations per search and fitted parameter (Powell's ``maxfev`` is this times
the number of parameters: a search over four parameters stopped at 250 ended 20-50 nats
below the true values' log posterior for a ``beta_bernoulli`` participant with
alpha0 = 0.09, lambda = 1; with 1000 at or above it)."""
TIME_TOLERANCE_S = 1e-9


class FitError(TrustMonitorError):
    """Data a fit cannot use (named in one line)."""


@dataclass(frozen=True)
class RatedDrive:
    """One drive: E per applied plan and the ratings given during it.

    Attributes:
        participant: who drove.
        drive: the drive's name (unique per participant).
        times_s: start of each step, s (increasing).
        scores: E of the plan applied from ``times_s[i]`` to the next time (the last for
            the median step), dimensionless in [0, 1].
        rating_times_s: when each rating was given, s.
        ratings: the ratings, 0-100.
    """

    participant: str
    drive: str
    times_s: np.ndarray
    scores: np.ndarray
    rating_times_s: np.ndarray
    ratings: np.ndarray

    def __post_init__(self) -> None:
        where = f'participant {self.participant!r} drive {self.drive!r}'
        t, e = np.asarray(self.times_s, float), np.asarray(self.scores, float)
        rt, r = np.asarray(self.rating_times_s, float), np.asarray(self.ratings, float)
        if t.ndim != 1 or len(t) < 2 or len(e) != len(t):
            raise FitError(f'{where}: need at least two steps with one score each')
        if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
            raise FitError(f'{where}: step times must be finite and increasing')
        if not (np.all(np.isfinite(e)) and e.min() >= 0.0 and e.max() <= 1.0):
            raise FitError(f'{where}: explicability must be in [0, 1]')
        if len(rt) != len(r) or not (np.all(np.isfinite(rt)) and np.all(np.isfinite(r))):
            raise FitError(f'{where}: ratings and their times must be finite and paired')
        if len(r) and (r.min() < 0.0 or r.max() > 100.0):
            raise FitError(f'{where}: ratings must be in [0, 100]')


@dataclass(frozen=True)
class ModelSpec:
    """A registered model as the fit sees it: how to build it with given parameter values.

    Attributes:
        name: the registered name.
        trust: the shared trust parameters the fit starts from.
        values: the model's own parameters (params-file values).
        parameters: the fitted (identifiable) parameters.
        fixed: the declared parameters held at their configured value.
        observation: ``linear`` or ``direct``.
    """

    name: str
    trust: TrustConfig
    values: Mapping[str, Any]
    parameters: tuple[FitParameter, ...]
    fixed: tuple[FitParameter, ...]
    observation: str

    def build(self, theta: Mapping[str, float]) -> TrustModel:
        """The model with the fitted parameters set to ``theta``."""
        shared: dict[str, Any] = {k: v for k, v in theta.items()
                                  if k in TrustConfig.__dataclass_fields__}
        own = {**self.values, **{k: v for k, v in theta.items() if k not in shared}}
        return make_trust_model(dataclasses.replace(self.trust, **shared), own)

    def configured(self, name: str) -> float:
        """The configured value of a declared parameter."""
        if name in TrustConfig.__dataclass_fields__:
            return float(getattr(self.trust, name))
        model = make_trust_model(self.trust, self.values)
        return float(getattr(getattr(model, 'params', None), name))


def model_spec(trust: TrustConfig, name: str, values: Mapping[str, Any] | None = None
               ) -> ModelSpec:
    """The fit's view of the registered model ``name`` (its declaration, no edit needed).

    Raises:
        RegistryError: not registered.
        FitError: a declared observation model this fit does not know.
    """
    cfg = dataclasses.replace(trust, trust_model=name)
    model = make_trust_model(cfg, values)
    declared = fit_parameters(model)
    observation = getattr(model, 'rating_observation', 'linear')
    if observation not in OBSERVATIONS:
        raise FitError(f'trust model {name!r}: rating_observation must be one of '
                       f'{list(OBSERVATIONS)}, got {observation!r}')
    return ModelSpec(name, cfg, dict(values or {}),
                     tuple(p for p in declared if p.identifiable),
                     tuple(p for p in declared if not p.identifiable), observation)


@dataclass(frozen=True)
class _Timeline:
    """A drive's step lengths and, per rating, the number of steps completed by then (the
    same for every model: a fit reads it once per drive, not at every evaluation)."""

    scores: np.ndarray
    """E per step."""
    dts_s: np.ndarray
    """Each step's length, s (the last: the median step)."""
    done: np.ndarray

    @classmethod
    def of(cls, drive: RatedDrive) -> _Timeline:
        t = np.asarray(drive.times_s, float)
        steps = np.diff(t)
        dt = np.append(steps, np.median(steps))
        done = np.searchsorted(t + dt, np.asarray(drive.rating_times_s, float)
                               + TIME_TOLERANCE_S, side='right')
        return cls(np.ascontiguousarray(drive.scores, float), dt, done)


def model_trust(model: TrustModel, drive: RatedDrive,
                every_step: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The model's trust on the common scale at each rating time (after every step
    completed by then; before any: the initial trust), and after each step when
    ``every_step`` (else an empty array: the fit reads the rating times only)."""
    return _trust_on(model, _Timeline.of(drive), every_step)


def _common_trusts(model: TrustModel, trust: np.ndarray) -> np.ndarray:
    """:func:`~trust_monitor.model_interface.common_trust` of each of the model's trust
    values (own units) at once."""
    low, high = getattr(model, 'trust_range', COMMON_SCALE)
    common: np.ndarray = np.minimum(np.maximum((trust - low) / (high - low), 0.0), 1.0)
    return common


def _trust_on(model: TrustModel, timeline: _Timeline,
              every_step: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """:func:`model_trust` on a drive's :class:`_Timeline` (through the model's fast path
    when it has one: :func:`~trust_monitor.model_interface.trust_trajectory`)."""
    done = timeline.done
    after = _common_trusts(model, trust_trajectory(model, timeline.scores, timeline.dts_s))
    initial = common_trust(model, model.initial_state())
    at = np.where(done > 0, after[np.maximum(done - 1, 0)], initial)
    return (after if every_step else np.array([])), at


@dataclass
class Fit:
    """A fitted model: parameter values, observation model and the objective reached."""

    model: str
    theta: dict[str, float]
    observation: Observation
    log_posterior: float
    ratings: int
    evaluations: int
    fixed: dict[str, float] = field(default_factory=dict)


def _to_search(p: FitParameter, value: float) -> float:
    """A parameter value in search units: prior standard deviations from the prior mean
    (on the log scale for ``log_scale``), so one tolerance suits every parameter."""
    return ((math.log(value) if p.log_scale else value) - p.prior_mean) / p.prior_std


def _from_search(p: FitParameter, z: float) -> float:
    x = p.prior_mean + p.prior_std * z
    return math.exp(x) if p.log_scale else x


def _prior(params: Sequence[FitParameter], z: np.ndarray) -> float:
    return float(-0.5 * np.sum(np.asarray(z) ** 2)) if len(params) else 0.0


def fit(spec: ModelSpec, drives: Sequence[RatedDrive], seed: int = 0) -> Fit:
    """Fit ``spec``'s identifiable parameters and its observation model to ``drives``.

    Raises:
        FitError: no ratings in ``drives``.
    """
    y = np.concatenate([np.asarray(d.ratings, float) for d in drives]) / 100.0 \
        if drives else np.array([])
    if len(y) == 0:
        raise FitError('no ratings to fit')
    params = spec.parameters
    box = [(_to_search(p, p.low), _to_search(p, p.high)) for p in params]
    evaluations = [0]

    def theta_of(x: np.ndarray) -> dict[str, float]:
        return {p.name: min(max(_from_search(p, float(v)), p.low), p.high)
                for p, v in zip(params, x, strict=True)}

    timelines = [_Timeline.of(d) for d in drives]

    def trust_at(x: np.ndarray) -> np.ndarray:
        model = spec.build(theta_of(x))
        return np.concatenate([_trust_on(model, timeline)[1] for timeline in timelines])

    last: list[Observation | None] = [None]

    def objective(x: np.ndarray) -> float:
        evaluations[0] += 1
        x = np.clip(x, [b[0] for b in box], [b[1] for b in box])
        trust = trust_at(x)
        obs = last[0] = fit_observation(spec.observation, trust, y, last[0])
        loglik = float(log_density(obs, trust, 100.0 * y).sum())
        return -(loglik + _prior(params, x))

    if not params:
        x_best = np.array([])
    else:
        from scipy import optimize  # lazy: importing scipy costs every trust-av start
        from scipy.stats import qmc

        rng = np.random.Generator(np.random.PCG64(seed))
        low, high = [b[0] for b in box], [b[1] for b in box]
        spread = qmc.Sobol(len(params), seed=rng).random(SPREAD_STARTS)
        starts = [np.clip(np.zeros(len(params)), low, high)] + [
            np.clip(rng.normal(0.0, 1.0, len(params)), low, high) for _ in range(STARTS)] + [
            np.asarray(qmc.scale(spread, low, high))[k] for k in range(SPREAD_STARTS)]
        values = [objective(s) for s in starts]
        x_best, f_best = starts[int(np.argmin(values))], min(values)
        for k in np.argsort(values)[:SEARCHES]:
            result = optimize.minimize(objective, starts[int(k)], method='Powell', bounds=box,
                                       options={'maxfev': MAX_EVALUATIONS * len(params),
                                                'xtol': 1e-2,
                                                'ftol': 1e-4})
            if result.fun < f_best:
                x_best, f_best = np.asarray(result.x), float(result.fun)
    trust = trust_at(x_best)
    obs = fit_observation(spec.observation, trust, y)
    return Fit(spec.name, theta_of(x_best), obs, -objective(x_best), len(y), evaluations[0],
               {p.name: spec.configured(p.name) for p in spec.fixed})


@dataclass(frozen=True)
class Prediction:
    """A fitted model on drives it may not have seen: trust and ratings at rating times;
    ``predicted`` is the observation model's latent mean (x 100: it may lie beyond 0-100,
    where the rating itself stops), ``log_density`` each rating's log likelihood."""

    trust: np.ndarray
    ratings: np.ndarray
    predicted: np.ndarray
    log_density: np.ndarray


def predict(spec: ModelSpec, fitted: Fit, drives: Sequence[RatedDrive]) -> Prediction:
    """``fitted`` applied to ``drives``: predicted ratings and their log densities."""
    model = spec.build(fitted.theta)
    trust = np.concatenate([model_trust(model, d)[1] for d in drives]) if drives \
        else np.array([])
    ratings = np.concatenate([np.asarray(d.ratings, float) for d in drives]) if drives \
        else np.array([])
    return Prediction(trust, ratings, 100.0 * fitted.observation.mean(trust),
                      log_density(fitted.observation, trust, ratings))


@dataclass(frozen=True)
class Score:
    """Held-out scores of one model for one participant (or pooled).

    Attributes:
        model: the model.
        scheme: ``leave_one_drive_out`` or ``leave_one_participant_out``.
        pointwise: held-out log density of every rating (nats, 0-100 scale).
        errors: held-out rating errors, rating points.
        sd: the predictive SD of every held-out rating, rating points (empty: not kept).
    """

    model: str
    scheme: str
    pointwise: np.ndarray
    errors: np.ndarray
    sd: np.ndarray = field(default_factory=lambda: np.array([]))

    @property
    def elpd(self) -> float:
        """Sum of the held-out log densities."""
        return float(self.pointwise.sum())

    @property
    def elpd_se(self) -> float:
        """Its standard error: sqrt(n) x the pointwise standard deviation."""
        n = len(self.pointwise)
        return float(math.sqrt(n) * np.std(self.pointwise, ddof=1)) if n > 1 else math.nan

    @property
    def rmse(self) -> float:
        """Root mean squared held-out rating error, rating points."""
        return float(math.sqrt(np.mean(self.errors ** 2)))

    @property
    def rmse_se(self) -> float:
        """Its standard error (delta method on the mean squared error)."""
        n = len(self.errors)
        if n < 2 or self.rmse == 0.0:
            return math.nan
        return float(np.std(self.errors ** 2, ddof=1) / math.sqrt(n) / (2.0 * self.rmse))


def held_out(spec: ModelSpec, groups: Sequence[Sequence[RatedDrive]], scheme: str,
             seed: int = 0) -> Score:
    """Score ``spec`` leaving each group out in turn (fit on the others, predict it).

    Raises:
        FitError: fewer than two groups, or a fold without ratings to fit.
    """
    if len(groups) < 2:
        raise FitError(f'{scheme} needs at least two held-out units, got {len(groups)}')
    points, errors, sds = [], [], []
    for k, group in enumerate(groups):
        train = [d for j, g in enumerate(groups) if j != k for d in g]
        fitted = fit(spec, train, seed)
        out = predict(spec, fitted, group)
        points.append(out.log_density)
        errors.append(out.ratings - out.predicted)
        sds.append(np.full(len(out.ratings), 100.0 * fitted.observation.s))
    return Score(spec.name, scheme, *(np.concatenate(x) for x in (points, errors, sds)))


def compare(scores: Sequence[Score]) -> list[dict[str, Any]]:
    """Rows of the model comparison: each model's elpd, its difference to the best and the
    difference's standard error (pointwise over the same ratings), RMSE; best first.

    Raises:
        FitError: the scores are not over the same ratings.
    """
    if not scores:
        return []
    n = {len(s.pointwise) for s in scores}
    if len(n) != 1:
        raise FitError('scores to compare must be over the same ratings')
    best = max(scores, key=lambda s: s.elpd)
    rows = []
    for s in sorted(scores, key=lambda s: -s.elpd):
        diff = s.pointwise - best.pointwise
        rows.append({'model': s.model, 'scheme': s.scheme, 'ratings': len(s.pointwise),
                     'elpd': s.elpd, 'elpd_se': s.elpd_se, 'elpd_diff': float(diff.sum()),
                     'elpd_diff_se': float(math.sqrt(len(diff)) * np.std(diff, ddof=1))
                     if len(diff) > 1 else math.nan,
                     'rmse': s.rmse, 'rmse_se': s.rmse_se})
    return rows


PARSIMONY_SE = 1.0
""":func:`preferred`: a model with more parameters must beat a simpler one by more than this
many standard errors of the held-out elpd difference."""


def preferred(scores: Sequence[Score], sizes: Mapping[str, int]) -> str:
    """The model the held-out scores prefer, with a parsimony rule: the simplest model
    (fewest fitted parameters, ``sizes``: ``model_check.parameter_count``; then the higher elpd)
    whose elpd is within :data:`PARSIMONY_SE` standard errors of the paired difference to
    the best model's. A model nested in another (``paper`` in ``asymmetric``: loss ratio 1)
    fits at least as well in sample and can win a held-out comparison by noise alone; this
    rule asks for evidence before the extra parameter is preferred.

    Raises:
        FitError: no scores, or scores not over the same ratings.
    """
    rows = compare(scores)
    if not rows:
        raise FitError('no scores to choose from')
    within = [r for r in rows if r['model'] == rows[0]['model']
              or -r['elpd_diff'] <= PARSIMONY_SE * r['elpd_diff_se']]
    return str(min(within, key=lambda r: (sizes[r['model']], -r['elpd']))['model'])


def by_participant(drives: Sequence[RatedDrive]) -> dict[str, list[RatedDrive]]:
    """Drives grouped by participant, in first-seen order."""
    out: dict[str, list[RatedDrive]] = {}
    for d in drives:
        out.setdefault(d.participant, []).append(d)
    return out

