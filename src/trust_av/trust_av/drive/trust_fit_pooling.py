"""Partial pooling of per-participant trust-model fits: each participant's parameters shrunk
toward the pooled fit, by a between-participant spread fitted from the data (empirical
Bayes).

The hierarchical model, per identifiable parameter p, in the fit's search units (prior
standard deviations from the declared prior mean; log scale for ``log_scale`` parameters,
:mod:`trust_monitor.trust_fit`)::

    z_ip ~ N(mu_p, tau_p^2)        participant i's parameter
    ratings_i | z_i                the fit's likelihood (model trust, observation model)

- ``mu_p``: the pooled fit's value (all participants' ratings, complete pooling);
- ``tau_p``: the root mean square of the participants' own (no-pooling) estimates around
  ``mu_p``, clipped to [:data:`MIN_SPREAD`, 1]: a method-of-moments estimate that includes
  each estimate's own noise, so it errs toward less shrinkage; never wider than the declared
  prior (1 in these units);
- each participant's partially pooled fit is then the same MAP fit
  (:func:`~trust_monitor.trust_fit.fit`) with the prior ``N(mu_p, tau_p^2)`` in
  place of the declared one: a participant with few or flat ratings stays near the
  population, one with informative ratings keeps their own values.

Its held-out score (:func:`held_out_partial`) leaves one drive out per participant, with
``mu`` and ``tau`` estimated from the *other* participants only, so no rating scored was
seen by any step of its fit. It needs at least three participants (two others to estimate a
spread from).

**Folds of participants.** The participants are dealt round-robin, in first-seen order, into
at most :data:`PARTICIPANT_FOLDS` folds (:func:`participant_folds`). The pooled fit to the
participants outside a fold is made once per fold and model, and serves both the
fold's leave-one-participant-out score (each participant of the fold predicted from it) and
the population of the fold's partially pooled held-out scores (``mu`` from it, ``tau`` from
the own fits outside the fold). Refitting the pooled model once per participant made these
two schemes grow with the square of the participants; with at most
:data:`PARTICIPANT_FOLDS` folds they grow linearly. Up to :data:`PARTICIPANT_FOLDS`
participants each fold is one participant, and both schemes are exactly leave one
participant out; beyond, a participant is scored from fits that left out its fold-mates
too (fewer participants fitted, each score still from fits that saw none of it).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from trust_monitor.model_interface import FitParameter
from trust_monitor.trust_fit import (
    Fit,
    FitError,
    ModelSpec,
    RatedDrive,
    Score,
    fit,
    held_out,
)

__all__ = ['MIN_PARTICIPANTS', 'MIN_SPREAD', 'PARTICIPANT_FOLDS', 'SCHEME', 'Population',
           'fold_prior', 'held_out_partial', 'partial_fits', 'participant_folds', 'population',
           'shrunk']

MIN_SPREAD = 0.05
"""Smallest between-participant spread, in prior standard deviations (participants whose
own estimates all equal the pooled one would otherwise pin every fit to it exactly)."""
MIN_PARTICIPANTS = 3
"""Participants a held-out partial-pooling score needs (two others give a spread)."""
SCHEME = 'leave_one_drive_out_partial_pooling'
PARTICIPANT_FOLDS = 8
"""Most folds of participants (module docstring): the pooled refits per model that the
leave-one-participant-out and the partially pooled held-out scores need."""


def participant_folds(participants: Sequence[str], folds: int = PARTICIPANT_FOLDS
                      ) -> list[list[str]]:
    """The participants dealt round-robin into ``min(folds, len(participants))`` folds
    (one participant each up to ``folds``).

    Raises:
        ValueError: ``folds`` < 1.
    """
    if folds < 1:
        raise ValueError(f'need at least one fold, got {folds}')
    count = min(folds, len(participants))
    return [list(participants[k::count]) for k in range(count)]


@dataclass(frozen=True)
class Population:
    """The fitted population of one model: its center and spread per parameter.

    Attributes:
        model: the model.
        center: each parameter's pooled value (the model's units).
        spread: each parameter's between-participant spread, in prior standard deviations.
        participants: how many participants the spread is estimated from.
    """

    model: str
    center: dict[str, float]
    spread: dict[str, float]
    participants: int


def _search(p: FitParameter, value: float) -> float:
    """``value`` in the fit's search units (prior standard deviations from the declared
    prior mean, on the log scale for ``log_scale``)."""
    return ((math.log(value) if p.log_scale else value) - p.prior_mean) / p.prior_std


def population(spec: ModelSpec, pooled: Fit, own: Mapping[str, Fit]) -> Population:
    """The center (the pooled fit) and the spread of the participants' own fits around it.

    Args:
        spec: the model.
        pooled: its fit to every participant's ratings together.
        own: each participant's own (no-pooling) fit.

    Raises:
        FitError: fewer than two participants' fits.
    """
    if len(own) < 2:
        raise FitError(f'{spec.name}: partial pooling needs at least two participants, got '
                       f'{len(own)}')
    spread = {}
    for p in spec.parameters:
        mu = _search(p, pooled.theta[p.name])
        deviations = [_search(p, f.theta[p.name]) - mu for f in own.values()]
        tau = math.sqrt(float(np.mean(np.square(deviations))))
        spread[p.name] = min(max(tau, MIN_SPREAD), 1.0)
    return Population(spec.name, {p.name: pooled.theta[p.name] for p in spec.parameters},
                      spread, len(own))


def shrunk(spec: ModelSpec, fitted: Population) -> ModelSpec:
    """``spec`` with each parameter's prior replaced by the population's: centered on the
    pooled value, with the fitted spread (bounds unchanged)."""
    params = tuple(dataclasses.replace(
        p, prior_mean=math.log(fitted.center[p.name]) if p.log_scale else fitted.center[p.name],
        prior_std=fitted.spread[p.name] * p.prior_std) for p in spec.parameters)
    return dataclasses.replace(spec, parameters=params)


def partial_fits(spec: ModelSpec, people: Mapping[str, Sequence[RatedDrive]],
                 own: Mapping[str, Fit], pooled: Fit, seed: int = 0
                 ) -> tuple[Population, dict[str, Fit]]:
    """Every participant's partially pooled fit, and the population it is shrunk to.

    Args:
        spec: the model.
        people: each participant's rated drives.
        own: each participant's own fit (no pooling).
        pooled: the fit to all of them (complete pooling).
        seed: the fits' seed.
    """
    fitted = population(spec, pooled, own)
    prior = shrunk(spec, fitted)
    return fitted, {who: fit(prior, drives, seed) for who, drives in people.items()}


def held_out_partial(spec: ModelSpec, people: Mapping[str, Sequence[RatedDrive]],
                     own: Mapping[str, Fit], who: str, seed: int = 0, *,
                     fold: Sequence[str] | None = None, others: Fit | None = None) -> Score:
    """Leave-one-drive-out score of participant ``who``'s partially pooled fit, its
    population estimated from the participants outside ``who``'s fold only.

    Args:
        spec: the model.
        people: every participant's rated drives.
        own: every participant's own fit (those outside the fold are used).
        who: the participant scored.
        seed: the fits' seed.
        fold: the participants left out with ``who`` (default: ``who`` alone).
        others: the pooled fit to the participants outside the fold, when already made
            (:func:`~trust_monitor.trust_fit.fit` of their drives in ``people``'s order,
            with ``seed``); fitted here when None.

    Raises:
        FitError: fewer than :data:`MIN_PARTICIPANTS` participants, fewer than two outside
            the fold, or fewer than two drives of ``who``.
    """
    if len(people) < MIN_PARTICIPANTS:
        raise FitError(f'partial pooling scores need at least {MIN_PARTICIPANTS} '
                       f'participants, got {len(people)}')
    out = set(fold if fold is not None else [who]) | {who}
    if others is None:
        others = fit(spec, [d for k, drives in people.items() if k not in out for d in drives],
                     seed)
    return held_out(fold_prior(spec, own, out, others), [[d] for d in people[who]], SCHEME,
                    seed)


def fold_prior(spec: ModelSpec, own: Mapping[str, Fit], fold: Collection[str],
               others: Fit) -> ModelSpec:
    """``spec`` shrunk (:func:`shrunk`) toward the population of the participants outside
    ``fold``: their pooled fit ``others`` and their own fits.

    Raises:
        FitError: fewer than two own fits outside the fold.
    """
    return shrunk(spec, population(spec, others, {k: f for k, f in own.items()
                                                  if k not in fold}))
