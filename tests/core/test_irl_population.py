"""Driver populations are seeded and deterministic; fit-driver reports a clear data error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from human_driver_sim.fitting import CAUTION_BOUNDS, MPC_BOUNDS
from human_driver_sim.population import (
    SAMPLED_SCALARS,
    sample_driver_params,
    sample_population,
)
from trust_av.cli.main import main
from trust_av.errors import TrustAvAppError
from trust_av.study.population import population_cases
from trust_av.study.sweep import Case

PER_PAIR = np.array([[1.0, 0.01, 0.05, 0.001], [1.0, 0.02, 0.06, 0.002]])


def test_population_seeded() -> None:
    first = sample_population(PER_PAIR, 8, seed=1)
    assert np.array_equal(first, sample_population(PER_PAIR, 8, seed=1))
    assert not np.array_equal(first, sample_population(PER_PAIR, 8, seed=2))
    assert first.shape == (8, 4) and np.all(first > 0.0) and np.all(first[:, 0] == 1.0)


def test_fit_driver_missing_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['fit-driver', '--data', str(tmp_path), '--out', str(tmp_path / 'o.yaml')]) == 2
    assert 'no *.csv files' in capsys.readouterr().err


PER_DRIVER = [
    {'weight_acceleration': 1.0, 'weight_desired_speed': 0.01, 'weight_relative_speed': 0.1,
     'weight_relative_distance': 0.002, 'time_headway_s': 0.9, 'desired_standstill_gap_m': 5.4,
     'av_extra_decel_mps2': 0.2},
    {'weight_acceleration': 1.0, 'weight_desired_speed': 0.02, 'weight_relative_speed': 0.3,
     'weight_relative_distance': 0.004, 'time_headway_s': 1.5, 'desired_standstill_gap_m': 6.0,
     'av_extra_decel_mps2': 1.4}]


def test_population_from_per_driver_fits_is_seeded_and_inside_the_fit_bounds() -> None:
    drawn = sample_driver_params(PER_DRIVER, 50, seed=3)
    assert drawn == sample_driver_params(PER_DRIVER, 50, seed=3)
    assert drawn != sample_driver_params(PER_DRIVER, 50, seed=4)
    bounds = {**MPC_BOUNDS, **CAUTION_BOUNDS}
    for name, (lo, hi) in SAMPLED_SCALARS.items():
        assert bounds[name] == (lo, hi)
        values = [d[name] for d in drawn]
        assert all(lo <= v <= hi for v in values)
        assert len(set(values)) > 40            # drawn, not copied
    # The caution is drawn around the fits' (mean 0.8, sd 0.6 m/s^2).
    assert 0.4 < float(np.mean([d['av_extra_decel_mps2'] for d in drawn])) < 1.2
    assert all(d['weight_acceleration'] == 1.0 for d in drawn)


def test_population_cases_use_per_driver_fits(tmp_path: Path) -> None:
    fit = tmp_path / 'fit.yaml'
    fit.write_text(yaml.safe_dump({'per_driver': {f'd{i}': p for i, p in
                                                  enumerate(PER_DRIVER)}}))
    cases = population_cases([Case('us06', 'ca', 0.5)], 3, 1, fit)
    assert [c.driver for c in cases] == [1, 2, 3]
    first = dict(cases[0].driver_params)
    assert set(first) == set(PER_DRIVER[0])
    assert first == sample_driver_params(PER_DRIVER, 3, seed=1)[0]
    fit.write_text(yaml.safe_dump({'per_driver': {'d0': {'weight_acceleration': 1.0}}}))
    with pytest.raises(TrustAvAppError, match=r"per_driver\['d0'\] must hold"):
        population_cases([Case('us06', 'ca', 0.5)], 3, 1, fit)
