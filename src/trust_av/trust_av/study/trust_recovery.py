"""Synthetic participants for the trust-model fit: can it recover what generated the ratings?

Each synthetic participant drives (the shipped follower in the in-process closed loop,
:func:`trust_av.system.closed_loop.simulate`) the study's conditions in which trust
moves (:mod:`trust_av_planner.perturbations`); the explicability of every applied plan is
recorded, and ratings (one at the start of each drive, then every :data:`RATING_PERIOD_S`)
are generated from a *known* trust model with known parameters (drawn from the model's
declared prior within its bounds, or from :data:`TRUE_RANGES`) through a known observation
model with known rating noise (:func:`synthetic_study`, :func:`write_ratings_table`).
``benchmarks/bench_trust_recovery.py`` fits every registered model to them
(:mod:`trust_monitor.trust_fit`) and reports how well the true parameters are recovered
and which model held-out drives prefer (docs/tutorials/fit-trust-models.md).
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trust_av.system.closed_loop import control_trace, simulate
from trust_av.system.config import RunConfig
from trust_monitor.trust_fit import (
    ModelSpec,
    Observation,
    RatedDrive,
    model_spec,
    model_trust,
)

__all__ = ['RATING_NOISE', 'RATING_PERIOD_S', 'Participant', 'drive_scores', 'make_participant',
           'synthetic_study', 'write_ratings_table']

CONDITIONS = ('rough_random', 'rough_random', 'rough_random', 'rough_random')
"""The drives of a synthetic participant, in order (cycled), each ``*_random`` one with its
own seed (:func:`drive_seed`)."""
DRIVES_PER_SEED = 100
"""Participant ``i``'s drive ``j`` is random draw ``DRIVES_PER_SEED i + j``."""


def conditions(drives: int) -> list[str]:
    """The conditions of a participant's ``drives`` drives (:data:`CONDITIONS`, cycled)."""
    return [CONDITIONS[j % len(CONDITIONS)] for j in range(drives)]


def drive_seed(seed: int, k: int) -> int:
    """The ``perturbation_seed`` of random draw ``k`` of a study seeded ``seed``."""
    return seed * 1_000_000 + k
DRIVE_S = 120
"""Length of a drive, s (the study's ``drive_duration_s``)."""
RATING_PERIOD_S = 2.5
"""A synthetic participant's rating is read this often, s: a continuous rating (a slider
the person keeps at their trust) read every 2.5 s. The shipped study asks every 15 s; with
a rating every 5 s a threshold is recovered with r of about 0.8 at best
(docs/tutorials/fit-trust-models.md)."""
TRUE_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    'paper': {'performance_threshold': (0.7, 0.98)},
    'asymmetric': {'performance_threshold': (0.7, 0.98), 'asymmetric_loss_ratio': (2.0, 10.0)},
    'optimo': {'optimo_performance_rate_per_s': (0.003, 0.02),
               'optimo_initial_trust': (0.2, 0.8)},
}
"""Where synthetic participants' true values are drawn uniformly (log-uniformly for a
``log_scale`` parameter) instead of from the declared prior: the ranges in which the
parameter changes the rating trajectory in these drives. Below 0.7 a threshold is crossed
by under 4 % of the steps of a ``rough_random`` drive (it changes almost nothing); an
asymmetric loss ratio within (0.5, 2) is ``paper`` up to the rating noise (the nested
case: docs/tutorials/fit-trust-models.md says how much data separates them). OPTIMo's trust
saturates at 0 or 1 within a drive at the tails of its prior (a drift of 0.02 /s crosses
[0, 1] in 50 s), and a saturated stretch says nothing about the parameters."""
RATING_NOISE = 5.0
"""Standard deviation of the rating noise, rating points."""
RATING_SPAN = (40.0, 60.0)
"""``linear`` observation: the model's trust range over the participant's drives is mapped to
a span of ratings drawn from this interval (rating points), starting at 20-30."""


@dataclass(frozen=True)
class Participant:
    """A synthetic participant: the true model, its parameters, the observation, the drives."""

    name: str
    model: str
    theta: dict[str, float]
    observation: Observation
    drives: tuple[RatedDrive, ...]


def drive_scores(config: RunConfig, perturbation: str, seed: int,
                 steps: int = DRIVE_S) -> tuple[np.ndarray, np.ndarray]:
    """(times, E) of one in-process drive of ``steps`` control steps under ``perturbation``."""
    cfg = dataclasses.replace(config, planner=dataclasses.replace(
        config.planner, perturbation=perturbation, perturbation_seed=seed))
    trace = dataclasses.replace(control_trace(cfg), step_limit=steps)
    result = simulate(cfg, trace)
    times = np.array([r.t_s for r in result.records]) - result.records[0].t_s
    return times, np.array([r.explicability for r in result.records])


