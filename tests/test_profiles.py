"""The `as_reported` params file differs from the default only where the evidence says so."""

from __future__ import annotations

from pathlib import Path

from trust_av_planner.system.config import DEFAULT_PARAMS_FILE, load_run_config
from trust_monitor.common.params import read_params_file

AS_REPORTED = Path(__file__).resolve().parents[1] / 'config' / 'paper_as_reported.yaml'


def test_as_reported_changes_only_epsilon_and_the_explicability_scale() -> None:
    default = read_params_file(DEFAULT_PARAMS_FILE)
    reported = read_params_file(AS_REPORTED)
    assert set(default) == set(reported)
    changed = {(node, key): (default[node][key], reported[node].get(key))
               for node in default for key in set(default[node]) | set(reported[node])
               if default[node].get(key) != reported[node].get(key)}
    assert changed == {('/**', 'epsilon_mps2'): (6.0, 3.0),
                       ('/**/planner', 'explicability_scale'): (0.005, 0.02)}


def test_as_reported_loads() -> None:
    config = load_run_config(AS_REPORTED, {})
    assert config.trust.epsilon_mps2 == 3.0
    assert config.planner.explicability_scale == 0.02
