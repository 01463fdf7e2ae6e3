"""Driver populations are seeded and deterministic; fit-driver reports a clear data error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from human_driver_sim.population import sample_population
from trust_av_planner.cli.main import main

PER_PAIR = np.array([[1.0, 0.01, 0.05, 0.001], [1.0, 0.02, 0.06, 0.002]])


def test_population_seeded() -> None:
    first = sample_population(PER_PAIR, 8, seed=1)
    assert np.array_equal(first, sample_population(PER_PAIR, 8, seed=1))
    assert not np.array_equal(first, sample_population(PER_PAIR, 8, seed=2))
    assert first.shape == (8, 4) and np.all(first > 0.0) and np.all(first[:, 0] == 1.0)


def test_fit_driver_missing_data(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(['fit-driver', '--data', str(tmp_path), '--out', str(tmp_path / 'o.yaml')]) == 2
    assert 'no *.csv files' in capsys.readouterr().err
