"""Seeded driver populations sampled from per-pair fitted weights."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from human_driver_sim.errors import HumanDriverSimError

__all__ = ['CAUTIOUS_FIT_FILE', 'DRIVER_FIT_FILE', 'SAMPLED_SCALARS', 'WEIGHT_NAMES',
           'DriverFitError', 'fitted_idm_params', 'fitted_time_headway_s', 'per_driver_fits',
           'per_pair_weights', 'sample_driver_params', 'sample_population']


def sample_population(per_pair_weights: np.ndarray, count: int, *, seed: int) -> np.ndarray:
    """Sample ``count`` weight vectors from a log-normal fitted to per-pair log-weights.

    w_a stays 1 (the normalisation); the other weights are drawn as exp(N(mu, Sigma)) with
    mu and the diagonal Sigma of the per-pair log-weights (floor 1e-6, std floor 0.05).

    Args:
        per_pair_weights: P x 4 weights (w_a, w_ds, w_rs, w_rd), P >= 1.
        count: Number of drivers K.
        seed: RNG seed (same seed, same population).

    Raises:
        ValueError: Bad shape or count.
    """
    weights = np.asarray(per_pair_weights, dtype=float)
    if weights.ndim != 2 or weights.shape[1] != 4 or weights.shape[0] < 1 or count < 1:
        raise ValueError('need per_pair_weights of shape (P >= 1, 4) and count >= 1')
    logs = np.log(np.maximum(weights[:, 1:] / weights[:, :1], 1e-6))
    mean = logs.mean(axis=0)
    std = np.maximum(logs.std(axis=0), 0.05)
    rng = np.random.default_rng(seed)
    draws = np.exp(rng.normal(mean, std, size=(count, 3)))
    return np.column_stack([np.ones(count), draws])


DRIVER_FIT_FILE = Path(__file__).parent / 'models' / 'driver_fit_caution.yaml'
"""The fit of the shipped human driver (``trust-av fit-driver``: fitted on the training split,
picked on the validation split, with its fitted caution; docs/DRIVER_IRL.md): its ``pooled``
is config/trust_av.yaml's driver, its per-driver fits the population's source."""
CAUTIOUS_FIT_FILE = Path(__file__).parent / 'models' / 'driver_fit.yaml'
"""The fit of the cautious driver (the profile config/human_cautious.yaml), made before the
train / validation / test split: its ``pooled`` and per-pair weights."""
WEIGHT_NAMES = ('weight_acceleration', 'weight_desired_speed', 'weight_relative_speed',
                'weight_relative_distance')
"""Driver-MPC parameter names of W, in the order of the weight vectors."""


class DriverFitError(HumanDriverSimError):
    """The driver-fit file is missing or malformed; the message names the file and key."""


def _read_fit(path: Path) -> dict[str, object]:
    try:
        fit = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise DriverFitError(f'{path}: cannot read the driver fit ({err})') from err
    if not isinstance(fit, dict):
        raise DriverFitError(f'{path}: not a driver-fit file (expected a mapping)')
    return fit


def fitted_time_headway_s(path: Path = DRIVER_FIT_FILE) -> float | None:
    """The pooled fit's time headway tau_H (s), or None for a fit that kept the config's.

    Raises:
        DriverFitError: unreadable file, or a tau_H that is not a positive number.
    """
    pooled = _read_fit(path).get('pooled')
    value = pooled.get('time_headway_s') if isinstance(pooled, dict) else None
    if value is None:
        return None
    if not isinstance(value, int | float) or value <= 0:
        raise DriverFitError(f'{path}: pooled.time_headway_s must be > 0, got {value!r}')
    return float(value)


def per_pair_weights(path: Path = DRIVER_FIT_FILE) -> np.ndarray:
    """The per-pair inverse-KKT weights of a driver-fit file, P x 4 (population source).

    Raises:
        DriverFitError: missing file, missing ``per_pair_inverse_kkt``, or a bad row.
    """
    fit = _read_fit(path)
    pairs = fit.get('per_pair_inverse_kkt')
    if not isinstance(pairs, dict) or not pairs:
        raise DriverFitError(f'{path}: no per_pair_inverse_kkt weights')
    rows = []
    for name, weights in pairs.items():
        if (not isinstance(weights, list) or len(weights) != len(WEIGHT_NAMES)
                or not all(isinstance(w, int | float) and w >= 0 for w in weights)):
            raise DriverFitError(f'{path}: per_pair_inverse_kkt[{name!r}] must be '
                                 f'{len(WEIGHT_NAMES)} non-negative numbers, got {weights!r}')
        rows.append([float(w) for w in weights])
    return np.array(rows)


SAMPLED_SCALARS: dict[str, tuple[float, float]] = {
    'time_headway_s': (0.5, 3.0), 'desired_standstill_gap_m': (5.0, 10.0),
    'av_extra_decel_mps2': (0.0, 3.0)}
"""Per-driver parameters besides W that a population draws, with the fit's bounds
(``fitting.MPC_BOUNDS``, ``fitting.CAUTION_BOUNDS``; a test keeps them equal)."""


def per_driver_fits(path: Path = DRIVER_FIT_FILE) -> list[dict[str, float]] | None:
    """The per-driver fits of a driver-fit file (``per_driver``), or None if it has none.

    Raises:
        DriverFitError: a driver whose fit lacks a weight or holds a bad number.
    """
    section = _read_fit(path).get('per_driver')
    if section is None:
        return None
    if not isinstance(section, dict) or not section:
        raise DriverFitError(f'{path}: per_driver must map drivers to their fitted parameters')
    out = []
    for name, params in section.items():
        names = (*WEIGHT_NAMES, *(n for n in SAMPLED_SCALARS if isinstance(params, dict)
                                  and n in params))
        if not isinstance(params, dict) or any(
                not isinstance(params.get(n), int | float) or params[n] < 0 for n in names):
            raise DriverFitError(f'{path}: per_driver[{name!r}] must hold '
                                 f'{", ".join(WEIGHT_NAMES)} as non-negative numbers')
        out.append({n: float(params[n]) for n in names})
    return out


def sample_driver_params(per_driver: list[dict[str, float]], count: int, *,
                         seed: int) -> list[dict[str, float]]:
    """``count`` drivers drawn from per-driver fits: W as :func:`sample_population` does
    (log-normal), each of :data:`SAMPLED_SCALARS` that every fit holds from a normal with the
    fits' mean and standard deviation (floor 1 % of its range), clipped to its bounds.

    Args:
        per_driver: The fits (:func:`per_driver_fits`), at least one.
        count: Number of drivers K.
        seed: RNG seed (same seed, same population).

    Raises:
        ValueError: No fits or count < 1.
    """
    if not per_driver or count < 1:
        raise ValueError('need at least one per-driver fit and count >= 1')
    weights = sample_population(np.array([[f[n] for n in WEIGHT_NAMES] for f in per_driver]),
                                count, seed=seed)
    drawn: list[dict[str, float]] = [dict(zip(WEIGHT_NAMES, (float(w) for w in row),
                                              strict=True)) for row in weights]
    rng = np.random.default_rng([seed, 1])
    for name, (lo, hi) in SAMPLED_SCALARS.items():
        if not all(name in f for f in per_driver):
            continue
        values = np.array([f[name] for f in per_driver])
        std = max(float(values.std()), 0.01 * (hi - lo))
        for row, value in zip(drawn, rng.normal(values.mean(), std, size=count), strict=True):
            row[name] = float(np.clip(value, lo, hi))
    return drawn


def fitted_idm_params(path: Path = DRIVER_FIT_FILE) -> dict[str, float]:
    """The bounded IDM fitted beside the driver (``idm`` section of a driver-fit file).

    Raises:
        DriverFitError: missing section, or a parameter that is not a positive number.
    """
    section = _read_fit(path).get('idm')
    names = ('desired_speed_mps', 'time_headway_s', 'min_gap_m', 'max_accel_mps2',
             'comfort_decel_mps2')
    if not isinstance(section, dict) or any(
            not isinstance(section.get(n), int | float) or section[n] <= 0 for n in names):
        raise DriverFitError(f'{path}: idm must hold {", ".join(names)} as positive numbers')
    return {n: float(section[n]) for n in names}
