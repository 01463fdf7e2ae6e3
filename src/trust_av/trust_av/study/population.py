"""Sweeps over a population of drivers: each case once per sampled driver, the results per
driver and their mean (``trust-av reproduce --drivers K``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from human_driver_sim.population import (
    DRIVER_FIT_FILE,
    WEIGHT_NAMES,
    fitted_time_headway_s,
    per_driver_fits,
    per_pair_weights,
    sample_driver_params,
    sample_population,
)
from trust_av.errors import TrustAvAppError
from trust_av.study.sweep import Case

__all__ = ['by_driver', 'population_cases', 'population_mean']


def population_cases(cases: Sequence[Case], drivers: int, seed: int,
                     driver_fit: Path = DRIVER_FIT_FILE) -> list[Case]:
    """Each case once per driver of a seeded population of ``drivers`` sampled drivers.

    With per-driver fits in ``driver_fit`` (``per_driver``, written by ``fit-driver``) the
    population is :func:`human_driver_sim.population.sample_driver_params` of them (W,
    tau_H, d_s and the caution a_extra per driver); otherwise
    :func:`human_driver_sim.population.sample_population` of the per-pair fitted weights,
    each with the fit's time headway tau_H when the fit has one. The same seed gives the
    same drivers.

    Raises:
        TrustAvAppError: ``drivers`` < 1, or an unreadable driver-fit file.
    """
    if drivers < 1:
        raise TrustAvAppError(f'the number of drivers must be >= 1, got {drivers}')
    try:
        per_driver = per_driver_fits(driver_fit)
        if per_driver is not None:
            params = [tuple(row.items()) for row in
                      sample_driver_params(per_driver, drivers, seed=seed)]
        else:
            population = sample_population(per_pair_weights(driver_fit), drivers, seed=seed)
            time_headway_s = fitted_time_headway_s(driver_fit)
            extra = () if time_headway_s is None else (('time_headway_s', time_headway_s),)
            params = [tuple(zip(WEIGHT_NAMES, (float(w) for w in weights), strict=True))
                      + extra for weights in population]
    except ValueError as err:
        raise TrustAvAppError(str(err)) from err
    return [dataclasses.replace(case, driver=k + 1, driver_params=params[k])
            for case in cases for k in range(drivers)]


def by_driver(results: dict[Case, dict[str, Any]]) -> dict[int, dict[Case, dict[str, Any]]]:
    """Results split per driver, each keyed by the base case (trace, predictor, alpha)."""
    out: dict[int, dict[Case, dict[str, Any]]] = {}
    for case, result in results.items():
        out.setdefault(case.driver, {})[case.base] = result
    return out


def population_mean(results: dict[Case, dict[str, Any]]) -> dict[Case, dict[str, Any]]:
    """Per base case, the mean over drivers of every metric and of the trust series."""
    groups: dict[Case, list[dict[str, Any]]] = {}
    for case, result in results.items():
        groups.setdefault(case.base, []).append(result)
    out = {}
    for case, members in groups.items():
        out[case] = {
            'metrics': {name: float(np.mean([m['metrics'][name] for m in members]))
                        for name in members[0]['metrics']},
            'time_s': members[0]['time_s'],
            'trust': np.mean([m['trust'] for m in members], axis=0).tolist(),
            'drivers': len(members)}
    return out