Ranges = dict[str, dict[str, tuple[float, float]]]
"""{model: {parameter: (low, high)}}: where true values are drawn."""


def draw_theta(spec: ModelSpec, rng: np.random.Generator,
               true_ranges: Ranges | None = None) -> dict[str, float]:
    """Parameters drawn from the declared prior (truncated to the bounds), or uniformly
    (log-uniformly for ``log_scale``) from ``true_ranges`` (default :data:`TRUE_RANGES`)
    where it names the parameter."""
    out = {}
    ranges = (TRUE_RANGES if true_ranges is None else true_ranges).get(spec.name, {})
    for p in spec.parameters:
        low, high = (math.log(p.low), math.log(p.high)) if p.log_scale else (p.low, p.high)
        if p.name in ranges:
            a, b = ranges[p.name]
            x = float(rng.uniform(*((math.log(a), math.log(b)) if p.log_scale else (a, b))))
        else:
            x = float(np.clip(rng.normal(p.prior_mean, p.prior_std), low, high))
        out[p.name] = math.exp(x) if p.log_scale else x
    return out


def make_participant(spec: ModelSpec, name: str, drives: Sequence[tuple[str, np.ndarray,
                                                                        np.ndarray]],
                     rng: np.random.Generator, noise: float = RATING_NOISE,
                     rating_period_s: float = RATING_PERIOD_S,
                     rating_span: tuple[float, float] = RATING_SPAN,
                     true_ranges: Ranges | None = None) -> Participant:
    """A participant whose ratings ``spec`` generates over ``drives`` ((name, times, E)):
    true values from ``true_ranges`` (:func:`draw_theta`); a ``linear`` observation maps the
    model's trust range onto a span of ratings drawn from ``rating_span``."""
    theta = draw_theta(spec, rng, true_ranges)
    model = spec.build(theta)
    rated = []
    for drive, times, scores in drives:
        rating_times = np.arange(0.0, times[-1] + 1.0 + 1e-9, rating_period_s)
        rated.append(RatedDrive(name, drive, times, scores, rating_times,
                                np.zeros(len(rating_times))))
    trusts = [model_trust(model, d)[1] for d in rated]
    if spec.observation == 'direct':
        obs = Observation(0.0, 1.0, noise / 100.0)
    else:
        low = min(float(t.min()) for t in trusts)
        high = max(float(t.max()) for t in trusts)
        span = rng.uniform(*rating_span) / 100.0
        b = span / max(high - low, 1e-6)
        obs = Observation(rng.uniform(0.2, 0.3) - b * low, b, noise / 100.0)
    out = []
    for d, trust in zip(rated, trusts, strict=True):
        ratings = np.clip(np.round(100.0 * obs.mean(trust)
                                   + rng.normal(0.0, noise, len(trust))), 0.0, 100.0)
        out.append(dataclasses.replace(d, ratings=ratings))
    return Participant(name, spec.name, theta, obs, tuple(out))


def synthetic_study(config: RunConfig, models: Sequence[str], per_model: int, drives: int,
                    seed: int = 0, steps: int = DRIVE_S) -> list[Participant]:
    """``per_model`` synthetic participants of each model in ``models``, ``drives`` drives
    each (:func:`conditions`; participant ``i``'s drive ``j`` seeded by :func:`drive_seed`
    of ``DRIVES_PER_SEED i + j``, so participant ``i`` of every model drives the same)."""
    rng = np.random.Generator(np.random.PCG64(seed))
    out = []
    for true in models:
        spec = model_spec(config.trust, true)
        for i in range(per_model):
            data = [(f'{c}_{j + 1}',
                     *drive_scores(config, c, drive_seed(seed, DRIVES_PER_SEED * i + j), steps))
                    for j, c in enumerate(conditions(drives))]
            out.append(make_participant(spec, f'{true}_{i:02d}', data, rng))
    return out


def write_ratings_table(path: Path, participants: Sequence[Participant]) -> None:
    """The participants' drives as a tidy ratings table (the format of
    :mod:`trust_av.drive.trust_fit_data`)."""
    rows = []
    for who in participants:
        for d in who.drives:
            rows += [(who.name, d.drive, float(t), repr(float(e)), '')
                     for t, e in zip(d.times_s, d.scores, strict=True)]
            rows += [(who.name, d.drive, float(t), '', f'{r:g}')
                     for t, r in zip(d.rating_times_s, d.ratings, strict=True)]
    with Path(path).open('w', newline='') as handle:
        writer = csv.writer(handle, lineterminator='\n')
        writer.writerow(('participant', 'drive', 't_s', 'explicability', 'rating'))
        writer.writerows(rows)
