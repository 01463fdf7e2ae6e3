"""Seeded driver populations sampled from per-pair fitted weights."""

from __future__ import annotations

import numpy as np


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
