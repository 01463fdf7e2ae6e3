"""Platoons of recorded pairs and the cluster bootstrap of a mean over pairs: pairs that
share vehicles are resampled together, so the interval is not the too narrow one of
independent pairs."""

from __future__ import annotations

import math

import pytest

from human_driver_sim.evaluation import cluster_ci95, platoons
from trust_av_common.stats import mean_ci95


def test_pairs_that_share_a_vehicle_are_one_platoon() -> None:
    pairs = ['ngsim:1->2', 'ngsim:2->3', 'ngsim:7->8', 'ngsim:3->4', 'other:1->2']
    groups = platoons(pairs)
    assert groups['ngsim:1->2'] == groups['ngsim:2->3'] == groups['ngsim:3->4']
    assert len({groups['ngsim:1->2'], groups['ngsim:7->8'], groups['other:1->2']}) == 3
    with pytest.raises(ValueError, match='not a pair name'):
        platoons(['ngsim:12'])


def test_one_platoon_has_no_cluster_interval() -> None:
    low, high = cluster_ci95({'a:1->2': 0.1, 'a:2->3': 0.3, 'a:3->4': 0.2})
    assert math.isnan(low) and math.isnan(high)


def test_the_cluster_interval_is_wider_when_pairs_of_a_platoon_agree() -> None:
    """Ten platoons of five pairs each, the pairs of a platoon equal: there are ten
    independent values, not fifty, and the cluster interval is about as wide as the t
    interval over the ten platoon means, much wider than the one over fifty pairs."""
    values = {}
    for platoon in range(10):
        for k in range(5):
            values[f'p{platoon}:{k}->{k + 1}'] = float(platoon % 4) - 1.5
    mean, half_pairs = mean_ci95(list(values.values()))
    _, half_platoons = mean_ci95([float(p % 4) - 1.5 for p in range(10)])
    low, high = cluster_ci95(values)
    assert low < mean < high
    assert (high - low) / 2 > 1.8 * half_pairs
    assert (high - low) / 2 == pytest.approx(half_platoons, rel=0.35)
    assert cluster_ci95(values) == (low, high)      # seeded
